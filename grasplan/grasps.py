"""Stages 5-6 composed: candidates -> TCP poses (rolled) -> collision status, and their JSON.

``compute_grasps(part, ...)`` is the pure function behind ``grasplan grasps``; the plan pipeline
starts from its :class:`GraspResult`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from .candidates import CandidateParams, CandidateResult, compute_candidates
from .cell import Cell, load_cell, stable_pose
from .collision import STATUSES, GripperCollider
from .errors import InputError
from .frames import GraspFrames, grasp_frames
from .gripper import Gripper, load_gripper
from .mesh import Part
from .transforms import check_transform

SCHEMA = "grasplan.grasps/1"


@dataclass(frozen=True)
class GraspResult:
    """Candidates, the gripper poses built from them and each pose's collision status.

    frames.candidate indexes ``cand.candidates``; ``status`` is (M,) str in
    {"ok", "collision_part", "collision_table"}; ``T_world_part`` (4, 4)."""

    cand: CandidateResult
    gripper: Gripper
    cell: Cell
    T_world_part: np.ndarray
    frames: GraspFrames
    status: np.ndarray
    timing_s: dict = field(default_factory=dict)
    roll_step_deg: float = 15.0
    part_pose_source: str = "stable_pose"
    merge_distance: float = 0.0
    thin: tuple = (0.003, 10.0)

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
        return {
            "candidates": len(self.cand.candidates),
            "posed_candidates": int(len(np.unique(self.frames.candidate))),
            "poses": int(len(st)),
            **{s: int(np.count_nonzero(st == s)) for s in STATUSES},
        }

    def to_json(self) -> dict:
        c = self.cand.candidates
        fr = self.frames
        part = self.cand.part.to_json()
        part["T_world_part"] = self.T_world_part.tolist()
        cell = self.cell.to_json()
        cell["part_pose"] = self.part_pose_source
        params = self.cand.params.to_json()
        params["roll_step_deg"] = float(self.roll_step_deg)
        params["merge_distance"] = float(self.merge_distance)
        params["thin_spacing"] = float(self.thin[0])
        params["thin_axis_deg"] = float(self.thin[1])
        ci = fr.candidate
        r = lambda a: np.round(a, 10).tolist()  # noqa: E731 - 1e-10 m / rad: keeps the files small
        contacts = r(c.contacts[ci])
        normals = r(c.normals[ci])
        width = r(c.width[ci])
        T = r(fr.T_part_tcp)
        roll = r(fr.roll)
        st = self.status.tolist()
        cil = ci.tolist()
        grasps = [
            {"id": i, "candidate": cil[i], "contacts": contacts[i], "normals": normals[i], "width": width[i],
             "T_part_tcp": T[i], "roll": roll[i], "status": st[i]}
            for i in range(len(st))
        ]
        return {
            "schema": SCHEMA,
            "part": part,
            "gripper": self.gripper.to_json(),
            "cell": cell,
            "params": params,
            "counts": self.counts(),
            "timing_s": dict(self.timing_s),
            "grasps": grasps,
        }


def compute_grasps(
    part: Part,
    *,
    cand_params: CandidateParams = CandidateParams(),
    gripper: str | Gripper = "schunk_egp_c_40",
    cell: str | Cell = "table",
    T_world_part: np.ndarray | None = None,
    roll_step_deg: float = 15.0,
    merge_distance: float = 0.0,
    thin_spacing: float = 0.003,
    thin_axis_deg: float = 10.0,
    load_s: float = 0.0,
) -> GraspResult:
    """Candidates (``cand_params``), TCP poses every ``roll_step_deg`` about each closing axis, and
    the collision status of each pose against the part and the cell's table.

    ``T_world_part`` (4, 4) overrides the cell's stable resting pose. Candidates wider than the
    gripper's ``max_opening`` are not posed. Swapped duplicate candidates are posed once when the
    gripper is symmetric. ``thin_spacing`` (m, default 3 mm; 0 = off) poses only one candidate per
    cluster of :func:`grasplan.thinning.thin_candidates` (grasp-centre grid of that pitch x
    closing-axis direction quantised to ``thin_axis_deg``): the BLM yields many near-identical
    pairs on neighbouring triangles (TLess20: 72 k candidates, 1.7 M poses unthinned; 1.7 k
    candidates at 3 mm, far below the jaws' 16 mm width). ``merge_distance`` (m, default 0 = off)
    additionally skips a candidate whose two contacts fall in the same grid cells of that size as
    an earlier candidate's.
    """
    if not (np.isfinite(merge_distance) and merge_distance >= 0):
        raise InputError(f"merge_distance must be >= 0 m, got {merge_distance!r}")
    g = load_gripper(gripper)
    c = load_cell(cell)
    if cand_params.max_opening is None:  # search exactly as far as this gripper opens
        cand_params = replace(cand_params, max_opening=g.max_opening)
    timing: dict = {}
    t = time.perf_counter()
    cand = compute_candidates(part, cand_params, load_s=load_s)
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
    if thin_spacing > 0:
        from .thinning import thin_candidates

        select = thin_candidates(cand.candidates, spacing=float(thin_spacing), axis_step_deg=float(thin_axis_deg))
    frames = grasp_frames(cand.candidates, roll_step_deg=roll_step_deg, reference=down_in_part,
                          max_width=g.max_opening, dedupe_swapped=g.symmetric,
                          merge_distance=merge_distance, select=select)
    timing["frames"] = time.perf_counter() - t

    t = time.perf_counter()
    collider = GripperCollider(part.mesh, g, c, T)
    status = collider.check(frames.T_part_tcp, cand.candidates.width[frames.candidate])
    timing["collision"] = time.perf_counter() - t
    return GraspResult(cand=cand, gripper=g, cell=c, T_world_part=T, frames=frames, status=status,
                       timing_s=timing, roll_step_deg=float(roll_step_deg), part_pose_source=source,
                       merge_distance=float(merge_distance), thin=(float(thin_spacing), float(thin_axis_deg)))

