"""Stages 5-6 composed: candidates -> TCP poses (rolled) -> collision status, and their JSON.

``compute_grasps(part, gripper=, cell=, candidates=CandidateParams(), grasps=GraspParams())`` is
the pure function behind ``grasplan grasps``; the plan pipeline starts from its
:class:`GraspResult`, and :meth:`GraspResult.to_result` turns it into the typed
:class:`grasplan.result.PlanResult` that files, exports and the viewer use.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from .candidates import CandidateResult, compute_candidates
from .cell import Cell, load_cell, stable_pose
from .collision import GripperCollider
from .frames import GraspFrames, grasp_frames
from .gripper import Gripper, load_gripper
from .mesh import Part
from .params import DEFAULT_CELL, DEFAULT_GRIPPER, CandidateParams, GraspParams
from .result import GRASP_STATUSES as STATUSES
from .result import GraspTable, Params, PartRecord, PlanResult
from .transforms import check_transform

SCHEMA = "grasplan.grasps/1"


@dataclass(frozen=True)
class GraspResult:
    """Candidates, the gripper poses built from them and each pose's collision status.

    frames.candidate indexes ``cand.candidates``; ``status`` is (M,) str in
    {"ok", "collision_part", "collision_table", "collision_obstacle"}; ``T_world_part`` (4, 4)."""

    cand: CandidateResult
    gripper: Gripper
    cell: Cell
    T_world_part: np.ndarray
    frames: GraspFrames
    status: np.ndarray
    params: GraspParams = GraspParams()
    timing_s: dict = field(default_factory=dict)
    part_pose_source: str = "stable_pose"
    #: grasp quality of the ``ok`` poses (grasplan.quality.Quality, rows = np.flatnonzero(status == "ok"))
    quality: object = None
    #: the part's mass properties (grasplan.mass.MassProperties) the quality was computed with
    mass_props: object = None
    #: (M,) score of every pose (grasplan.scoring; NaN for poses that collide)
    score: np.ndarray | None = None
    #: why there is no quality ("" when there is): e.g. a flat part has no mass
    quality_note: str = ""
    #: (M,) grasp-stage reason per pose ("grasp stage: gripper:finger_left hits obstacle:wall ..."; "" for ok)
    reasons: np.ndarray | None = None

    @property
    def width(self) -> np.ndarray:
        """(M,) contact distance per pose, m."""
        return self.cand.candidates.width[self.frames.candidate]

    @property
    def T_world_tcp(self) -> np.ndarray:
        """(M, 4, 4) TCP poses in the world frame."""
        return self.T_world_part @ self.frames.T_part_tcp

    def counts(self) -> dict:
        st = self.status
        out = {
            "candidates": len(self.cand.candidates),
            "posed_candidates": int(len(np.unique(self.frames.candidate))),
            "poses": int(len(st)),
        }
        region = getattr(self.cand.candidates, "region", None)
        if region is not None and len(region):
            out["regions"] = int(len(np.unique(region[region >= 0])))
        out.update({s: int(np.count_nonzero(st == s)) for s in STATUSES})
        return out

    def table(self) -> GraspTable:
        """Per-pose arrays (:class:`grasplan.result.GraspTable`)."""
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

    def _quality_columns(self, M: int) -> dict:
        """GraspTable quality arrays (M rows; NaN / -1 where a pose has none)."""
        if self.quality is None:
            return {}
        from .quality import quality_columns

        return quality_columns(self.quality, np.flatnonzero(np.asarray(self.status).astype(str) == "ok"), M)

    def to_result(self) -> PlanResult:
        """This grasp result as a :class:`grasplan.result.PlanResult` (no robot)."""
        part = self.cand.part
        rec = PartRecord(path=part.path, sha256=part.sha256, scale_to_m=part.scale_to_m, triangles=part.triangles,
                         T_world_part=np.asarray(self.T_world_part, dtype=np.float64))
        counts = self.counts()
        stage = {k: counts[k] for k in ("candidates", "posed_candidates", "poses", "regions") if k in counts}
        return PlanResult(part=rec, gripper=self.gripper, cell=self.cell, robot=None, grasps=self.table(),
                          params=Params(self.cand.params, self.params), counts_stage=stage,
                          timing_s=dict(self.timing_s), part_pose_source=self.part_pose_source,
                          grasp_result=self, part_mesh=part.mesh,
                          mass=None if self.mass_props is None else self.mass_props.record())

    def to_json(self, *, only_ok: bool = False) -> dict:
        """``grasplan.grasps/1`` (see :meth:`grasplan.result.PlanResult.to_json`)."""
        return self.to_result().to_json(only_ok=only_ok)


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
    The collision-free (``ok``) poses get their grasp quality (:mod:`grasplan.quality`: contact
    patches, gravity margin, epsilon at ``grasps.density`` / ``grasps.mass``) and a score
    (:mod:`grasplan.scoring`, weights ``grasps.score_weights``).
    ``grasps.thin_spacing`` (m; 0 = off) poses one candidate per cluster of
    :func:`grasplan.thinning.thin_candidates`; ``grasps.merge_distance`` (m; 0 = off) additionally
    skips a candidate whose two contacts fall in the same grid cells as an earlier candidate's.
    """
    g = load_gripper(gripper)
    c = load_cell(cell)
    if grasps.pose_index is not None:
        c = replace(c, pose_index=grasps.pose_index)
    if candidates.max_opening is None:  # search exactly as far as this gripper opens
        candidates = replace(candidates, max_opening=g.max_opening)
    timing: dict = {}
    t = time.perf_counter()
    cand = compute_candidates(part, candidates, load_s=load_s)
    timing.update(cand.timing_s)
    timing["candidates"] = time.perf_counter() - t

    t = time.perf_counter()
    if T_world_part is None:
        T = stable_pose(part.mesh, c)
        source = "stable_pose"
    else:
        T = check_transform(T_world_part, "T_world_part")
        source = "given"
    timing["stable_pose"] = time.perf_counter() - t

    t = time.perf_counter()
    down_in_part = T[:3, :3].T @ np.array([0.0, 0.0, -1.0])
    select = None
    if grasps.thin_spacing > 0:
        from .thinning import thin_candidates

        select = thin_candidates(cand.candidates, spacing=float(grasps.thin_spacing),
                                 axis_step_deg=float(grasps.thin_axis_deg))
    frames = grasp_frames(cand.candidates, roll_step_deg=grasps.roll_step_deg, reference=down_in_part,
                          max_width=g.max_opening, dedupe_swapped=g.symmetric,
                          merge_distance=grasps.merge_distance, select=select)
    timing["frames"] = time.perf_counter() - t

    t = time.perf_counter()
    collider = GripperCollider(part.mesh, g, c, T)
    status, hit_elem, hit_body = collider.check_detail(frames.T_part_tcp, cand.candidates.width[frames.candidate])
    reasons = collider.reasons(status, hit_elem, hit_body)
    timing["collision"] = time.perf_counter() - t

    t = time.perf_counter()
    from .quality import quality_and_score

    quality, mass_props, score, note = quality_and_score(part.mesh, g, T, frames.T_part_tcp, frames.candidate,
                                                         cand.candidates, status, candidates.mu, grasps)
    timing["quality"] = time.perf_counter() - t
    return GraspResult(cand=cand, gripper=g, cell=c, T_world_part=T, frames=frames, status=status, params=grasps,
                       timing_s=timing, part_pose_source=source, quality=quality, mass_props=mass_props, score=score,
                       quality_note=note,
                       reasons=reasons)
