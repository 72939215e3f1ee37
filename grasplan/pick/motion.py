"""One pick's motion: IK at the grasp, the straight approach, the lift with the part in the jaws
and the transit from home, against a pile (:class:`~grasplan.scene.CollisionScene` variants whose
extra bodies are the other instances and the cloud).

Per grasp (world TCP ``T_world_tcp``), for each IK solution closest to ``q_home`` first: the
solution free at the grasp with the jaws at the pre-grasp opening; the straight approach traced
back from the grasp to the pre-grasp (``backoff`` along the TCP's -z) and free; the straight lift
(the cell's retreat direction and distance, jaws at the contact width, the part attached) free
except that within the first ``lift_contact`` of TCP travel the part in the jaws may touch what it
rests on (the table, the bin, an obstacle, a neighbour); then the transit ``q_home -> q_pregrasp``:
the straight joint-space segment when it is free, else OMPL RRTConnect. Straight moves use the one
line tracker (:func:`grasplan.paths.approach_path_reason`) with waypoints every
:data:`grasplan.pickplace.LINE_SAMPLE`; every path is checked at ``interpolation.STEP`` rad.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..gripper.model import Gripper
from ..ik import solve_ik
from ..interpolation import interpolate_path
from ..motion import Motion
from ..paths import approach_path_reason, plan_joint_path
from ..pickplace import LINE_SAMPLE, T_tcp_part_of, assemble_motion, lift_pose
from ..robot_model import Robot
from ..scene import CollisionScene, describe_pairs
from .params import PickParams

#: what the part in the jaws may rest on at the start of the lift (body name or prefix)
SUPPORT_BODIES = ("table", "obstacle:", "instance:")


@dataclass(frozen=True)
class Outcome:
    """One grasp's motion planning: ``status`` (``planned``, ``unreachable``, ``ik_collision``,
    ``lift_collision``, ``no_path``), why, and the motion when planned."""

    status: str
    reason: str
    motion: Motion | None = None
    opening: float = 0.0


@dataclass
class MotionContext:
    """What every grasp of one instance shares: robot, gripper, options, the pile scenes (part
    static, part attached), home and the lift."""

    robot: Robot
    gripper: Gripper
    params: PickParams
    static: CollisionScene
    attached: CollisionScene
    retreat_dir: np.ndarray
    retreat_dist: float
    timing: dict[str, float]

    def __post_init__(self) -> None:
        self.q_home = np.asarray(self.robot.q_home, dtype=np.float64)
        self.T_flange_tcp = np.asarray(self.gripper.T_flange_tcp, dtype=np.float64)
        self.T_tcp_flange = np.linalg.inv(self.T_flange_tcp)


def _support_only(pairs: list[tuple[str, str, str]]) -> bool:
    for a, b, _ in pairs:
        other = b if a == "part" else a if b == "part" else None
        if other is None or not other.startswith(SUPPORT_BODIES):
            return False
    return True


def lift_collision(scene: CollisionScene, path: np.ndarray, width: float, n_touch: int) -> str | None:
    """What the lift ``path`` (k, n) hits with the part attached (None: free). Within the first
    ``n_touch`` waypoints only the part resting on a support is allowed."""
    n_touch = int(min(max(n_touch, 0), len(path) - 1))
    tail = path[n_touch:]
    if not scene.path_free(tail, width):
        hit = scene.path_collisions(tail, width)
        return "unknown" if hit is None else describe_pairs(hit[1], 2)
    if n_touch == 0:
        return None
    head = path[: n_touch + 1]
    if scene.path_free(head, width):
        return None
    for q in interpolate_path(head):
        if scene.is_free(q, width):
            continue
        pairs = scene.colliding_pairs(q, width)
        if not _support_only(pairs):
            return describe_pairs(pairs, 2)
    return None


def plan_pick_motion(ctx: MotionContext, T_world_tcp: np.ndarray, T_part_tcp: np.ndarray, width: float,
                     seed: int) -> Outcome:
    """Plan one grasp (see the module docstring)."""
    p, robot, timing = ctx.params, ctx.robot, ctx.timing
    opening = float(ctx.gripper.pregrasp_opening(width))
    T_pre = T_world_tcp.copy()
    T_pre[:3, 3] -= p.backoff * T_world_tcp[:3, 2]
    t = time.perf_counter()
    ik = solve_ik(robot, T_world_tcp @ ctx.T_tcp_flange, seed=p.seed)
    timing["ik"] += time.perf_counter() - t
    sols = np.asarray(ik.q, dtype=np.float64).reshape(-1, robot.nq)[: p.max_ik_solutions]
    if len(sols) == 0:
        return Outcome("unreachable", f"no IK solution within the joint limits ({ik.reason})", opening=opening)
    static, att = ctx.static, ctx.attached
    att.move_attached(T_tcp_part_of(T_part_tcp))
    n_touch = int(np.ceil(p.lift_contact / LINE_SAMPLE - 1e-9))
    T_lift = lift_pose(T_world_tcp, ctx.retreat_dir, ctx.retreat_dist)
    why: dict[str, str] = {}
    count = {"grasp": 0, "approach": 0, "approach_kin": 0, "lift": 0, "lift_kin": 0, "path": 0}
    for j, q_grasp in enumerate(sols):
        t = time.perf_counter()
        free = static.is_free(q_grasp, opening)
        timing["collision"] += time.perf_counter() - t
        if not free:
            count["grasp"] += 1
            why.setdefault("grasp", describe_pairs(static.colliding_pairs(q_grasp, opening), 2))
            continue
        t = time.perf_counter()
        back, reason = approach_path_reason(robot, static, T_world_tcp, T_pre, q_grasp, opening=opening,
                                            max_dev=p.max_dev, T_flange_tcp=ctx.T_flange_tcp, sample=LINE_SAMPLE)
        timing["approach"] += time.perf_counter() - t
        if back is None:
            count["approach" if reason == "collision" else "approach_kin"] += 1
            why.setdefault("approach_kin" if reason != "collision" else "approach", reason)
            continue
        t = time.perf_counter()
        lift, reason = approach_path_reason(robot, None, T_world_tcp, T_lift, q_grasp, opening=width,
                                            max_dev=p.max_dev, T_flange_tcp=ctx.T_flange_tcp, sample=LINE_SAMPLE)
        hit = None if lift is None else lift_collision(att, lift, width, n_touch)
        timing["lift"] += time.perf_counter() - t
        if lift is None or hit is not None:
            count["lift_kin" if lift is None else "lift"] += 1
            why.setdefault("lift_kin" if lift is None else "lift", reason if lift is None else hit or "")
            continue
        approach = back[::-1]
        t = time.perf_counter()
        transit = plan_joint_path(static, ctx.q_home, approach[0], lower=robot.lower, upper=robot.upper,
                                  opening=opening, seed=seed, time_limit=p.time_limit_per_query,
                                  attempts=p.path_attempts)
        timing["transit"] += time.perf_counter() - t
        if transit is None:
            count["path"] += 1
            if count["path"] >= p.max_path_queries:
                break
            continue
        motion = assemble_motion(transit, approach, lift, width=width, opening=opening,
                                 T_tcp_part=T_tcp_part_of(T_part_tcp))
        return Outcome("planned", f"planned with IK solution {j} of {len(sols)} (closest to q_home first)", motion,
                       opening)
    detail = (f"{len(sols)} IK solutions: {count['grasp']} collide at the grasp, {count['approach']} on the approach, "
              f"{count['approach_kin']} cannot follow it, {count['lift']} collide on the lift, {count['lift_kin']} "
              f"cannot follow it, {count['path']} found no transit")
    if count["lift"]:
        return Outcome("lift_collision", f"lift: with the part in the jaws {why['lift']}; " + detail, opening=opening)
    if count["path"]:
        return Outcome("no_path", "RRTConnect found no verified transit home -> pre-grasp; " + detail, opening=opening)
    if count["grasp"] or count["approach"]:
        hit = why.get("grasp", "")
        return Outcome("ik_collision", detail + (f"; at the grasp: {hit}" if hit else ""), opening=opening)
    return Outcome("unreachable", detail, opening=opening)
