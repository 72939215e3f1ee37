"""One grasp's motion (:func:`plan_pick_motion`), the one per-grasp pipeline of ``plan``
(:func:`grasplan.motion.planning.plan_grasps`, a part alone) and ``pick`` (a pile): IK at the grasp,
then per IK solution, closest to ``q_home`` first: free at the grasp with the jaws at the
pre-grasp opening; the straight approach (``backoff`` along the TCP's -z) followed and free; the
straight lift (the cell's retreat, jaws at the contact width, the part attached) followed and free
but for the contacts :func:`lift_collision` allows; with a place, the place side
(:func:`~grasplan.motion.pickplace.place_candidates`, once per grasp; none: the grasp fails at
once); the transit ``q_home -> q_pregrasp`` (:func:`transit_path`); with a place, the transfer. Every
path is checked at ``interpolation.STEP`` rad against one
:class:`~grasplan.motion.collision_scene.CollisionScene` and its attached variant (a pile's other
instances and cloud are extra bodies); straight TCP lines: :func:`line_path`. What the two roads
set differently is explicit in :class:`MotionContext`: the lift's contact allowance and depth
rule, the checks before IK, the budget and the timing keys.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from ..gripper.model import Gripper
from ..robot.ik.solve import solve_ik
from ..results.joint_motion import Motion
from .joint_paths import approach_path_reason, plan_joint_path
from .pickplace import (
    LINE_SAMPLE, PlaceCandidate, T_tcp_part_of, assemble_motion, lift_pose, place_candidates, place_poses,
    transfer_path
)
from ..robot.model import Robot
from .collision_scene import CollisionScene, describe_pairs
from .codes import Reason
from .lift_check import LIFT_SAMPLE, _drop_pairs, lift_collision, lift_travel, touch_waypoints
from ..robot.ik.lines import world_fk
from ..status import Status

#: largest per-joint change (rad) between consecutive line waypoints (more: a branch jump)
MAX_JOINT_STEP = 0.1


def line_path(robot: Robot, T_from: np.ndarray, T_to: np.ndarray, q_from: np.ndarray, *, max_dev: float,
              T_flange_tcp: np.ndarray, sample: float = LINE_SAMPLE) -> tuple[np.ndarray | None, str]:
    """Joint waypoints moving the TCP straight ``T_from -> T_to`` (same orientation) from
    ``q_from``: the one line tracker of ``plan`` and ``pick``
    (:func:`grasplan.motion.joint_paths.approach_path_reason`, collisions left to the caller) with
    the pick's waypoint spacing (:data:`grasplan.motion.pickplace.LINE_SAMPLE`) and
    :data:`MAX_JOINT_STEP`: ``(path (k, n), "ok")`` or ``(None, why)``."""
    return approach_path_reason(robot, None, T_from, T_to, q_from, opening=0.0, max_dev=max_dev,
                                T_flange_tcp=T_flange_tcp, sample=sample, max_joint_step=MAX_JOINT_STEP)


@dataclass(frozen=True)
class Outcome:
    """One grasp's motion planning: why (``code``; ``reason`` in words), the motion when planned,
    the jaws' pre-grasp opening, the neighbours (``instance:<id>``) the lift or approach hit and,
    when the place side failed (``code`` ``place``), its plan status (``place_unreachable`` or
    ``place_no_path``)."""

    code: Reason
    reason: str
    motion: Motion | None = None
    opening: float = 0.0
    blockers: tuple[str, ...] = ()
    place_status: Status | None = None


class MotionParams(Protocol):
    """The options the per-grasp pipeline reads (:class:`~grasplan.config.params.PlanParams` and
    :class:`~grasplan.pick.params.PickParams` both have them)."""

    @property
    def seed(self) -> int: ...
    @property
    def backoff(self) -> float: ...
    @property
    def max_dev(self) -> float: ...
    @property
    def max_ik_solutions(self) -> int: ...
    @property
    def time_limit_per_query(self) -> float: ...
    @property
    def path_attempts(self) -> int: ...
    @property
    def max_path_queries(self) -> int: ...


class Deadline(Protocol):
    """A wall-clock budget (:class:`grasplan.pick.budget.Budget`): ``check()`` raises once it is
    spent, ``cap(seconds)`` caps a time at what is left."""

    def check(self) -> None: ...
    def cap(self, seconds: float) -> float: ...


@dataclass(frozen=True)
class TimingKeys:
    """The ``timing`` key each step's seconds are added to: IK at the grasp, the collision checks
    of the grasp and the approach, the approach's line (and its Cartesian sweep), the lift's line
    (and its gripper check before IK), the lift's collision check, the transit, the place side and
    the transfer. The defaults are the pick's keys; :data:`PLAN_TIMING` the plan's."""

    ik: str = "ik"
    collision: str = "collision"
    approach: str = "approach"
    lift: str = "lift"
    lift_collision: str = "collision"
    transit: str = "transit"
    place: str = "place"
    transfer: str = "place"


#: ``plan``'s timing keys (``PlanResult.timing_s``, docs/plan.md): the grasp's and the approach's
#: collision checks count to ``approach``, the lift's to ``lift``, the transit is ``joint_path``
PLAN_TIMING = TimingKeys(collision="approach", lift_collision="lift", transit="joint_path", transfer="transfer")


@dataclass
class MotionContext:
    """What every grasp of one plan (a part alone) or one instance (a pile) shares: robot, gripper,
    options, the scenes (part static, part attached; one attached variant whose part is moved per
    grasp), home, the lift and what the two roads set differently: ``lift_contact`` (the lift's
    TCP travel within which the part may rest on its support), ``depth_limit`` with ``lift_depth``
    (the depth rule of contacts with neighbours; 0: off), the checks before IK, the budget and the
    timing keys."""

    robot: Robot
    gripper: Gripper
    params: MotionParams
    static: CollisionScene
    attached: CollisionScene
    retreat_dir: np.ndarray
    retreat_dist: float
    timing: dict[str, float]
    lift_contact: float = 0.0
    depth_limit: float = 0.0
    keys: TimingKeys = TimingKeys()
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
    #: ``(T_pre, T_grasp, opening) -> (covered, drop) or None``, the pairs the open gripper's sweep
    #: decided, for ``CollisionScene.path_free``'s ``reduced`` (:func:`grasplan.pick.cover.approach_cover`)
    approach_sweep: Any = None
    #: the budget (:mod:`grasplan.pick.budget`): checked before each IK solution's checks and
    #: each OMPL query, whose time it caps; None: none
    budget: Deadline | None = None
    _released: CollisionScene | None = field(default=None, init=False, repr=False)

    def rrt_time(self) -> float:
        """Seconds per RRTConnect attempt: ``time_limit_per_query``, capped so that all
        ``path_attempts`` fit in the budget left (:class:`grasplan.pick.budget.BudgetSpent` when none is)."""
        p, n = self.params, max(self.params.path_attempts, 1)
        if self.budget is None:
            return p.time_limit_per_query
        left = self.budget.cap(p.time_limit_per_query * n)
        return p.time_limit_per_query if left >= p.time_limit_per_query * n else left / n

    def check_budget(self) -> None:
        """Raise when the budget is spent (no budget: never)."""
        if self.budget is not None:
            self.budget.check()

    def released(self) -> CollisionScene:
        """The static scene with the part at the place (released), built once per context."""
        assert self.T_place is not None
        if self._released is None:
            self._released = self.static.with_part_at(self.T_place)
        return self._released

    def __post_init__(self) -> None:
        self.q_home = np.asarray(self.robot.q_home, dtype=np.float64)
        self.T_flange_tcp = np.asarray(self.gripper.T_flange_tcp, dtype=np.float64)
        self.T_tcp_flange = np.linalg.inv(self.T_flange_tcp)


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


def _place_side(ctx: MotionContext, q_lifted: np.ndarray, T_part_tcp: np.ndarray, width: float, opening: float
                ) -> tuple[list[PlaceCandidate], Status, str]:
    """The place side of one grasp (IK at the place, descent, release, retreat;
    :func:`~grasplan.motion.pickplace.place_candidates`): the candidates, or none with the status
    and the reason; the same for every IK solution of the grasp."""
    p = ctx.params
    assert ctx.T_place is not None
    poses = place_poses(ctx.T_place, T_part_tcp, ctx.retreat_dir, ctx.retreat_dist, p.backoff)
    return place_candidates(ctx.robot, ctx.attached, ctx.released(), poses, width=width, opening=opening,
                            max_dev=p.max_dev, T_flange_tcp=ctx.T_flange_tcp, q_ref=q_lifted, seed=p.seed,
                            max_solutions=p.max_ik_solutions, limit=p.max_path_queries, contact=ctx.lift_contact)


def _transfer(ctx: MotionContext, q_lifted: np.ndarray, cands: list[PlaceCandidate], width: float, seed: int
              ) -> tuple[PlaceCandidate | None, np.ndarray | None]:
    """RRTConnect lifted -> above the place with the part in the jaws, to each candidate in turn:
    ``(candidate, path)`` of the first one reached, else ``(None, None)``."""
    p, robot = ctx.params, ctx.robot
    for c in cands:
        transfer = transfer_path(ctx.attached, q_lifted, c, lower=robot.lower, upper=robot.upper, width=width,
                                 seed=seed + 7, time_limit=ctx.rrt_time(), attempts=p.path_attempts)
        if transfer is not None:
            return c, transfer
    return None, None


#: the transit's via point: the pre-grasp TCP raised this far (m) along world +z, same IK branch
VIA_HEIGHT = 0.25


def transit_path(ctx: MotionContext, q_pre: np.ndarray, T_pre: np.ndarray, opening: float, seed: int
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


@dataclass(frozen=True, eq=False)
class GraspPoses:
    """One grasp's TCP poses in the world (grasp, pre-grasp ``backoff`` along the TCP's -z, lifted),
    the lift's TCP travel at its waypoints (:func:`lift_travel`), the jaws' contact ``width`` and
    pre-grasp ``opening``, and the grasp in the part's frame."""

    T_grasp: np.ndarray
    T_pre: np.ndarray
    T_lift: np.ndarray
    travel: np.ndarray
    width: float
    opening: float
    T_part_tcp: np.ndarray

    @classmethod
    def of(cls, ctx: MotionContext, T_world_tcp: np.ndarray, T_part_tcp: np.ndarray, width: float) -> GraspPoses:
        T_pre = T_world_tcp.copy()
        T_pre[:3, 3] -= ctx.params.backoff * T_world_tcp[:3, 2]
        return cls(T_world_tcp, T_pre, lift_pose(T_world_tcp, ctx.retreat_dir, ctx.retreat_dist),
                   lift_travel(ctx.retreat_dist), width, float(ctx.gripper.pregrasp_opening(width)), T_part_tcp)


