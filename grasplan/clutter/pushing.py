"""Execute one planned push in the clutter world (:class:`grasplan.clutter.world.ClutterWorld`).

:func:`execute_push` runs a push planned by :func:`grasplan.pick.push.plan_push` (a
:class:`grasplan.pick.push.Push`, or anything with its poses, :class:`PushLike`): the gripper with
its jaws held at the push's ``opening`` descends along its TCP z to the push's start, moves
horizontally along the push, retreats along its TCP z; then the pile settles. The
:class:`PushOutcome` is one of :data:`PUSH_OUTCOMES`: *moved* (the part's centre of mass moved at
least :data:`PUSH_MIN_MOVE` horizontally), *collided* (the gripper hit something fixed: the rules
of :func:`grasplan.clutter.execute.execute_pick`) or *no effect*. The hand is driven as a pick
drives it (:class:`grasplan.clutter.execute.Run`: cosine speed profiles, the collision checks
every control period). Deterministic: the same pile and push give the same bits.

"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from ..geometry.transforms import check_transform
from ..grasps.wrench import CONTACTS_PER_GRIP
from ..sim.drop import REST_ANG, REST_HOLD_S, REST_LIN
from ..sim.simulate import CLOSE_SPEED
from .execute import (
    APPROACH_SPEED, COLLIDE_FORCE, LIFT_SPEED, PATH_DEV, SETTLE_MAX_S, START_DEPTH, Run, angle_deg, collision_reason
)
from .world import CONTROL_DT, PICK_TIMESTEP, ClutterWorld

#: peak TCP speed (m/s) along the push (cosine profile, as the moves of a pick)
PUSH_SPEED = 0.05
#: a push *moved* its part when the part's centre of mass ended at least this far (m, horizontally)
#: from where it started; another part that moved more than this (m) is in ``others_moved``
PUSH_MIN_MOVE = 0.005
MOVED, COLLIDED, NO_EFFECT = "moved", "collided", "no_effect"
#: every outcome of an executed push, in the order they are decided
PUSH_OUTCOMES = (MOVED, COLLIDED, NO_EFFECT)
#: each pad hinge's twist capacity per newton of grip force (m) while pushing: far above any load a
#: push puts on a finger, so the fingers stay square on the jaws (the hinges model a grip's twist)
PUSH_PAD_TORSION = 1.0
#: the jaws' hold: the share of the opening's error their drive corrects per control period
JAW_HOLD_GAIN = 0.5
#: a target opening at most this (m) is the jaws' closed stop: the drive presses them shut
CLOSED_TOL = 1e-6

#: the push protocol's numbers, as a report records them (with the pick's :data:`PROTOCOL`)
PUSH_PROTOCOL = {"push_speed": PUSH_SPEED, "approach_speed": APPROACH_SPEED, "lift_speed": LIFT_SPEED,
                 "push_min_move": PUSH_MIN_MOVE, "start_depth": START_DEPTH, "collide_force": COLLIDE_FORCE,
                 "path_dev": PATH_DEV, "settle_max_s": SETTLE_MAX_S, "timestep": PICK_TIMESTEP,
                 "control_dt": CONTROL_DT}


class PushLike(Protocol):
    """What execution needs of a planned push (:class:`grasplan.pick.push.Push` has it): the
    horizontal ``direction`` (3,) of the push, the jaws' ``opening`` (m) and the TCP poses (4, 4,
    world) of the descent's start, the push's start and end and the retreat's end."""

    @property
    def direction(self) -> np.ndarray: ...

    @property
    def opening(self) -> float: ...

    @property
    def T_world_above(self) -> np.ndarray: ...

    @property
    def T_world_start(self) -> np.ndarray: ...

    @property
    def T_world_end(self) -> np.ndarray: ...

    @property
    def T_world_retreat(self) -> np.ndarray: ...


@dataclass(frozen=True)
class PushOutcome:
    """How an executed push went: ``outcome`` (one of :data:`PUSH_OUTCOMES`), ``reason`` (a
    sentence), the target's horizontal centre-of-mass displacement ``moved_m`` (m) and its
    component along the push's direction ``along_m`` (m), how far it turned ``turned_deg``, the
    body names of the other parts whose centre of mass moved more than :data:`PUSH_MIN_MOVE`
    (``others_moved``), all measured at the end (after the pile settled, when it did); the largest
    force of the gripper on a fixed obstacle ``fixed_force`` (N), the simulated seconds of the push
    ``sim_s`` (descent, push, retreat; not the settling) and, when recorded, the replay samples
    ``track`` (as :attr:`grasplan.clutter.execute.Outcome.track`) of the parts ``track_parts``."""

    outcome: str
    reason: str
    moved_m: float
    along_m: float
    turned_deg: float
    others_moved: tuple[str, ...]
    fixed_force: float
    sim_s: float
    track: tuple[tuple[float, np.ndarray, float, np.ndarray], ...] = field(default=(), repr=False)
    track_parts: tuple[str, ...] = ()

    @property
    def moved(self) -> bool:
        return self.outcome == MOVED

    def to_json(self) -> dict:
        """The outcome as JSON (no replay samples)."""
        return {"outcome": self.outcome, "reason": self.reason, "moved_m": self.moved_m, "along_m": self.along_m,
                "turned_deg": self.turned_deg, "others_moved": list(self.others_moved),
                "fixed_force_n": self.fixed_force, "sim_s": self.sim_s}


