"""The one interpreter of option values: every kind of option (a length, an angle, a pose, a
file, ...) says here, once, how a value is read and which values are valid.

A parameter dataclass field (:mod:`grasplan.config.params`) carries an :class:`OptionSpec` in its
``metadata`` (:func:`spec`): its kind, CLI spelling, range, help. From it
- :func:`parse_value` reads a value given as text (a command-line argument, a CSV cell) or as a
  plain value (YAML, JSON, Python): ``"2mm"`` -> ``0.002``, ``"15deg"`` -> ``15.0``, ``"none"``
  -> ``None`` for an optional option, ``"0.45,0.3,0,0,0,180"`` -> a 4x4 pose. The command line's
  click types (:mod:`grasplan.cli.options`) and the batch manifests (:mod:`grasplan.batch.manifest`)
  both call it, so one text means one value everywhere;
- :func:`check_fields` validates a dataclass's values (its ``__post_init__``): the kind and the
  range, :class:`~grasplan.errors.InputError` naming the CLI option, the value and what would pass.

The kinds and where an output records an option: :class:`OptionSpec`.
"""
from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import Field, dataclass, field, fields
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..geometry.units import parse_angle_deg, parse_length

#: the largest length any option accepts, m (a cell is a few metres; 1e308 is refused)
MAX_LENGTH = 10.0
#: the longest seconds option, s (one day)
MAX_SECONDS = 86400.0
#: whole numbers read from text stay below this magnitude
MAX_INT = 2**62
#: text read as True / False for a ``bool`` option
TRUE_WORDS = ("1", "true", "yes", "on")
FALSE_WORDS = ("0", "false", "no", "off")
#: text read as None for an optional option
NONE_WORDS = ("none", "null")
RECORDS = ("always", "elsewhere", "never")


@dataclass(frozen=True)
class OptionSpec:
    """What a parameter field is as an option.

    Kinds (``optional=True``: None allowed)::

        length    m, lo < v <= hi (default (0, MAX_LENGTH]); text with a unit suffix (2mm); 0 refused
        length0   m, 0 <= v <= hi; 0 means "off"
        angle     degrees (text: 15, 15deg, 0.26rad); lo/hi
        float     a finite number; lo/hi (lo_open: lo excluded)
        seconds   a finite number of seconds in (0, hi] (default hi one day)
        int       a whole number; lo/hi; ``words`` are also accepted (pose_index: "all")
        bool      true/false (text: true, yes, on, 1 / false, no, off, 0; a --x/--no-x flag on the CLI)
        choice    one of ``choices``
        pose      a rigid transform (4, 4) kept as a nested tuple; text 'x,y,z,roll,pitch,yaw' (lengths
                  m or with units, angles deg, R = Rz(yaw) Ry(pitch) Rx(roll)), the same six as a list,
                  or a 4x4 matrix
        file      a file name (text; relative to the manifest's folder in a manifest); read by its owner
        internal  not an option (no CLI, no manifest column): validated by the dataclass itself

    ``record`` says where an output file records the option: ``"always"`` (the dataclass's
    ``to_json``, the default), ``"elsewhere"`` (another part of the output holds it, e.g. the place
    in the plan's ``cell.place``: left out of ``to_json``, kept in ``options_json``) or ``"never"``
    (an input read into other fields, e.g. the scoring file into the score weights).
    """

    kind: str
    help: str
    cli: str | None = None  #: CLI spelling, default ``--field-name``
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    choices: tuple[str, ...] = ()
    words: tuple[str, ...] = ()  #: an ``int`` option also accepts these words
    optional: bool = False  #: None allowed
    flag: str | None = None  #: a bool's click flag, e.g. ``--blm/--no-blm``
    show: str | None = None  #: the default as shown in ``--help``
    metavar: str | None = None
    record: str = "always"

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"unknown option kind {self.kind!r}; known: {', '.join(KINDS)}")
        if self.record not in RECORDS:
            raise ValueError(f"record {self.record!r}: use one of {', '.join(RECORDS)}")


