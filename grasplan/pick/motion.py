"""One pick's motion: IK at the grasp, the straight approach, the lift with the part in the jaws
and the transit from home, against a pile (:class:`~grasplan.motion.collision_scene.CollisionScene` variants whose
extra bodies are the other instances and the cloud).

Per grasp (world TCP ``T_world_tcp``), for each IK solution closest to ``q_home`` first: the
solution free at the grasp with the jaws at the pre-grasp opening; the straight approach traced
back from the grasp to the pre-grasp (``backoff`` along the TCP's -z) and free; the straight lift
(the cell's retreat direction and distance, jaws at the contact width, the part attached) free
except that within the first ``lift_contact`` of TCP travel the part in the jaws may touch what it
rests on (the table, the bin, an obstacle, a neighbour) and all along it a neighbour by at most
``lift_depth`` (:mod:`grasplan.pick.depth`); then the transit ``q_home -> q_pregrasp``:
the straight joint-space segment when it is free, else through a via point above the pre-grasp
(:func:`_transit`), else OMPL RRTConnect. Every path is checked at
``interpolation.STEP`` rad.

Straight moves (:func:`line_path`): TCP waypoints every :data:`grasplan.motion.pickplace.LINE_SAMPLE`
with constant orientation. With a closed-form IK (the UR5's, :mod:`grasplan.robot.ik.ur`) every waypoint
is solved exactly and the branch kept continuous (each joint wrapped to the previous waypoint's
value, the closest of the up to eight solutions taken; a joint moving more than ``max_joint_step``
between waypoints is a branch jump); the joint-linear motion between waypoints is held to
``max_dev`` from the line by forward kinematics at every midpoint. Robots without a closed form
use the CLIK tracker :func:`grasplan.motion.joint_paths.approach_path_reason`.
"""
from __future__ import annotations

import time
import weakref
from dataclasses import dataclass
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..gripper.model import Gripper
from ..robot.ik.solve import solve_ik
from ..robot.ik.ur_batch import line_deviation
from ..geometry.interpolation import interpolate_path
from ..results.joint_motion import Motion
from ..motion.pathboxes import scene_open
from ..motion.joint_paths import approach_path_reason, plan_joint_path
from ..motion.pickplace import (
    LINE_SAMPLE, T_tcp_part_of, assemble_motion, lift_pose, place_candidates, place_poses, transfer_path
)
from ..robot.model import Robot
from ..motion.collision_scene import PART, CollisionScene, describe_pairs
from ..geometry.transforms import inv_rigid
from .budget import UNLIMITED, Budget
from .cover import APPROACH_PAD, covered_check, gripper_world_pairs
from .lines import fk_base_tool, ur_closed_form, ur_line, world_fk
from .params import PickParams

#: what the part in the jaws may rest on at the start of the lift (body name or prefix)
SUPPORT_BODIES = ("table", "obstacle:", "instance:")
#: largest per-joint change (rad) between consecutive line waypoints (more: a branch jump)
MAX_JOINT_STEP = 0.1
#: the lift's TCP waypoints are this far apart (m), half the approach's
#: (:data:`~grasplan.motion.pickplace.LINE_SAMPLE`): on the UR5 in the bench piles the joints then move at
#: most 0.0085 rad between two of them, less than ``interpolation.STEP``, so the lift has no
#: configuration between waypoints to check and every waypoint is one the checks before IK covered
#: (:func:`lift_collision`); at 4 mm half the lift's configurations lay between waypoints and were
#: checked with every pair (docs/pick.md, timing)
LIFT_SAMPLE = 0.5 * LINE_SAMPLE


