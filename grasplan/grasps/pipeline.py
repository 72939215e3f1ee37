"""Stages 5-6 composed: candidates -> TCP poses (rolled) -> collision status, and their JSON.

``compute_grasps(part, gripper=, cell=, candidates=CandidateParams(), grasps=GraspParams())`` is
the pure function behind ``grasplan grasps``; the plan pipeline starts from its
:class:`GraspResult`, and :meth:`GraspResult.to_result` turns it into the typed
:class:`grasplan.results.plan_result.PlanResult` that files, exports and the viewer use.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..candidates.pipeline import CandidateResult, compute_candidates
from ..cell.model import NO_CELL_NAME, Cell, load_cell
from .collision import GripperCollider
from ..candidates.antipodal_base import Candidates
from .frames import GraspFrames, grasp_frames, roll_angles
from ..results.grasp_table import GraspTable
from ..gripper.load import load_gripper
from ..gripper.model import Gripper
from ..part.mass import MassProperties
from ..part.mesh import Part
from ..config.params import DEFAULT_CELL, DEFAULT_GRIPPER, CandidateParams, GraspParams
from .quality import Quality, quality_and_score, quality_columns, stage_warnings
from ..results.plan_result import Params, PartRecord, PlanResult
from ..status import GRASP_STATUSES, Status
from ..candidates.thinning import thin_candidates
from ..cell.resting import stable_pose
from ..geometry.transforms import check_transform


@dataclass(frozen=True)
class GraspResult:
    """Candidates, the gripper poses built from them and each pose's collision status.

    frames.candidate indexes ``cand.candidates``; ``status`` is (M,) str, a value of
    :data:`grasplan.status.GRASP_STATUSES` (or ``not_checked``: see ``lazy``); ``T_world_part`` (4, 4)."""

    cand: CandidateResult
    gripper: Gripper
    cell: Cell
    T_world_part: np.ndarray
    frames: GraspFrames
    status: np.ndarray
    params: GraspParams = GraspParams()
    timing_s: dict[str, float] = field(default_factory=dict)
    part_pose_source: str = "stable_pose"
    #: grasp quality of the ``ok`` poses (rows = np.flatnonzero(status == Status.OK.value))
    quality: Quality | None = None
    #: the part's mass properties the quality was computed with
    mass_props: MassProperties | None = None
    #: (M,) score of every pose (grasplan.config.scoring; NaN for poses that collide)
    score: np.ndarray | None = None
    #: why there is no quality ("" when there is): e.g. a flat part has no mass
    quality_note: str = ""
    #: (M,) grasp-stage reason per pose ("grasp stage: gripper:finger_left hits obstacle:wall ..."; "" for ok)
    reasons: np.ndarray | None = None

    def quality_warnings(self) -> list[str]:
        """What to tell the user: the work bounds the candidate and pose stages applied
        (``cand.notes``), the mass properties' warnings (or why there is no quality) and
        :func:`grasplan.grasps.quality.holding_warning`."""
        return stage_warnings(self.cand.notes, self.quality, self.mass_props, self.quality_note,
                              part=Path(self.cand.part.path).name)

    @property
    def width(self) -> np.ndarray:
        """(M,) contact distance per pose, m."""
        return self.cand.candidates.width[self.frames.candidate]

    @property
    def T_world_tcp(self) -> np.ndarray:
        """(M, 4, 4) TCP poses in the world frame."""
        return self.T_world_part @ self.frames.T_part_tcp

    def counts(self) -> dict[str, int]:
        st = self.status
        out = {
            "candidates": len(self.cand.candidates),
            "posed_candidates": int(len(np.unique(self.frames.candidate))),
            "poses": int(len(st)),
        }
        region = getattr(self.cand.candidates, "region", None)
        if region is not None and len(region):
            out["regions"] = int(len(np.unique(region[region >= 0])))
        out.update({s: int(np.count_nonzero(st == s)) for s in GRASP_STATUSES})
        return out

    def table(self) -> GraspTable:
        """Per-pose arrays (:class:`grasplan.results.grasp_table.GraspTable`)."""
        c = self.cand.candidates
        ci = np.asarray(self.frames.candidate, dtype=np.int64)
        M = len(ci)
        region = getattr(c, "region", None)
        return GraspTable(candidate=ci, region=np.asarray(region)[ci] if region is not None else np.full(M, -1, dtype=np.int64),
                          contacts=c.contacts[ci], normals=c.normals[ci], width=c.width[ci],
                          T_part_tcp=np.asarray(self.frames.T_part_tcp, dtype=np.float64).reshape(M, 4, 4),
                          roll=np.asarray(self.frames.roll, dtype=np.float64), status=self.status.astype(object),
                          score=np.full(M, np.nan) if self.score is None else np.asarray(self.score, dtype=np.float64),
                          rank=np.full(M, -1, dtype=np.int64),
                          reason=np.full(M, "", dtype=object) if self.reasons is None
                          else np.asarray(self.reasons, dtype=object), **self._quality_columns(M))

    def _quality_columns(self, M: int) -> dict[str, np.ndarray]:
        """GraspTable quality arrays (M rows; NaN / -1 where a pose has none)."""
        if self.quality is None:
            return {}
        return quality_columns(self.quality, np.flatnonzero(np.asarray(self.status).astype(str) == Status.OK.value), M)

    def to_result(self) -> PlanResult:
        """This grasp result as a :class:`grasplan.results.plan_result.PlanResult` (no robot)."""
        part = self.cand.part
        rec = PartRecord(path=part.path, sha256=part.sha256, scale_to_m=part.scale_to_m, triangles=part.triangles,
                         T_world_part=np.asarray(self.T_world_part, dtype=np.float64))
        counts = self.counts()
        stage: dict[str, int] = {k: counts[k] for k in ("candidates", "posed_candidates", "poses", "regions", "checked")
                 if k in counts}
        return PlanResult(part=rec, gripper=self.gripper, cell=self.cell, robot=None, grasps=self.table(),
                          params=Params(self.cand.params, self.params), counts_stage=stage,
                          timing_s=dict(self.timing_s), part_pose_source=self.part_pose_source,
                          grasp_result=self, part_mesh=part.mesh,
                          mass=None if self.mass_props is None else self.mass_props.record())

    def to_json(self, *, only_ok: bool = False) -> dict[str, Any]:
        """``grasplan.grasps/1`` (see :meth:`grasplan.results.plan_result.PlanResult.to_json`)."""
        return self.to_result().to_json(only_ok=only_ok)


#: at most this many poses (posed candidates x rolls) per part: more are thinned (see
#: :func:`bounded_selection`). The paper parts pose up to ~100 k (SileaneGear, pose 1).
MAX_POSES = 200_000
#: and at most this many (poses x part triangles): a pose's collision check costs about in
#: proportion to the triangles near the gripper, so a part of 500 k triangles poses at most 40 k
#: (the paper parts, up to 21 k triangles, stay under MAX_POSES)
MAX_POSE_TRIANGLES = 20_000_000_000


def pose_limit(n_triangles: int) -> int:
    """The most poses a part of ``n_triangles`` triangles gets: :data:`MAX_POSES`, or fewer for a
    large part (:data:`MAX_POSE_TRIANGLES`)."""
    return int(min(MAX_POSES, MAX_POSE_TRIANGLES // max(1, int(n_triangles))))


def bounded_selection(cands: Candidates, select: np.ndarray | None, params: GraspParams, gripper: Gripper,
                      n_triangles: int = 0) -> tuple[np.ndarray | None, str]:
    """``(select, note)``: the candidates to pose so that (posable candidates) x (rolls) stays within
    :func:`pose_limit` of the part's ``n_triangles``. Unchanged (note "") when it does already; else one candidate per cluster of
    :func:`grasplan.candidates.thinning.thin_candidates` at the smallest pitch ``max(--thin, 1 mm) x 2^(k/2)`` that
    fits (axis step ``params.thin_axis_deg``), and, should even a pitch of a metre not fit, the first
    candidates of that selection; the note says what was posed and how to choose."""
    n_rolls = len(roll_angles(params.roll_step_deg))
    posable = (cands.width <= gripper.max_opening) & (cands.width >= gripper.min_opening)
    base = np.flatnonzero(posable) if select is None else np.asarray(select, dtype=np.int64)[posable[select]]
    cap = pose_limit(n_triangles)
    if len(base) * n_rolls <= cap:
        return select, ""
    sub = cands.subset(base)
    pitch = max(float(params.thin_spacing), 1e-3)
    while True:
        keep = base[thin_candidates(sub, spacing=pitch, axis_step_deg=float(params.thin_axis_deg))]
        if len(keep) * n_rolls <= cap or pitch >= 1.0:
            break
        pitch *= np.sqrt(2.0)
    keep = keep[: max(1, cap // n_rolls)]
    why = (f"grasplan.grasps.pipeline.MAX_POSES ({MAX_POSES:,})" if cap == MAX_POSES else
           f"{cap:,} (grasplan.grasps.pipeline.MAX_POSE_TRIANGLES {MAX_POSE_TRIANGLES:.0e} / {n_triangles:,} triangles)")
    note = (f"grasps: {len(base):,} candidates x {n_rolls} rolls = {len(base) * n_rolls:,} poses, more than "
            f"{why}: posing {len(keep):,} candidates, one per {pitch * 1e3:.3g} mm x "
            f"{params.thin_axis_deg:g} deg cluster (as --thin {pitch * 1e3:.3g}mm); choose with --thin, a larger "
            f"--roll-step, or --spacing")
    return keep, note


def compute_grasps(
    part: Part,
    *,
    gripper: str | Gripper = DEFAULT_GRIPPER,
    cell: str | Cell = DEFAULT_CELL,
    candidates: CandidateParams = CandidateParams(),
    grasps: GraspParams = GraspParams(),
    T_world_part: np.ndarray | None = None,
    load_s: float = 0.0,
) -> GraspResult:
    """Candidates, TCP poses every ``grasps.roll_step_deg`` about each closing axis, and the
    collision status of each pose against the part and the cell's table.

    ``T_world_part`` (4, 4) overrides the cell's stable resting pose (``grasps.pose_index``, else
    the cell's). Candidates wider than the gripper's ``max_opening`` are not posed; the candidate
    search runs up to the gripper's ``max_opening`` unless ``candidates.max_opening`` says
    otherwise. Swapped duplicate candidates are posed once when the gripper is symmetric.
    The collision-free (``ok``) poses get their grasp quality (:mod:`grasplan.grasps.quality`: contact
    patches, gravity margin, epsilon at ``grasps.density`` / ``grasps.mass``) and a score
    (:mod:`grasplan.config.scoring`, weights ``grasps.score_weights``).
    ``grasps.thin_spacing`` (m; 0 = off) poses one candidate per cluster of
    :func:`grasplan.candidates.thinning.thin_candidates`; ``grasps.merge_distance`` (m; 0 = off) additionally
    skips a candidate whose two contacts fall in the same grid cells as an earlier candidate's.
    The poses (and so the grasp ids) depend on the part, the gripper and these options only, not
    on the cell or the part's pose: roll 0 is the approach closest to the part frame's -z
    (:func:`grasplan.grasps.frames.grasp_frames`), so a grasp database's poses
    (:mod:`grasplan.grasps.graspdb`) are these.
    """
    g = load_gripper(gripper)
    c = load_cell(cell)
    k = grasps.single_pose_index()
    if k is not None:
        c = replace(c, pose_index=k)
    if candidates.max_opening is None:  # search exactly as far as this gripper opens
        candidates = replace(candidates, max_opening=g.max_opening)
    timing: dict[str, float] = {}
    t = time.perf_counter()
    cand = compute_candidates(part, candidates, load_s=load_s)
    timing.update(cand.timing_s)
    timing["candidates"] = time.perf_counter() - t

    t = time.perf_counter()
    T, source = part_pose(part, c, T_world_part)
    timing["stable_pose"] = time.perf_counter() - t

    t = time.perf_counter()
    select = None
    if grasps.thin_spacing > 0:
        select = thin_candidates(cand.candidates, spacing=float(grasps.thin_spacing),
                                 axis_step_deg=float(grasps.thin_axis_deg))
    select, cap_note = bounded_selection(cand.candidates, select, grasps, g, n_triangles=len(part.mesh.faces))
    if cap_note:
        cand = replace(cand, notes=(*cand.notes, cap_note))
    frames = grasp_frames(cand.candidates, roll_step_deg=grasps.roll_step_deg,
                          max_width=g.max_opening, min_width=g.min_opening, dedupe_swapped=g.symmetric,
                          merge_distance=grasps.merge_distance, select=select)
    timing["frames"] = time.perf_counter() - t

    t = time.perf_counter()
    collider = GripperCollider(part.mesh, g, c, T)
    status, hit_elem, hit_body = collider.check_detail(frames.T_part_tcp, cand.candidates.width[frames.candidate])
    reasons = collider.reasons(status, hit_elem, hit_body)
    timing["collision"] = time.perf_counter() - t
    timing.update(collider.timing_s())

    t = time.perf_counter()
    quality, mass_props, score, note = quality_and_score(part.mesh, g, T, frames.T_part_tcp, frames.candidate,
                                                         cand.candidates, status, candidates.mu, grasps,
                                                         timing=timing)
    timing["quality"] = time.perf_counter() - t
    return GraspResult(cand=cand, gripper=g, cell=c, T_world_part=T, frames=frames, status=status, params=grasps,
                       timing_s=timing, part_pose_source=source, quality=quality, mass_props=mass_props, score=score,
                       quality_note=note,
                       reasons=reasons)


def part_pose(part: Part, cell: Cell, T_world_part: np.ndarray | None) -> tuple[np.ndarray, str]:
    """The part's pose ``T_world_part`` (4, 4) and where it came from: ``given``, the cell's
    ``stable_pose`` or, in cell ``none`` (the part alone), ``part_frame`` (the identity)."""
    if T_world_part is None and cell.name == NO_CELL_NAME:
        return np.eye(4), "part_frame"
    if T_world_part is None:
        return stable_pose(part.mesh, cell), "stable_pose"
    return check_transform(T_world_part, "T_world_part"), "given"