def spec(default: Any, kind: str, help: str, **options: Any) -> Any:
    """A dataclass field that is an option: ``default``, :class:`OptionSpec` ``(kind, help, **options)``.

    A field whose value is given by its file (``record="never"``) takes no part in equality."""
    s = OptionSpec(kind, help, **options)
    return field(default=default, metadata={"option": s}, compare=s.record != "never")


def option_spec(f: Field) -> OptionSpec | None:
    """The :class:`OptionSpec` of a dataclass field (None: not an option)."""
    s = f.metadata.get("option")
    return s if isinstance(s, OptionSpec) else None


def is_option(f: Field) -> bool:
    """A field the user sets (a CLI option, a manifest column): not ``internal``."""
    s = option_spec(f)
    return s is not None and s.kind != "internal"


def option_name(f: Field) -> str:
    """The CLI spelling of a dataclass field (``--roll-step`` for ``roll_step_deg``)."""
    s = option_spec(f)
    return (s.cli if s is not None and s.cli else None) or "--" + f.name.replace("_", "-")


# ---------------------------------------------------------------------------------------- reading
class _Refused(Exception):
    """A value a kind cannot read: the reason (the caller names the option)."""


def _number(value: Any) -> float:
    if isinstance(value, bool):
        raise _Refused(f"expected a number, got {value!r}")
    if isinstance(value, (int, float)):
        v = float(value)
    else:
        try:
            v = float(str(value).strip())
        except ValueError:
            raise _Refused(f"{value!r} is not a number") from None
    if not math.isfinite(v):
        raise _Refused(f"{value!r} is not a finite number")
    return v


def _read_length(value: Any, s: OptionSpec, name: str) -> float:
    return parse_length(value, name=name, allow_zero=s.kind == "length0")


def _read_angle(value: Any, s: OptionSpec, name: str) -> float:
    return parse_angle_deg(value, name=name)


def _read_float(value: Any, s: OptionSpec, name: str) -> float:
    return _number(value)


def _read_int(value: Any, s: OptionSpec, name: str) -> int | str:
    if isinstance(value, str) and value.strip().lower() in s.words:
        return value.strip().lower()
    if isinstance(value, bool):
        raise _Refused(f"expected a whole number, got {value!r}")
    if isinstance(value, int):
        v = value
    elif isinstance(value, float) and value.is_integer():
        v = int(value)
    else:
        try:
            v = int(str(value).strip())
        except ValueError:
            alt = "".join(f" nor {w!r}" for w in s.words)
            raise _Refused(f"{value!r} is {'neither' if alt else 'not'} a whole number{alt}") from None
    if abs(v) >= MAX_INT:
        raise _Refused(f"{value!r} is out of range")
    return v


def _read_bool(value: Any, s: OptionSpec, name: str) -> bool:
    if isinstance(value, bool):
        return value
    text = str(value).strip().lower()
    if text in TRUE_WORDS:
        return True
    if text in FALSE_WORDS:
        return False
    raise _Refused(f"expected true or false, got {value!r}")


def _read_choice(value: Any, s: OptionSpec, name: str) -> str:
    text = str(value).strip()
    if text not in s.choices:
        raise _Refused(f"{text!r} is not one of {', '.join(s.choices)}")
    return text


def _read_pose(value: Any, s: OptionSpec, name: str) -> tuple[tuple[float, ...], ...]:
    from ..geometry.transforms import check_transform, parse_pose_text

    if isinstance(value, (list, tuple)) and len(value) == 6 and not any(isinstance(v, (list, tuple)) for v in value):
        value = ",".join(map(str, value))  # YAML [x, y, z, roll, pitch, yaw]: read as the text form
    if isinstance(value, str):
        if len(value) > 4096 or "\x00" in value:
            raise _Refused("expected 'x,y,z,roll,pitch,yaw' (m or with units; degrees)")
        return as_pose(parse_pose_text(value, name))
    return as_pose(check_transform(value, name))