def line_path(robot: Robot, T_from: np.ndarray, T_to: np.ndarray, q_from: np.ndarray, *, max_dev: float,
              T_flange_tcp: np.ndarray, sample: float = LINE_SAMPLE) -> tuple[np.ndarray | None, str]:
    """Joint waypoints moving the TCP straight ``T_from -> T_to`` (same orientation) from
    ``q_from`` (which reaches ``T_from``): ``(path (k, n), "ok")`` or ``(None, why)`` with why in
    ``ik``, ``limits``, ``jump``, ``deviation`` (see the module docstring)."""
    closed = ur_closed_form(robot)
    if closed is None:
        return approach_path_reason(robot, None, T_from, T_to, q_from, opening=0.0, max_dev=max_dev,
                                    T_flange_tcp=T_flange_tcp, sample=sample)
    T_base = inv_rigid(np.asarray(robot.T_world_base, dtype=np.float64))
    T_tcp_flange = inv_rigid(T_flange_tcp)
    a, b = T_from[:3, 3], T_to[:3, 3]
    m = max(1, int(np.ceil(float(np.linalg.norm(b - a)) / sample - 1e-12)))
    T = np.broadcast_to(np.asarray(T_from, dtype=np.float64), (m, 4, 4)).copy()
    T[:, :3, 3] = a + (b - a) * (np.arange(1, m + 1) / m)[:, None]
    T0 = fk_base_tool(closed, np.asarray(q_from, dtype=np.float64)[None])[0]
    T0_want = T_base @ np.asarray(T_from, dtype=np.float64) @ T_tcp_flange
    if np.linalg.norm(T0[:3, 3] - T0_want[:3, 3]) > 0.5 * max_dev or np.max(np.abs(T0[:3, :3] - T0_want[:3, :3])) > 1e-4:
        return None, "start"
    path, why = ur_line(closed, T_base @ T @ T_tcp_flange, q_from, robot.lower, robot.upper, MAX_JOINT_STEP)
    if path is None:
        return None, why
    if line_deviation(closed.chain, path, robot.T_world_base, T_flange_tcp, a, b) > max_dev:
        return None, "deviation"
    return path, "ok"


@dataclass(frozen=True)
class Outcome:
    """One grasp's motion planning: ``status`` (``planned``, ``unreachable``, ``ik_collision``,
    ``lift_collision``, ``no_path``, ``place``), why, and the motion when planned."""

    status: str
    reason: str
    motion: Motion | None = None
    opening: float = 0.0
    blockers: tuple[str, ...] = ()  #: neighbours (``instance:<id>``) the lift or approach hit

    @property
    def lift_may_help(self) -> bool:
        """Whether another lift direction may plan the grasp: its lift collided or could not be
        followed (not: no IK solution, a collision at the grasp or on the approach, no transit)."""
        return self.status == "lift_collision" or (self.status == "unreachable" and not self.reason.startswith("no IK"))


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
    T_place: np.ndarray | None = None  #: T_world_part after release (pick-and-place), or None
    #: the gripper along the lift in Cartesian space (branch-independent, before any IK):
    #: ``(T_world_tcp (k, 4, 4), width) -> first body hit per pose (-1 none)`` and the body names
    lift_gripper_check: Any = None
    body_names: tuple[str, ...] = ()
    #: ``(T_world_part of the carried part, neighbour names) -> deepest penetration (m)``
    #: (:mod:`grasplan.pick.depth`); None: any contact beyond ``lift_contact`` is a collision
    lift_depth: Any = None
    #: ``(T_world_part, shifts (s, 3), clear (s,))``: before any grasp, the carried part was checked
    #: against the neighbours and the cloud at ``T_world_part`` moved by each shift and found free,
    #: a contact with a neighbour accepted only when ``lift_depth`` accepts it (the rule
    #: :func:`lift_collision` applies with ``shallow``); where ``clear``, also against the cell's
    #: table and obstacles (shrunk by :data:`grasplan.motion.collision_scene.ATTACHED_CONTACT_TOL`, as the attached
    #: variant has them); None: not checked (every pair is then checked at every waypoint)
    lift_part_checked: Any = None
    #: the gripper along the approach in Cartesian space (branch-independent, once IK found solutions):
    #: ``(T_pre, T_grasp, opening, pad) -> SweptGripper or None`` (:mod:`grasplan.pick.cover`)
    approach_sweep: Any = None
    #: the plan's budget (:mod:`grasplan.pick.budget`): checked before each IK solution's checks and
    #: each OMPL query, whose time it caps
    budget: Budget = UNLIMITED

    def rrt_time(self) -> float:
        """Seconds per RRTConnect attempt: ``time_limit_per_query``, capped so that all
        ``path_attempts`` fit in the budget left (:class:`grasplan.pick.budget.BudgetSpent` when none is)."""
        p, n = self.params, max(self.params.path_attempts, 1)
        left = self.budget.cap(p.time_limit_per_query * n)
        return p.time_limit_per_query if left >= p.time_limit_per_query * n else left / n

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


