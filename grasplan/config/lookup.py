"""Finding described things (grippers, cells, robots) by name or by path, and reading YAML numbers.

One rule tells a name from a path (:func:`is_path_like`): a reference is a path when it ends in
``.yaml``/``.yml`` (any case), holds a path separator, or names an existing file (relative to the
folder of the document that names it: :func:`document_ref`); anything else is a name. A name's
YAML is the first ``<name>.yaml`` found in: ``--config-dir DIR`` (CLI) / :func:`use_config_dirs`
(API), in the order given; ``$GRASPLAN_CONFIG_PATH`` (folders separated by ``os.pathsep``);
``./configs`` and ``./robots`` of the current folder; the descriptions packaged inside grasplan
(``grasplan/data``). A config folder holds ``grippers/``, ``cells/`` and ``robots/`` (or, laid out
like this repository, ``configs/grippers``, ``configs/cells`` and ``robots/``). An unknown name
lists every folder looked in and the names found there.
"""
from __future__ import annotations

import contextlib
import contextvars
import math
import os
import re
from collections.abc import Iterator, Sequence
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError

#: descriptions shipped inside the package (also reached through the repository's
#: top-level ``configs`` and ``robots`` links)
PACKAGED_DIR = Path(str(resources.files("grasplan") / "data"))
#: kind -> sub-folder of a config folder
KIND_FOLDERS = {"gripper": "grippers", "cell": "cells", "robot": "robots"}
ENV_VAR = "GRASPLAN_CONFIG_PATH"

_CONFIG_DIRS: contextvars.ContextVar[tuple[Path, ...]] = contextvars.ContextVar("grasplan_config_dirs", default=())


def set_config_dirs(dirs: Sequence[str | os.PathLike]) -> None:
    """Put ``dirs`` first in the lookup order (what ``--config-dir`` does) for this context."""
    out = []
    for d in dirs:
        p = Path(d).expanduser()
        try:
            ok = p.is_dir()
        except (OSError, ValueError):
            ok = False
        if not ok:
            raise ConfigError(f"--config-dir {str(p)[:200]}: no such folder (give a folder holding grippers/, "
                              "cells/ or robots/)")
        out.append(p.resolve())
    _CONFIG_DIRS.set(tuple(out))


@contextlib.contextmanager
def use_config_dirs(*dirs: str | os.PathLike) -> Iterator[None]:
    """Context manager: look in ``dirs`` first (API twin of ``--config-dir``)."""
    token = _CONFIG_DIRS.set(())
    try:
        set_config_dirs(dirs)
        yield
    finally:
        _CONFIG_DIRS.reset(token)


def _roots_sub(root: Path, sub: str) -> list[Path]:
    if sub == "robots":
        return [root / "robots"]
    return [root / sub, root / "configs" / sub]


def search_path(kind: str) -> list[Path]:
    """The folders looked in for ``kind`` ("gripper", "cell" or "robot"), in lookup order."""
    sub = KIND_FOLDERS[kind]
    folders: list[Path] = []
    for d in _CONFIG_DIRS.get():
        folders += _roots_sub(d, sub)
    for entry in os.environ.get(ENV_VAR, "").split(os.pathsep):
        if entry.strip():
            folders += _roots_sub(Path(entry).expanduser(), sub)
    cwd = Path.cwd()
    folders.append(cwd / "robots" if sub == "robots" else cwd / "configs" / sub)
    folders.append(PACKAGED_DIR / "robots" if sub == "robots" else PACKAGED_DIR / "configs" / sub)
    seen: set[Path] = set()
    out: list[Path] = []
    for f in folders:
        key = f.resolve() if f.exists() else f
        if key not in seen:
            seen.add(key)
            out.append(f)
    return out


def available(kind: str) -> list[str]:
    """Names of the ``kind`` descriptions found anywhere on the search path, sorted."""
    names: set[str] = set()
    for folder in search_path(kind):
        if folder.is_dir():
            names.update(p.stem for p in folder.glob("*.yaml"))
    return sorted(names)


def _looked(kind: str) -> str:
    rows = []
    for folder in search_path(kind):
        found = sorted(p.stem for p in folder.glob("*.yaml")) if folder.is_dir() else None
        rows.append(f"{folder} ({', '.join(found) or 'empty'})" if found is not None else f"{folder} (missing)")
    return "; ".join(rows)


