"""Stages 7-8 composed: grasps a robot can reach, each with a verified joint path from home.

``plan(part, robot, *, gripper=, cell=, candidates=, grasps=, planning=)`` is the pure function
behind ``grasplan plan``:

1. ``compute_grasps`` (candidates, TCP frames, full-jaw collision filter) -> the ``ok`` grasps.
2. Every ``ok`` grasp has a **score** in [0, 1] from the grasp stage (:mod:`grasplan.config.scoring`:
   reachability terms and the physical quality of :mod:`grasplan.grasps.quality`, weights from the scoring
   YAML; ``PlanParams.score_weights`` re-scores with other weights); they are ranked by score (ties by grasp id), then reordered so
   that no two of the leading grasps are within ``distinct_distance`` and ``distinct_angle_deg``
   of each other while distinct ones remain (:func:`grasplan.config.scoring.distinct_order`).
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
4. ``simulate > 0``: the top ``simulate`` planned grasps are closed, lifted and shaken in MuJoCo
   (:func:`grasplan.sim.simulate.simulate_plan`); each gets ``sim`` and the ranking puts the grasps
   that held first (stable: otherwise the score order).

The planner hands over typed results: :class:`GraspOutcome` per tried grasp and
:class:`PlanOutcome` for the stage (status, score, rank and reason arrays, motions, timing, and the
final :class:`~grasplan.grasps.pipeline.GraspResult` when rank-order evaluation checked poses while
planning). The checks before planning are :mod:`grasplan.motion.start_checks`. Result types and their
JSON live in :mod:`grasplan.results.plan_result`; the score in :mod:`grasplan.config.scoring`.
"""
from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..cell.model import NO_CELL_NAME, Cell, load_cell
from ..errors import ConfigError, InputError
from ..grasps.pipeline import GraspResult, LazyGrasps, compute_grasps
from ..gripper.load import load_gripper
from ..gripper.model import Gripper
from ..robot.ik.solve import solve_ik
from ..part.mass import MassProperties
from ..geometry.meshdata import TriangleMesh
from ..part.mesh import Part, load_part
from ..config.params import DEFAULT_CELL, DEFAULT_GRIPPER, DEFAULT_ROBOT, CandidateParams, GraspParams, PlanParams
from .joint_paths import approach_path_reason, plan_joint_path
from .pickplace import (
    PlaceCandidate, T_tcp_part_of, assemble_motion, place_candidates, place_poses, plan_lift, transfer_path
)
from ..results.joint_motion import Motion
from ..results.plan_result import Params, PlanResult
from ..robot.description import load_robot
from ..robot.model import Robot
from .collision_scene import CollisionScene, describe_pairs, no_path_reason
from ..config.scoring import ScoringConfig, distinct_order, score_grasps
from ..cell.resting import stable_pose
from ..part.stability import stable_poses
from .start_checks import check_part_placement, check_start
from ..status import Status
from ..geometry.transforms import check_transform, translation

SCHEMA = "grasplan.plan/1"

#: the reason of an ``ok`` grasp the planner did not try
NOT_TRIED_REASON = "not tried: beyond the top K or the planning budget"
#: the reason of each grasp-stage rejection (when the grasp stage recorded none of its own)
STAGE_REJECTION_REASONS = {
    Status.COLLISION_PART: "grasp stage: the gripper hits the part at the grasp or while closing",
    Status.COLLISION_TABLE: "grasp stage: the gripper hits the table at the grasp or while closing",
    Status.COLLISION_OBSTACLE: "grasp stage: the gripper hits an obstacle at the grasp or while closing",
}


@dataclass(frozen=True)
class GraspOutcome:
    """What planning one grasp gave: its plan ``status``, a human-readable ``reason`` and, when
    ``status`` is ``planned``, its ``motion`` (else None)."""

    status: Status
    reason: str
    motion: Motion | None = None