def _part_vs_instances(pairs: list[tuple[str, str, str]]) -> list[str] | None:
    """The neighbours (``instance:<id>``) of pairs that are all the carried part against an
    instance, else None."""
    out = []
    for a, b, _ in pairs:
        other = b if a == "part" else a if b == "part" else None
        if other is None or not other.startswith("instance:"):
            return None
        out.append(other)
    return out


_SUPPORT: "weakref.WeakKeyDictionary[Any, np.ndarray]" = weakref.WeakKeyDictionary()


def _support_pairs(scene: CollisionScene) -> np.ndarray:
    """Indices of the pairs of ``scene`` (an attached variant) between the carried part and what it
    may rest on (:data:`SUPPORT_BODIES`), once per scene model."""
    idx = _SUPPORT.get(scene._shared)
    if idx is None:
        idx = _SUPPORT[scene._shared] = np.array(
            [k for k, (a, b, _, _, _) in enumerate(scene.pair_rows())
             if (a == "part" and b.startswith(SUPPORT_BODIES)) or (b == "part" and a.startswith(SUPPORT_BODIES))],
            dtype=np.int64)
    return idx


def _sample_ok(scene: CollisionScene, q: np.ndarray, width: float, support: bool,
               shallow: Callable[[np.ndarray, list[str]], bool] | None) -> bool:
    """Configuration ``q`` of the lift is free, or its contacts are allowed (module docstring):
    with ``support`` (it may rest) every pair the carried part against what it may rest on
    (:data:`SUPPORT_BODIES`), else every pair the part against neighbours within the depth rule
    ``shallow``. :func:`lift_collision` checks a resting configuration of a CollisionScene with
    those pairs switched off instead (the same answer, without coal finding the contacts)."""
    if scene.is_free(q, width):
        return True
    pairs = scene.colliding_pairs(q, width)
    if support and _support_only(pairs):
        return True
    names = None if shallow is None else _part_vs_instances(pairs)
    return bool(names and shallow is not None and shallow(q, names))


def lift_travel(dist: float) -> np.ndarray:
    """TCP travel (m) at each waypoint of a straight lift of ``dist`` (:func:`line_path` with
    :data:`LIFT_SAMPLE`: equal steps of at most that), from 0 to ``dist``: the one definition the
    lift's line, its gripper check before IK and the picker's part-alone checks share."""
    m = max(1, int(np.ceil(dist / LIFT_SAMPLE - 1e-12)))
    return dist * np.arange(m + 1) / m


def touch_waypoints(lift_contact: float, travel: np.ndarray) -> int:
    """``n_touch`` of :func:`lift_collision` for a lift whose waypoints lie at ``travel``
    (:func:`lift_travel`): the index of the first waypoint beyond ``lift_contact`` of travel (0
    when no contact is allowed). The waypoints before it, one lying at ``lift_contact`` itself
    included, may rest where ``resting(q)`` says so; from it on none may."""
    return int(np.searchsorted(travel, lift_contact + 1e-9, side="right")) if lift_contact > 0 else 0


