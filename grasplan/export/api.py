"""The export API on plans given as results, files or documents: :func:`render` and :func:`write`
(the formats themselves: :mod:`grasplan.results.export_registry` and one module per format)."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..results.export_registry import get_format, program_options, render_export, write_export
from ..results.plan_result import PlanResult
from ..results.reader import load_result

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
