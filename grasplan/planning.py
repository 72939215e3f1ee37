"""Stages 7-8 composed: grasps a robot can reach, each with a verified joint path from home.

``plan(part, robot, *, gripper=, cell=, candidates=, grasps=, planning=)`` is the pure function
behind ``grasplan plan``:

1. ``compute_grasps`` (candidates, TCP frames, full-jaw collision filter) -> the ``ok`` grasps.
2. Every ``ok`` grasp gets a **score** in [0, 1] (:mod:`grasplan.scoring`, terms and weights in
   ``PlanParams.score_weights``); they are ranked by score (ties by grasp id), then reordered so
   that no two of the leading grasps are within ``distinct_distance`` and ``distinct_angle_deg``
   of each other while distinct ones remain (:func:`grasplan.scoring.distinct_order`).
3. In rank order, until ``top`` grasps are planned, the list is exhausted or ``budget_s`` is spent:

   - grasp TCP ``T_world_tcp = T_world_part @ T_part_tcp``; pre-grasp = the grasp TCP backed off
     ``backoff`` along its own -z; the jaws are at ``Gripper.pregrasp_opening`` for the whole
     motion (they close only at the grasp);
   - IK at the grasp (``solve_ik``; solutions closest to ``q_home`` first). None within the joint
     limits -> ``unreachable``;
   - for each IK solution in that order: the solution must be collision-free, then the straight
     approach is traced backwards from the grasp to the pre-grasp (``approach_path``: TCP on the
     line within ``max_dev``, continuous IK, collision-free with the jaws open); its end is
     ``q_pregrasp``. Then OMPL RRTConnect ``q_home -> q_pregrasp`` (``plan_joint_path``). The
     first solution that gets through all three is ``planned``;
   - otherwise the status says why: ``ik_collision`` (IK exists but every solution collides at
     the grasp or on the approach), ``unreachable`` (the straight approach leaves the workspace or
     the joint limits for every solution), ``no_path`` (RRTConnect found no verified path within
     its time). Each grasp also gets a human-readable ``reason``.

   ``ok`` grasps never tried (beyond the top K, or after the budget) are ``not_tried``; grasps the
   grasp stage rejected keep ``collision_part`` / ``collision_table``.

Result types and their JSON live in :mod:`grasplan.result`; the score in :mod:`grasplan.scoring`.
"""
from __future__ import annotations

import os
import time
from collections.abc import Callable

import numpy as np

from .mesh import Part, load_part
from .params import (
    DEFAULT_CELL,
    DEFAULT_GRIPPER,
    DEFAULT_ROBOT,
    CandidateParams,
    GraspParams,
    PlanParams,
)
from .result import Motion, Params, PlanResult
from .scoring import distinct_order, score_grasps

SCHEMA = "grasplan.plan/1"


def _translate_z(d: float) -> np.ndarray:
    T = np.eye(4)
    T[2, 3] = d
    return T


