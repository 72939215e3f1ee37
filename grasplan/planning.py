"""Stages 7-8 composed: grasps a robot can reach, each with a verified joint path from home.

``plan(part, robot="ur5", ...)`` is the pure function behind ``grasplan plan``:

1. ``compute_grasps`` (candidates, TCP frames, full-jaw collision filter) -> the ``ok`` grasps.
2. Every ``ok`` grasp gets a **score** in [0, 1] (higher is better, see :func:`score_grasps`); the
   ``ok`` grasps are ranked by score (ties broken by grasp id, so the order is deterministic).
3. In rank order, until ``top`` grasps are planned, the list is exhausted or ``budget_s`` is spent:

   - grasp TCP ``T_world_tcp = T_world_part @ T_part_tcp``; pre-grasp = the grasp TCP backed off
     ``backoff`` (0.05 m) along its own -z; the jaws are at the gripper's pre-grasp opening
     ``min(max_opening, width + 10 mm)`` for the whole motion (they close only at the grasp);
   - IK at the grasp (``solve_ik``; solutions closest to ``q_home`` first). None within the joint
     limits -> ``unreachable``;
   - for each IK solution in that order: the solution must be collision-free, then the straight
     approach is traced backwards from the grasp to the pre-grasp (``approach_path``: TCP on the
     line within 2 mm, continuous IK, collision-free with the jaws open); its end is
     ``q_pregrasp``. Then OMPL RRTConnect ``q_home -> q_pregrasp`` (``plan_joint_path``). The
     first solution that gets through all three is ``planned``;
   - otherwise the status says why: ``ik_collision`` (IK exists but every solution collides at
     the grasp or on the approach / pre-grasp), ``unreachable`` (IK exists at the grasp but the
     straight approach leaves the workspace or the joint limits for every solution),
     ``no_path`` (some solution had a free grasp and approach, but RRTConnect found no verified path
     within its time). Each planned / failed grasp also gets a human-readable ``reason``.

   ``ok`` grasps never tried (beyond the top K, or after the budget) are ``not_tried``; grasps the
   grasp stage rejected keep ``collision_part`` / ``collision_table``.

Score (documented, all terms in [0, 1])::

    score = 0.4 * s_center + 0.4 * s_top + 0.2 * s_width
    s_center = 1 - min(1, |c_grasp - c_mass| / r_part)    grasp centre (TCP origin) close to the
               centre of mass (of the watertight part, else its mesh centroid); r_part = half the
               part's bounding-box diagonal
    s_top    = max(0, -z_tcp . z_world)                   approach from above (1: TCP z straight down)
    s_width  = (max_opening - width) / max_opening        margin to the gripper's maximum opening
"""
from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .candidates import CandidateParams
from .errors import InputError
from .io import write_json
from .mesh import Part, load_part

SCHEMA = "grasplan.plan/1"
Status = Literal["planned", "collision_part", "collision_table", "unreachable", "ik_collision", "no_path", "not_tried"]
STATUSES: tuple[str, ...] = ("planned", "collision_part", "collision_table", "unreachable", "ik_collision",
                             "no_path", "not_tried")
#: score weights (centre of mass, approach from above, width margin)
SCORE_WEIGHTS = (0.4, 0.4, 0.2)
#: pre-grasp back-off along the TCP's -z, m
BACKOFF = 0.05