@dataclass(frozen=True, eq=False)
class PlanOutcome:
    """The plan stage's result for the M poses of a grasp result.

    ``status`` (M,) object: the plan status values (:class:`~grasplan.status.Status` ``.value``);
    ``score`` (M,) float64 (NaN: not ranked); ``rank`` (M,) int64 (-1: not ranked); ``reason``
    (M,) object str; ``motions`` ``{pose id: Motion}`` of the planned grasps; ``timing_s`` seconds
    per stage; ``grasp_result``: the final :class:`~grasplan.grasps.pipeline.GraspResult` when the
    rank-order evaluation checked poses while planning (its unchecked poses ``not_checked``), else
    None (the grasp result planned from is final)."""

    status: np.ndarray
    score: np.ndarray
    rank: np.ndarray
    reason: np.ndarray
    motions: dict[int, Motion]
    timing_s: dict[str, float]
    grasp_result: GraspResult | None = None


@dataclass(frozen=True, eq=False)
class _Setting:
    """What every grasp of one plan shares: the robot, the scenes, the poses and the options;
    ``timing`` (seconds per stage) is added to as grasps are planned."""

    robot: Robot
    scene: CollisionScene
    gripper: Gripper
    params: PlanParams
    T_world_part: np.ndarray
    T_flange_tcp: np.ndarray
    T_tcp_flange: np.ndarray
    q_home: np.ndarray
    retreat_dir: np.ndarray
    retreat_dist: float
    T_place: np.ndarray | None
    scene_released: CollisionScene | None
    timing: dict[str, float]