def plan_grasps(grasps, robot, scene, *, params: PlanParams = PlanParams(),
                progress: Callable[[dict], None] | None = None):
    """Plan the ranked ``ok`` grasps of ``grasps`` (a GraspResult) for ``robot`` in ``scene``.

    Returns ``(status, score, rank, reason, motions, timing_s)``: (M,) arrays, ``{id: Motion}``
    for the planned grasps and seconds per stage. ``progress`` gets a dict after every tried grasp:
    ``{"tried", "planned", "top", "candidates", "id", "status"}``.
    """
    from .ik import solve_ik
    from .paths import approach_path_reason, plan_joint_path

    t_all = time.perf_counter()
    timing = {"ik": 0.0, "approach": 0.0, "joint_path": 0.0}
    status_in = np.asarray(grasps.status).astype(str)
    M = len(status_in)
    frames = grasps.frames
    T_part_tcp = np.asarray(frames.T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    width = np.asarray(grasps.width, dtype=np.float64)
    gripper = grasps.gripper
    T_world_part = np.asarray(grasps.T_world_part, dtype=np.float64)
    T_flange_tcp = np.asarray(gripper.T_flange_tcp, dtype=np.float64)
    T_tcp_flange = np.linalg.inv(T_flange_tcp)

    ok = np.flatnonzero(status_in == "ok")
    scores = np.full(M, np.nan)
    if len(ok):
        scores[ok] = score_grasps(grasps.cand.part.mesh, T_world_part, T_part_tcp[ok], width[ok],
                                  float(gripper.max_opening), weights=params.score_weights)
    order = ok[np.lexsort((ok, -scores[ok]))] if len(ok) else ok
    order = distinct_order(T_part_tcp, order, min_distance=params.distinct_distance,
                           min_angle_deg=params.distinct_angle_deg)
    rank = np.full(M, -1, dtype=np.int64)
    rank[order] = np.arange(len(order))
    status = np.where(status_in == "ok", "not_tried", status_in).astype(object)
    reason = np.empty(M, dtype=object)
    reason[:] = "not tried: beyond the top K or the planning budget"
    reason[status_in == "collision_part"] = "grasp stage: the gripper hits the part at the grasp or while closing"
    reason[status_in == "collision_table"] = "grasp stage: the gripper hits the table at the grasp or while closing"
    motions: dict[int, Motion] = {}

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
                motions[int(i)] = Motion(q_grasp=approach[-1].copy(), q_pregrasp=q_pre.copy(), path=path,
                                         pregrasp_index=int(len(transit) - 1))
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
    return status, scores, rank, reason, motions, timing


def plan(
    part: Part | str | os.PathLike,
    robot=DEFAULT_ROBOT,
    *,
    gripper=DEFAULT_GRIPPER,
    cell=DEFAULT_CELL,
    candidates: CandidateParams = CandidateParams(),
    grasps: GraspParams = GraspParams(),
    planning: PlanParams = PlanParams(),
    T_world_part: np.ndarray | None = None,
    units: str = "auto",
    progress: Callable[[dict], None] | None = None,
    load_s: float = 0.0,
) -> PlanResult:
    """Grasps of ``part`` that ``robot`` can reach, each with a verified path from ``q_home``.

    Parameters
    ----------
    part : Part or path
        From :func:`grasplan.mesh.load_part`, or a mesh file path (loaded with ``units``).
    robot, gripper, cell : name, path or model
        A :class:`~grasplan.robot.Robot` / :class:`~grasplan.gripper.Gripper` /
        :class:`~grasplan.cell.Cell`, or a name or YAML path resolved once here (unknown names
        raise ``ConfigError`` listing what exists and where grasplan looked).
    candidates, grasps, planning : CandidateParams, GraspParams, PlanParams
        Every option of the stages, validated by the dataclasses (see :mod:`grasplan.params`).
    T_world_part : (4, 4), optional
        The part's pose in the world instead of its stable resting pose.
    progress : callable(dict) or None
        Called after the grasp stage (``{"stage": "grasps", "counts": ...}``) and after every tried grasp.
    load_s : float
        Seconds the caller spent loading ``part`` (recorded as ``timing_s["load"]``).
    """
    from .cell import load_cell
    from .grasps import compute_grasps
    from .gripper import load_gripper
    from .robot import Robot, load_robot
    from .scene import CollisionScene

    t = time.perf_counter()
    rob = robot if isinstance(robot, Robot) else load_robot(robot)
    g = load_gripper(gripper)
    c = load_cell(cell)
    t_robot = time.perf_counter() - t
    if not isinstance(part, Part):
        t = time.perf_counter()
        part = load_part(part, units=units)
        load_s = time.perf_counter() - t
    gr = compute_grasps(part, gripper=g, cell=c, candidates=candidates, grasps=grasps, T_world_part=T_world_part,
                        load_s=load_s)
    if progress is not None:
        progress({"stage": "grasps", "counts": gr.counts()})
    t = time.perf_counter()
    scene = CollisionScene(rob, gr.gripper, part.mesh, gr.T_world_part, gr.cell)
    t_robot += time.perf_counter() - t
    status, score, rank, reason, motions, timing = plan_grasps(gr, rob, scene, params=planning, progress=progress)
    base = gr.to_result()
    return PlanResult(part=base.part, gripper=gr.gripper, cell=gr.cell, robot=rob,
                      grasps=base.grasps.with_plan(status, score, rank, reason), motions=motions,
                      params=Params(gr.cand.params, grasps, planning), counts_stage=base.counts_stage,
                      timing_s={**gr.timing_s, "robot": t_robot, **timing}, part_pose_source=gr.part_pose_source,
                      grasp_result=gr, part_mesh=part.mesh)
