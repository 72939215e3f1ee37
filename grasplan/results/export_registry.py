"""The export registry: one :class:`ExportFormat` per robot-program / data format, and writing a
plan through it.

A format is one module (in :mod:`grasplan.export`) that ends with ``register(ExportFormat(...))``;
the built-in modules are listed once in :data:`BUILTIN_MODULES` and imported by name on the first
look-up (:func:`load_builtin_formats`). ``grasplan export --help`` and ``--format`` choices are
read from :data:`FORMATS`.

This module sits below :mod:`grasplan.results.plan_result`: :meth:`grasplan.results.plan_result.PlanResult.export` writes
through :func:`write_export` without importing the format modules or the plan loader, and
:func:`grasplan.export.write` (which also takes a plan file or document) loads the plan, then
calls the same function. Every writer refuses bad input with :class:`grasplan.errors.InputError`
(CLI exit 3) and writes nothing then: the whole output is rendered in memory first, then each file
is written atomically.
"""
from __future__ import annotations

import importlib
import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from ..errors import InputError
from .program_names import program_name_problem, suggest_program_name

#: joint acceleration limit of the joint trajectory when none is given, rad/s^2 (all joints): the
#: URDF has none; 1.4 rad/s^2 is the UR controller's default ``movej`` acceleration
DEFAULT_MAX_ACCEL = 1.4
#: the shipped formats (modules of :mod:`grasplan.export`), imported (and so registered) on the
#: first look-up; adding a format is a module plus one name here
BUILTIN_MODULES = ("urscript", "trajectory", "csvfile", "pathcsv", "krl", "rapid", "moveit_grasp")
_EXPORT_PACKAGE = "grasplan.export"


@dataclass(frozen=True, kw_only=True)
class ExportOptions:
    """Options of every format (each format reads the ones it needs)."""

    grasp_id: int | None = None      #: None: the best planned grasp (per-grasp formats) / every grasp
    source: str = ""                 #: a label of the plan (its file name), recorded in headers
    program_name: str = "grasplan_pick"  #: KRL/RAPID routine and module name base (a safe identifier)
    max_accel: float = DEFAULT_MAX_ACCEL  #: joint-trajectory: rad/s^2
    velocity_scale: float = 1.0      #: joint-trajectory: fraction of the URDF velocity limits

    def __post_init__(self) -> None:
        if self.grasp_id is not None and (isinstance(self.grasp_id, bool) or not isinstance(self.grasp_id, int)
                                          or not 0 <= self.grasp_id < 2**62):
            raise InputError(f"--grasp: expected a grasp id >= 0, got {self.grasp_id!r}")
        problem = program_name_problem(self.program_name)
        if problem is not None:
            raise InputError(f"program_name: {problem}; use e.g. {suggest_program_name(self.program_name)!r}")
        if not (isinstance(self.max_accel, (int, float)) and math.isfinite(self.max_accel) and 0 < self.max_accel <= 1000):
            raise InputError(f"--max-accel: expected rad/s^2 in (0, 1000], got {self.max_accel!r}")
        if not (isinstance(self.velocity_scale, (int, float)) and 0 < self.velocity_scale <= 1):
            raise InputError(f"--velocity-scale: expected a fraction in (0, 1], got {self.velocity_scale!r}")


@dataclass(frozen=True)
class ExportFormat:
    """``render(plan: PlanResult, options: ExportOptions) -> {extension: text}``: the first key is the
    file the user names with ``-o``; further keys are written next to it with the same stem."""

    name: str
    extension: str
    description: str
    #: takes a :class:`grasplan.results.plan_result.PlanResult` (not named here: the result module imports this one)
    render: Callable[[Any, ExportOptions], dict[str, str]]
    per_grasp: bool = True
    extra_extensions: tuple[str, ...] = ()  #: further files written next to the primary one (KRL: (".dat",))
    #: the program inside is named after the output file (KUKA loads NAME.src only with DEF NAME)
    program_named_by_file: bool = False


class ExportablePlan(Protocol):
    """What the registry itself reads of a plan (a :class:`grasplan.results.plan_result.PlanResult`); the
    formats read the rest."""

    @property
    def robot(self) -> object | None: ...

    def select(self, grasp_id: int | None = None) -> object: ...


