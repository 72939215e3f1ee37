"""Clutter removal rounds (the protocol of VGN, Breyer et al. 2020, with known models).

:func:`run_round` makes a pile by a protocol (:mod:`grasplan.clutter.protocols`: ``bin``, ``pile``,
``packed``), then :func:`clear_pile` perceives, plans and executes picks until the workspace is
empty, two attempts in a row failed or nothing is feasible; the round's record is a
:class:`RoundResult`. Rates: GSR = successes / attempts, DR = parts removed / parts in the round
(per round, and in total over all rounds' counts, as VGN reports them).
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..cell.model import Cell
from ..sim.drop import DropParams, PileItem
from ..gripper.model import Gripper
from ..part.mesh import Part
from ..piles.scene_file import Instance, Scene
from ..geometry.transforms import pose_error
from .execute import SUCCESS, Outcome, execute_pick
from .perception import apply_error, draw_errors
from .protocols import PROTOCOLS, Protocol, make_pile, park_outside, wall_distance
from .world import ClutterWorld

if TYPE_CHECKING:
    from ..pick.result import Pick, PickResult
    from ..sim.pileworld import PartBody, PileWorld

__all__ = ["Attempt", "LeftPart", "RoundResult", "clear_pile", "run_round"]

#: a round ends after this many failed attempts in a row (VGN: 2)
MAX_FAILURES_IN_ROW = 2
#: failure reason of a planning call that found no pick
NO_PLAN = "no_plan"
#: why a round ended
ENDS = ("empty", "two_failures", "nothing_feasible")
#: status of a part left at the end that the planner did not see (too occluded)
HIDDEN = "hidden"
#: a part is pushed at most this many times per round
MAX_PUSHES_PER_PART = 2


# ------------------------------------------------------------------------------------------------
# records
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Attempt:
    """One planning call and, when it found a pick, its execution: ``instance`` and ``part`` picked
    ('' when nothing was feasible), the planning time ``plan_ms``, ``cold`` (the run's first
    planning call: loads and caches), the ``outcome`` (:data:`grasplan.clutter.execute.OUTCOMES`
    or :data:`NO_PLAN`), the pose error of the target as planned (``pose_error_mm``, ``_deg``),
    the pick's frames, the execution's record and the parts the planner did not see
    (``hidden``: too occluded)."""

    instance: str
    part: str
    plan_ms: float
    cold: bool
    outcome: str
    reason: str
    pose_error_mm: float = 0.0
    pose_error_deg: float = 0.0
    pick: dict[str, Any] = field(default_factory=dict)
    execution: Outcome | None = None
    fell_out: tuple[str, ...] = ()
    seconds: float = 0.0
    hidden: tuple[str, ...] = ()
    #: "pick", or "push" (a planned push executed: ``push`` its plan's summary, ``push_execution`` its record)
    kind: str = "pick"
    push: dict[str, Any] = field(default_factory=dict)
    push_execution: Any = None

    @property
    def executed(self) -> bool:
        """An executed pick (a grasp attempt; a push is not one)."""
        return self.execution is not None

    def to_json(self) -> dict:
        d: dict[str, Any] = {"kind": self.kind, "instance": self.instance or None, "part": self.part or None,
                             "plan_ms": self.plan_ms, "cold": self.cold, "outcome": self.outcome, "reason": self.reason,
                             "hidden": list(self.hidden)}
        if self.push_execution is not None:
            d.update(push=self.push, execution=self.push_execution.to_json(), fell_out=list(self.fell_out),
                     seconds=self.seconds)
        if self.execution is not None:
            d.update(pose_error_mm=self.pose_error_mm, pose_error_deg=self.pose_error_deg, pick=self.pick,
                     execution=self.execution.to_json(), fell_out=list(self.fell_out), seconds=self.seconds)
        return d


@dataclass(frozen=True)
class LeftPart:
    """A part still in the workspace when the round ended: ``instance``, ``part``, the planner's
    last ``status`` for it (:data:`HIDDEN` when it did not see it) and ``reason``, how far it keeps
    from the bin's nearest inner wall (``wall_m``; where the wall stood without one; negative:
    beyond it) and, when occlusion was measured, its ``occlusion`` (0..1)."""

    instance: str
    part: str
    status: str
    reason: str
    wall_m: float
    occlusion: float | None = None

    def to_json(self) -> dict:
        return {"instance": self.instance, "part": self.part, "status": self.status, "reason": self.reason,
                "wall_m": self.wall_m, "occlusion": self.occlusion}


@dataclass(frozen=True)
class RoundResult:
    """One round: its index ``r``, drop ``seed``, the pile as the round starts (``scene``: the
    parts in the workspace), the planning calls in order (``attempts``: executed picks and a final
    nothing-feasible call), how it ``ended`` (:data:`ENDS`), parts that left the workspace during
    the round (``fell_out``) and before it (``outside``: not in the round), the parts ``left`` at
    the end, wall-clock ``seconds`` (pile making included), ``drop_s`` of it, the process's CPU
    seconds ``cpu_s`` (user + system: what a round costs on a shared machine, whose load stretches
    wall time), simulated seconds ``sim_s``, the ``protocol``'s name; ``replay``: per executed
    attempt the poses before it and the samples (only when recorded)."""

    r: int
    seed: int
    scene: Scene
    attempts: tuple[Attempt, ...]
    ended: str
    fell_out: tuple[str, ...]
    seconds: float
    drop_s: float
    sim_s: float
    cpu_s: float = 0.0
    replay: tuple[dict, ...] = ()
    protocol: str = "bin"
    outside: tuple[str, ...] = ()
    left: tuple[LeftPart, ...] = ()

    @property
    def parts(self) -> int:
        return len(self.scene.instances)

    @property
    def executed(self) -> list[Attempt]:
        return [a for a in self.attempts if a.executed]

    @property
    def successes(self) -> int:
        return sum(a.outcome == SUCCESS for a in self.executed)

    @property
    def removed(self) -> int:
        return self.successes

    @property
    def pushes(self) -> list[Attempt]:
        return [a for a in self.attempts if a.kind == "push"]

    @property
    def freed(self) -> list[str]:
        """Parts pushed in this round and picked (held) after their last push."""
        out = []
        for k, a in enumerate(self.attempts):
            if a.kind == "push" and not any(b.kind == "push" and b.instance == a.instance
                                            for b in self.attempts[k + 1:]):
                if any(b.executed and b.instance == a.instance and b.outcome == SUCCESS for b in self.attempts[k + 1:]):
                    out.append(a.instance)
        return out


# ------------------------------------------------------------------------------------------------
# the round
# ------------------------------------------------------------------------------------------------
#: ``plan_fn(scene) -> PickResult``; after pushes, ``plan_fn(scene, ids)`` with the ids pushed
#: :data:`MAX_PUSHES_PER_PART` times, not to be pushed again (``Picker.plan``'s ``push_skip``)
PlanFn = Callable[..., Any]


def _planned_torsion(part: Part, gripper: Gripper, pick: Pick, mu: float) -> np.ndarray | None:
    """Each jaw's torsional friction (m, ``mu`` included) from the pick's planned contact patches;
    None when the pick does not carry its part-frame grasp (``T_part_tcp``, ``contacts``)."""
    T = getattr(pick, "T_part_tcp", None)
    C = getattr(pick, "contacts", None)
    if T is None or C is None:
        return None
    return _patch_torsion(part, gripper, mu)(np.asarray(T), np.asarray(C))


def _patch_torsion(part: Part, gripper: Gripper, mu: float) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``f(T_part_tcp (4, 4), contacts (2, 3) part frame) -> (2,)``: each jaw's torsional friction
    (m, ``mu`` included) of the pad patches at that grasp (:func:`grasplan.grasps.patches.contact_patches`,
    :func:`grasplan.grasps.wrench.torsion_length`): what execution applies from the contact made."""
    from ..grasps.patches import contact_patches
    from ..grasps.wrench import torsion_length

    def f(T_part_tcp: np.ndarray, contacts: np.ndarray) -> np.ndarray:
        area = contact_patches(part.mesh, gripper, np.asarray(T_part_tcp, dtype=np.float64)[None],
                               np.asarray(contacts, dtype=np.float64)[None])[0][0]
        return mu * torsion_length(area)

    return f