class _PushRun(Run):
    """A :class:`grasplan.clutter.execute.Run` whose jaws are held at ``opening`` every control period."""

    def __init__(self, cw: ClutterWorld, target: int, record: bool, opening: float):
        super().__init__(cw, target, record)
        self.opening = opening
        # the jaws' drive: damped to close at CLOSE_SPEED under the full grip force (ClutterWorld),
        # so a force of gain x error per control period closes that share of the error
        damping = self.cw.grip_force / CONTACTS_PER_GRIP / CLOSE_SPEED  # per jaw, N s/m
        self.gain = JAW_HOLD_GAIN * damping / CONTROL_DT * CONTACTS_PER_GRIP / 2.0  # N (both jaws) per m of opening

    def hold_jaws(self) -> None:
        """Command the jaws' drive for the next control period: closed against their stop with the
        grip force (an opening of 0), else a force against the opening's error (at most the grip
        force either way), so that they neither close nor open under the push's loads."""
        if self.opening <= CLOSED_TOL:
            self.cw.squeeze(self.cw.grip_force)
        else:
            self.cw.squeeze(self.gain * (self.cw.opening() - self.opening))

    def period(self, expect: np.ndarray | None = None) -> bool:
        self.hold_jaws()
        return super().period(expect)


def _horizontal(v: np.ndarray) -> np.ndarray:
    h = np.array([float(v[0]), float(v[1]), 0.0])
    n = float(np.linalg.norm(h))
    if not math.isfinite(n) or n < 1e-9:
        raise ValueError(f"execute_push: the push's direction must be horizontal and non-zero, got {v!r}")
    return h / n