def _gripper_along_lift(ctx: MotionContext, g: GraspPoses) -> tuple[np.ndarray | None, Outcome | None]:
    """The closed gripper checked along the lift before any IK (the same for every IK branch):
    ``(TCP poses at the lift's waypoints, None)``, ``(those, the lift_collision outcome)`` when it
    hits something, ``(None, None)`` when the context has no such check."""
    if ctx.lift_gripper_check is None:
        return None, None
    t = time.perf_counter()
    T_line = np.broadcast_to(g.T_grasp, (len(g.travel), 4, 4)).copy()
    T_line[:, :3, 3] += g.travel[:, None] * ctx.retreat_dir
    hit = ctx.lift_gripper_check(T_line, g.width)
    ctx.timing[ctx.keys.lift] += time.perf_counter() - t
    if not np.any(hit >= 0):
        return T_line, None
    k = int(np.flatnonzero(hit >= 0)[0])
    name = ctx.body_names[int(hit[k])]
    return T_line, Outcome(Reason.LIFT_GRIPPER, f"lift: the closed gripper hits {name} {1e3 * g.travel[k]:.0f} "
                           f"mm up (any IK solution)", opening=g.opening,
                           blockers=(name,) if name.startswith("instance:") else ())


@dataclass(frozen=True, eq=False)
class SolutionChecks:
    """What the checks of every IK solution of one grasp share: the approach's pairs the open
    gripper's sweep decided (``cover``, ``MotionContext.approach_sweep``), the lift's
    waypoints the checks before IK decided (``T_line``, ``drop``: :func:`_lift_covered`,
    :func:`_drop_pairs`), the carried part in the flange frame and the lift's resting waypoints
    (``n_touch``, :func:`touch_waypoints`)."""

    ctx: MotionContext
    cover: Any
    T_line: np.ndarray | None
    drop: tuple[np.ndarray, np.ndarray] | None
    T_flange_part: np.ndarray
    n_touch: int
    flange_at_grasp: np.ndarray

    @classmethod
    def of(cls, ctx: MotionContext, g: GraspPoses, T_line: np.ndarray | None) -> SolutionChecks:
        """Sweep the open gripper along the approach, then attach the part to the attached variant."""
        cover = None
        if ctx.approach_sweep is not None:  # the open gripper along the approach: the same for every IK branch
            t = time.perf_counter()
            cover = ctx.approach_sweep(g.T_pre, g.T_grasp, g.opening)
            ctx.timing[ctx.keys.approach] += time.perf_counter() - t
        ctx.attached.move_attached(T_tcp_part_of(g.T_part_tcp))
        drop = _drop_pairs(ctx.attached) if T_line is not None and ctx.lift_part_checked is not None else None
        return cls(ctx, cover, T_line, drop, ctx.T_flange_tcp @ T_tcp_part_of(g.T_part_tcp),
                   touch_waypoints(ctx.lift_contact, g.travel), (g.T_grasp @ ctx.T_tcp_flange)[:3, 3])

    def resting(self, qs: np.ndarray) -> np.ndarray:
        """(k,) bool: whether each configuration of ``qs`` (k, n) is within ``lift_contact`` of TCP
        travel from the grasp (FK, all at once)."""
        d = world_fk(self.ctx.robot, np.asarray(qs, dtype=np.float64).reshape(-1, self.ctx.robot.nq))[:, :3, 3]
        return np.linalg.norm(d - self.flange_at_grasp, axis=1) <= self.ctx.lift_contact + 1e-9

    def shallow(self) -> Callable[[np.ndarray, list[str]], bool] | None:
        """The depth rule of the lift's contacts with neighbours (None: any contact is a collision)."""
        ctx = self.ctx
        if ctx.lift_depth is None or ctx.depth_limit <= 0:
            return None

        def shallow(q: np.ndarray, names: list[str]) -> bool:
            return bool(ctx.lift_depth(ctx.robot.fk(q) @ self.T_flange_part, names) <= ctx.depth_limit)
        return shallow


