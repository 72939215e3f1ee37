"""One grasp's plan (:func:`plan_grasp`), step by step, for :func:`grasplan.motion.planning.plan_grasps`.

The grasp TCP is ``T_world_part @ T_part_tcp``, the pre-grasp that TCP backed off ``backoff``
along its own -z; the jaws stay at ``Gripper.pregrasp_opening`` until the grasp. IK at the grasp
(solutions closest to ``q_home`` first; none within the joint limits: ``unreachable``), then per
solution: free at the grasp, the straight approach traced back to the pre-grasp (``max_dev``,
continuous IK, collision-free), the lift with the part in the jaws, the place side (with a place,
once per grasp), RRTConnect ``q_home -> q_pregrasp`` and the transfer to the place. The first
solution through all is ``planned``; otherwise the counts say why: ``ik_collision``,
``unreachable``, ``no_path``, ``place_unreachable`` or ``place_no_path``, with a reason naming
what was hit (docs/plan.md).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..gripper.model import Gripper
from ..robot.ik.solve import solve_ik
from ..config.params import PlanParams
from .joint_paths import approach_path_reason, plan_joint_path
from .pickplace import (
    PlaceCandidate, T_tcp_part_of, assemble_motion, place_candidates, place_poses, plan_lift, transfer_path
)
from ..results.joint_motion import Motion
from ..robot.model import Robot
from .collision_scene import CollisionScene, describe_pairs, no_path_reason
from ..status import Status
from ..geometry.transforms import translation


@dataclass(frozen=True)
class GraspOutcome:
    """What planning one grasp gave: its plan ``status``, a human-readable ``reason`` and, when
    ``status`` is ``planned``, its ``motion`` (else None)."""

    status: Status
    reason: str
    motion: Motion | None = None


@dataclass(frozen=True, eq=False)
class PlanSetting:
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


@dataclass(frozen=True, eq=False)
class _Grasp:
    """One grasp as the planner moves it: pose id ``i``, ``T_part_tcp`` (4, 4) in the frame the
    gripper's shapes are given in, contact ``width`` m, the grasp and pre-grasp TCPs in the world,
    the jaws' ``opening`` while moving, ``T_tcp_part`` and ``scene_att`` (the part in the jaws)."""

    i: int
    T_part_tcp: np.ndarray
    width: float
    T_world_tcp: np.ndarray
    T_world_pre: np.ndarray
    opening: float
    T_tcp_part: np.ndarray
    scene_att: CollisionScene


@dataclass(eq=False)
class _Tally:
    """What the IK solutions of one grasp ran into so far: the failures counted by step, the first
    reason of each kind, and ``place``: the place side once computed (candidates, status, reason)."""

    grasp_coll: int = 0
    app_coll: int = 0
    app_kin: int = 0
    lift_coll: int = 0
    lift_kin: int = 0
    path_fail: int = 0
    transfer_fail: int = 0
    grasp_hit: str = ""  # what the best IK branch hits
    lift_why: str = ""
    path_why: str = ""  # why the transit failed
    place: tuple[list[PlaceCandidate], Status, str] | None = None


