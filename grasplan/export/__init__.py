"""Robot-program and data exports of a plan (the last pipeline stage), one registry.

Every format is one module that registers an :class:`~grasplan.export.registry.ExportFormat`
(name, file extension, one-line description, ``render(plan, options) -> {extension: text}``);
:data:`BUILTIN_MODULES` lists the shipped ones and ``grasplan export --help`` lists the registry.
Adding a format is a module plus one line here.

Python API::

    import grasplan
    plan = grasplan.load_result("plan.json")             # or the PlanResult of grasplan.plan(...)
    grasplan.export.write(plan, "urscript", "pick.script")          # best planned grasp
    grasplan.export.write(plan, "krl", "pick.src", grasp_id=17)     # writes pick.src and pick.dat
    plan.export("csv", "grasps.csv")

Every writer refuses bad input with :class:`grasplan.errors.InputError` (CLI exit 3) and writes
nothing then: the whole output is rendered in memory first, then each file is written atomically.
"""
from __future__ import annotations

import importlib
import os
from pathlib import Path

from ..errors import InputError
from .registry import (
    DEFAULT_MAX_ACCEL,
    FORMATS,
    PROGRAM_NAME,
    ExportFormat,
    ExportOptions,
    get_format,
    register,
)

#: the shipped formats, imported (and so registered) on first use of the registry
BUILTIN_MODULES = ("urscript", "trajectory", "csvfile", "pathcsv", "krl", "rapid", "moveit_grasp")

__all__ = ["write", "render", "FORMATS", "ExportFormat", "ExportOptions", "register", "get_format",
           "load_builtin_formats", "DEFAULT_MAX_ACCEL", "output_paths"]

_loaded = False


def load_builtin_formats() -> dict[str, ExportFormat]:
    """Import the built-in format modules (idempotent); returns :data:`FORMATS`."""
    global _loaded
    if not _loaded:
        for name in BUILTIN_MODULES:
            try:
                importlib.import_module(f"{__name__}.{name}")
            except ModuleNotFoundError as exc:  # a format module not shipped in this build
                if exc.name != f"{__name__}.{name}":
                    raise
        _loaded = True
    return FORMATS


def render(plan, fmt: str, *, grasp_id: int | None = None, part=None, **options) -> dict[str, str]:
    """The export's files as ``{extension: text}`` (nothing written). ``plan``: a
    :class:`~grasplan.result.PlanResult`, a plan file path or a parsed plan document."""
    from ..result import load_result

    f = get_format(fmt)
    res = load_result(plan, part=part, load_mesh=part is not None)  # a PlanResult is passed through
    if res.robot is None:
        raise InputError("exports need a plan (robot, IK, paths); this is a grasps result: run "
                         "`grasplan plan PART --robot NAME -o plan.json` first")
    opts = ExportOptions(grasp_id=grasp_id, **options)
    if f.per_grasp:
        res.select(grasp_id)  # a planned grasp, or an error that lists them
    out = f.render(res, opts)
    if not out or next(iter(out)) != f.extension:
        raise AssertionError(f"format {fmt!r} must return its primary file {f.extension!r} first")
    return out


def output_paths(fmt: str, path: str | os.PathLike) -> list[Path]:
    """The files ``write(..., fmt, path)`` creates: ``path`` and, for multi-file formats, its
    siblings with the format's other extensions (e.g. KRL's ``.dat``)."""
    f = get_format(fmt)
    return [Path(path)] + [Path(path).with_suffix(e) for e in f.extra_extensions]


def write(plan, fmt: str, path: str | os.PathLike, *, grasp_id: int | None = None, part=None,
          **options) -> Path:
    """Write ``fmt`` for ``plan`` to ``path`` (and siblings for multi-file formats); returns ``path``.

    ``grasp_id``: the planned grasp to export (default: the best planned one; for ``csv`` and
    ``moveit-grasp`` None means every grasp). Other keyword options: see :class:`ExportOptions`.
    """
    from ..io import write_atomic_text

    path = Path(path)
    f = get_format(fmt)
    if f.program_named_by_file and "program_name" not in options:
        if not PROGRAM_NAME.fullmatch(path.stem):
            raise InputError(f"{path.name}: a {fmt} program is named after its file; use -o NAME{f.extension} with "
                             "NAME a letter then letters, digits or _ (at most 24 characters), e.g. pick_part1"
                             f"{f.extension}")
        options["program_name"] = path.stem
    files = render(plan, fmt, grasp_id=grasp_id, part=part, **options)
    paths = output_paths(fmt, path)
    if len(paths) != len(files):
        raise AssertionError(f"format {fmt!r} rendered {list(files)}, its registration names {len(paths)} files")
    targets = list(zip(paths, files.values()))
    written: list[Path] = []
    try:
        for target, text in targets:  # each atomically; a failure removes the ones already written
            write_atomic_text(target, text)
            written.append(target)
    except BaseException:
        for w in written:
            w.unlink(missing_ok=True)
        raise
    return path
