"""Robot-program and data exports of a plan (the last pipeline stage), one registry.

Every format is one module here that registers an :class:`~grasplan.export_registry.ExportFormat`
(name, file extension, one-line description, ``render(plan, options) -> {extension: text}``);
:data:`grasplan.export_registry.BUILTIN_MODULES` lists the shipped ones and ``grasplan export
--help`` lists the registry. Adding a format is a module plus one name there.

Python API::

    import grasplan
    plan = grasplan.load_result("plan.json")             # or the PlanResult of grasplan.plan(...)
    grasplan.export.write(plan, "urscript", "pick.script")          # best planned grasp
    grasplan.export.write(plan, "krl", "pick.src", grasp_id=17)     # writes pick.src and pick.dat
    plan.export("csv", "grasps.csv")

:func:`write` and :func:`render` also take a plan file or a parsed plan document (validated in
full by :func:`grasplan.result_reader.load_result`). Every writer refuses bad input with
:class:`grasplan.errors.InputError` (CLI exit 3) and writes nothing then: the whole output is
rendered in memory first, then each file is written atomically.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..export_registry import (
    DEFAULT_MAX_ACCEL,
    FORMATS,
    ExportFormat,
    ExportOptions,
    get_format,
    load_builtin_formats,
    output_paths,
    program_options,
    register,
    render_export,
    write_export,
)
from ..result import PlanResult
from ..result_reader import load_result

__all__ = ["write", "render", "FORMATS", "ExportFormat", "ExportOptions", "register", "get_format",
           "load_builtin_formats", "DEFAULT_MAX_ACCEL", "output_paths"]

#: a plan: a PlanResult, a plan file or a parsed plan document
Plan = PlanResult | str | os.PathLike[str] | dict[str, Any]


def render(plan: Plan, fmt: str, *, grasp_id: int | None = None, part: str | os.PathLike[str] | None = None,
           **options: Any) -> dict[str, str]:
    """The export's files as ``{extension: text}`` (nothing written). ``part``: the part's mesh
    when the plan's recorded path does not find it."""
    get_format(fmt)  # an unknown format is named before the plan is read
    res = load_result(plan, part=part, load_mesh=part is not None)  # a PlanResult is passed through
    return render_export(res, fmt, grasp_id=grasp_id, **options)


def write(plan: Plan, fmt: str, path: str | os.PathLike[str], *, grasp_id: int | None = None,
          part: str | os.PathLike[str] | None = None, **options: Any) -> Path:
    """Write ``fmt`` for ``plan`` to ``path`` (and siblings for multi-file formats); returns ``path``.

    ``grasp_id``: the planned grasp to export (default: the best planned one; for ``csv`` and
    ``moveit-grasp`` None means every grasp). Other keyword options: see :class:`ExportOptions`.
    """
    options = program_options(fmt, path, options)  # a bad format or file name before the plan is read
    res = load_result(plan, part=part, load_mesh=part is not None)
    return write_export(res, fmt, path, grasp_id=grasp_id, **options)