def plan_grasp(s: PlanSetting, i: int, T_part_tcp: np.ndarray, width: float) -> GraspOutcome:
    """Plan grasp ``i`` (TCP ``T_part_tcp`` (4, 4) in the part frame, contact ``width`` m): IK at the
    grasp, then for each IK solution (closest to q_home first) the approach, the lift, the place
    side and the transit from q_home; the first solution that gets through all is ``planned``."""
    if s.gripper.moving_tcp:  # plan in the frame the gripper's shapes and T_flange_tcp are given in
        T_part_tcp = T_part_tcp @ s.gripper.T_tcp_gripper(width)
    T_world_tcp = s.T_world_part @ T_part_tcp
    t = time.perf_counter()
    ik = solve_ik(s.robot, T_world_tcp @ s.T_tcp_flange, seed=s.params.seed)
    s.timing["ik"] += time.perf_counter() - t
    sols = np.asarray(ik.q, dtype=np.float64).reshape(-1, len(s.q_home))[: s.params.max_ik_solutions]
    if len(sols) == 0:
        return GraspOutcome(Status.UNREACHABLE, f"no IK solution within the joint limits ({ik.reason})")
    T_tcp_part = T_tcp_part_of(T_part_tcp)
    g = _Grasp(i=i, T_part_tcp=T_part_tcp, width=width, T_world_tcp=T_world_tcp,
               T_world_pre=T_world_tcp @ translation(z=-s.params.backoff),
               opening=float(s.gripper.pregrasp_opening(width)), T_tcp_part=T_tcp_part,
               scene_att=s.scene.attached(T_tcp_part))
    a = _Tally()
    limit = s.params.max_path_queries
    for j, q_grasp in enumerate(sols):
        approach = _approach(s, g, a, j, q_grasp)
        if approach is None:
            continue
        lift_path = _lift(s, g, a, approach[-1])
        if lift_path is None:
            continue
        if s.T_place is not None and s.scene_released is not None and a.place is None:
            a.place = _place_side(s, g, s.T_place, s.scene_released, lift_path[-1])
        if a.place is not None and not a.place[0]:
            break  # the place side does not depend on the grasp's IK solution
        transit = _transit(s, g, a, approach[0])
        if transit is None:
            if a.path_fail >= limit:
                break
            continue
        transfer, cand = (None, None) if a.place is None else _transfer(s, g, a, a.place[0], lift_path[-1])
        if a.place is not None and cand is None:
            if a.transfer_fail >= limit:
                break
            continue
        motion = assemble_motion(transit, approach, lift_path, width=width, opening=g.opening, T_tcp_part=T_tcp_part,
                                 transfer=transfer, place=cand, T_world_part_place=s.T_place)
        return GraspOutcome(Status.PLANNED, f"planned with IK solution {j} of {len(sols)} (closest to q_home first)"
                            + ("" if cand is None else " and a place"), motion)
    return _failure(s, a, len(sols))


def _approach(s: PlanSetting, g: _Grasp, a: _Tally, j: int, q_grasp: np.ndarray) -> np.ndarray | None:
    """IK solution ``j``'s straight approach pre-grasp -> grasp (k, n), traced back from the grasp
    with the jaws open; None when the solution collides at the grasp or on the approach or cannot
    follow the line (counted in ``a``, the first hit named)."""
    scene = s.scene
    if not scene.is_free(q_grasp, g.opening):
        a.grasp_coll += 1
        a.grasp_hit = a.grasp_hit or f"IK solution {j} at the grasp: " + describe_pairs(
            scene.colliding_pairs(q_grasp, g.opening), 2)
        return None
    t = time.perf_counter()
    back, why = approach_path_reason(s.robot, scene, g.T_world_tcp, g.T_world_pre, q_grasp, opening=g.opening,
                                     max_dev=s.params.max_dev, T_flange_tcp=s.T_flange_tcp)
    s.timing["approach"] += time.perf_counter() - t
    if back is not None:
        return back[::-1]
    if why != "collision":
        a.app_kin += 1
        return None
    a.app_coll += 1
    if not a.grasp_hit:  # re-trace the approach without the scene to name the hit
        kin, _ = approach_path_reason(s.robot, None, g.T_world_tcp, g.T_world_pre, q_grasp, opening=g.opening,
                                      max_dev=s.params.max_dev, T_flange_tcp=s.T_flange_tcp)
        hit = None if kin is None else scene.path_collisions(kin, g.opening)
        a.grasp_hit = "" if hit is None else f"IK solution {j} on the approach: " + describe_pairs(hit[1], 2)
    return None


def _lift(s: PlanSetting, g: _Grasp, a: _Tally, q_grasp: np.ndarray) -> np.ndarray | None:
    """The straight lift from ``q_grasp`` with the part in the jaws (None: counted in ``a``)."""
    t = time.perf_counter()
    lift = plan_lift(s.robot, g.scene_att, q_grasp, g.T_world_tcp, direction=s.retreat_dir, distance=s.retreat_dist,
                     width=g.width, max_dev=s.params.max_dev, T_flange_tcp=s.T_flange_tcp)
    s.timing["lift"] += time.perf_counter() - t
    if lift.path is None:
        a.lift_coll += int(lift.status == Status.IK_COLLISION)
        a.lift_kin += int(lift.status != Status.IK_COLLISION)
        a.lift_why = a.lift_why or lift.reason
    return lift.path