def _pick_json(pick: Pick) -> dict:
    out = {"T_world_pregrasp": np.asarray(pick.T_world_pregrasp).tolist(),
           "T_world_tcp": np.asarray(pick.T_world_tcp).tolist(),
           "T_world_lifted": np.asarray(pick.T_world_lifted).tolist(),
           "opening": float(pick.opening), "width": float(pick.width)}
    if getattr(pick, "score", None) is not None:
        out["score"] = float(pick.score)
    if getattr(pick, "carries", None) is not None:
        out["lift_carries"] = list(pick.carries)
    return out


def _no_pick_reason(result: PickResult) -> str:
    reps = getattr(result, "instances", ()) or ()
    if not reps:
        return "planning found no pick"
    counts: dict[str, int] = {}
    for r in reps:
        counts[r.status] = counts.get(r.status, 0) + 1
    return "planning found no pick (" + ", ".join(f"{n} {s}" for s, n in sorted(counts.items())) + ")"


def _perceive(world: PileWorld, truth: Mapping[str, np.ndarray], errors: Mapping[str, tuple[np.ndarray, np.ndarray]],
              camera: np.ndarray | None, max_occlusion: float, seed: int, occ: np.ndarray | None
              ) -> tuple[dict[str, np.ndarray], tuple[str, ...], np.ndarray | None]:
    """What the planner sees of the parts at their ``truth`` poses: ``(poses seen, hidden ids,
    occlusion per body or the last one)``: each pose off by its error (``errors``; none: exact),
    the parts the ``camera`` sees at least ``max_occlusion`` of hidden left out."""
    hidden: tuple[str, ...] = ()
    if camera is not None:
        from .occlusion import occlusion

        occ = occlusion(world, camera, seed=seed)
        hidden = tuple(k for k in truth if occ[world.index(k)] >= max_occlusion)
    seen = {k: (apply_error(T, world.bodies[world.index(k)].mass.com, *errors[k]) if k in errors else T)
            for k, T in truth.items() if k not in hidden}
    return seen, hidden, occ


