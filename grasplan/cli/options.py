"""Every command's options, built from the parameter dataclasses (:mod:`grasplan.config.params`).

``@param_options(CandidateParams, GraspParams)`` adds one click option per dataclass field, with the
field's default, help and CLI spelling; its click type (:class:`OptionType`) reads the text with the
one interpreter of option kinds (:func:`grasplan.config.option_kinds.read_value`: lengths take unit suffixes,
angles are degrees, a pose is 'x,y,z,roll,pitch,yaw', ``--pose-index`` also takes ``all``), the same
reading a batch manifest gets. :meth:`grasplan.config.params.RunParams.from_options` pops them
again and builds the dataclasses, which validate the ranges (InputError, exit 3, naming the option
and what would pass). Parsing errors (``--top x``, ``--alpha 5parsecs``, ``--mu nan``) are click
usage errors (exit 2). Commands only parse, call and print.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import MISSING, Field, fields
from typing import Any, TypeVar

import click

from ..errors import InputError
from ..config.option_kinds import OptionSpec, is_option, metavar, option_name, option_spec, read_value
from ..config.params import DEFAULT_CELL, DEFAULT_GRIPPER, DEFAULT_ROBOT
from .common import units_option

#: a command function being decorated with options
_F = TypeVar("_F", bound=Callable[..., Any])


class OptionType(click.ParamType):
    """A click type for an option of spec ``s``: the text is read by
    :func:`grasplan.config.option_kinds.read_value` (a refused text is a usage error, exit 2; the range is
    the dataclass's to check, exit 3)."""

    def __init__(self, s: OptionSpec) -> None:
        self.spec = s
        self.name = metavar(s)

    def get_metavar(self, param: click.Parameter, ctx: click.Context) -> str | None:
        return self.name  # as written (click would upper-case "INDEX|all" and "[regions|paper]")

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        name = option_name_of(param)
        try:
            return read_value(self.spec, value, name)
        except InputError as exc:
            self.fail(str(exc), param, ctx)


def option_name_of(param: click.Parameter | None) -> str:
    """The spelling of a click option for messages (``--thin``)."""
    if isinstance(param, click.Option) and param.opts:
        return max(param.opts, key=len)
    return f"--{(param.name or 'value').replace('_', '-')}" if param is not None else "value"


#: free-standing numbers of commands that take no parameter dataclass (``grasplan export``)
FLOAT = OptionType(OptionSpec("float", "a finite number"))
INT = OptionType(OptionSpec("int", "a whole number"))


def _option(f: Field[Any]) -> Callable[[_F], _F]:
    s = option_spec(f)
    assert s is not None
    default = f.default if f.default is not MISSING else None
    name = option_name(f)
    if s.kind == "bool":
        flag = s.flag or f"{name}/--no-{name[2:]}"
        return click.option(flag, f.name, default=default, show_default=True, help=s.help)
    show: Any = s.show if s.show is not None else (default if default is not None else False)
    if s.optional and default is None:
        show = False
    return click.option(name, f.name, type=OptionType(s), default=default, show_default=show, help=s.help)


def param_options(*classes: type, exclude: tuple[str, ...] = (),
                  only: tuple[str, ...] | None = None) -> Callable[[_F], _F]:
    """Decorator: one click option per option field of each parameter class (all but ``exclude``,
    or just ``only``)."""
    opts = [_option(f) for cls in classes for f in fields(cls)
            if is_option(f) and f.name not in exclude and (only is None or f.name in only)]

    def deco(fn: _F) -> _F:
        for o in reversed(opts):
            fn = o(fn)
        return fn
    return deco


def config_dir_option(fn: _F) -> _F:
    return click.option("--config-dir", "config_dir", multiple=True, type=click.Path(file_okay=False),
                        help="Look up gripper, cell and robot names here first (folders with grippers/, cells/, "
                             "robots/); then $GRASPLAN_CONFIG_PATH, ./configs and ./robots, then the packaged ones. "
                             "Repeatable.")(fn)


def apply_config_dirs(kwargs: dict[str, Any]) -> None:
    """Pop ``config_dir`` and put it first in the config lookup (before anything resolves a name)."""
    from ..config.lookup import set_config_dirs

    dirs = kwargs.pop("config_dir", ())
    if dirs:
        set_config_dirs(dirs)


def cell_options(fn: _F) -> _F:
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


def robot_option(fn: _F) -> _F:
    return click.option("--robot", default=DEFAULT_ROBOT, show_default=True,
                        help="Robot name (see --config-dir) or path to a robot YAML; an unknown name lists the "
                             "available ones.")(fn)


def output_option(help_: str) -> Callable[[_F], _F]:
    return click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False),
                        help=help_)


def keep_option(fn: _F) -> _F:
    """``--keep``: what a plan file keeps of the poses the robot stage did not plan."""
    from ..results.compact import DEFAULT_KEEP, KEEP_CHOICES

    return click.option("--keep", type=click.Choice(KEEP_CHOICES), default=DEFAULT_KEEP, show_default=True,
                        help="What the plan file keeps: collision_free (the grasps the robot tried in full, the other "
                             "collision-free grasps in columns, colliding poses as counts per candidate) or all "
                             "(every pose in full; files 10-30x larger).")(fn)