@dataclass
class _Tally:
    """The IK solutions of one grasp that failed, per kind (``grasp``, ``approach``,
    ``approach_kin``, ``lift``, ``lift_kin``, ``path``, ``place``): how many, the first one's
    reason, the neighbours hit; ``stop``: ``max_path_queries`` transits failed or the place side
    has no candidate; ``place``: the place side once computed (candidates, status, reason) and
    ``place_status``: the plan status of a place failure; ``every_grasp``: the grasp collides on a
    pair the TCP pose alone places (:func:`_placed_by_tcp`), so every IK solution does."""

    count: dict[str, int] = field(default_factory=lambda: dict.fromkeys(
        ("grasp", "approach", "approach_kin", "lift", "lift_kin", "path", "place"), 0))
    why: dict[str, str] = field(default_factory=dict)
    blockers: set[str] = field(default_factory=set)
    stop: bool = False
    place: tuple[list[PlaceCandidate], Status, str] | None = None
    place_status: Status | None = None
    every_grasp: bool = False

    def fail(self, kind: str, why: str | None = None, pairs: list[tuple[str, str, str]] | None = None) -> None:
        self.count[kind] += 1
        if why is not None:
            self.why.setdefault(kind, why)
        if pairs is not None:
            self.blockers |= _blockers(pairs)