def _execute(cw: ClutterWorld, pick: Pick, part: Part, part_of: Mapping[str, str], floor_z: float | None,
             clear_z: float | None, truth: Mapping[str, np.ndarray], seen: Mapping[str, np.ndarray], plan_ms: float,
             cold: bool, hidden: tuple[str, ...], record: bool, replay: list[dict]) -> Attempt:
    """Execute a planned pick (:func:`grasplan.clutter.execute.execute_pick`, the pads' torsion
    from the contact made) and park the parts it left outside the workspace: its :class:`Attempt`."""
    world = cw.world
    t = time.perf_counter()
    out = execute_pick(cw, world.index(pick.instance), pick,
                       jaw_torsion=_planned_torsion(part, cw.gripper, pick, cw.mu),
                       patch_torsion=_patch_torsion(part, cw.gripper, cw.mu), clear_z=clear_z, record=record)
    fell = park_outside(world, floor_z)
    err = pose_error(truth[pick.instance], seen[pick.instance])
    if record:
        replay.append({"before": dict(truth), "seen": seen[pick.instance], "track": out.track})
    return Attempt(pick.instance, part_of[pick.instance], plan_ms, cold, out.outcome, out.reason,
                   pose_error_mm=1e3 * err[0], pose_error_deg=math.degrees(err[1]), pick=_pick_json(pick),
                   execution=out, fell_out=tuple(fell), seconds=time.perf_counter() - t, hidden=hidden)


def _push(cw: ClutterWorld, push: Any, part_of: Mapping[str, str], floor_z: float | None, plan_ms: float,
          cold: bool, hidden: tuple[str, ...], record: bool, replay: list[dict],
          truth: Mapping[str, np.ndarray]) -> Attempt:
    """Execute a planned push (:func:`grasplan.clutter.pushing.execute_push`) and park the parts it
    left outside the workspace: its :class:`Attempt` (``kind`` "push")."""
    from .pushing import execute_push

    world = cw.world
    t = time.perf_counter()
    out = execute_push(cw, world.index(push.instance), push, record=record)
    fell = park_outside(world, floor_z)
    if record:
        replay.append({"before": dict(truth), "seen": truth[push.instance], "track": out.track})
    summary = {"against": push.against, "gap_m": float(push.gap), "direction": [float(x) for x in push.direction],
               "distance_m": float(push.distance), "opening": float(push.opening),
               "T_world_above": np.asarray(push.T_world_above).tolist(),
               "T_world_start": np.asarray(push.T_world_start).tolist(),
               "T_world_end": np.asarray(push.T_world_end).tolist()}
    return Attempt(push.instance, part_of[push.instance], plan_ms, cold, out.outcome, out.reason, kind="push",
                   push=summary, push_execution=out, fell_out=tuple(fell), seconds=time.perf_counter() - t,
                   hidden=hidden)


