"""Finger windows of a short-stroke gripper for one part (``grasplan fingers``).

A short-stroke gripper (a ``stroke`` in its YAML: SCHUNK EGP 25 moves each jaw 3 mm) grips only
widths in the window its fingers set: ``[max_opening - stroke, max_opening]``; integrators make
the fingers for the part. :func:`finger_windows` ranks the windows by the part's distinct grasps
that are collision-free and predicted to hold, summed over its resting poses weighted by their
probability: for each window the part's grasp database with that window
(:func:`grasplan.grasps.graspdb.database_for`, cached) placed in each resting pose
(:func:`grasplan.grasps.placed.place_database`), the holdable grasps counted once per near-duplicate
group (:func:`grasplan.grasps.ranking.distinct_order`). :func:`gripper_yaml` writes the gripper's
YAML with the chosen window.
"""
from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..candidates.pipeline import compute_candidates
from ..cell.model import Cell
from ..config.params import CandidateParams, GraspParams
from ..errors import InputError
from ..gripper.model import Gripper
from ..part.mesh import Part
from ..status import Status
from .graspdb import database_for
from .placed import place_database
from .ranking import distinct_order

#: widest window searched: the part's largest extent, at most this (m)
MAX_WIDTH = 0.25


@dataclass(frozen=True)
class FingerWindow:
    """One finger design: the jaws grip widths ``min_opening .. max_opening`` (m). ``per_pose``:
    ``(pose index, probability, distinct grasps collision-free and predicted to hold)``;
    ``weighted``: their sum weighted by probability; ``candidates``: contact pairs whose width is
    in the window."""

    min_opening: float
    max_opening: float
    per_pose: tuple[tuple[int, float, int], ...]
    weighted: float
    candidates: int


def window_offsets(widths: np.ndarray, stroke: float, step: float, evaluate: int) -> list[float]:
    """The ``evaluate`` window offsets (narrowest opening, m, on a grid of ``step``) holding the most
    candidate ``widths`` in ``[offset, offset + stroke]`` (ties: the narrower window)."""
    w = np.sort(np.asarray(widths, dtype=np.float64))
    if not len(w):
        return []
    offsets = np.arange(np.floor(w[0] / step) * step, w[-1] + step, step)
    offsets = offsets[offsets >= 0.0]
    n = np.searchsorted(w, offsets + stroke, side="right") - np.searchsorted(w, offsets, side="left")
    order = np.lexsort((offsets, -n))
    return [float(np.round(offsets[i], 9)) for i in order[:evaluate] if n[i] > 0]


def finger_windows(part: Part, gripper: Gripper, cell: Cell, *, poses: list[tuple[int, float]],
                   candidates: CandidateParams = CandidateParams(), grasps: GraspParams = GraspParams(),
                   step: float | None = None, evaluate: int = 6, distinct_distance: float = 0.005,
                   distinct_angle_deg: float = 15.0, progress: Callable[[str], None] | None = None
                   ) -> list[FingerWindow]:
    """The windows of ``gripper`` (a ``stroke`` needed) for ``part`` resting in ``cell`` in ``poses``
    (``(index, probability)``), best first (module docstring). ``step``: grid of the window offsets
    (default half the stroke); ``evaluate``: how many windows (those holding the most candidate
    widths) get the full count. InputError for a gripper whose jaws close fully."""
    if gripper.stroke is None:
        raise InputError(f"gripper {gripper.name!r} has no stroke (its jaws close fully from "
                         f"{gripper.max_opening * 1e3:g} mm): fingers are designed for a short-stroke gripper; "
                         f"give one with a 'stroke:' in its YAML, e.g. --gripper schunk_egp_c_40, schunk_egp_25 or schunk_egp_64")
    stroke = float(gripper.stroke)
    step = float(step) if step else 0.5 * stroke
    reach = min(MAX_WIDTH, float(np.ptp(np.asarray(part.mesh.vertices), axis=0).max()) + 1e-3)
    cand = compute_candidates(part, replace(candidates, max_opening=reach))
    out = []
    for o in window_offsets(cand.candidates.width, stroke, step, evaluate):
        g = replace(gripper, max_opening=o + stroke)
        if progress is not None:
            progress(f"fingers: window {o * 1e3:.1f}-{(o + stroke) * 1e3:.1f} mm ...")
        db = database_for(part, g, candidates=replace(candidates, max_opening=None), grasps=grasps)
        per = []
        for k, p in poses:
            pg = place_database(db, part, cell, params=replace(grasps, pose_index=k))
            rows = np.flatnonzero(pg.table.status.astype(str) == Status.OK.value)
            gm = pg.table.gravity_margin
            if gm is not None:
                rows = rows[gm[rows] >= 1.0]
            rows = rows[np.lexsort((rows, -pg.table.score[rows]))]
            _, n = distinct_order(pg.table.T_part_tcp, rows, min_distance=distinct_distance,
                                  min_angle_deg=distinct_angle_deg)
            per.append((k, p, int(n)))
        w = cand.candidates.width
        inside = int(np.count_nonzero((w >= o) & (w <= o + stroke)))
        out.append(FingerWindow(o, o + stroke, tuple(per), float(sum(p * n for _, p, n in per)), inside))
    return sorted(out, key=lambda fw: (-fw.weighted, -fw.candidates, fw.min_opening))


def gripper_yaml(source: Path, window: FingerWindow, *, name: str, note: str) -> str:
    """The text of the gripper YAML ``source`` with ``max_opening`` set to the window's and ``name``
    replaced, ``note`` (one comment line) first; the rest (comments, shapes) as it was. InputError
    when the file has no top-level ``name:`` or ``max_opening:`` line to set."""
    text = source.read_text(encoding="utf-8")
    for key, value in (("max_opening", f"{window.max_opening:.4f}"), ("name", name)):
        text, n = re.subn(rf"^{key}:[^#\n]*", f"{key}: {value}  ", text, count=1, flags=re.MULTILINE)
        if n != 1:
            raise InputError(f"{source}: no top-level '{key}:' line to set; write the gripper YAML by hand with "
                             f"{key}: {value}")
    desc = f"fingers for {window.min_opening * 1e3:.1f}-{window.max_opening * 1e3:.1f} mm widths"
    text = re.sub(r"^description:.*$", lambda m: f"description: {desc}", text, count=1, flags=re.MULTILINE)
    return f"# {note}\n" + text


def window_hint(gripper: Gripper, candidates: int, posed: int) -> str:
    """``"; ..."``: why a short-stroke gripper posed none of a part's ``candidates`` (each narrower
    than its jaws close) and what would fit; "" when that is not the reason."""
    if candidates <= 0 or posed > 0 or gripper.min_opening <= 0.0:
        return ""
    return (f"; all {candidates} contact pairs are narrower than {gripper.name}'s jaws close "
            f"({gripper.min_opening * 1e3:.1f} mm; its fingers hold {gripper.min_opening * 1e3:.1f}-"
            f"{gripper.max_opening * 1e3:.1f} mm): choose fingers for this part with `grasplan fingers PART "
            f"--gripper {gripper.name} -o GRIPPER.yaml`, or a gripper whose jaws close further "
            f"(e.g. --gripper long_stroke_50)")