def is_path_like(ref: str | os.PathLike, base: Path | None = None) -> bool:
    """True when ``ref`` is a path, False when it is a name: the one rule (module docstring) every
    loader, the output guard and the scene reader and writer apply. A path ends in ``.yaml`` or
    ``.yml`` (any case), holds a path separator, or names an existing file, looked for in ``base``
    (the folder of the document that names it; None: the current folder)."""
    s = os.fspath(ref)
    if s.lower().endswith((".yaml", ".yml")) or "/" in s or os.sep in s:
        return True
    try:
        return (Path(s) if base is None else Path(base) / s).is_file()
    except (OSError, ValueError):  # a name too long for the file system is no file
        return False


def document_ref(ref: str, base: Path | None) -> str:
    """A reference written in a document whose folder is ``base`` (a scene's ``cell``), as a loader
    takes it: a path (:func:`is_path_like` in ``base``) made absolute against ``base`` (``~``
    expanded), a name unchanged. ``base`` None: the current folder (the path stays as written)."""
    if not is_path_like(ref, base):
        return ref
    p = Path(ref).expanduser()
    return str(p if p.is_absolute() or base is None else Path(base) / p)


def resolve_yaml(kind: str, name_or_path: str | os.PathLike) -> Path:
    """The YAML file for ``name_or_path`` (absolute path); raises ConfigError naming what exists."""
    s = str(name_or_path)
    if not s or "\x00" in s or len(s) > 255:
        raise ConfigError(f"invalid {kind} name {s[:80]!r}; available {kind}s: {', '.join(available(kind)) or '(none)'}")
    if is_path_like(s):
        p = Path(s).expanduser()
        try:
            ok = p.is_file()
        except OSError:
            ok = False
        if not ok:
            raise ConfigError(f"{kind} file {p} not found; give an existing YAML file or a name "
                              f"({', '.join(available(kind)) or 'none found'})")
        return p.resolve()
    for folder in search_path(kind):
        candidate = folder / f"{s}.yaml"
        if candidate.is_file():
            return candidate.resolve()
    names = ", ".join(available(kind)) or "(none)"
    raise ConfigError(f"unknown {kind} {s!r}; available: {names}. Looked in: {_looked(kind)}. "
                      f"Give a path to a {kind} YAML, --config-dir DIR or ${ENV_VAR}")


#: a description file larger than this is refused before it is parsed
MAX_CONFIG_BYTES = 1_000_000


def read_yaml(kind: str, path: Path) -> Any:
    """Parse a gripper/cell/robot YAML with the one YAML reader (:func:`grasplan.config.yamlfile.read_yaml_file`:
    a regular file of at most :data:`MAX_CONFIG_BYTES`, no Python tags, alias bombs, duplicate keys
    and unconstructible values refused naming the field): whatever the document holds, for the
    caller to validate; ConfigError for an unreadable, binary, oversized or invalid file."""
    from ..errors import InputError
    from .yamlfile import read_yaml_file

    try:
        return read_yaml_file(path, what=f"{kind} file", max_bytes=MAX_CONFIG_BYTES)
    except ConfigError:
        raise
    except InputError as exc:
        raise ConfigError(str(exc)) from None


def packaged_file(*parts: str) -> Path:
    """A file shipped in ``grasplan/data`` (e.g. ``packaged_file("configs", "paper_parts.yaml")``)."""
    return PACKAGED_DIR.joinpath(*parts)


# ------------------------------------------------------------------------------------------------
# numbers in YAML files: a tiny grammar, never Python's eval
# ------------------------------------------------------------------------------------------------
_TOKEN = re.compile(r"\s*(?:(\d+\.?\d*(?:[eE][-+]?\d+)?|\.\d+(?:[eE][-+]?\d+)?)|(pi)|([-+*/()]))")
_MAX_EXPR = 64