def run_round(cell: Cell, items: Sequence[PileItem], gripper: Gripper, plan_fn: PlanFn, *, r: int = 0,
              drop: DropParams = DropParams(), noise: tuple[float, float] = (0.0, 0.0), cell_ref: str | None = None,
              record: bool = False, cold: bool = False, cache: bool = True, protocol: Protocol = PROTOCOLS["bin"],
              max_occlusion: float = 1.0, progress: Callable[[str], None] | None = None) -> RoundResult:
    """Run clutter-removal round ``r``: make a pile with seed ``drop.seed + r`` by ``protocol``,
    then :func:`clear_pile` (pose errors seeded with ``(drop.seed, r)``). ``cold`` marks the first
    planning call as the run's cold one; ``record`` keeps the replay samples.

    1. **Make the pile** (:func:`grasplan.clutter.protocols.make_pile`, seed ``seed + r`` for round
       ``r``; ``bin``: the same pile as ``grasplan scene drop --seed S+r``) in a world that also holds
       the gripper (:class:`grasplan.clutter.world.ClutterWorld`). Parts outside the workspace then
       are not in the round.
    2. **Perceive** (:mod:`grasplan.clutter.perception`): the poses of the parts still in the
       workspace, exact (ground truth) or each off by its pose error (drawn once per part and round:
       ``noise_m`` in a random direction and ``noise_deg`` about a random axis through its centre of
       mass, from a generator seeded with ``(seed, r)``); with ``max_occlusion`` < 1, the parts an
       overhead camera sees less than ``1 - max_occlusion`` of are left out.
    3. **Plan** with the caller's ``plan_fn(scene) -> PickResult`` (``grasplan.Picker.plan``, whose
       cell is ``protocol.planner_cell(cell)``): a ``grasplan.scene/1`` scene of those instances; the
       first pick is executed. No pick: the round ends (*nothing feasible*; not an attempt, as in VGN).
    4. **Execute** it (:func:`grasplan.clutter.execute.execute_pick`; success: the part's lowest
       point at ``protocol.clear_z(cell)`` and still held after the hold): success removes the part;
       the others stay where the physics left them (settled). A part whose centre of mass ends
       outside the workspace leaves the round, not counted as removed.
    5. Repeat from 2 until the workspace is empty, two attempts in a row failed
       (:data:`MAX_FAILURES_IN_ROW`) or nothing is feasible.
    """
    t0, c0 = time.perf_counter(), time.process_time()
    seed = int(drop.seed) + int(r)
    holder: dict[str, ClutterWorld] = {}

    def make(bodies: list[PartBody]) -> PileWorld:
        holder["cw"] = ClutterWorld(cell, bodies, gripper, mu=drop.mu)
        return holder["cw"].world

    made = make_pile(protocol, cell, items, params=replace(drop, seed=seed), make_world=make, cell_ref=cell_ref,
                     cache=cache)
    rr = clear_pile(holder["cw"], made.scene, {it.name: it.part for it in items}, plan_fn, r=r, seed=seed,
                    noise=noise, noise_seed=(int(drop.seed), int(r)), record=record, cold=cold, progress=progress,
                    clear_z=protocol.clear_z(cell), max_occlusion=max_occlusion, floor_z=protocol.floor_z(cell))
    return replace(rr, seconds=time.perf_counter() - t0, drop_s=time.perf_counter() - t0 - rr.seconds,
                   sim_s=rr.sim_s + made.sim_s, cpu_s=time.process_time() - c0, protocol=protocol.name,
                   outside=made.outside)


