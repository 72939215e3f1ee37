"""Every command's options, built from the parameter dataclasses (:mod:`grasplan.params`).

``@param_options(CandidateParams, GraspParams)`` adds one click option per dataclass field, with the
field's default, help, CLI spelling and value type (lengths take unit suffixes, angles degrees);
:func:`params_from_kwargs` pops them again and builds the dataclasses, which validate the ranges
(InputError, exit 3, naming the option and what would pass). Parsing errors (``--top x``,
``--alpha 5parsecs``, ``--mu nan``) are click usage errors (exit 2). Commands only parse, call and print.
"""
from __future__ import annotations

import math
from dataclasses import MISSING, fields

import click

from ..params import (
    DEFAULT_CELL,
    DEFAULT_GRIPPER,
    DEFAULT_ROBOT,
    PARAM_CLASSES,
    CandidateParams,
    GraspParams,
    PlanParams,
    option_name,
)
from .common import ANGLE, LENGTH, LENGTH_OR_ZERO, units_option

#: which keyword of params_from_kwargs' result each class fills
PARAM_KEYS = {CandidateParams: "candidates", GraspParams: "grasps", PlanParams: "planning"}


class FiniteFloat(click.ParamType):
    """A finite number (NaN and inf are usage errors; ranges are the dataclass's to check)."""

    name = "NUMBER"

    def convert(self, value, param, ctx):
        if isinstance(value, float) and math.isfinite(value):
            return value
        try:
            v = float(str(value).strip())
        except ValueError:
            self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(v):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return v


class BoundedInt(click.ParamType):
    """A whole number that fits in 64 bits (ranges are the dataclass's to check)."""

    name = "INTEGER"

    def convert(self, value, param, ctx):
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        try:
            v = int(str(value).strip())
        except ValueError:
            self.fail(f"{value!r} is not a whole number", param, ctx)
        if abs(v) >= 2**62:
            self.fail(f"{value!r} is out of range", param, ctx)
        return v


FLOAT = FiniteFloat()
INT = BoundedInt()


def _click_type(kind: str, choices: tuple):
    base = kind.removeprefix("optional_")
    return {"length": LENGTH, "length0": LENGTH_OR_ZERO, "angle": ANGLE, "float": FLOAT, "seconds": FLOAT,
            "int": INT}.get(base) or (click.Choice(choices) if base == "choice" else None)


def _option(f):
    md = f.metadata
    default = f.default if f.default is not MISSING else None
    name = option_name(f)
    if md["kind"] == "bool":
        flag = md.get("flag") or f"{name}/--no-{name[2:]}"
        return click.option(flag, f.name, default=default, show_default=True, help=md["help"])
    show = md.get("show") if md.get("show") is not None else (default if default is not None else False)
    if md["kind"].startswith("optional_") and default is None:
        show = False
    return click.option(name, f.name, type=_click_type(md["kind"], md.get("choices", ())), default=default,
                        show_default=show, help=md["help"])


def param_options(*classes, exclude: tuple[str, ...] = (), only: tuple[str, ...] | None = None):
    """Decorator: one click option per (non-internal) field of each parameter class (all but
    ``exclude``, or just ``only``)."""
    opts = [_option(f) for cls in classes for f in fields(cls)
            if f.metadata.get("kind") not in (None, "internal") and f.name not in exclude
            and (only is None or f.name in only)]

    def deco(fn):
        for o in reversed(opts):
            fn = o(fn)
        return fn
    return deco


def params_from_kwargs(kwargs: dict, classes=PARAM_CLASSES) -> dict:
    """Pop the parameter options from click's ``kwargs`` and build the dataclasses:
    ``{"candidates": CandidateParams, "grasps": GraspParams, "planning": PlanParams}`` (those asked for)."""
    out = {}
    for cls in classes:
        names = {f.name for f in fields(cls)}
        kw = {k: kwargs.pop(k) for k in list(kwargs) if k in names}
        out[PARAM_KEYS[cls]] = cls(**kw)
    return out


def config_dir_option(fn):
    return click.option("--config-dir", "config_dir", multiple=True, type=click.Path(file_okay=False),
                        help="Look up gripper, cell and robot names here first (folders with grippers/, cells/, "
                             "robots/); then $GRASPLAN_CONFIG_PATH, ./configs and ./robots, then the packaged ones. "
                             "Repeatable.")(fn)


def apply_config_dirs(kwargs: dict) -> None:
    """Pop ``config_dir`` and put it first in the config lookup (before anything resolves a name)."""
    from ..config_files import set_config_dirs

    dirs = kwargs.pop("config_dir", ())
    if dirs:
        set_config_dirs(dirs)


def cell_options(fn):
    """``--gripper``, ``--cell``, ``--part-pose``, ``--units``, ``--config-dir``."""
    fn = config_dir_option(fn)
    fn = units_option(fn)
    fn = click.option("--part-pose", default=None,
                      help="Override the part's resting pose: 'x,y,z,roll,pitch,yaw' (lengths m or with units, angles "
                           "deg, R = Rz(yaw) Ry(pitch) Rx(roll)) or a JSON/YAML file with a 4x4 T_world_part. "
                           "Default: the cell's stable pose.")(fn)
    fn = click.option("--cell", default=DEFAULT_CELL, show_default=True,
                      help="Cell name (see --config-dir) or path to a cell YAML.")(fn)
    fn = click.option("--gripper", default=DEFAULT_GRIPPER, show_default=True,
                      help="Gripper name (see --config-dir) or path to a gripper YAML.")(fn)
    return fn


def robot_option(fn):
    return click.option("--robot", default=DEFAULT_ROBOT, show_default=True,
                        help="Robot name (see --config-dir) or path to a robot YAML; an unknown name lists the "
                             "available ones.")(fn)


def output_option(help_: str):
    return click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False),
                        help=help_)