def _read_file(value: Any, s: OptionSpec, name: str) -> str:
    text = os.fspath(value) if isinstance(value, (str, os.PathLike)) else None
    if not text or not str(text).strip():
        raise _Refused("expected a file name")
    if "\x00" in str(text) or len(str(text)) > 4096:
        raise _Refused("expected a file name (no NUL, at most 4096 characters)")
    return str(Path(str(text)).expanduser())


def _read_internal(value: Any, s: OptionSpec, name: str) -> Any:
    raise _Refused("not an option: set it in Python (it has no command-line or manifest form)")


# ------------------------------------------------------------------------------------------ checks
def _range(v: float, s: OptionSpec) -> str | None:
    lo, hi = s.lo, s.hi
    if lo is not None and (v < lo or (s.lo_open and v == lo)):
        return f"must be {'>' if s.lo_open else '>='} {lo:g}" + (f" and <= {hi:g}" if hi is not None else "")
    if hi is not None and v > hi:
        return f"must be <= {hi:g}" + (f" and >= {lo:g}" if lo is not None else "")
    return None


def _finite(v: Any) -> str | None:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        return "expected a finite number"
    return None


def _check_length(v: Any, s: OptionSpec) -> str | None:
    if (why := _finite(v)) is not None:
        return why
    lo, hi = (s.lo if s.lo is not None else 0.0), (s.hi if s.hi is not None else MAX_LENGTH)
    return None if lo < v <= hi else f"expected a length in ({lo:g}, {hi:g}] m (e.g. 2mm)"


def _check_length0(v: Any, s: OptionSpec) -> str | None:
    if (why := _finite(v)) is not None:
        return why
    hi = s.hi if s.hi is not None else MAX_LENGTH
    return None if 0.0 <= v <= hi else f"expected a length in [0, {hi:g}] m (0 = off)"


def _check_seconds(v: Any, s: OptionSpec) -> str | None:
    if (why := _finite(v)) is not None:
        return why
    hi = s.hi if s.hi is not None else MAX_SECONDS
    return None if 0.0 < v <= hi else f"expected seconds in (0, {hi:g}]"


def _check_number(v: Any, s: OptionSpec) -> str | None:
    return _finite(v) or _range(v, s)


def _check_int(v: Any, s: OptionSpec) -> str | None:
    if isinstance(v, str) and v in s.words:
        return None
    if isinstance(v, bool) or not isinstance(v, int):
        return "expected a whole number" + "".join(f" or {w!r}" for w in s.words)
    return _range(v, s)


def _check_bool(v: Any, s: OptionSpec) -> str | None:
    return None if isinstance(v, bool) else "expected true or false"


def _check_choice(v: Any, s: OptionSpec) -> str | None:
    return None if v in s.choices else f"expected one of {', '.join(map(str, s.choices))}"


def _check_pose(v: Any, s: OptionSpec) -> str | None:
    from ..geometry.transforms import check_transform

    try:
        check_transform(v, "pose")
    except InputError as exc:
        return str(exc).removeprefix("pose: ")
    return None


def _check_file(v: Any, s: OptionSpec) -> str | None:
    return None if isinstance(v, str) and v.strip() else "expected a file name"


def _check_internal(v: Any, s: OptionSpec) -> str | None:
    return None  # the dataclass's own _check validates it


@dataclass(frozen=True)
class Kind:
    """How one kind of option is read (text or a plain value -> the value) and checked (a reason
    or None); ``metavar`` names it in ``--help``; ``coerce`` turns a valid value into the form the
    frozen dataclass keeps (a pose given as an array -> a nested tuple)."""

    read: Callable[[Any, OptionSpec, str], Any]
    check: Callable[[Any, OptionSpec], str | None]
    metavar: str
    coerce: Callable[[Any], Any] | None = None


