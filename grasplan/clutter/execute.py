"""Execute one planned pick in the clutter world (:class:`grasplan.clutter.world.ClutterWorld`).

:func:`execute_pick` runs the protocol (pre-grasp, straight approach, close, straight lift, an
optional straight extraction up to a clearance height, hold, then the pile settles) and judges the
:class:`Outcome`: one of :data:`OUTCOMES` (:func:`judge` decides it from the measured quantities).
A pick succeeds when the part is still between both jaws at the end of the hold, high enough (its
centre of mass :data:`LIFT_MIN` above its start, or its lowest point at a given clearance height)
and turned at most :data:`TURN_MAX_DEG` in the jaws. The pads' twist resistance can come from the
contact actually made (``patch_torsion``) instead of the plan. Its numbers are the constants below
(:data:`PROTOCOL`, as a report records them). Deterministic: MuJoCo single-threaded; the same pile
and pick give the same bits.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from ..sim.drop import REST_ANG, REST_HOLD_S, REST_LIN
from ..geometry.transforms import check_transform, inv_rigid
from .world import CONTROL_DT, PICK_TIMESTEP, ClutterWorld

#: peak TCP speed on the approach and on the lift (m/s); shortest move (s)
APPROACH_SPEED, LIFT_SPEED, MIN_MOVE_S = 0.1, 0.2, 0.2
#: jaws closing (s), the hold at the top (s), the jaws opening afterwards (s)
CLOSE_S, HOLD_S, OPEN_S = 0.3, 1.0, 0.2
#: success: the target's centre of mass at least this far (m) above its start (no clearance height given)
LIFT_MIN = 0.05
#: a clearance height given: the extraction lifts the target's lowest point this far (m) above it
CLEAR_MARGIN = 0.01
#: success: the target turned at most this much (deg) relative to the hand from the jaws' closing
#: to the end of the hold (more: it swung in the jaws, *turned*)
TURN_MAX_DEG = 15.0
#: a gripper starting inside something deeper than this (m) has collided
START_DEPTH = 0.001
#: contact force (N) of the gripper on the bin, the table or an obstacle that stops the run
COLLIDE_FORCE = 50.0
#: the hand (TCP) ended a control period farther (m) than this from its planned path: it ran into
#: something fixed (the hand is driven along the path; only a collision pushes it off it)
PATH_DEV = 0.001
#: the target moved farther (m) or turned more (deg) than this before the jaws closed: pushed
PUSH_DIST, PUSH_DEG = 0.005, 10.0
#: longest settling of the pile after a pick (simulated s)
SETTLE_MAX_S = 3.0

#: the execution protocol's numbers, as a report records them
PROTOCOL = {"approach_speed": APPROACH_SPEED, "lift_speed": LIFT_SPEED, "close_s": CLOSE_S, "hold_s": HOLD_S,
            "lift_min": LIFT_MIN, "clear_margin": CLEAR_MARGIN, "turn_max_deg": TURN_MAX_DEG,
            "start_depth": START_DEPTH, "collide_force": COLLIDE_FORCE, "path_dev": PATH_DEV, "push_dist": PUSH_DIST,
            "push_deg": PUSH_DEG, "timestep": PICK_TIMESTEP, "control_dt": CONTROL_DT}

SUCCESS, COLLIDED, SLIPPED, PUSHED, MISSED = "success", "collided", "slipped", "pushed_away", "missed"
TURNED, DROPPED = "turned", "dropped"
#: every outcome of an executed pick, in the order they are decided
OUTCOMES = (SUCCESS, COLLIDED, TURNED, DROPPED, SLIPPED, PUSHED, MISSED)
#: where the pads' twist resistance of a pick came from (``Outcome.patch``): the ``jaw_torsion``
#: given (or the nominal), or ``patch_torsion`` of the contact made when the jaws closed
PATCH_PLANNED, PATCH_CONTACT = "planned", "contact"


class PickLike(Protocol):
    """What execution needs of a planned pick (:class:`grasplan.pick.Pick` has it), read only."""

    @property
    def T_world_pregrasp(self) -> np.ndarray: ...
    @property
    def T_world_tcp(self) -> np.ndarray: ...
    @property
    def T_world_lifted(self) -> np.ndarray: ...
    @property
    def opening(self) -> float: ...
    @property
    def width(self) -> float: ...


@dataclass(frozen=True)
class Outcome:
    """How an executed pick went: ``outcome`` (one of :data:`OUTCOMES`), ``reason`` (a sentence),
    the target's rise ``lift`` (m, centre of mass, end of the hold), how far it moved ``pushed``
    (m) and turned ``turned_deg`` before the jaws closed, whether both jaws ``held_at_close``, the
    jaws' ``opening`` at the end (m), the largest force on a fixed obstacle ``fixed_force`` (N),
    the simulated seconds ``sim_s`` and, when recorded, the replay samples ``track`` every
    :data:`TRACK_DT`: (t, hand pose (4, 4), jaw opening, poses (k, 4, 4) of the parts
    ``track_parts`` present when the pick started). ``turned_in_jaws_deg``: how far the target
    turned relative to the hand from the end of the close to the end of the run (deg; 0 when the
    jaws never closed); ``low_z``: the target's lowest point (convex hull, world z, m) at the end;
    ``patch``: where the pads' twist resistance came from (:data:`PATCH_PLANNED` or
    :data:`PATCH_CONTACT`)."""

    outcome: str
    reason: str
    lift: float
    pushed: float
    turned_deg: float
    held_at_close: bool
    opening: float
    fixed_force: float
    sim_s: float
    track: tuple[tuple[float, np.ndarray, float, np.ndarray], ...] = field(default=(), repr=False)
    track_parts: tuple[str, ...] = ()
    turned_in_jaws_deg: float = 0.0
    low_z: float | None = None
    patch: str = PATCH_PLANNED

    @property
    def success(self) -> bool:
        return self.outcome == SUCCESS

    def to_json(self) -> dict:
        return {"outcome": self.outcome, "reason": self.reason, "lift_m": self.lift, "pushed_m": self.pushed,
                "turned_deg": self.turned_deg, "held_at_close": self.held_at_close, "opening_m": self.opening,
                "fixed_force_n": self.fixed_force, "sim_s": self.sim_s,
                "turned_in_jaws_deg": self.turned_in_jaws_deg, "low_z_m": self.low_z, "patch": self.patch}


#: a replay sample every this many simulated seconds
TRACK_DT = 0.05


def _profile(distance: float, speed: float) -> tuple[int, np.ndarray, np.ndarray]:
    """Control periods of a straight move of ``distance`` (m) at peak ``speed`` (cosine profile):
    their count, the path fraction at each period's start and the speed factor (1/s, d s/dt) at
    its middle."""
    T = max(MIN_MOVE_S, math.pi * distance / (2.0 * speed))
    n = max(1, round(T / CONTROL_DT))
    T = n * CONTROL_DT
    t0 = np.arange(n) * CONTROL_DT
    tm = t0 + 0.5 * CONTROL_DT
    s = 0.5 * (1.0 - np.cos(math.pi * t0 / T))
    ds = 0.5 * math.pi / T * np.sin(math.pi * tm / T)
    return n, s, ds


def _rotvec(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).as_rotvec()


def _rotation(rv: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(rv).as_matrix()


def angle_deg(R: np.ndarray) -> float:
    """The rotation angle (deg) of rotation matrix ``R`` (3, 3)."""
    return math.degrees(math.acos(float(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


class Run:
    """State of one execution in the clutter world (a pick, :func:`execute_pick`; a push,
    :func:`grasplan.clutter.pushing.execute_push`): the world ``cw``, the ``target`` part (body
    index), the simulated time ``t`` (s), the replay samples ``track`` (when ``record``: every
    :data:`TRACK_DT`, of the parts ``ids`` present at the start), the worst fixed contact
    (``fixed_force`` N, ``fixed_what``) and how far contacts pushed the hand off its path
    (``off_path``). :meth:`move` drives the hand along a straight line, :meth:`stay` holds it,
    each control period checked by :meth:`period` (the collision rules)."""

    def __init__(self, cw: ClutterWorld, target: int, record: bool):
        self.cw, self.target, self.record = cw, target, record
        self.t = 0.0
        self.track: list = []
        self.fixed_force = 0.0
        self.fixed_what = ""
        self.off_path = 0.0  #: how far (m) contacts pushed the hand off its planned path, when beyond PATH_DEV
        self.next_sample = 0.0
        self.ids = [int(i) for i in np.flatnonzero(cw.world.present)] if record else []
        self.R_close: np.ndarray | None = None  #: the target's orientation in the hand frame when the jaws closed
        self.patch = PATCH_PLANNED

    def com(self) -> np.ndarray:
        return np.array(self.cw.data.xipos[self.cw.world.body_ids[self.target]])

    def sample(self) -> None:
        if self.record and self.t >= self.next_sample - 1e-9:
            self.next_sample += TRACK_DT
            w = self.cw.world
            poses = np.stack([w.pose(i) for i in self.ids]) if self.ids else np.zeros((0, 4, 4))
            self.track.append((round(self.t, 4), self.cw.hand_pose(), max(0.0, self.cw.opening()), poses))

    def period(self, expect: np.ndarray | None = None) -> bool:
        """Step one control period; False when the gripper pressed a fixed obstacle too hard, or
        the hand ended more than :data:`PATH_DEV` from ``expect`` (where the planned path puts the
        TCP at the period's end: contacts pushed it off, e.g. driven into a wall between samples)."""
        self.cw.step(CONTROL_DT)
        self.t += CONTROL_DT
        self.sample()
        for c in self.cw.contacts():
            if c.part < 0 and c.force > self.fixed_force:
                self.fixed_force, self.fixed_what = c.force, f"the {c.gripper} on {c.other}"
        if self.fixed_force > COLLIDE_FORCE:
            return False
        if expect is not None:
            dev = float(np.linalg.norm(self.cw.hand_pose()[:3, 3] - expect))
            if dev > PATH_DEV:
                self.off_path = dev
                return False
        return True

    def move(self, T_from: np.ndarray, T_to: np.ndarray, speed: float) -> bool:
        """Drive the hand along the straight line ``T_from`` -> ``T_to``; False when it collided."""
        dp = T_to[:3, 3] - T_from[:3, 3]
        rv = _rotvec(T_from[:3, :3].T @ T_to[:3, :3])  # in the start frame
        n, s, ds = _profile(float(np.linalg.norm(dp)), speed)
        for k in range(n):
            T = np.eye(4)
            T[:3, :3] = T_from[:3, :3] @ _rotation(s[k] * rv)
            T[:3, 3] = T_from[:3, 3] + s[k] * dp
            self.cw.set_hand(T, v=ds[k] * dp, w=T_from[:3, :3] @ (ds[k] * rv))
            if not self.period(T_from[:3, 3] + (s[k + 1] if k + 1 < n else 1.0) * dp):
                return False
        return self.stay(T_to, 0.0)

    def stay(self, T: np.ndarray, seconds: float) -> bool:
        for _ in range(round(seconds / CONTROL_DT)):
            self.cw.set_hand(T)
            if not self.period(T[:3, 3]):
                return False
        self.cw.set_hand(T)
        return True

    def jaws_on_target(self) -> bool:
        touching = {c.gripper for c in self.cw.contacts() if c.part == self.target}
        return {"jaw0", "jaw1"} <= touching

    def low_z(self) -> float:
        """The target's lowest point now (world z of its convex hull, m)."""
        return float(self.cw.world.hull_world(self.target)[:, 2].min())

    def in_hand(self) -> np.ndarray:
        """The target's orientation in the hand frame now (3, 3)."""
        return self.cw.hand_pose()[:3, :3].T @ self.cw.world.pose(self.target)[:3, :3]

    def turned_in_jaws(self) -> float:
        """How far (deg) the target turned relative to the hand since the jaws closed (0 before)."""
        return 0.0 if self.R_close is None else angle_deg(self.R_close.T @ self.in_hand())


def execute_pick(cw: ClutterWorld, target: int, pick: PickLike, *, jaw_torsion: ArrayLike | None = None,
                 record: bool = False, settle: bool = True, clear_z: float | None = None,
                 patch_torsion: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None) -> Outcome:
    """Execute ``pick`` on part body ``target`` of the clutter world and leave the world ready for
    the next one (the target parked when picked, the gripper parked, the pile settled unless
    ``settle`` is False). ``jaw_torsion`` (2,): each pad's torsional friction per newton (m, ``mu``
    included; :meth:`ClutterWorld.set_jaw_torsion`); ``record``: keep replay samples.
    ``clear_z``: the world height (m) the target's lowest point must reach and keep to the end of
    the hold (None: its centre of mass must rise :data:`LIFT_MIN`). ``patch_torsion(T_part_tcp,
    contacts_part) -> (2,)``: the pads' torsional friction of the grasp the jaws actually made.

    In the world frame with every part present (docs/clutter.md, "A pick"; a linkage gripper's
    poses moved by ``T_g = T_tcp_gripper(width)``, the hand frame being the TCP at full opening):
    **pre-grasp** (overlap beyond :data:`START_DEPTH`: *collided*); **approach** along the line
    (peak :data:`APPROACH_SPEED`); **close** for :data:`CLOSE_S` under the grip force (the
    target's orientation in the hand then is the reference of its turn in the jaws); **contact
    patch**: with both jaws on the target, ``T_part_tcp = inv(T_world_part) @ T_world_hand @
    inv(T_g)`` and each jaw's normal-force-weighted contact point give ``patch_torsion``'s
    lengths for the rest of the pick (``Outcome.patch`` "contact"; else the torsion set before
    stays, "planned"); **lift** to ``T_world_lifted`` (peak :data:`LIFT_SPEED`); **extract**
    straight up by what the lowest point lacks of ``clear_z + CLEAR_MARGIN`` while the target is
    between both jaws; **hold** :data:`HOLD_S`; the **outcome** (:func:`judge`): *collided* (more
    than :data:`COLLIDE_FORCE` on something fixed, or the hand pushed more than :data:`PATH_DEV`
    off its path within a control period; the reason names the phase), *success*, *turned* (more
    than :data:`TURN_MAX_DEG` in the jaws), *dropped* (lost during the hold), *slipped* (lost in
    the lift or extraction, or never high enough), *pushed away* (moved more than
    :data:`PUSH_DIST` or turned more than :data:`PUSH_DEG` before the jaws closed) or *missed*;
    **afterwards** a picked part leaves the world, the jaws open for :data:`OPEN_S`, the gripper
    leaves and the pile settles (at most :data:`SETTLE_MAX_S`).
    """
    import mujoco

    w = cw.world
    if not w.present[target]:
        raise ValueError(f"execute_pick: part {w.bodies[target].name} is not in the world")
    if clear_z is not None and not math.isfinite(clear_z):
        raise ValueError(f"execute_pick: clear_z must be a finite height (m), got {clear_z!r}")
    # the hand is the frame the gripper's shapes are given in: for a linkage gripper (its TCP moves
    # with the opening) the pick's grasp TCP moved back to full opening, as the planner checks it
    T_g = np.asarray(cw.gripper.T_tcp_gripper(float(pick.width)), dtype=np.float64)
    T_pre = check_transform(pick.T_world_pregrasp, "T_world_pregrasp") @ T_g
    T_grasp = check_transform(pick.T_world_tcp, "T_world_tcp") @ T_g
    T_lift = check_transform(pick.T_world_lifted, "T_world_lifted") @ T_g
    timestep = float(cw.model.opt.timestep)
    cw.model.opt.timestep = PICK_TIMESTEP
    cw.set_jaw_torsion(jaw_torsion, target)
    run = Run(cw, target, record)
    try:
        T0 = w.pose(target)
        com0 = run.com()
        cw.set_hand(T_pre)
        cw.set_jaws(float(pick.opening))
        mujoco.mj_forward(cw.model, cw.data)
        run.sample()
        deep = [c for c in cw.contacts() if c.depth > START_DEPTH]
        if deep:
            c = max(deep, key=lambda c: c.depth)
            out = _outcome(run, COLLIDED, f"at the pre-grasp pose the {c.gripper} overlaps {c.other} by "
                           f"{c.depth * 1e3:.1f} mm", T0, com0, False)
        elif not run.move(T_pre, T_grasp, APPROACH_SPEED):
            out = _collided(run, "approach", T0, com0)
        else:
            cw.squeeze(cw.grip_force)
            ok = run.stay(T_grasp, CLOSE_S)
            held = run.jaws_on_target()
            moved = (float(np.linalg.norm(run.com() - com0)), angle_deg(T0[:3, :3].T @ w.pose(target)[:3, :3]))
            run.R_close = run.in_hand()
            if not ok:
                out = _collided(run, "closing", T0, com0, held, moved)
            else:
                if patch_torsion is not None:
                    _contact_patch(run, patch_torsion, T_g)
                out = _lift_and_hold(run, T_grasp, T_lift, clear_z, T0, com0, held, moved)
        _finish(run, out.success)
    finally:
        cw.model.opt.timestep = timestep
    if settle and w.present.any():  # at the pile world's own timestep, as the drop settles
        w.settle(lin=REST_LIN, ang=REST_ANG, hold=REST_HOLD_S, max_s=SETTLE_MAX_S)
    return out


def actual_grasp(cw: ClutterWorld, target: int, T_g: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The grasp the jaws hold part body ``target`` with now, in the part's frame: ``T_part_tcp``
    (4, 4; the TCP is the hand frame moved back by ``inv(T_g)``, ``T_g = T_tcp_gripper(width)``) and
    per jaw (``jaw0``, ``jaw1``) the normal-force-weighted mean of its contact points with the part
    (2, 3), m; None unless both jaws touch it."""
    cons = [c for c in cw.contacts() if c.part == target]
    points = []
    for jaw in ("jaw0", "jaw1"):
        mine = [c for c in cons if c.gripper == jaw]
        if not mine:
            return None
        P = np.stack([c.pos for c in mine])
        f = np.array([max(c.force, 0.0) for c in mine])
        points.append(f @ P / f.sum() if f.sum() > 0 else P.mean(axis=0))
    T_part_world = inv_rigid(cw.world.pose(target))
    T_part_tcp = T_part_world @ cw.hand_pose() @ inv_rigid(np.asarray(T_g, dtype=np.float64))
    return T_part_tcp, np.stack(points) @ T_part_world[:3, :3].T + T_part_world[:3, 3]


def _contact_patch(run: Run, patch_torsion: Callable[[np.ndarray, np.ndarray], np.ndarray],
                   T_g: np.ndarray) -> None:
    """Step 4 of :func:`execute_pick`: the pads' torsion from the contact made, when both jaws touch."""
    grasp = actual_grasp(run.cw, run.target, T_g)
    if grasp is None:
        return
    try:  # set_jaw_torsion refuses (ValueError) anything but two finite lengths >= 0, changing nothing
        run.cw.set_jaw_torsion(np.asarray(patch_torsion(*grasp), dtype=np.float64), run.target)
    except ValueError:
        return  # the torsion set before stays; Outcome.patch says "planned"
    run.patch = PATCH_CONTACT


def _lift_and_hold(run: Run, T_grasp: np.ndarray, T_lift: np.ndarray, clear_z: float | None, T0: np.ndarray,
                   com0: np.ndarray, held: bool, moved: tuple[float, float]) -> Outcome:
    """Steps 5 to 8 of :func:`execute_pick`: lift, extract, hold, judge."""
    if not run.move(T_grasp, T_lift, LIFT_SPEED):
        return _collided(run, "lift", T0, com0, held, moved)
    T_top, extract = T_lift, 0.0
    if clear_z is not None and run.jaws_on_target():
        missing = clear_z + CLEAR_MARGIN - run.low_z()
        if missing > 0.0:
            T_top = T_lift.copy()
            T_top[2, 3] += missing
            extract = missing
            if not run.move(T_lift, T_top, LIFT_SPEED):
                return _collided(run, "extract", T0, com0, held, moved)
    held_lift = run.jaws_on_target()
    if not run.stay(T_top, HOLD_S):
        return _collided(run, "lift", T0, com0, held, moved)
    return _judge(run, T0, com0, held, moved, held_lift, clear_z, extract)


def _outcome(run: Run, outcome: str, reason: str, T0: np.ndarray, com0: np.ndarray, held: bool,
             moved: tuple[float, float] | None = None) -> Outcome:
    if moved is None:
        moved = (float(np.linalg.norm(run.com() - com0)),
                 angle_deg(T0[:3, :3].T @ run.cw.world.pose(run.target)[:3, :3]))
    return Outcome(outcome=outcome, reason=reason, lift=float(run.com()[2] - com0[2]), pushed=moved[0],
                   turned_deg=moved[1], held_at_close=held, opening=max(0.0, run.cw.opening()), fixed_force=run.fixed_force,
                   sim_s=run.t, track=tuple(run.track),
                   track_parts=tuple(run.cw.world.bodies[i].name for i in run.ids),
                   turned_in_jaws_deg=run.turned_in_jaws(), low_z=run.low_z(), patch=run.patch)


def collision_reason(run: Run, phase: str) -> str:
    """Why ``run`` stopped in ``phase`` (a sentence): pushed off its path by more than
    :data:`PATH_DEV`, or pressed on something fixed with more than :data:`COLLIDE_FORCE`."""
    if run.off_path > 0:
        what = f" ({run.fixed_what}, {run.fixed_force:.0f} N)" if run.fixed_what else ""
        return (f"{phase}: the gripper was pushed {run.off_path * 1e3:.1f} mm off its path"
                f"{what} (> {PATH_DEV * 1e3:g} mm: it ran into something fixed; a protective stop)")
    return f"{phase}: {run.fixed_what} pressed with {run.fixed_force:.0f} N (> {COLLIDE_FORCE:g} N, a protective stop)"


def _collided(run: Run, phase: str, T0: np.ndarray, com0: np.ndarray, held: bool = False,
              moved: tuple[float, float] | None = None) -> Outcome:
    return _outcome(run, COLLIDED, collision_reason(run, phase), T0, com0, held, moved)


def judge(*, held_at_close: bool, held_after_lift: bool, held_at_end: bool, high: bool, turned_in_jaws_deg: float,
          pushed: float, turned_deg: float) -> str:
    """The outcome of a pick that did not collide, from what was measured: whether both jaws touched
    the target when they closed (``held_at_close``), at the end of the lift or extraction
    (``held_after_lift``) and at the end of the hold (``held_at_end``); whether it was ``high``
    enough at the end of the hold; how far it turned relative to the hand since the jaws closed
    (``turned_in_jaws_deg``); how far it moved (``pushed``, m) and turned (``turned_deg``) before
    the jaws closed. In this order: success, turned, dropped, slipped, pushed away, missed
    (:func:`execute_pick`, step 8)."""
    if held_at_end and high:
        return SUCCESS if turned_in_jaws_deg <= TURN_MAX_DEG else TURNED
    if held_after_lift and not held_at_end:
        return DROPPED
    if held_at_close:
        return SLIPPED
    if pushed > PUSH_DIST or turned_deg > PUSH_DEG:
        return PUSHED
    return MISSED


def _judge(run: Run, T0: np.ndarray, com0: np.ndarray, held: bool, moved: tuple[float, float], held_lift: bool,
           clear_z: float | None, extract: float) -> Outcome:
    lift = float(run.com()[2] - com0[2])
    low = run.low_z()
    between = run.jaws_on_target()
    high = lift >= LIFT_MIN if clear_z is None else low >= clear_z
    turn = run.turned_in_jaws()
    outcome = judge(held_at_close=held, held_after_lift=held_lift, held_at_end=between, high=high,
                    turned_in_jaws_deg=turn, pushed=moved[0], turned_deg=moved[1])
    height = (f"lifted {lift * 1e3:.0f} mm" if clear_z is None else
              f"lifted {lift * 1e3:.0f} mm, lowest point {(low - clear_z) * 1e3:+.0f} mm from the clearance height")
    if extract > 0.0:
        height += f" (extracted {extract * 1e3:.0f} mm above the planned lift)"
    if outcome == SUCCESS:
        reason = f"{height}, held between the jaws, turned {turn:.0f} deg in them"
    elif outcome == TURNED:
        reason = f"{height}, held, but turned {turn:.0f} deg in the jaws (> {TURN_MAX_DEG:g} deg)"
    elif outcome == DROPPED:
        reason = f"held at the top, then fell out of the jaws during the {HOLD_S:g} s hold; {height}"
    elif outcome == SLIPPED:
        if not between:
            why = "fell out of the jaws"
        elif clear_z is None:
            why = f"rose only {lift * 1e3:.0f} mm"
        else:
            why = f"its lowest point stayed {(clear_z - low) * 1e3:.0f} mm below the clearance height"
        reason = f"held when the jaws closed, then {why} ({height})"
    elif outcome == PUSHED:
        reason = f"pushed {moved[0] * 1e3:.1f} mm, turned {moved[1]:.1f} deg before the jaws closed; not held"
    else:
        reason = (f"the jaws closed to {max(0.0, run.cw.opening()) * 1e3:.1f} mm without holding it "
                  f"(moved {moved[0] * 1e3:.1f} mm)")
    return _outcome(run, outcome, reason, T0, com0, held, moved)


def _finish(run: Run, picked: bool) -> None:
    """After a pick: park the picked part, open the jaws, park the gripper."""
    cw = run.cw
    if picked:
        cw.world.park(run.target)
    T = cw.hand_pose()
    cw.squeeze(-cw.grip_force)
    for _ in range(round(OPEN_S / CONTROL_DT)):
        cw.set_hand(T)
        cw.step(CONTROL_DT)
    cw.park_hand()
