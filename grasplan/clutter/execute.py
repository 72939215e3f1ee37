"""Execute one planned pick in the clutter world (:class:`grasplan.clutter.world.ClutterWorld`).

:func:`execute_pick` runs the protocol (pre-grasp, straight approach, close, straight lift and
hold, then the pile settles) and judges the :class:`Outcome`: one of :data:`OUTCOMES`. Its
numbers are the constants below (:data:`PROTOCOL`, as a report records them). Deterministic:
MuJoCo single-threaded; the same pile and pick give the same bits.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from ..sim.drop import REST_ANG, REST_HOLD_S, REST_LIN
from ..geometry.transforms import check_transform
from .world import CONTROL_DT, PICK_TIMESTEP, ClutterWorld

#: peak TCP speed on the approach and on the lift (m/s); shortest move (s)
APPROACH_SPEED, LIFT_SPEED, MIN_MOVE_S = 0.1, 0.2, 0.2
#: jaws closing (s), the hold at the top (s), the jaws opening afterwards (s)
CLOSE_S, HOLD_S, OPEN_S = 0.3, 1.0, 0.2
#: success: the target's centre of mass at least this far (m) above its start
LIFT_MIN = 0.05
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
            "lift_min": LIFT_MIN, "start_depth": START_DEPTH, "collide_force": COLLIDE_FORCE, "path_dev": PATH_DEV,
            "push_dist": PUSH_DIST,
            "push_deg": PUSH_DEG, "timestep": PICK_TIMESTEP, "control_dt": CONTROL_DT}

SUCCESS, COLLIDED, SLIPPED, PUSHED, MISSED = "success", "collided", "slipped", "pushed_away", "missed"
#: every outcome of an executed pick, in the order they are decided
OUTCOMES = (SUCCESS, COLLIDED, SLIPPED, PUSHED, MISSED)


class PickLike(Protocol):
    """What execution needs of a planned pick (:class:`grasplan.pick.Pick` has it)."""

    T_world_pregrasp: np.ndarray
    T_world_tcp: np.ndarray
    T_world_lifted: np.ndarray
    opening: float
    width: float


@dataclass(frozen=True)
class Outcome:
    """How an executed pick went: ``outcome`` (one of :data:`OUTCOMES`), ``reason`` (a sentence),
    the target's rise ``lift`` (m, centre of mass, end of the hold), how far it moved ``pushed``
    (m) and turned ``turned_deg`` before the jaws closed, whether both jaws ``held_at_close``, the
    jaws' ``opening`` at the end (m), the largest force on a fixed obstacle ``fixed_force`` (N),
    the simulated seconds ``sim_s`` and, when recorded, the replay samples ``track`` every
    :data:`TRACK_DT`: (t, hand pose (4, 4), jaw opening, poses (k, 4, 4) of the parts
    ``track_parts`` present when the pick started)."""

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

    @property
    def success(self) -> bool:
        return self.outcome == SUCCESS

    def to_json(self) -> dict:
        return {"outcome": self.outcome, "reason": self.reason, "lift_m": self.lift, "pushed_m": self.pushed,
                "turned_deg": self.turned_deg, "held_at_close": self.held_at_close, "opening_m": self.opening,
                "fixed_force_n": self.fixed_force, "sim_s": self.sim_s}


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


def _angle_deg(R: np.ndarray) -> float:
    return math.degrees(math.acos(float(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


class _Run:
    """State of one execution: the world, the target, the samples, the worst fixed contact."""

    def __init__(self, cw: ClutterWorld, target: int, record: bool):
        self.cw, self.target, self.record = cw, target, record
        self.t = 0.0
        self.track: list = []
        self.fixed_force = 0.0
        self.fixed_what = ""
        self.off_path = 0.0  #: how far (m) contacts pushed the hand off its planned path, when beyond PATH_DEV
        self.next_sample = 0.0
        self.ids = [int(i) for i in np.flatnonzero(cw.world.present)] if record else []

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


def execute_pick(cw: ClutterWorld, target: int, pick: PickLike, *, jaw_torsion: ArrayLike | None = None,
                 record: bool = False, settle: bool = True) -> Outcome:
    """Execute ``pick`` on part body ``target`` of the clutter world and leave the world ready for
    the next one (the target parked when picked, the gripper parked, the pile settled unless
    ``settle`` is False). ``jaw_torsion`` (2,): each pad's torsional friction per newton (m, ``mu``
    included) for this pick, its hinge's friction following the pad's contact forces on the target
    (:meth:`ClutterWorld.set_jaw_torsion`); ``record``: keep replay samples (``Outcome.track``).

    The protocol, all in the world frame with the bin and every part present:

    1. **Pre-grasp.** The hand appears at the pick's ``T_world_pregrasp`` with the jaws at its
       ``opening`` (for a linkage gripper whose TCP moves with the opening, every pose of the pick
       is moved by ``T_tcp_gripper(width)``: the hand frame is the TCP at full opening); the transit
       from above is not simulated (the arm is not modelled). A gripper that already overlaps
       something there by more than :data:`START_DEPTH` has *collided*.
    2. **Approach.** The TCP follows the straight line to ``T_world_tcp`` (cosine speed profile,
       peak :data:`APPROACH_SPEED`), the jaws idle (their damping holds them).
    3. **Close.** The jaws close under the full grip force for :data:`CLOSE_S`.
    4. **Lift.** The TCP follows the straight line to ``T_world_lifted`` (the retreat, peak
       :data:`LIFT_SPEED`), then **holds** still for :data:`HOLD_S`.
    5. **Outcome.** *Success*: the target's centre of mass is at least :data:`LIFT_MIN` above where
       it started and both jaws touch it. Otherwise, in this order: *collided* (the gripper pressed
       on the bin, the table or another fixed obstacle with more than :data:`COLLIDE_FORCE`, or
       contacts pushed the hand more than :data:`PATH_DEV` off its planned path within a control
       period: a cobot's protective stop; the run stops there), *slipped* (both jaws held the
       target when they closed; it was lost in the lift or the hold), *pushed away* (the target
       moved more than :data:`PUSH_DIST` or turned more than :data:`PUSH_DEG` before the jaws
       closed on it) and *missed* (the jaws closed beside it).
    6. **Afterwards.** A picked part leaves the world (:meth:`PileWorld.park`); the jaws open for
       :data:`OPEN_S` where they are (a part still between them drops), the gripper leaves, and the
       pile settles (:meth:`PileWorld.settle`, the drop's rest thresholds, at most :data:`SETTLE_MAX_S`).
    """
    import mujoco

    w = cw.world
    if not w.present[target]:
        raise ValueError(f"execute_pick: part {w.bodies[target].name} is not in the world")
    # the hand is the frame the gripper's shapes are given in: for a linkage gripper (its TCP moves
    # with the opening) the pick's grasp TCP moved back to full opening, as the planner checks it
    T_g = np.asarray(cw.gripper.T_tcp_gripper(float(pick.width)), dtype=np.float64)
    T_pre = check_transform(pick.T_world_pregrasp, "T_world_pregrasp") @ T_g
    T_grasp = check_transform(pick.T_world_tcp, "T_world_tcp") @ T_g
    T_lift = check_transform(pick.T_world_lifted, "T_world_lifted") @ T_g
    timestep = float(cw.model.opt.timestep)
    cw.model.opt.timestep = PICK_TIMESTEP
    cw.set_jaw_torsion(jaw_torsion, target)
    run = _Run(cw, target, record)
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
            moved = (float(np.linalg.norm(run.com() - com0)), _angle_deg(T0[:3, :3].T @ w.pose(target)[:3, :3]))
            if not ok:
                out = _collided(run, "closing", T0, com0, held, moved)
            elif not (run.move(T_grasp, T_lift, LIFT_SPEED) and run.stay(T_lift, HOLD_S)):
                out = _collided(run, "lift", T0, com0, held, moved)
            else:
                out = _judge(run, T0, com0, held, moved)
        _finish(run, out.success)
    finally:
        cw.model.opt.timestep = timestep
    if settle and w.present.any():  # at the pile world's own timestep, as the drop settles
        w.settle(lin=REST_LIN, ang=REST_ANG, hold=REST_HOLD_S, max_s=SETTLE_MAX_S)
    return out


def _outcome(run: _Run, outcome: str, reason: str, T0: np.ndarray, com0: np.ndarray, held: bool,
             moved: tuple[float, float] | None = None) -> Outcome:
    if moved is None:
        moved = (float(np.linalg.norm(run.com() - com0)),
                 _angle_deg(T0[:3, :3].T @ run.cw.world.pose(run.target)[:3, :3]))
    return Outcome(outcome=outcome, reason=reason, lift=float(run.com()[2] - com0[2]), pushed=moved[0],
                   turned_deg=moved[1], held_at_close=held, opening=max(0.0, run.cw.opening()), fixed_force=run.fixed_force,
                   sim_s=run.t, track=tuple(run.track),
                   track_parts=tuple(run.cw.world.bodies[i].name for i in run.ids))


def _collided(run: _Run, phase: str, T0: np.ndarray, com0: np.ndarray, held: bool = False,
              moved: tuple[float, float] | None = None) -> Outcome:
    if run.off_path > 0:
        what = f" ({run.fixed_what}, {run.fixed_force:.0f} N)" if run.fixed_what else ""
        return _outcome(run, COLLIDED, f"{phase}: the gripper was pushed {run.off_path * 1e3:.1f} mm off its path"
                        f"{what} (> {PATH_DEV * 1e3:g} mm: it ran into something fixed; a protective stop)",
                        T0, com0, held, moved)
    return _outcome(run, COLLIDED, f"{phase}: {run.fixed_what} pressed with {run.fixed_force:.0f} N "
                    f"(> {COLLIDE_FORCE:g} N, a protective stop)", T0, com0, held, moved)


def _judge(run: _Run, T0: np.ndarray, com0: np.ndarray, held: bool, moved: tuple[float, float]) -> Outcome:
    lift = float(run.com()[2] - com0[2])
    between = run.jaws_on_target()
    if lift >= LIFT_MIN and between:
        return _outcome(run, SUCCESS, f"lifted {lift * 1e3:.0f} mm, held between the jaws", T0, com0, held, moved)
    if held:
        why = "fell out of the jaws" if not between else f"rose only {lift * 1e3:.0f} mm"
        return _outcome(run, SLIPPED, f"held when the jaws closed, then {why} (lift {lift * 1e3:.0f} mm)",
                        T0, com0, held, moved)
    if moved[0] > PUSH_DIST or moved[1] > PUSH_DEG:
        return _outcome(run, PUSHED, f"pushed {moved[0] * 1e3:.1f} mm, turned {moved[1]:.1f} deg before the jaws "
                        f"closed; not held", T0, com0, held, moved)
    return _outcome(run, MISSED, f"the jaws closed to {max(0.0, run.cw.opening()) * 1e3:.1f} mm without holding it "
                    f"(moved {moved[0] * 1e3:.1f} mm)", T0, com0, held, moved)


def _finish(run: _Run, picked: bool) -> None:
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