def lift_collision(scene: CollisionScene, path: np.ndarray, width: float, n_touch: int,
                   shallow: Callable[[np.ndarray, list[str]], bool] | None = None,
                   covered: np.ndarray | None = None, drop: np.ndarray | Sequence[np.ndarray] | None = None,
                   resting: Callable[[np.ndarray], bool] | None = None
                   ) -> list[tuple[str, str, str]] | None:
    """The colliding pairs where the lift ``path`` (k, n) first hits something with the part
    attached (None: free), checked at ``interpolation.STEP``. Within the first ``n_touch``
    waypoints the part resting on a support is allowed; all along, contacts of the part with
    neighbours only for which ``shallow(q, names)`` is true (their penetration depth within the
    tolerance, :mod:`grasplan.pick.depth`).

    ``covered`` (per waypoint a level, 0 none; a bool array: level 1), ``drop`` (pair indices of
    ``scene``, one array per level, or one array for level 1): at the waypoints of level ``l`` the
    pairs ``drop[l - 1]`` that the checks before IK already decided the same way
    (:func:`lift_precheck_drop`) are switched off; those waypoints are checked first, the highest
    level first, then the configurations between waypoints with every pair, up to the first
    waypoint that failed (the first failing configuration in path order is the one reported).

    ``resting(q)``: whether configuration ``q`` of the first ``n_touch`` waypoints is still within
    ``lift_contact`` of TCP travel (the waypoints are :data:`LIFT_SAMPLE` apart,
    so the last of them may lie beyond it); where it is not, resting contact is not allowed
    either. None: every configuration up to waypoint ``n_touch`` may rest."""
    n_touch = int(min(max(n_touch, 0), len(path) - 1))
    drops: list[np.ndarray] = [] if drop is None else [drop] if isinstance(drop, np.ndarray) else list(drop)
    for k0, k1, support in ((n_touch, len(path), False), (0, n_touch + 1, True)):
        part = path[k0:k1]
        if support and n_touch == 0:
            continue
        dense, rows = interpolate_path(part, return_index=True)
        level = np.zeros(len(dense), dtype=np.int64)
        if covered is not None and drops:
            level[rows] = np.minimum(np.asarray(covered[k0:k1], dtype=np.int64), len(drops))
        # a configuration that may rest (within lift_contact of travel) is free exactly when it is
        # with the part's support pairs off (:func:`_sample_ok`): those are switched off for it too
        may_rest = np.array([support and (resting is None or resting(q)) for q in dense], dtype=bool)
        support_ids = _support_pairs(scene) if isinstance(scene, CollisionScene) else None
        if support_ids is not None:
            support_ids = support_ids[scene._active[support_ids]]
        rests = may_rest & (support_ids is not None)
        bad: int | None = None
        for lv, rest in sorted({(int(a), bool(b)) for a, b in zip(level, rests)}, reverse=True):
            idx = np.flatnonzero((level == lv) & (rests == rest))
            offs = ([drops[lv - 1]] if lv else []) + ([support_ids] if rest and support_ids is not None else [])
            off = np.union1d(*offs) if len(offs) == 2 else offs[0] if offs else None
            if off is not None:
                scene.switch_pairs(off, False)
            try:
                # free where coal finds none of the pairs whose oriented boxes overlap colliding
                # (grasplan.motion.pathboxes: the others cannot); only the rest needs the allowances
                found = None
                if isinstance(scene, CollisionScene):
                    scene.set_opening(width)
                    found = scene_open(scene, dense[idx])
                if found is not None:  # only the configurations with pairs left to coal
                    starts, pair_ids = found
                    keep = np.flatnonzero(starts[1:] > starts[:-1])
                    spans = list(zip(starts[keep].tolist(), starts[keep + 1].tolist()))
                    idx = idx[keep]
                for j, i in enumerate(idx.tolist()):
                    if bad is not None and i > bad:
                        break
                    if found is not None and not scene.pairs_collide(dense[i], pair_ids[spans[j][0]:spans[j][1]]):
                        continue
                    if rest:  # with its support pairs off: colliding is a hit (no boxes: coal decides)
                        if found is None and scene.is_free(dense[i], width):
                            continue
                    elif _sample_ok(scene, dense[i], width, bool(may_rest[i]), shallow):
                        continue
                    bad = i
                    break
            finally:
                if off is not None:
                    scene.switch_pairs(off, True)
        if bad is not None:
            return scene.colliding_pairs(dense[bad], width)
    return None