@dataclass(frozen=True, kw_only=True)
class PlanParams:
    """Options of the planning stage (lengths m, times s)."""

    top: int = 20                       #: plan at most this many grasps (the best-scored first)
    seed: int = 0                       #: seeds IK and OMPL
    backoff: float = BACKOFF            #: pre-grasp back-off along the TCP's -z, m
    time_limit_per_query: float = 1.0   #: RRTConnect budget per attempt, s
    path_attempts: int = 2              #: RRTConnect attempts per query (new seed, finer checks)
    max_ik_solutions: int = 8           #: IK solutions tried per grasp (closest to q_home first)
    max_path_queries: int = 2           #: RRTConnect queries per grasp (distinct IK solutions)
    budget_s: float | None = 100.0      #: wall-clock budget of the planning loop; None = unlimited
    max_dev: float = 0.002              #: approach: largest TCP distance from the straight line, m

    def __post_init__(self):
        if self.top < 1:
            raise InputError(f"top must be >= 1, got {self.top}")
        if not self.backoff > 0:
            raise InputError(f"backoff must be a positive length in metres, got {self.backoff!r}")
        if not self.time_limit_per_query > 0:
            raise InputError(f"time_limit_per_query must be > 0 s, got {self.time_limit_per_query!r}")
        if self.budget_s is not None and not self.budget_s > 0:
            raise InputError(f"budget_s must be > 0 s (or None), got {self.budget_s!r}")

    def to_json(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class PlanTable:
    """Per-grasp planning outcome, as arrays (there can be millions of grasp poses).

    status : (M,) str, one of :data:`STATUSES`
    score : (M,) float64, NaN for grasps the grasp stage rejected
    rank : (M,) int64, 0 = best-scored ``ok`` grasp, -1 for rejected grasps
    reason : (M,) object (str), why the grasp has its status
    details : dict id -> {"q_grasp" (n,), "q_pregrasp" (n,), "path" (k, n), "pregrasp_index"}
        for the planned grasps
    """

    status: np.ndarray
    score: np.ndarray
    rank: np.ndarray
    reason: np.ndarray
    details: dict

    def entry(self, i: int) -> dict:
        """Grasp ``i`` as a dict: id, status, score (None), rank (None), reason, and when planned
        q_grasp, q_pregrasp, path, pregrasp_index."""
        i = int(i)
        e = {"id": i, "status": str(self.status[i]),
             "score": None if np.isnan(self.score[i]) else float(self.score[i]),
             "rank": None if self.rank[i] < 0 else int(self.rank[i]), "reason": str(self.reason[i])}
        e.update(self.details.get(i, {}))
        return e


@dataclass(frozen=True)
class PlanResult:
    """What ``plan`` found.

    Attributes
    ----------
    grasps : GraspResult
        The grasp stage's result (candidates, frames, collision status).
    robot : Robot
        The robot model planned for.
    table : PlanTable
        Per-grasp status, score, rank, reason and (planned) joint vectors and path.
    timing_s : dict
        Seconds per planning stage: ``robot`` (load + scene), ``ik``, ``approach``,
        ``joint_path``, ``plan`` (the whole planning loop incl. scoring); the grasp stage's own
        timings are in ``grasps.timing_s``.
    params : PlanParams
    """

    grasps: Any
    robot: Any
    table: PlanTable
    timing_s: dict = field(default_factory=dict)
    params: PlanParams = field(default_factory=PlanParams)

    @property
    def entries(self) -> list[dict]:
        """Every grasp as a dict (:meth:`PlanTable.entry`), in id order."""
        return [self.table.entry(i) for i in range(len(self.table.status))]

    def entry(self, grasp_id: int) -> dict:
        return self.table.entry(grasp_id)

    def counts(self) -> dict:
        u, c = np.unique(self.table.status.astype(str), return_counts=True)
        got = dict(zip(u.tolist(), c.tolist()))
        out = {s: int(got.get(s, 0)) for s in STATUSES}
        out["grasps"] = int(len(self.table.status))
        return out

    def planned(self) -> list[dict]:
        """Planned entries, best rank first."""
        return sorted((self.table.entry(i) for i in self.table.details), key=lambda e: e["rank"])

    def to_json(self) -> dict:
        """``grasplan.plan/1``: the grasps document plus ``robot``, ``plan_params`` and per grasp
        ``status``, ``score``, ``rank``, ``reason`` (+ ``q_grasp``, ``q_pregrasp``, ``path``,
        ``pregrasp_index`` when planned). ``counts`` gains one entry per plan status; ``timing_s``
        gains the planning stages."""
        doc = self.grasps.to_json()
        doc["schema"] = SCHEMA
        r = self.robot
        doc["robot"] = {
            "name": r.name,
            "joint_names": list(r.joint_names),
            "T_world_base": np.asarray(r.T_world_base, dtype=np.float64).tolist(),
            "q_home": np.asarray(r.q_home, dtype=np.float64).tolist(),
        }
        # the grasp stage's "ok" (collision-free) poses are split into the plan statuses here; its
        # other counts (candidates, poses, ...) stay, and "collision_free" keeps the stage's number
        stage_counts = dict(doc.get("counts", {}))
        stage_counts["collision_free"] = stage_counts.pop("ok", 0)
        counts = self.counts()
        counts.pop("grasps", None)  # == stage_counts["poses"]
        doc["counts"] = {**stage_counts, **counts}
        doc["timing_s"] = {**doc.get("timing_s", {}), **{k: float(v) for k, v in self.timing_s.items()}}
        doc["plan_params"] = self.params.to_json()
        t = self.table
        status = t.status.astype(str).tolist()
        score = t.score.tolist()
        rank = t.rank.tolist()
        reason = t.reason.tolist()
        grasps = doc["grasps"]
        if len(grasps) != len(status):
            raise AssertionError("grasps and plan table disagree in length")
        for i, g in enumerate(grasps):
            if int(g["id"]) != i:
                raise AssertionError("grasp ids must be 0..M-1 in order")
            g["status"] = status[i]
            g["score"] = None if score[i] != score[i] else score[i]
            g["rank"] = None if rank[i] < 0 else rank[i]
            g["reason"] = reason[i]
        for i, d in t.details.items():
            g = grasps[i]
            g["q_grasp"] = np.asarray(d["q_grasp"]).tolist()
            g["q_pregrasp"] = np.asarray(d["q_pregrasp"]).tolist()
            g["path"] = np.asarray(d["path"]).tolist()
            g["pregrasp_index"] = int(d["pregrasp_index"])
        return doc

    def write(self, path) -> Path:
        """Write ``grasplan.plan/1`` JSON atomically."""
        return write_json(path, self.to_json())

    def export(self, fmt: str, path, grasp_id: int | None = None, **kwargs) -> Path:
        """Write one planned grasp as ``urscript`` / ``joint-trajectory`` / ``csv`` (grasplan.export)."""
        from . import export

        return export.write(self.to_json(), fmt, path, grasp_id=grasp_id, **kwargs)


# --------------------------------------------------------------------------------------------------
# score
# --------------------------------------------------------------------------------------------------
def score_grasps(part_mesh, T_world_part: np.ndarray, T_part_tcp: np.ndarray, width: np.ndarray,
                 max_opening: float) -> np.ndarray:
    """Score in [0, 1] per grasp (higher is better); see the module docstring for the formula.

    ``T_part_tcp`` (M, 4, 4), ``width`` (M,) m -> (M,) float64.
    """
    T_part_tcp = np.asarray(T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    width = np.asarray(width, dtype=np.float64).reshape(-1)
    if len(width) != len(T_part_tcp):
        raise ValueError("T_part_tcp (M, 4, 4) and width (M,) disagree")
    T_world_part = np.asarray(T_world_part, dtype=np.float64)
    com = np.asarray(part_mesh.center_mass if part_mesh.is_watertight else part_mesh.centroid, dtype=np.float64)
    r = 0.5 * float(np.linalg.norm(part_mesh.extents))
    d = np.linalg.norm(T_part_tcp[:, :3, 3] - com, axis=1)
    s_center = 1.0 - np.minimum(1.0, d / max(r, 1e-12))
    z_world = np.einsum("ij,mj->mi", T_world_part[:3, :3], T_part_tcp[:, :3, 2])
    s_top = np.maximum(0.0, -z_world[:, 2])
    s_width = np.clip((max_opening - width) / max_opening, 0.0, 1.0)
    w = SCORE_WEIGHTS
    return w[0] * s_center + w[1] * s_top + w[2] * s_width


# --------------------------------------------------------------------------------------------------
# pipeline
# --------------------------------------------------------------------------------------------------
def _translate_z(d: float) -> np.ndarray:
    T = np.eye(4)
    T[2, 3] = d
    return T


def plan_grasps(grasps, robot, scene, *, params: PlanParams = PlanParams(),
                progress: Callable[[dict], None] | None = None) -> tuple[PlanTable, dict]:
    """Plan the ranked ``ok`` grasps of ``grasps`` (a GraspResult) for ``robot`` in ``scene``.

    Returns (PlanTable, timing_s); see :func:`plan`. ``progress`` gets a dict after every tried
    grasp: ``{"tried", "planned", "top", "candidates", "id", "status"}``.
    """
    from .ik import solve_ik
    from .paths import approach_path_reason, plan_joint_path

    t_all = time.perf_counter()
    timing = {"ik": 0.0, "approach": 0.0, "joint_path": 0.0}
    status_in = np.asarray(grasps.status).astype(str)
    M = len(status_in)
    frames = grasps.frames
    T_part_tcp = np.asarray(frames.T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    width = np.asarray(grasps.cand.candidates.width, dtype=np.float64)[np.asarray(frames.candidate, dtype=np.int64)]
    gripper = grasps.gripper
    T_world_part = np.asarray(grasps.T_world_part, dtype=np.float64)
    T_flange_tcp = np.asarray(gripper.T_flange_tcp, dtype=np.float64)
    T_tcp_flange = np.linalg.inv(T_flange_tcp)

    ok = np.flatnonzero(status_in == "ok")
    scores = np.full(M, np.nan)
    if len(ok):
        scores[ok] = score_grasps(grasps.cand.part.mesh, T_world_part, T_part_tcp[ok], width[ok], float(gripper.max_opening))
    # rank: score descending, id ascending
    order = ok[np.lexsort((ok, -scores[ok]))] if len(ok) else ok
    rank = np.full(M, -1, dtype=np.int64)
    rank[order] = np.arange(len(order))
    status = np.where(status_in == "ok", "not_tried", status_in).astype(object)
    reason = np.empty(M, dtype=object)
    reason[:] = "not tried: beyond the top K or the planning budget"
    reason[status_in == "collision_part"] = "grasp stage: the gripper hits the part at the grasp or while closing"
    reason[status_in == "collision_table"] = "grasp stage: the gripper hits the table at the grasp or while closing"
    details: dict[int, dict] = {}

    q_home = np.asarray(robot.q_home, dtype=np.float64)
    planned = tried = 0
    for i in order:
        if planned >= params.top:
            break
        if params.budget_s is not None and time.perf_counter() - t_all > params.budget_s:
            break
        tried += 1
        e = {"status": "not_tried", "reason": ""}
        T_world_tcp = T_world_part @ T_part_tcp[i]
        T_world_pre = T_world_tcp @ _translate_z(-params.backoff)
        opening = float(gripper.pregrasp_opening(width[i]))

        t = time.perf_counter()
        ik = solve_ik(robot, T_world_tcp @ T_tcp_flange, seed=params.seed)
        timing["ik"] += time.perf_counter() - t
        sols = np.asarray(ik.q, dtype=np.float64).reshape(-1, len(q_home))[: params.max_ik_solutions]
        if len(sols) == 0:
            e["status"], e["reason"] = "unreachable", f"no IK solution within the joint limits ({ik.reason})"
        else:
            n_grasp_coll = n_app_coll = n_app_kin = n_path_fail = 0
            for j, q_grasp in enumerate(sols):
                if not scene.is_free(q_grasp, opening):
                    n_grasp_coll += 1
                    continue
                t = time.perf_counter()
                back, why = approach_path_reason(robot, scene, T_world_tcp, T_world_pre, q_grasp, opening=opening,
                                                 max_dev=params.max_dev, T_flange_tcp=T_flange_tcp)
                timing["approach"] += time.perf_counter() - t
                if back is None:
                    if why == "collision":
                        n_app_coll += 1
                    else:
                        n_app_kin += 1
                    continue
                approach = back[::-1]  # pre-grasp -> grasp
                q_pre = approach[0]
                t = time.perf_counter()
                transit = plan_joint_path(scene, q_home, q_pre, lower=robot.lower, upper=robot.upper, opening=opening,
                                          seed=params.seed * 1_000_003 + int(i), time_limit=params.time_limit_per_query,
                                          attempts=params.path_attempts)
                timing["joint_path"] += time.perf_counter() - t
                if transit is None:
                    n_path_fail += 1
                    if n_path_fail >= params.max_path_queries:
                        break
                    continue
                path = np.concatenate([transit, approach[1:]], axis=0)
                e.update(status="planned", reason=f"planned with IK solution {j} of {len(sols)} (closest to q_home first)")
                details[int(i)] = {"q_grasp": approach[-1].copy(), "q_pregrasp": q_pre.copy(), "path": path,
                                   "pregrasp_index": int(len(transit) - 1)}
                planned += 1
                break
            if e["status"] != "planned":
                k = len(sols)
                detail = (f"{k} IK solutions: {n_grasp_coll} collide at the grasp, {n_app_coll} collide on the "
                          f"approach, {n_app_kin} cannot follow the straight approach (IK lost, joint limit, "
                          f"jump or > {params.max_dev * 1e3:g} mm off the line)")
                if n_path_fail:
                    e["status"] = "no_path"
                    e["reason"] = (f"RRTConnect found no verified path home -> pre-grasp in {n_path_fail} "
                                   f"queries; " + detail)
                elif n_grasp_coll + n_app_coll > 0:
                    e["status"], e["reason"] = "ik_collision", detail
                else:
                    e["status"], e["reason"] = "unreachable", detail
        status[i], reason[i] = e["status"], e["reason"]
        if progress is not None:
            progress({"tried": tried, "planned": planned, "top": params.top, "candidates": len(order),
                      "id": int(i), "status": e["status"]})
    timing["plan"] = time.perf_counter() - t_all
    return PlanTable(status=status, score=scores, rank=rank, reason=reason, details=details), timing


def plan(
    part: Part | str | os.PathLike,
    *,
    units: str = "auto",
    robot: str = "ur5",
    gripper: str = "schunk_egp_c_40",
    cell: str = "table",
    top: int = 20,
    seed: int = 0,
    cand_params: CandidateParams = CandidateParams(),
    roll_step_deg: float = 15.0,
    thin_spacing: float = 0.003,
    T_world_part: np.ndarray | None = None,
    time_limit_per_query: float = 1.0,
    budget_s: float | None = 100.0,
    progress: Callable[[dict], None] | None = None,
    load_s: float = 0.0,
) -> PlanResult:
    """Grasps of ``part`` that ``robot`` can reach, each with a verified path from ``q_home``.

    Parameters
    ----------
    part : Part or path
        From :func:`grasplan.mesh.load_part`, or a mesh file path (loaded with ``units``).
    units : str
        Units of the mesh file when ``part`` is a path (see :func:`grasplan.mesh.load_part`).
    robot, gripper, cell : str
        Names (or paths) for ``load_robot``, ``load_gripper``, ``load_cell``; unknown names raise
        ``ConfigError`` listing the available ones (before any heavy work).
    top : int
        Plan at most ``top`` grasps, best score first.
    seed : int
        Seeds IK and OMPL: same inputs and seed, same result.
    cand_params, roll_step_deg, thin_spacing, T_world_part
        Passed to :func:`grasplan.grasps.compute_grasps`.
    time_limit_per_query : float, s
        RRTConnect budget per attempt.
    budget_s : float or None, s
        Wall-clock budget of the planning loop (grasps not reached are ``not_tried``).
    load_s : float
        Seconds the caller spent loading ``part`` (recorded as ``timing_s["load"]``).
    progress : callable(dict) or None
        Called after the grasp stage (``{"stage": "grasps", ...}``) and after every tried grasp.
    """
    from .grasps import compute_grasps
    from .robot import load_robot
    from .scene import CollisionScene

    if not isinstance(part, Part):
        t = time.perf_counter()
        part = load_part(part, units=units)
        load_s = time.perf_counter() - t
    params = PlanParams(top=top, seed=seed, time_limit_per_query=time_limit_per_query, budget_s=budget_s)
    t = time.perf_counter()
    rob = load_robot(robot)
    t_robot = time.perf_counter() - t
    gr = compute_grasps(part, cand_params=cand_params, gripper=gripper, cell=cell, T_world_part=T_world_part,
                        roll_step_deg=roll_step_deg, thin_spacing=thin_spacing, load_s=load_s)
    if progress is not None:
        progress({"stage": "grasps", "counts": gr.counts()})
    t = time.perf_counter()
    scene = CollisionScene(rob, gr.gripper, part.mesh, gr.T_world_part, gr.cell)
    t_robot += time.perf_counter() - t
    table, timing = plan_grasps(gr, rob, scene, params=params, progress=progress)
    timing = {"robot": t_robot, **timing}
    return PlanResult(grasps=gr, robot=rob, table=table, timing_s=timing, params=params)