def plan_grasps(grasps: GraspResult, robot: Robot, scene: CollisionScene, *, params: PlanParams = PlanParams(),
                progress: Callable[[dict], None] | None = None, ranked: Iterable[int] | None = None) -> PlanOutcome:
    """Plan the ranked ``ok`` grasps of ``grasps`` for ``robot`` in ``scene``.

    Returns a :class:`PlanOutcome` ((M,) status, score, rank and reason arrays, ``{id: Motion}``
    for the planned grasps and seconds per stage). ``progress`` gets a dict after every tried
    grasp: ``{"tried", "planned", "top", "candidates", "id", "status"}``. ``ranked``: the pose ids
    to try in this order instead of the ranking (the rank-order evaluation's).
    """
    t_all = time.perf_counter()
    timing = {"ik": 0.0, "approach": 0.0, "joint_path": 0.0, "lift": 0.0, "place": 0.0, "transfer": 0.0}
    lazy = grasps.lazy
    if isinstance(lazy, LazyGrasps) and params.score_weights is None and not params.check_all:
        return _plan_lazy(lazy, robot, scene, params=params, progress=progress, timing=timing, t_all=t_all)
    if isinstance(lazy, LazyGrasps):  # other weights or --check-all: check every pose first
        lazy.check_all()
        grasps = lazy.result()
    status_in = np.asarray(grasps.status).astype(str)
    M = len(status_in)
    T_part_tcp = np.asarray(grasps.frames.T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    width = np.asarray(grasps.width, dtype=np.float64)
    gripper = grasps.gripper
    T_world_part = np.asarray(grasps.T_world_part, dtype=np.float64)

    ok = np.flatnonzero(status_in == Status.OK.value)
    scores = np.full(M, np.nan)
    if grasps.score is not None and params.score_weights is None:
        scores[ok] = np.asarray(grasps.score, dtype=np.float64)[ok]  # the grasp stage's score (quality + reach)
    elif len(ok):
        mp = grasps.mass_props
        gp = grasps.params
        cfg = ScoringConfig.from_params(params.score_weights or gp.score_weights, gp.score_refs)
        scores[ok] = score_grasps(grasps.cand.part.mesh, T_world_part, T_part_tcp[ok], width[ok],
                                  float(gripper.max_opening), weights=cfg.weights, quality=grasps.quality,
                                  scoring=cfg, com=mp.com if isinstance(mp, MassProperties) else None)
    order = ok[np.lexsort((ok, -scores[ok]))] if len(ok) else ok
    order = distinct_order(T_part_tcp, order, min_distance=params.distinct_distance,
                           min_angle_deg=params.distinct_angle_deg)
    rank = np.full(M, -1, dtype=np.int64)
    rank[order] = np.arange(len(order))
    status = np.where(status_in == Status.OK.value, Status.NOT_TRIED.value, status_in).astype(object)
    reason = np.empty(M, dtype=object)
    reason[:] = NOT_TRIED_REASON
    for st, text in STAGE_REJECTION_REASONS.items():
        reason[status_in == st.value] = text
    stage_reasons = grasps.reasons  # per pose, naming the gripper element and the body
    if stage_reasons is not None:
        rejected = (status_in != Status.OK.value) & (np.asarray(stage_reasons, dtype=object) != "")
        reason[rejected] = np.asarray(stage_reasons, dtype=object)[rejected]
    motions: dict[int, Motion] = {}

    # pick-and-place (grasplan.motion.pickplace): the lift always, the place when the cell has one
    cell = grasps.cell
    T_place = None if cell.place is None else np.asarray(cell.place, dtype=np.float64)
    T_flange_tcp = np.asarray(gripper.T_flange_tcp, dtype=np.float64)
    setting = _Setting(robot=robot, scene=scene, gripper=gripper, params=params, T_world_part=T_world_part,
                       T_flange_tcp=T_flange_tcp, T_tcp_flange=np.linalg.inv(T_flange_tcp),
                       q_home=np.asarray(robot.q_home, dtype=np.float64),
                       retreat_dir=np.asarray(cell.retreat_direction, dtype=np.float64),
                       retreat_dist=float(cell.retreat_distance), T_place=T_place,
                       scene_released=scene.with_part_at(T_place) if T_place is not None else None, timing=timing)
    planned = tried = 0
    n_candidates = len(order)
    for i in (order if ranked is None else ranked):
        if planned >= params.top:
            break
        if params.budget_s is not None and time.perf_counter() - t_all > params.budget_s:
            break
        tried += 1
        out = _plan_grasp(setting, int(i), T_part_tcp[i], float(width[i]))
        if out.motion is not None:
            motions[int(i)] = out.motion
            planned += 1
        status[i], reason[i] = out.status.value, out.reason
        if progress is not None:
            progress({"tried": tried, "planned": planned, "top": params.top, "candidates": n_candidates,
                      "id": int(i), "status": out.status.value})
    timing["plan"] = time.perf_counter() - t_all
    return PlanOutcome(status=status, score=scores, rank=rank, reason=reason, motions=motions, timing_s=timing)


def _plan_grasp(s: _Setting, i: int, T_part_tcp: np.ndarray, width: float) -> GraspOutcome:
    """Plan grasp ``i`` (TCP ``T_part_tcp`` (4, 4) in the part frame, contact ``width`` m): IK at the
    grasp, then for each IK solution (closest to q_home first) the approach, the lift, the place
    side and the transit from q_home; the first solution that gets through all is ``planned``."""
    params, robot, scene, timing = s.params, s.robot, s.scene, s.timing
    T_place, T_flange_tcp = s.T_place, s.T_flange_tcp
    if s.gripper.moving_tcp:  # plan in the frame the gripper's shapes and T_flange_tcp are given in
        T_part_tcp = T_part_tcp @ s.gripper.T_tcp_gripper(width)
    T_world_tcp = s.T_world_part @ T_part_tcp
    T_world_pre = T_world_tcp @ translation(z=-params.backoff)
    opening = float(s.gripper.pregrasp_opening(width))

    t = time.perf_counter()
    ik = solve_ik(robot, T_world_tcp @ s.T_tcp_flange, seed=params.seed)
    timing["ik"] += time.perf_counter() - t
    sols = np.asarray(ik.q, dtype=np.float64).reshape(-1, len(s.q_home))[: params.max_ik_solutions]
    if len(sols) == 0:
        return GraspOutcome(Status.UNREACHABLE, f"no IK solution within the joint limits ({ik.reason})")
    n_grasp_coll = n_app_coll = n_app_kin = n_path_fail = 0
    n_lift_coll = n_lift_kin = n_transfer_fail = 0
    lift_why = ""
    grasp_hit = path_why = ""  # what the best IK branch hits; why the transit failed
    T_tcp_part = T_tcp_part_of(T_part_tcp)
    scene_att = scene.attached(T_tcp_part)
    # the place side (IK, descent, release, retreat), once per grasp: (candidates, status, reason)
    place: tuple[list[PlaceCandidate], Status, str] | None = None
    for j, q_grasp in enumerate(sols):
        if not scene.is_free(q_grasp, opening):
            n_grasp_coll += 1
            grasp_hit = grasp_hit or f"IK solution {j} at the grasp: " + describe_pairs(
                scene.colliding_pairs(q_grasp, opening), 2)
            continue
        t = time.perf_counter()
        back, why = approach_path_reason(robot, scene, T_world_tcp, T_world_pre, q_grasp, opening=opening,
                                         max_dev=params.max_dev, T_flange_tcp=T_flange_tcp)
        timing["approach"] += time.perf_counter() - t
        if back is None:
            if why == "collision":
                n_app_coll += 1
                if not grasp_hit:  # re-trace the approach without the scene to name the hit
                    kin, _ = approach_path_reason(robot, None, T_world_tcp, T_world_pre, q_grasp,
                                                  opening=opening, max_dev=params.max_dev,
                                                  T_flange_tcp=T_flange_tcp)
                    hit = None if kin is None else scene.path_collisions(kin, opening)
                    grasp_hit = "" if hit is None else (f"IK solution {j} on the approach: "
                                                        + describe_pairs(hit[1], 2))
            else:
                n_app_kin += 1
            continue
        approach = back[::-1]  # pre-grasp -> grasp
        q_pre = approach[0]
        t = time.perf_counter()
        lift = plan_lift(robot, scene_att, approach[-1], T_world_tcp, direction=s.retreat_dir,
                         distance=s.retreat_dist, width=width, max_dev=params.max_dev, T_flange_tcp=T_flange_tcp)
        timing["lift"] += time.perf_counter() - t
        if lift.path is None:
            n_lift_coll += lift.status == Status.IK_COLLISION
            n_lift_kin += lift.status != Status.IK_COLLISION
            lift_why = lift_why or lift.reason
            continue
        lift_path = lift.path
        if T_place is not None and s.scene_released is not None and place is None:
            t = time.perf_counter()
            place = place_candidates(
                robot, scene_att, s.scene_released,
                place_poses(T_place, T_part_tcp, s.retreat_dir, s.retreat_dist, params.backoff),
                width=width, opening=opening, max_dev=params.max_dev, T_flange_tcp=T_flange_tcp,
                q_ref=lift_path[-1], seed=params.seed, max_solutions=params.max_ik_solutions,
                limit=params.max_path_queries)
            timing["place"] += time.perf_counter() - t
        if place is not None and not place[0]:
            break  # the place side does not depend on the grasp's IK solution
        t = time.perf_counter()
        transit = plan_joint_path(scene, s.q_home, q_pre, lower=robot.lower, upper=robot.upper, opening=opening,
                                  seed=params.seed * 1_000_003 + i, time_limit=params.time_limit_per_query,
                                  attempts=params.path_attempts)
        timing["joint_path"] += time.perf_counter() - t
        if transit is None:
            n_path_fail += 1
            path_why = path_why or no_path_reason(scene, s.q_home, q_pre, opening,
                                                  params.time_limit_per_query, params.path_attempts)
            if n_path_fail >= params.max_path_queries:
                break
            continue
        transfer = cand = None
        if place is not None:
            t = time.perf_counter()
            for c in place[0]:
                if n_transfer_fail >= params.max_path_queries:
                    break
                transfer = transfer_path(scene_att, lift_path[-1], c, lower=robot.lower, upper=robot.upper,
                                         width=width, seed=params.seed * 1_000_003 + i + 7,
                                         time_limit=params.time_limit_per_query, attempts=params.path_attempts)
                if transfer is not None:
                    cand = c
                    break
                n_transfer_fail += 1
            timing["transfer"] += time.perf_counter() - t
            if cand is None:
                if n_transfer_fail >= params.max_path_queries:
                    break
                continue
        motion = assemble_motion(transit, approach, lift_path, width=width, opening=opening, T_tcp_part=T_tcp_part,
                                 transfer=transfer, place=cand, T_world_part_place=T_place)
        return GraspOutcome(Status.PLANNED, f"planned with IK solution {j} of {len(sols)} (closest to q_home first)"
                            + ("" if cand is None else " and a place"), motion)
    k = len(sols)
    detail = (f"{k} IK solutions: {n_grasp_coll} collide at the grasp, {n_app_coll} collide on the "
              f"approach, {n_app_kin} cannot follow the straight approach (IK lost, joint limit, "
              f"jump or > {params.max_dev * 1e3:g} mm off the line)")
    if place is not None and not place[0]:
        return GraspOutcome(place[1], place[2])
    if n_transfer_fail:
        return GraspOutcome(Status.PLACE_NO_PATH, f"place: RRTConnect found no verified transfer path (part in the "
                            f"jaws) lifted -> above the place in {n_transfer_fail} queries")
    if n_path_fail:
        return GraspOutcome(Status.NO_PATH, f"RRTConnect found no verified path home -> pre-grasp in {n_path_fail} "
                            f"queries ({path_why}); " + detail)
    if n_lift_coll + n_lift_kin > 0:
        return GraspOutcome(Status.IK_COLLISION if n_lift_coll else Status.NO_PATH,
                            f"{lift_why}; {n_lift_coll + n_lift_kin} of {len(sols)} IK solutions fail the lift "
                            f"({n_lift_coll} collide, {n_lift_kin} cannot follow the line); " + detail)
    if n_grasp_coll + n_app_coll > 0:
        return GraspOutcome(Status.IK_COLLISION, detail + (f"; {grasp_hit}" if grasp_hit else ""))
    return GraspOutcome(Status.UNREACHABLE, detail)


def _plan_lazy(lazy: LazyGrasps, robot: Robot, scene: CollisionScene, *, params: PlanParams,
               progress: Callable[[dict], None] | None, timing: dict[str, float], t_all: float) -> PlanOutcome:
    """:func:`plan_grasps` with the rank-order evaluation of :class:`grasplan.grasps.pipeline.LazyGrasps`:
    the planning loop takes the grasps in the full ranking's order, checking chunks of poses only
    while an unchecked pose could still rank ahead. The outcome carries the final
    :class:`grasplan.grasps.pipeline.GraspResult` (unchecked poses ``not_checked``)."""
    it = lazy.ranked(params.distinct_distance, params.distinct_angle_deg)
    tried: list[int] = []

    def gen() -> Iterator[int]:
        for i in it:
            tried.append(i)
            yield i

    # the loop of plan_grasps writes into arrays of its own; run it on a placeholder and re-apply
    sub = plan_grasps(replace(lazy.result(), lazy=None), robot, scene, params=params, progress=progress,
                      ranked=gen())
    timing.update(sub.timing_s)
    final = lazy.result()
    status_in = np.asarray(final.status).astype(str)
    M = len(status_in)
    ok = status_in == Status.OK.value
    scores = np.where(ok, np.asarray(final.score, dtype=np.float64), np.nan)
    order, n = lazy.order(params.distinct_distance, params.distinct_angle_deg)
    rank = np.full(M, -1, dtype=np.int64)
    rank[order[:n]] = np.arange(n)
    status = np.where(ok, Status.NOT_TRIED.value, status_in).astype(object)
    reason = np.asarray(final.reasons, dtype=object).copy()
    reason[ok] = NOT_TRIED_REASON
    bound = lazy.bound()
    unchecked = status_in == Status.NOT_CHECKED.value
    best = np.nanmax(scores[order[:n]]) if n else float("nan")
    floor = float(scores[order[n - 1]]) if n else float("nan")
    reason[unchecked] = (f"not checked: ranked below the planned grasps (the upper bound of its score is below "
                         f"{bound:.6g}, the best unchecked bound, <= the ranked grasps' scores {floor:.6g}..{best:.6g}); "
                         f"--check-all checks every pose")
    tried_a = np.asarray(tried, dtype=np.int64)  # pulled from the ranking; the last one may not be tried
    if len(tried_a):
        tried_a = tried_a[np.asarray(sub.status, dtype=object)[tried_a] != Status.NOT_CHECKED.value]
    status[tried_a] = sub.status[tried_a]
    reason[tried_a] = sub.reason[tried_a]
    timing["plan"] = time.perf_counter() - t_all
    return PlanOutcome(status=status, score=scores, rank=rank, reason=reason, motions=sub.motions, timing_s=timing,
                       grasp_result=final)


def plan(
    part: Part | str | os.PathLike,
    robot: Robot | str | Path = DEFAULT_ROBOT,
    *,
    gripper: Gripper | str | os.PathLike = DEFAULT_GRIPPER,
    cell: Cell | str | os.PathLike = DEFAULT_CELL,
    candidates: CandidateParams = CandidateParams(),
    grasps: GraspParams = GraspParams(),
    planning: PlanParams = PlanParams(),
    T_world_part: np.ndarray | None = None,
    units: str = "auto",
    progress: Callable[[dict], None] | None = None,
    load_s: float = 0.0,
    place: np.ndarray | None = None,
) -> PlanResult:
    """Grasps of ``part`` that ``robot`` can reach, each with a verified path from ``q_home``.

    Parameters
    ----------
    part : Part or path
        From :func:`grasplan.part.mesh.load_part`, or a mesh file path (loaded with ``units``).
    robot, gripper, cell : name, path or model
        A :class:`~grasplan.robot.description.Robot` / :class:`~grasplan.gripper.Gripper` /
        :class:`~grasplan.cell.model.Cell`, or a name or YAML path resolved once here (unknown names
        raise ``ConfigError`` listing what exists and where grasplan looked).
    candidates, grasps, planning : CandidateParams, GraspParams, PlanParams
        Every option of the stages, validated by the dataclasses (see :mod:`grasplan.config.params`).
    T_world_part : (4, 4), optional
        The part's pose in the world instead of its stable resting pose.
    progress : callable(dict) or None
        Called after the grasp stage (``{"stage": "grasps", "counts": ...}``) and after every tried grasp.
    load_s : float
        Seconds the caller spent loading ``part`` (recorded as ``timing_s["load"]``).
    place : (4, 4), optional
        ``T_world_part`` after release (pick-and-place, :mod:`grasplan.motion.pickplace`); overrides the
        cell's ``place``. Every plan lifts the part after the grasp; with a place it is also carried
        there, released and the gripper retreats. A place reaching into the table or an obstacle
        raises ``InputError`` before planning.
    """
    t = time.perf_counter()
    rob = robot if isinstance(robot, Robot) else load_robot(robot)
    g = gripper if isinstance(gripper, Gripper) else load_gripper(gripper)
    c = cell if isinstance(cell, Cell) else load_cell(cell)
    if c.name == NO_CELL_NAME:
        raise InputError("cell 'none' holds the part alone, with nothing to plan a robot against: it is for "
                         "`grasplan grasps` and `grasplan database`; plan in a cell (e.g. --cell table or bin)")
    t_robot = time.perf_counter() - t
    if place is None:
        place = planning.place_matrix()  # PlanParams.place (--place in a batch manifest)
    if place is not None:
        c = replace(c, place=check_transform(place, "place (T_world_part after release)"))
    if not isinstance(part, Part):
        t = time.perf_counter()
        part = load_part(part, units=units)
        load_s = time.perf_counter() - t
    # checks before planning (grasplan.motion.start_checks; exit 3 with what to change): the place and the
    # part inside the table or an obstacle, the robot's base inside an obstacle, q_home in collision
    if c.place is not None:
        check_part_placement(part.mesh, c.place, c, what="the part at the place (--place or the cell's place)",
                             pose_option="--place or the cell's place.T")
    k = grasps.single_pose_index()
    T_start = T_world_part if T_world_part is not None else stable_pose(
        part.mesh, c if k is None else replace(c, pose_index=k))
    check_start(CollisionScene(rob, g, part.mesh, T_start, c), part_mesh=part.mesh)
    lazy = not planning.check_all and planning.score_weights is None
    gr = compute_grasps(part, gripper=g, cell=c, candidates=candidates, grasps=grasps, T_world_part=T_world_part,
                        load_s=load_s, lazy=lazy)
    if progress is not None:
        progress({"stage": "grasps", "counts": gr.counts()})
    t = time.perf_counter()
    scene = CollisionScene(rob, gr.gripper, part.mesh, gr.T_world_part, gr.cell)
    t_robot += time.perf_counter() - t
    out = plan_grasps(gr, rob, scene, params=planning, progress=progress)
    if out.grasp_result is not None:  # rank-order evaluation: the poses checked while planning
        gr = out.grasp_result
    base = gr.to_result()
    result = PlanResult(part=base.part, gripper=gr.gripper, cell=gr.cell, robot=rob,
                        grasps=base.grasps.with_plan(out.status, out.score, out.rank, out.reason),
                        motions=out.motions, params=Params(gr.cand.params, grasps, planning),
                        counts_stage=base.counts_stage, timing_s={**gr.timing_s, "robot": t_robot, **out.timing_s},
                        part_pose_source=gr.part_pose_source, grasp_result=gr, part_mesh=part.mesh, mass=base.mass)
    if planning.simulate > 0:  # MuJoCo lift and shake of the top planned grasps; held ones rank first
        from ..sim.simulate import simulate_plan  # MuJoCo and trimesh load only when simulating

        mp = gr.mass_props
        result = simulate_plan(result, planning.simulate, mass_props=mp if isinstance(mp, MassProperties) else None,
                               seed=planning.seed)
    return result


# -- every resting pose (--pose-index all) -----------------------------------------------------------
#: ``--pose-index all`` plans every stable pose at least this probable
MIN_POSE_PROBABILITY = 0.02


def stable_pose_indices(part_mesh: TriangleMesh, min_probability: float = MIN_POSE_PROBABILITY
                        ) -> list[tuple[int, float]]:
    """``[(pose_index, probability)]`` of the part's stable poses with probability >= ``min_probability``."""
    _, prob = stable_poses(part_mesh)
    return [(int(k), float(p)) for k, p in enumerate(prob) if p >= min_probability]


def plan_poses(part: Part | str | os.PathLike, robot: Robot | str | Path = DEFAULT_ROBOT, *,
               grasps: GraspParams = GraspParams(),
               min_probability: float = MIN_POSE_PROBABILITY, units: str = "auto",
               **kwargs) -> list[tuple[int, float, PlanResult | str]]:
    """:func:`plan` for every stable pose of probability >= ``min_probability`` (``--pose-index
    all``): ``[(pose_index, probability, PlanResult or the error message)]``, most probable first.
    A pose whose checks before planning fail (the part inside an obstacle, InputError) gets the
    message; errors of the cell or robot (q_home in collision, ConfigError) are raised."""
    if "T_world_part" in kwargs and kwargs["T_world_part"] is not None:
        raise InputError("--pose-index all: the resting poses replace --part-pose; give one or the other")
    kwargs.pop("T_world_part", None)
    if not isinstance(part, Part):
        part = load_part(part, units=units)
    rob = robot if isinstance(robot, Robot) else load_robot(robot)
    out: list[tuple[int, float, PlanResult | str]] = []
    for k, p in stable_pose_indices(part.mesh, min_probability):
        try:
            res = plan(part, rob, grasps=replace(grasps, pose_index=k), **kwargs)
        except ConfigError:
            raise
        except InputError as exc:
            out.append((k, p, str(exc)))
            continue
        out.append((k, p, res))
    return out


def grasp_counts_by_pose(part: Part, *, gripper: Gripper | str = DEFAULT_GRIPPER, cell: Cell | str = DEFAULT_CELL,
                         candidates: CandidateParams = CandidateParams(), grasps: GraspParams = GraspParams(),
                         min_probability: float = MIN_POSE_PROBABILITY, skip: int | None = None
                         ) -> list[tuple[int, float, int]]:
    """``[(pose_index, probability, collision-free grasps)]`` for the stable poses of probability
    >= ``min_probability`` except ``skip``: the grasp stage only (cheap), for the exit-4 message."""
    out = []
    for k, p in stable_pose_indices(part.mesh, min_probability):
        if k == skip:
            continue
        gr = compute_grasps(part, gripper=gripper, cell=cell, candidates=candidates,
                            grasps=replace(grasps, pose_index=k))
        out.append((k, p, int(np.count_nonzero(np.asarray(gr.status).astype(str) == Status.OK.value))))
    return out