def lift_precheck_drop(scene: CollisionScene, cell: bool = True) -> np.ndarray:
    """Per pair of ``scene``: decided at the lift's waypoints by the checks before IK, the closed
    gripper (body and jaws) against the world (``MotionContext.lift_gripper_check``: the same
    shapes at the same poses) and the carried part against all but the robot's links: the
    neighbours and the cloud, and with ``cell`` the table and the obstacles
    (``MotionContext.lift_part_checked``, the picker's straight lift)."""
    return gripper_world_pairs(scene) | np.array([group == "attached" and kind != PART and (cell or extra != "")
                                                  for _, _, kind, group, extra in scene.pair_rows()], dtype=bool)


_DROP: "weakref.WeakKeyDictionary[Any, tuple[np.ndarray, np.ndarray]]" = weakref.WeakKeyDictionary()


def _drop_pairs(att: CollisionScene) -> tuple[np.ndarray, np.ndarray]:
    """The active pairs of ``att`` that :func:`lift_precheck_drop` names: without the cell (the
    waypoints of level 1 of :func:`_lift_covered`) and with it (level 2); the masks once per scene model."""
    masks = _DROP.get(att._shared)
    if masks is None:
        masks = _DROP[att._shared] = (lift_precheck_drop(att, cell=False), lift_precheck_drop(att))
    return np.flatnonzero(att._active & masks[0]), np.flatnonzero(att._active & masks[1])


#: a lift waypoint is covered by the checks before IK when its TCP and part poses are theirs within this (m)
COVER_TOL = 1e-7


def _lift_covered(ctx: MotionContext, lift: np.ndarray, T_line: np.ndarray, T_flange_part: np.ndarray
                  ) -> np.ndarray | None:
    """Per lift waypoint, what the checks before IK decided there (the levels of
    :func:`lift_collision`, pairs :func:`_drop_pairs`): 1 when the TCP is at the pose the gripper
    check used (``T_line``) and the carried part at a pose of ``ctx.lift_part_checked`` (rotation
    and position within :data:`COVER_TOL`), 2 when the part alone was also clear of the cell there,
    else 0; None when the checks before IK did not run."""
    if ctx.lift_gripper_check is None or ctx.lift_part_checked is None or len(lift) != len(T_line):
        return None
    T_part0, shifts, clear = ctx.lift_part_checked
    F = world_fk(ctx.robot, lift)
    tcp = F @ ctx.T_flange_tcp
    part = F @ T_flange_part
    ok = (np.abs(tcp[:, :3, :] - T_line[:, :3, :]).max(axis=(1, 2)) <= COVER_TOL)
    ok &= np.abs(part[:, :3, :3] - T_part0[:3, :3]).max(axis=(1, 2)) <= COVER_TOL
    off = part[:, :3, 3] - T_part0[:3, 3]
    S = np.asarray(shifts, dtype=np.float64).reshape(-1, 3)
    # candidates by the offsets' projections on the lift direction (a match within COVER_TOL in
    # every coordinate differs there by at most sqrt(3) COVER_TOL |u|), then each one exactly
    u = np.asarray(ctx.retreat_dir, dtype=np.float64)
    ki, si = np.nonzero(np.abs((off @ u)[:, None] - (S @ u)[None]) <= 2.0 * COVER_TOL * max(1.0, float(u @ u)))
    hit = np.abs(off[ki] - S[si]).max(axis=1, initial=0.0) <= COVER_TOL
    ki, si = ki[hit], si[hit]
    level = np.zeros(len(lift), dtype=np.int64)
    level[ki] = 1
    level[ki[np.asarray(clear, dtype=bool)[si]]] = 2
    return level * ok