def execute_push(cw: ClutterWorld, target: int, push: PushLike, *, record: bool = False,
                 settle: bool = True) -> PushOutcome:
    """Execute ``push`` on part body ``target`` of the clutter world (the push's part:
    ``cw.world.index(push.instance)``) and leave the world ready for the next pick or push (the
    gripper parked, the pile settled unless ``settle`` is False). ``record``: keep replay samples
    (``PushOutcome.track``).

    The protocol, all in the world frame with the bin and every part present, stepped at
    :data:`grasplan.clutter.world.PICK_TIMESTEP` (the world's own timestep is restored afterwards):

    1. **Above.** The hand appears at ``T_world_above`` with the jaws at ``opening`` (the push's
       poses are the hand's as they are: the planner placed the fingers with
       ``gripper.fingers(opening)`` in the frame the gripper's shapes are given in, so unlike a
       pick's grasp TCP they are not moved by ``T_tcp_gripper(opening)``, which for a linkage
       gripper would lift the fingertips off the height the planner chose). From then on the jaws are held
       at ``opening`` every control period: closed against their stop with the grip force when
       ``opening`` is 0 (the planner's pushes: the gripper's ``min_opening``), else driven against
       any change of their opening (at most the grip force, :data:`JAW_HOLD_GAIN`); the pads'
       hinges are held rigid (:data:`PUSH_PAD_TORSION`; the nominal torsion is set back
       afterwards). A gripper that already overlaps something there (a part too) by more than
       :data:`grasplan.clutter.execute.START_DEPTH` has *collided*.
    2. **Descent.** Straight to ``T_world_start`` (cosine speed profile, peak
       :data:`grasplan.clutter.execute.APPROACH_SPEED`).
    3. **Push.** Straight to ``T_world_end`` (peak :data:`PUSH_SPEED`).
    4. **Retreat.** Straight to ``T_world_retreat`` (peak :data:`grasplan.clutter.execute.LIFT_SPEED`).
    5. **Afterwards.** The gripper is parked (:meth:`ClutterWorld.park_hand`) and the pile settles
       (:meth:`PileWorld.settle`, the drop's rest thresholds, at most
       :data:`grasplan.clutter.execute.SETTLE_MAX_S`) when ``settle``.
    6. **Outcome**, in this order: *collided* when the gripper pressed on the bin, the table or
       another fixed obstacle with more than :data:`grasplan.clutter.execute.COLLIDE_FORCE`, or
       contacts pushed the hand more than :data:`grasplan.clutter.execute.PATH_DEV` off its path
       within a control period (the run stops there; the reason names the phase: descent, push or
       retreat), or it overlapped something at the first pose; else *moved* when the target's
       centre of mass ended at least :data:`PUSH_MIN_MOVE` (horizontally) from its start; else
       *no effect*.

    ``push.direction`` is taken horizontally (its x, y); ValueError: ``target`` not in the world,
    an opening outside the gripper's stroke, a direction without a horizontal part, a pose that is
    not a rigid transform."""
    import mujoco

    w = cw.world
    if not 0 <= target < len(w.bodies) or not w.present[target]:
        raise ValueError(f"execute_push: part body {target} is not in the world")
    opening = float(push.opening)
    if not (math.isfinite(opening) and 0.0 <= opening <= cw.gripper.max_opening + 1e-9):
        raise ValueError(f"execute_push: opening {push.opening!r} is outside the gripper's stroke "
                         f"(0 .. {cw.gripper.max_opening:g} m)")
    d = _horizontal(np.asarray(push.direction, dtype=np.float64))
    # the push's poses are already the hand's (the frame of the gripper's shapes; module docstring)
    T_above = check_transform(push.T_world_above, "T_world_above", error=ValueError)
    T_start = check_transform(push.T_world_start, "T_world_start", error=ValueError)
    T_end = check_transform(push.T_world_end, "T_world_end", error=ValueError)
    T_retreat = check_transform(push.T_world_retreat, "T_world_retreat", error=ValueError)
    ids = [int(i) for i in np.flatnonzero(w.present)]
    com0 = {i: np.array(cw.data.xipos[w.body_ids[i]]) for i in ids}
    T0 = w.pose(target)
    timestep = float(cw.model.opt.timestep)
    cw.model.opt.timestep = PICK_TIMESTEP
    cw.set_jaw_torsion(np.full(2, PUSH_PAD_TORSION))
    run = _PushRun(cw, target, record, opening)
    collided = ""
    try:
        cw.set_hand(T_above)
        cw.set_jaws(opening)
        mujoco.mj_forward(cw.model, cw.data)
        run.sample()
        deep = [c for c in cw.contacts() if c.depth > START_DEPTH]
        if deep:
            c = max(deep, key=lambda c: c.depth)
            collided = f"at the push's first pose (above the part) the {c.gripper} overlaps {c.other} by " \
                       f"{c.depth * 1e3:.1f} mm"
        else:
            for phase, T_a, T_b, speed in (("descent", T_above, T_start, APPROACH_SPEED),
                                           ("push", T_start, T_end, PUSH_SPEED),
                                           ("retreat", T_end, T_retreat, LIFT_SPEED)):
                if not run.move(T_a, T_b, speed):
                    collided = collision_reason(run, phase)
                    break
        cw.park_hand()
    finally:
        cw.model.opt.timestep = timestep
        cw.set_jaw_torsion(None)
    if settle and w.present.any():  # at the pile world's own timestep, as the drop settles
        w.settle(lin=REST_LIN, ang=REST_ANG, hold=REST_HOLD_S, max_s=SETTLE_MAX_S)
    return _judge(run, d, T0, com0, collided)


def _judge(run: _PushRun, d: np.ndarray, T0: np.ndarray, com0: dict[int, np.ndarray], collided: str) -> PushOutcome:
    """Step 6 of :func:`execute_push`: measure the pile now and decide the outcome."""
    cw, w, target = run.cw, run.cw.world, run.target
    shift = np.array(cw.data.xipos[w.body_ids[target]]) - com0[target]
    moved = float(math.hypot(shift[0], shift[1]))
    along = float(shift @ d)
    turned = angle_deg(T0[:3, :3].T @ w.pose(target)[:3, :3])
    others = tuple(w.bodies[i].name for i in com0 if i != target and w.present[i]
                   and float(np.linalg.norm(np.array(cw.data.xipos[w.body_ids[i]]) - com0[i])) > PUSH_MIN_MOVE)
    effect = f"the part moved {moved * 1e3:.1f} mm ({along * 1e3:+.1f} mm along the push), turned {turned:.0f} deg"
    if others:
        effect += f"; also moved: {', '.join(others)}"
    if collided:
        outcome, reason = COLLIDED, f"{collided}; {effect}"
    elif moved >= PUSH_MIN_MOVE:
        outcome, reason = MOVED, effect
    else:
        outcome, reason = NO_EFFECT, f"{effect} (< {PUSH_MIN_MOVE * 1e3:g} mm: no effect)"
    return PushOutcome(outcome=outcome, reason=reason, moved_m=moved, along_m=along, turned_deg=turned,
                       others_moved=others, fixed_force=run.fixed_force, sim_s=run.t, track=tuple(run.track),
                       track_parts=tuple(w.bodies[i].name for i in run.ids))