def parse_number_expr(text: str) -> float:
    """A number or an expression of numbers, ``pi``, ``+ - * /``, unary signs and parentheses
    (``-pi/2``, ``3*pi/4``, ``1e-3``). Raises ValueError for anything else (at most 64 chars)."""
    if len(text) > _MAX_EXPR:
        raise ValueError("too long")
    tokens: list[tuple[str, str]] = []
    pos, s = 0, text.strip()
    while pos < len(s):
        m = _TOKEN.match(s, pos)
        if not m or m.end() == pos:
            raise ValueError(f"unexpected {s[pos:pos + 10]!r}")
        num, pi, op = m.groups()
        tokens.append(("n", num) if num else ("pi", "pi") if pi else ("op", op))
        pos = m.end()
    i = 0

    def peek() -> str | None:
        return tokens[i][1] if i < len(tokens) else None

    def take() -> tuple[str, str]:
        nonlocal i
        i += 1
        return tokens[i - 1]

    def expr(depth: int) -> float:
        v = term(depth)
        while peek() in ("+", "-"):
            op = take()[1]
            r = term(depth)
            v = v + r if op == "+" else v - r
        return v

    def term(depth: int) -> float:
        v = unary(depth)
        while peek() in ("*", "/"):
            op = take()[1]
            r = unary(depth)
            if op == "/" and r == 0:
                raise ValueError("division by zero")
            v = v * r if op == "*" else v / r
        return v

    def unary(depth: int) -> float:
        if depth > 8:
            raise ValueError("nested too deep")
        if peek() in ("+", "-"):
            op = take()[1]
            v = unary(depth + 1)
            return -v if op == "-" else v
        return atom(depth)

    def atom(depth: int) -> float:
        if i >= len(tokens):
            raise ValueError("unexpected end")
        kind, val = take()
        if kind == "n":
            return float(val)
        if kind == "pi":
            return math.pi
        if val == "(":
            v = expr(depth + 1)
            if peek() != ")":
                raise ValueError("missing )")
            take()
            return v
        raise ValueError(f"unexpected {val!r}")

    if not tokens:
        raise ValueError("empty")
    out = expr(0)
    if i != len(tokens):
        raise ValueError("trailing text")
    return out


def config_number(value: object, where: str, *, positive: bool = False, nonneg: bool = False,
                  max_abs: float = 1e6) -> float:
    """A float from a YAML scalar: a number, or an expression of numbers and ``pi`` (``-pi/2``).

    Finite and at most ``max_abs`` in magnitude (lengths in metres, angles; 1e6 by default)."""
    if isinstance(value, bool):
        raise ConfigError(f"{where}: expected a number, got {value!r}")
    if isinstance(value, (int, float)):
        out = float(value) if abs(value) < 1e300 or not isinstance(value, int) else math.inf
    elif isinstance(value, str):
        try:
            out = parse_number_expr(value)
        except (ValueError, OverflowError):
            shown = value if len(value) <= 40 else value[:40] + "..."
            raise ConfigError(f"{where}: cannot read {shown!r} as a number (use e.g. 1.57 or -pi/2)") from None
    else:
        shown = repr(value)
        raise ConfigError(f"{where}: expected a number, got {shown[:60]}")
    if not math.isfinite(out):
        raise ConfigError(f"{where}: must be finite, got {value!r}")
    if abs(out) > max_abs:
        shown = f"{value[:40]!r} = {out:g}" if isinstance(value, str) else f"{out:g}"  # an expression: both
        raise ConfigError(f"{where}: {shown} is out of range (|value| <= {max_abs:g})")
    if positive and out <= 0:
        raise ConfigError(f"{where}: must be > 0, got {value!r}")
    if nonneg and out < 0:
        raise ConfigError(f"{where}: must be >= 0, got {value!r}")
    return out


def config_vector(value: object, where: str, n: int | None = 3, *, positive: bool = False) -> np.ndarray:
    """``(n,)`` float64 from a YAML list of numbers (each read by :func:`config_number`)."""
    if not isinstance(value, (list, tuple)):
        raise ConfigError(f"{where}: expected a list of {n or 'some'} numbers, got {str(value)[:60]!r}")
    if n is not None and len(value) != n:
        raise ConfigError(f"{where}: expected a list of {n} numbers, got {len(value)}")
    if len(value) > 10000:
        raise ConfigError(f"{where}: list too long ({len(value)})")
    return np.array([config_number(v, f"{where}[{i}]", positive=positive) for i, v in enumerate(value)],
                    dtype=np.float64)