def _blockers(pairs: list[tuple[str, str, str]]) -> set[str]:
    return {x for a, b, _ in pairs for x in (a, b) if x.startswith("instance:")}


def _place(ctx: MotionContext, q_lifted: np.ndarray, T_part_tcp: np.ndarray, width: float, opening: float,
           seed: int) -> tuple[Any, np.ndarray | None, str]:
    """``(place candidate, transfer path, "")`` or ``(None, None, why)``: the place side of
    :func:`grasplan.motion.planning.plan_grasp`'s pick-and-place for one picked grasp."""
    p, robot = ctx.params, ctx.robot
    assert ctx.T_place is not None
    released = ctx.static.with_part_at(ctx.T_place)
    poses = place_poses(ctx.T_place, T_part_tcp, ctx.retreat_dir, ctx.retreat_dist, p.backoff)
    cands, _, why = place_candidates(robot, ctx.attached, released, poses, width=width, opening=opening,
                                     max_dev=p.max_dev, T_flange_tcp=ctx.T_flange_tcp, q_ref=q_lifted, seed=p.seed,
                                     max_solutions=p.max_ik_solutions, limit=p.max_path_queries)
    for c in cands:
        transfer = transfer_path(ctx.attached, q_lifted, c, lower=robot.lower, upper=robot.upper, width=width,
                                 seed=seed + 7, time_limit=ctx.rrt_time(), attempts=p.path_attempts)
        if transfer is not None:
            return c, transfer, ""
    if cands:
        why = "place: RRTConnect found no verified transfer path (part in the jaws) lifted -> above the place"
    return None, None, why


#: the transit's via point: the pre-grasp TCP raised this far (m) along world +z, same IK branch
VIA_HEIGHT = 0.25


def _transit(ctx: MotionContext, q_pre: np.ndarray, T_pre: np.ndarray, opening: float, seed: int
             ) -> np.ndarray | None:
    """``q_home -> q_pre``: the straight joint segment when free; else home -> a via point above
    the pre-grasp (:data:`VIA_HEIGHT`, reached from ``q_pre`` by a straight TCP line on its IK branch)
    -> down that line, directly or after turning the base joint alone; else OMPL RRTConnect. Every
    candidate is checked at ``interpolation.STEP``."""
    p, robot, static = ctx.params, ctx.robot, ctx.static
    direct = np.stack([ctx.q_home, q_pre])
    if static.path_free(direct, opening):
        return direct
    T_via = T_pre.copy()
    T_via[2, 3] += VIA_HEIGHT
    up, _ = line_path(robot, T_pre, T_via, q_pre, max_dev=0.05, T_flange_tcp=ctx.T_flange_tcp, sample=0.02)
    if up is not None:
        via = np.vstack([ctx.q_home[None], up[::-1]])
        if static.path_free(via, opening):
            return via
        turn = ctx.q_home.copy()  # home turned to face the via point first (the base joint alone)
        turn[0] = up[-1][0]
        via = np.vstack([ctx.q_home[None], turn[None], up[::-1]])
        if static.path_free(via, opening):
            return via
    return plan_joint_path(static, ctx.q_home, q_pre, lower=robot.lower, upper=robot.upper, opening=opening,
                           seed=seed, time_limit=ctx.rrt_time(), attempts=p.path_attempts)