def _timed(ctx: MotionContext, key: str, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """``fn(*args, **kwargs)``, its seconds added to ``ctx.timing[key]``."""
    t = time.perf_counter()
    try:
        return fn(*args, **kwargs)
    finally:
        ctx.timing[key] += time.perf_counter() - t


def _approach(ctx: MotionContext, g: GraspPoses, chk: SolutionChecks, q_grasp: np.ndarray, tally: _Tally
              ) -> np.ndarray | None:
    """The approach traced back from ``q_grasp`` to the pre-grasp (grasp first), or None when the
    grasp or the approach collides or the line cannot be followed (recorded in ``tally``)."""
    static = ctx.static
    # the grasp alone
    if not _timed(ctx, ctx.keys.collision, static.path_free, q_grasp[None], g.opening, reduced=chk.cover):
        if "grasp" in tally.why:
            tally.fail("grasp")
        else:
            pairs_g = static.colliding_pairs(q_grasp, g.opening)
            tally.fail("grasp", describe_pairs(pairs_g, 2), pairs_g)
            tally.every_grasp = chk.cover is None and _placed_by_tcp(ctx, q_grasp, g.opening)
        return None
    back, reason = _timed(ctx, ctx.keys.approach, line_path, ctx.robot, g.T_grasp, g.T_pre, q_grasp,
                          max_dev=ctx.params.max_dev, T_flange_tcp=ctx.T_flange_tcp)
    if back is None:
        tally.fail("approach_kin", reason)
        return None
    if not _timed(ctx, ctx.keys.collision, static.path_free, back, g.opening, reduced=chk.cover):
        if "approach" in tally.why:
            tally.fail("approach")
        else:
            hit_a = static.path_collisions(back, g.opening)
            pairs_a = [] if hit_a is None else hit_a[1]
            tally.fail("approach", describe_pairs(pairs_a, 2), pairs_a)
        return None
    return back


def _placed_by_tcp(ctx: MotionContext, q_grasp: np.ndarray, opening: float) -> bool:
    """Some pair colliding at ``q_grasp`` has both geometries fixed in the world or on the joint that
    carries the tool (the flange's link, the gripper): the TCP pose places them, so they collide at
    every IK solution of that pose."""
    gm, fixed = ctx.static.geom_model, (0, ctx.robot.tool_joint_id)
    return any(all(gm.geometryObjects[gm.getGeometryId(name)].parentJoint in fixed for name in (a, b))
               for a, b, _ in ctx.static.colliding_geometries(q_grasp, opening))


def _lift(ctx: MotionContext, g: GraspPoses, chk: SolutionChecks, q_grasp: np.ndarray, tally: _Tally
          ) -> np.ndarray | None:
    """The lift from ``q_grasp`` with the part in the jaws, or None when it cannot be followed or
    collides (recorded in ``tally``)."""
    lift, reason = _timed(ctx, ctx.keys.lift, line_path, ctx.robot, g.T_grasp, g.T_lift, q_grasp,
                          max_dev=ctx.params.max_dev, T_flange_tcp=ctx.T_flange_tcp, sample=LIFT_SAMPLE)
    if lift is None:
        tally.fail("lift_kin", reason)
        return None
    t = time.perf_counter()
    shallow = chk.shallow()
    covered = None if chk.drop is None or chk.T_line is None else _lift_covered(ctx, lift, chk.T_line, chk.T_flange_part)
    pairs = lift_collision(ctx.attached, lift, g.width, chk.n_touch, shallow, covered, chk.drop, chk.resting)
    ctx.timing[ctx.keys.lift_collision] += time.perf_counter() - t
    if pairs is not None:
        tally.fail("lift", describe_pairs(pairs, 2), pairs)
        return None
    return lift


def _motion_through(ctx: MotionContext, g: GraspPoses, chk: SolutionChecks, q_grasp: np.ndarray, tally: _Tally,
                    seed: int) -> Motion | None:
    """The motion through IK solution ``q_grasp``: grasp, approach, lift, (the place side,) transit
    (and the transfer), or None (``tally`` records why)."""
    back = _approach(ctx, g, chk, q_grasp, tally)
    if back is None:
        return None
    lift = _lift(ctx, g, chk, q_grasp, tally)
    if lift is None:
        return None
    if ctx.T_place is not None:  # the place side: once per grasp (it does not depend on the IK solution)
        if tally.place is None:
            tally.place = _timed(ctx, ctx.keys.place, _place_side, ctx, lift[-1], g.T_part_tcp, g.width, g.opening)
        if not tally.place[0]:
            tally.fail("place", tally.place[2])
            tally.place_status, tally.stop = tally.place[1], True
            return None
    approach = back[::-1]
    transit = _timed(ctx, ctx.keys.transit, transit_path, ctx, approach[0], g.T_pre, g.opening, seed)
    if transit is None:
        tally.fail("path")
        tally.stop = tally.count["path"] >= ctx.params.max_path_queries
        return None
    transfer = cand = None
    if tally.place is not None:  # carry it to the place (neighbours still in the scene)
        cand, transfer = _timed(ctx, ctx.keys.transfer, _transfer, ctx, lift[-1], tally.place[0], g.width, seed)
        if cand is None:
            tally.fail("place", "place: RRTConnect found no verified transfer path (part in the jaws) lifted -> "
                       "above the place")
            tally.place_status = Status.PLACE_NO_PATH
            return None
    return assemble_motion(transit, approach, lift, width=g.width, opening=g.opening,
                           T_tcp_part=T_tcp_part_of(g.T_part_tcp), transfer=transfer, place=cand,
                           T_world_part_place=ctx.T_place)


def _failed(tally: _Tally, n_solutions: int, opening: float) -> Outcome:
    """The outcome of a grasp none of whose ``n_solutions`` IK solutions gave a motion: the place,
    then the lift, the transit, a collision at the grasp or on the approach, else kinematics."""
    count, why = tally.count, tally.why
    detail = (f"{n_solutions} IK solutions: {count['grasp']} collide at the grasp, {count['approach']} on the "
              f"approach, {count['approach_kin']} cannot follow it, {count['lift']} collide on the lift, "
              f"{count['lift_kin']} cannot follow it, {count['path']} found no transit")
    bl = tuple(sorted(tally.blockers))
    if count["place"]:
        return Outcome(Reason.PLACE, f"{why['place']}; " + detail, opening=opening, place_status=tally.place_status)
    if count["lift"]:
        return Outcome(Reason.LIFT_COLLISION, f"lift: with the part in the jaws {why['lift']}; " + detail,
                       opening=opening, blockers=bl)
    if count["path"]:
        return Outcome(Reason.NO_TRANSIT, "RRTConnect found no verified transit home -> pre-grasp; " + detail,
                       opening=opening)
    if count["grasp"] or count["approach"]:
        hit = why.get("grasp", "") or why.get("approach", "")
        return Outcome(Reason.IK_COLLISION, detail + (f"; e.g. {hit}" if hit else ""), opening=opening, blockers=bl)
    return Outcome(Reason.LINE_NOT_FOLLOWED, detail + (f" ({why['approach_kin']})" if "approach_kin" in why else ""),
                   opening=opening)


def plan_pick_motion(ctx: MotionContext, T_world_tcp: np.ndarray, T_part_tcp: np.ndarray, width: float,
                     seed: int) -> Outcome:
    """Plan one grasp (module docstring): the closed gripper along the lift, IK, then per IK solution
    (closest to ``q_home`` first) the grasp, the approach, the lift, the transit and the place
    until one gives a motion."""
    p = ctx.params
    ctx.check_budget()
    g = GraspPoses.of(ctx, T_world_tcp, T_part_tcp, width)
    T_line, hit = _gripper_along_lift(ctx, g)
    if hit is not None:
        return hit
    ik = _timed(ctx, ctx.keys.ik, solve_ik, ctx.robot, T_world_tcp @ ctx.T_tcp_flange, seed=p.seed,
                max_solutions=p.max_ik_solutions)
    sols = np.asarray(ik.q, dtype=np.float64).reshape(-1, ctx.robot.nq)[: p.max_ik_solutions]
    if len(sols) == 0:
        return Outcome(Reason.NO_IK, f"no IK solution within the joint limits ({ik.reason})", opening=g.opening)
    chk = SolutionChecks.of(ctx, g, T_line)
    tally = _Tally()
    for j, q_grasp in enumerate(sols):
        ctx.check_budget()
        motion = _motion_through(ctx, g, chk, q_grasp, tally, seed)
        if motion is not None:
            return Outcome(Reason.PLANNED, f"planned with IK solution {j} of {len(sols)} (closest to q_home first)",
                           motion, g.opening)
        if tally.stop:
            break
        if tally.every_grasp:  # the others collide at the grasp as this one did
            tally.count["grasp"] += len(sols) - j - 1
            break
    return _failed(tally, len(sols), g.opening)