def clear_pile(cw: ClutterWorld, scene: Scene, parts: Mapping[str, Part], plan_fn: PlanFn, *, r: int = 0,
               seed: int = 0, noise: tuple[float, float] = (0.0, 0.0), noise_seed: Sequence[int] = (0, 0),
               record: bool = False, cold: bool = False, clear_z: float | None = None, max_occlusion: float = 1.0,
               floor_z: float | None = None, progress: Callable[[str], None] | None = None) -> RoundResult:
    """Steps 2-5 of a round (:func:`run_round`) on the pile now in ``cw`` (``scene``: its instances,
    whose ids are the world's body names, and its parts; ``parts``: the meshes by part name).
    ``clear_z``: the height a picked part's lowest point must reach (None: the execution's
    centre-of-mass rule); ``max_occlusion``: parts hidden at least this much are not planned;
    ``floor_z``: the height of what the parts lie on (default the bin floor's top): a part whose
    centre of mass is below it, or not over the bin's inner floor area, has left the workspace."""
    t0, c0 = time.perf_counter(), time.process_time()
    world = cw.world
    b = world.cell.bin
    assert b is not None  # every protocol's world is made in a cell with a bin
    part_of = {inst.id: inst.part for inst in scene.instances}
    noisy = noise[0] > 0 or noise[1] > 0
    errors = draw_errors([inst.id for inst in scene.instances], noise, np.random.default_rng(list(noise_seed))) \
        if noisy else {}
    camera = None
    if max_occlusion < 1.0:
        from .occlusion import camera_point

        camera = camera_point(world.cell)
    sim_s = 0.0
    attempts: list[Attempt] = []
    replay: list[dict] = []
    fell_all: list[str] = []
    fails = 0
    ended = ""
    last: dict[str, tuple[str, str]] = {}
    occ: np.ndarray | None = None
    pushed: dict[str, int] = {}
    while True:
        present = [int(i) for i in np.flatnonzero(world.present)]
        if not present:
            ended = "empty"
            break
        truth = {world.bodies[i].name: world.pose(i) for i in present}
        seen, hidden, occ = _perceive(world, truth, errors, camera, max_occlusion, seed, occ)
        if not seen:
            attempts.append(Attempt("", "", 0.0, False, NO_PLAN, "the camera sees too little of every part left",
                                    hidden=hidden))
            last = {k: (HIDDEN, "the camera sees too little of it") for k in hidden}
            ended = "nothing_feasible"
            break
        now = Scene(instances=tuple(Instance(k, part_of[k], T) for k, T in seen.items()), cell=scene.cell,
                    parts=scene.parts, base=scene.base)
        t = time.perf_counter()
        exhausted = tuple(k for k, n in pushed.items() if n >= MAX_PUSHES_PER_PART)
        result = plan_fn(now, exhausted) if exhausted else plan_fn(now)
        plan_ms = 1e3 * (time.perf_counter() - t)
        first_cold, cold = cold, False
        last = {rep.id: (str(rep.status), str(rep.reason)) for rep in (getattr(result, "instances", ()) or ())}
        last.update({k: (HIDDEN, f"the camera sees less than {100 * (1 - max_occlusion):.0f} % of it")
                     for k in hidden})
        picks = tuple(getattr(result, "picks", ()) or ())
        planned_push = getattr(result, "push", None)
        if not picks and planned_push is not None and pushed.get(planned_push.instance, 0) < MAX_PUSHES_PER_PART:
            pushed[planned_push.instance] = pushed.get(planned_push.instance, 0) + 1
            attempts.append(_push(cw, planned_push, part_of, floor_z, plan_ms, first_cold, hidden, record,
                                  replay, truth))
            sim_s += attempts[-1].push_execution.sim_s
            fell_all += attempts[-1].fell_out
            if progress is not None:
                a = attempts[-1]
                progress(f"round {r + 1}: push {a.instance} {a.push['distance_m'] * 1e3:.0f} mm from {a.push['against']}: "
                         f"{a.outcome} ({a.reason})")
            continue
        if not picks:
            why = _no_pick_reason(result)
            if planned_push is not None:
                why += f"; {planned_push.instance} pushed {MAX_PUSHES_PER_PART} times already"
            attempts.append(Attempt("", "", plan_ms, first_cold, NO_PLAN, why, hidden=hidden))
            ended = "nothing_feasible"
            break
        t = time.perf_counter()
        a = _execute(cw, picks[0], parts[part_of[picks[0].instance]], part_of, floor_z, clear_z, truth, seen,
                     plan_ms, first_cold, hidden, record, replay)
        attempts.append(a)
        assert a.execution is not None  # an executed pick
        sim_s += a.execution.sim_s
        fell_all += a.fell_out
        if progress is not None:
            progress(f"round {r + 1}: attempt {len([x for x in attempts if x.executed])} {a.instance}: "
                     f"{a.outcome} ({a.reason}); planned in {plan_ms:.0f} ms, executed in "
                     f"{time.perf_counter() - t:.1f} s")
        fails = 0 if a.outcome == SUCCESS else fails + 1
        if fails >= MAX_FAILURES_IN_ROW:
            ended = "two_failures"
            break
    left = tuple(LeftPart(world.bodies[j].name, part_of[world.bodies[j].name],
                          *last.get(world.bodies[j].name, ("", "")), wall_m=wall_distance(b, world.hull_world(int(j))),
                          occlusion=None if occ is None else float(occ[j]))
                 for j in np.flatnonzero(world.present))
    return RoundResult(r=int(r), seed=int(seed), scene=scene, attempts=tuple(attempts), ended=ended,
                       fell_out=tuple(fell_all), seconds=time.perf_counter() - t0, drop_s=0.0, sim_s=sim_s,
                       cpu_s=time.process_time() - c0, replay=tuple(replay), left=left)