def plan_pick_motion(ctx: MotionContext, T_world_tcp: np.ndarray, T_part_tcp: np.ndarray, width: float,
                     seed: int) -> Outcome:
    """Plan one grasp (see the module docstring)."""
    p, robot, timing = ctx.params, ctx.robot, ctx.timing
    ctx.budget.check()
    opening = float(ctx.gripper.pregrasp_opening(width))
    T_pre = T_world_tcp.copy()
    T_pre[:3, 3] -= p.backoff * T_world_tcp[:3, 2]
    T_lift = lift_pose(T_world_tcp, ctx.retreat_dir, ctx.retreat_dist)
    travel = lift_travel(ctx.retreat_dist)  # the lift's waypoints, as line_path makes them
    T_line = None
    if ctx.lift_gripper_check is not None:  # the closed gripper along the lift: the same for every IK branch
        t = time.perf_counter()
        T_line = np.broadcast_to(T_world_tcp, (len(travel), 4, 4)).copy()
        T_line[:, :3, 3] += travel[:, None] * ctx.retreat_dir
        hit = ctx.lift_gripper_check(T_line, width)
        timing["lift"] += time.perf_counter() - t
        if np.any(hit >= 0):
            k = int(np.flatnonzero(hit >= 0)[0])
            name = ctx.body_names[int(hit[k])]
            return Outcome("lift_collision", f"lift: the closed gripper hits {name} {1e3 * travel[k]:.0f} "
                           f"mm up (any IK solution)", opening=opening,
                           blockers=(name,) if name.startswith("instance:") else ())
    t = time.perf_counter()
    ik = solve_ik(robot, T_world_tcp @ ctx.T_tcp_flange, seed=p.seed, max_solutions=p.max_ik_solutions)
    timing["ik"] += time.perf_counter() - t
    sols = np.asarray(ik.q, dtype=np.float64).reshape(-1, robot.nq)[: p.max_ik_solutions]
    if len(sols) == 0:
        return Outcome("unreachable", f"no IK solution within the joint limits ({ik.reason})", opening=opening)
    cover = None
    if ctx.approach_sweep is not None:  # the open gripper along the approach: the same for every IK branch
        t = time.perf_counter()
        swept = ctx.approach_sweep(T_pre, T_world_tcp, opening, APPROACH_PAD)
        if swept is not None:
            cover = covered_check(robot, ctx.T_flange_tcp, ctx.static, swept)
        timing["approach"] += time.perf_counter() - t
    static, att = ctx.static, ctx.attached
    att.move_attached(T_tcp_part_of(T_part_tcp))
    drop = _drop_pairs(att) if T_line is not None and ctx.lift_part_checked is not None else None
    T_flange_part = ctx.T_flange_tcp @ T_tcp_part_of(T_part_tcp)
    n_touch = touch_waypoints(p.lift_contact, travel)
    flange_at_grasp = (T_world_tcp @ ctx.T_tcp_flange)[:3, 3]

    def resting(q: np.ndarray) -> bool:  # TCP travel from the grasp (FK) within lift_contact
        return bool(np.linalg.norm(world_fk(robot, q[None])[0, :3, 3] - flange_at_grasp) <= p.lift_contact + 1e-9)
    why: dict[str, str] = {}
    blockers: set[str] = set()
    count = {"grasp": 0, "approach": 0, "approach_kin": 0, "lift": 0, "lift_kin": 0, "path": 0, "place": 0}
    for j, q_grasp in enumerate(sols):
        ctx.budget.check()
        t = time.perf_counter()
        free = static.path_free(q_grasp[None], opening, reduced=cover)  # the grasp alone
        timing["collision"] += time.perf_counter() - t
        if not free:
            count["grasp"] += 1
            if "grasp" not in why:
                pairs_g = static.colliding_pairs(q_grasp, opening)
                why["grasp"] = describe_pairs(pairs_g, 2)
                blockers |= _blockers(pairs_g)
            continue
        t = time.perf_counter()
        back, reason = line_path(robot, T_world_tcp, T_pre, q_grasp, max_dev=p.max_dev, T_flange_tcp=ctx.T_flange_tcp)
        timing["approach"] += time.perf_counter() - t
        if back is None:
            count["approach_kin"] += 1
            why.setdefault("approach_kin", reason)
            continue
        t = time.perf_counter()
        free = static.path_free(back, opening, reduced=cover)
        timing["collision"] += time.perf_counter() - t
        if not free:
            count["approach"] += 1
            if "approach" not in why:
                hit_a = static.path_collisions(back, opening)
                pairs_a = [] if hit_a is None else hit_a[1]
                why["approach"] = describe_pairs(pairs_a, 2)
                blockers |= _blockers(pairs_a)
            continue
        t = time.perf_counter()
        lift, reason = line_path(robot, T_world_tcp, T_lift, q_grasp, max_dev=p.max_dev, T_flange_tcp=ctx.T_flange_tcp,
                                 sample=LIFT_SAMPLE)
        timing["lift"] += time.perf_counter() - t
        if lift is None:
            count["lift_kin"] += 1
            why.setdefault("lift_kin", reason)
            continue
        t = time.perf_counter()
        shallow = None
        if ctx.lift_depth is not None and p.lift_depth > 0:
            def shallow(q: np.ndarray, names: list[str]) -> bool:
                return bool(ctx.lift_depth(robot.fk(q) @ T_flange_part, names) <= p.lift_depth)
        covered = None if drop is None or T_line is None else _lift_covered(ctx, lift, T_line, T_flange_part)
        pairs = lift_collision(att, lift, width, n_touch, shallow, covered, drop, resting)
        timing["collision"] += time.perf_counter() - t
        if pairs is not None:
            count["lift"] += 1
            why.setdefault("lift", describe_pairs(pairs, 2))
            blockers |= _blockers(pairs)
            continue
        approach = back[::-1]
        t = time.perf_counter()
        transit = _transit(ctx, approach[0], T_pre, opening, seed)
        timing["transit"] += time.perf_counter() - t
        if transit is None:
            count["path"] += 1
            if count["path"] >= p.max_path_queries:
                break
            continue
        transfer = cand = None
        if ctx.T_place is not None:  # carry it to the place (grasplan.motion.pickplace, neighbours still in the scene)
            t = time.perf_counter()
            cand, transfer, place_why = _place(ctx, lift[-1], T_part_tcp, width, opening, seed)
            timing["place"] += time.perf_counter() - t
            if cand is None:
                why.setdefault("place", place_why)
                count["place"] += 1
                continue
        motion = assemble_motion(transit, approach, lift, width=width, opening=opening,
                                 T_tcp_part=T_tcp_part_of(T_part_tcp), transfer=transfer, place=cand,
                                 T_world_part_place=ctx.T_place)
        return Outcome("planned", f"planned with IK solution {j} of {len(sols)} (closest to q_home first)", motion,
                       opening)
    detail = (f"{len(sols)} IK solutions: {count['grasp']} collide at the grasp, {count['approach']} on the approach, "
              f"{count['approach_kin']} cannot follow it, {count['lift']} collide on the lift, {count['lift_kin']} "
              f"cannot follow it, {count['path']} found no transit")
    bl = tuple(sorted(blockers))
    if count["place"]:
        return Outcome("place", f"{why['place']}; " + detail, opening=opening)
    if count["lift"]:
        return Outcome("lift_collision", f"lift: with the part in the jaws {why['lift']}; " + detail, opening=opening,
                       blockers=bl)
    if count["path"]:
        return Outcome("no_path", "RRTConnect found no verified transit home -> pre-grasp; " + detail, opening=opening)
    if count["grasp"] or count["approach"]:
        hit = why.get("grasp", "") or why.get("approach", "")
        return Outcome("ik_collision", detail + (f"; e.g. {hit}" if hit else ""), opening=opening, blockers=bl)
    return Outcome("unreachable", detail + (f" ({why['approach_kin']})" if "approach_kin" in why else ""),
                   opening=opening)