KINDS: dict[str, Kind] = {
    "length": Kind(_read_length, _check_length, "LENGTH"),
    "length0": Kind(_read_length, _check_length0, "LENGTH"),
    "angle": Kind(_read_angle, _check_number, "DEG"),
    "float": Kind(_read_float, _check_number, "NUMBER"),
    "seconds": Kind(_read_float, _check_seconds, "SECONDS"),
    "int": Kind(_read_int, _check_int, "INTEGER"),
    "bool": Kind(_read_bool, _check_bool, "BOOLEAN"),
    "choice": Kind(_read_choice, _check_choice, "CHOICE"),
    "pose": Kind(_read_pose, _check_pose, "X,Y,Z,ROLL,PITCH,YAW", coerce=lambda v: as_pose(v)),
    "file": Kind(_read_file, _check_file, "FILE"),
    "internal": Kind(_read_internal, _check_internal, ""),
}


def as_pose(T: Any) -> tuple[tuple[float, ...], ...]:
    """A (4, 4) transform as the nested tuple a frozen dataclass keeps (hashable, exact floats)."""
    import numpy as np

    return tuple(tuple(float(x) for x in row) for row in np.asarray(T, dtype=np.float64))


def metavar(s: OptionSpec) -> str:
    """The placeholder of an option in ``--help``."""
    if s.metavar:
        return s.metavar
    if s.kind == "choice":
        return "[" + "|".join(s.choices) + "]"
    return KINDS[s.kind].metavar + "".join(f"|{w}" for w in s.words)


def read_value(s: OptionSpec, value: Any, name: str, *, base_dir: str | os.PathLike | None = None) -> Any:
    """``value`` read as an option of spec ``s`` named ``name`` (the one reading of every kind):
    text (command line, CSV) or a plain value (YAML, JSON, Python); the range is the dataclass's
    to check (:func:`check_fields`). ``"none"`` / ``"null"`` (or None) give None when ``s.optional``.
    ``base_dir``: a relative ``file`` is relative to it (a manifest's folder). InputError naming ``name``."""
    if value is None or (isinstance(value, str) and value.strip().lower() in NONE_WORDS):
        if s.optional:
            return None
        raise InputError(f"{name}: a value is required (it has no 'none')")
    try:
        v = KINDS[s.kind].read(value, s, name)
    except _Refused as exc:
        raise InputError(f"{name}: {exc}") from None
    if s.kind == "file" and base_dir is not None and not Path(v).is_absolute():
        v = str(Path(base_dir) / v)
    return v


def parse_value(f: Field, value: Any, *, where: str = "", base_dir: str | os.PathLike | None = None) -> Any:
    """``value`` for the option field ``f`` (:func:`read_value`); messages name ``where`` and the
    field's CLI spelling."""
    s = option_spec(f)
    if s is None:
        raise InputError(f"{where}{f.name}: not an option")
    return read_value(s, value, f"{where}{option_name(f)}", base_dir=base_dir)


def check_fields(obj: Any) -> None:
    """Validate every option field of the frozen dataclass ``obj`` (and keep each valid value in
    its kind's form); InputError naming the CLI option, the field, why and the value (e.g.
    ``--alpha (alpha): expected a length in (0, 0.1] m (e.g. 2mm), got 0.0``)."""
    for f in fields(obj):
        s = option_spec(f)
        if s is None:
            continue
        v = getattr(obj, f.name)
        if v is None and s.optional:
            continue
        kind = KINDS[s.kind]
        why = kind.check(v, s)
        if why is not None:
            raise InputError(f"{option_name(f)} ({f.name}): {why}, got {_show(v)}")
        if kind.coerce is not None:
            object.__setattr__(obj, f.name, kind.coerce(v))


def _show(v: Any) -> str:
    text = repr(v)
    return text if len(text) <= 200 else text[:197] + "..."