FORMATS: dict[str, ExportFormat] = {}
_loaded = False


def register(fmt: ExportFormat) -> ExportFormat:
    if fmt.name in FORMATS and FORMATS[fmt.name] is not fmt:
        raise ValueError(f"export format {fmt.name!r} is registered twice")
    FORMATS[fmt.name] = fmt
    return fmt


def load_builtin_formats() -> dict[str, ExportFormat]:
    """Import the built-in format modules (idempotent); returns :data:`FORMATS`."""
    global _loaded
    if not _loaded:
        for name in BUILTIN_MODULES:
            try:
                importlib.import_module(f"{_EXPORT_PACKAGE}.{name}")
            except ModuleNotFoundError as exc:  # a format module not shipped in this build
                if exc.name != f"{_EXPORT_PACKAGE}.{name}":
                    raise
        _loaded = True
    return FORMATS


def get_format(name: str) -> ExportFormat:
    load_builtin_formats()
    if name not in FORMATS:
        raise InputError(f"unknown export format {name!r}; available: {', '.join(sorted(FORMATS))}")
    return FORMATS[name]


def output_paths(fmt: str, path: str | os.PathLike[str]) -> list[Path]:
    """The files ``write_export(..., fmt, path)`` creates: ``path`` and, for multi-file formats,
    its siblings with the format's other extensions (e.g. KRL's ``.dat``)."""
    f = get_format(fmt)
    return [Path(path)] + [Path(path).with_suffix(e) for e in f.extra_extensions]


def program_options(fmt: str, path: str | os.PathLike[str], options: dict[str, Any]) -> dict[str, Any]:
    """``options`` with ``program_name`` = the file's stem for a format whose program is named
    after its file (unless given); InputError when the stem is no program name
    (:func:`grasplan.results.program_names.program_name_problem`), naming a file name that would pass."""
    f = get_format(fmt)
    if not f.program_named_by_file or "program_name" in options:
        return options
    path = Path(path)
    problem = program_name_problem(path.stem)
    if problem is not None:
        good = path.with_name(suggest_program_name(path.stem) + path.suffix)
        raise InputError(f"{path.name}: a {fmt} program is named after its file, and {problem}; "
                         f"write it as {good.name}")
    return {**options, "program_name": path.stem}


def render_export(plan: ExportablePlan, fmt: str, *, grasp_id: int | None = None, **options: Any) -> dict[str, str]:
    """The export's files as ``{extension: text}`` (nothing written) for a plan result."""
    f = get_format(fmt)
    if plan.robot is None:
        raise InputError("exports need a plan (robot, IK, paths); this is a grasps result: run "
                         "`grasplan plan PART --robot NAME -o plan.json` first")
    opts = ExportOptions(grasp_id=grasp_id, **options)
    if f.per_grasp:
        plan.select(grasp_id)  # a planned grasp, or an error that lists them
    out = f.render(plan, opts)
    if not out or next(iter(out)) != f.extension:
        raise AssertionError(f"format {fmt!r} must return its primary file {f.extension!r} first")
    return out


def write_export(plan: ExportablePlan, fmt: str, path: str | os.PathLike[str], *, grasp_id: int | None = None,
                 **options: Any) -> Path:
    """Write ``fmt`` for a plan result to ``path`` (and siblings for multi-file formats); returns
    ``path``. ``grasp_id``: the planned grasp to export (default: the best planned one; for ``csv``
    and ``moveit-grasp`` None means every grasp). Other keyword options: see :class:`ExportOptions`."""
    path = Path(path)
    options = program_options(fmt, path, options)
    files = render_export(plan, fmt, grasp_id=grasp_id, **options)
    paths = output_paths(fmt, path)
    if len(paths) != len(files):
        raise AssertionError(f"format {fmt!r} rendered {list(files)}, its registration names {len(paths)} files")
    from ..io import write_files_atomic

    # all or nothing: a companion that cannot be written (a folder named pick.dat) leaves pick.src as it was
    write_files_atomic(list(zip(paths, files.values())))
    return path