def _place_side(s: PlanSetting, g: _Grasp, T_place: np.ndarray, scene_released: CollisionScene,
                q_lifted: np.ndarray) -> tuple[list[PlaceCandidate], Status, str]:
    """The place side of a grasp (IK at the place, descent, release, retreat): the candidates
    (empty: the status and reason say why); computed once per grasp."""
    p = s.params
    t = time.perf_counter()
    place = place_candidates(
        s.robot, g.scene_att, scene_released,
        place_poses(T_place, g.T_part_tcp, s.retreat_dir, s.retreat_dist, p.backoff),
        width=g.width, opening=g.opening, max_dev=p.max_dev, T_flange_tcp=s.T_flange_tcp,
        q_ref=q_lifted, seed=p.seed, max_solutions=p.max_ik_solutions, limit=p.max_path_queries)
    s.timing["place"] += time.perf_counter() - t
    return place


def _transit(s: PlanSetting, g: _Grasp, a: _Tally, q_pre: np.ndarray) -> np.ndarray | None:
    """RRTConnect q_home -> ``q_pre`` with the jaws open (None: counted in ``a``, the first reason kept)."""
    p, robot = s.params, s.robot
    t = time.perf_counter()
    transit = plan_joint_path(s.scene, s.q_home, q_pre, lower=robot.lower, upper=robot.upper, opening=g.opening,
                              seed=p.seed * 1_000_003 + g.i, time_limit=p.time_limit_per_query,
                              attempts=p.path_attempts)
    s.timing["joint_path"] += time.perf_counter() - t
    if transit is None:
        a.path_fail += 1
        a.path_why = a.path_why or no_path_reason(s.scene, s.q_home, q_pre, g.opening, p.time_limit_per_query,
                                                  p.path_attempts)
    return transit


def _transfer(s: PlanSetting, g: _Grasp, a: _Tally, cands: list[PlaceCandidate], q_lifted: np.ndarray
              ) -> tuple[np.ndarray | None, PlaceCandidate | None]:
    """RRTConnect lifted -> above the place with the part in the jaws, to the place candidates in
    turn until one is reached or ``max_path_queries`` failed (counted in ``a``): (path, candidate)."""
    p, robot = s.params, s.robot
    t = time.perf_counter()
    transfer = cand = None
    for c in cands:
        if a.transfer_fail >= p.max_path_queries:
            break
        transfer = transfer_path(g.scene_att, q_lifted, c, lower=robot.lower, upper=robot.upper, width=g.width,
                                 seed=p.seed * 1_000_003 + g.i + 7, time_limit=p.time_limit_per_query,
                                 attempts=p.path_attempts)
        if transfer is not None:
            cand = c
            break
        a.transfer_fail += 1
    s.timing["transfer"] += time.perf_counter() - t
    return transfer, cand


def _failure(s: PlanSetting, a: _Tally, k: int) -> GraspOutcome:
    """Why none of a grasp's ``k`` IK solutions got through: the status and reason from ``a``."""
    detail = (f"{k} IK solutions: {a.grasp_coll} collide at the grasp, {a.app_coll} collide on the "
              f"approach, {a.app_kin} cannot follow the straight approach (IK lost, joint limit, "
              f"jump or > {s.params.max_dev * 1e3:g} mm off the line)")
    if a.place is not None and not a.place[0]:
        return GraspOutcome(a.place[1], a.place[2])
    if a.transfer_fail:
        return GraspOutcome(Status.PLACE_NO_PATH, f"place: RRTConnect found no verified transfer path (part in the "
                            f"jaws) lifted -> above the place in {a.transfer_fail} queries")
    if a.path_fail:
        return GraspOutcome(Status.NO_PATH, f"RRTConnect found no verified path home -> pre-grasp in {a.path_fail} "
                            f"queries ({a.path_why}); " + detail)
    if a.lift_coll + a.lift_kin > 0:
        return GraspOutcome(Status.IK_COLLISION if a.lift_coll else Status.NO_PATH,
                            f"{a.lift_why}; {a.lift_coll + a.lift_kin} of {k} IK solutions fail the lift "
                            f"({a.lift_coll} collide, {a.lift_kin} cannot follow the line); " + detail)
    if a.grasp_coll + a.app_coll > 0:
        return GraspOutcome(Status.IK_COLLISION, detail + (f"; {a.grasp_hit}" if a.grasp_hit else ""))
    return GraspOutcome(Status.UNREACHABLE, detail)
