"""Clutter removal rounds (the protocol of VGN, Breyer et al. 2020, with known models).

:func:`run_round` drops a pile into the bin, then :func:`clear_pile` perceives, plans and executes
picks until the bin is empty, two attempts in a row failed or nothing is feasible; the round's
record is a :class:`RoundResult`. Rates: GSR = successes / attempts, DR = parts removed / parts
dropped (per round, and in total over all rounds' counts, as VGN reports them).
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..cell.model import Cell
from ..sim.drop import DropParams, PileItem, drop_pile
from ..errors import InputError
from ..gripper.model import Gripper
from ..part.mesh import Part
from ..piles.scene_file import Instance, Scene
from ..geometry.transforms import pose_error
from ..geometry.units import parse_angle_deg, parse_length
from .execute import SUCCESS, Outcome, execute_pick
from .world import ClutterWorld

if TYPE_CHECKING:
    from ..pick.result import Pick, PickResult
    from ..sim.pileworld import PartBody, PileWorld

#: a round ends after this many failed attempts in a row (VGN: 2)
MAX_FAILURES_IN_ROW = 2
#: a part whose centre of mass is farther than this (m) outside the bin's inner box has left it
OUT_OF_BIN = 0.0
#: failure reason of a planning call that found no pick
NO_PLAN = "no_plan"
#: why a round ended
ENDS = ("empty", "two_failures", "nothing_feasible")


# ------------------------------------------------------------------------------------------------
# pose noise
# ------------------------------------------------------------------------------------------------
def parse_pose_noise(text: str) -> tuple[float, float]:
    """``--pose-noise 2mm,2deg`` -> (0.002 m, 2.0 deg); InputError naming what would pass."""
    parts = [p.strip() for p in str(text).split(",")]
    example = "e.g. --pose-noise 2mm,2deg (a position error and an angle; 0,0 for ground truth)"
    if len(parts) != 2 or not all(parts):
        raise InputError(f"--pose-noise {text!r}: expected LENGTH,ANGLE, {example}")
    try:
        m = parse_length(parts[0], name="length", allow_zero=True)
        deg = parse_angle_deg(parts[1])
    except (InputError, ValueError) as exc:
        raise InputError(f"--pose-noise {text!r}: {exc}; {example}") from None
    if not (math.isfinite(m) and 0.0 <= m <= 0.05):
        raise InputError(f"--pose-noise {text!r}: the position error must be 0..50 mm, got {m * 1e3:g} mm")
    if not (math.isfinite(deg) and 0.0 <= deg <= 45.0):
        raise InputError(f"--pose-noise {text!r}: the angle must be 0..45 deg, got {deg:g} deg")
    return float(m), float(deg)


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.standard_normal(3)
    return v / np.linalg.norm(v)


def perturb(T_world_part: np.ndarray, com: np.ndarray, noise_m: float, noise_deg: float,
            rng: np.random.Generator) -> np.ndarray:
    """``T_world_part`` moved ``noise_m`` (m) in a uniformly random direction and turned
    ``noise_deg`` about a uniformly random axis through the part's centre of mass ``com`` (3,
    part frame): a pose estimate off by exactly that much. Draws 6 normals from ``rng``."""
    from scipy.spatial.transform import Rotation

    d = _unit(rng) * noise_m
    R = Rotation.from_rotvec(_unit(rng) * math.radians(noise_deg)).as_matrix()
    T = np.array(T_world_part, dtype=np.float64)
    c = T[:3, :3] @ com + T[:3, 3]
    out = np.eye(4)
    out[:3, :3] = R @ T[:3, :3]
    out[:3, 3] = c + R @ (T[:3, 3] - c) + d
    return out


def noise_reach(parts: Sequence[Part], noise: tuple[float, float]) -> float:
    """How far (m) the pose noise moves any point of these parts: ``noise_m`` plus the chord the
    turn sweeps at the point farthest from its centre of mass (bounded here by the farthest vertex
    from the vertex centroid, doubled: a safe bound for any centre inside the part's hull). A
    planner that refuses parts below the bin floor beyond a tolerance needs that much more."""
    if noise[0] <= 0 and noise[1] <= 0:
        return 0.0
    reach = max(2.0 * float(np.linalg.norm(p.vertices - p.vertices.mean(axis=0), axis=1).max()) for p in parts)
    return float(noise[0] + 2.0 * reach * math.sin(0.5 * math.radians(noise[1])))


# ------------------------------------------------------------------------------------------------
# records
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Attempt:
    """One planning call and, when it found a pick, its execution: ``instance`` and ``part`` picked
    ('' when nothing was feasible), the planning time ``plan_ms``, ``cold`` (the run's first
    planning call: loads and caches), the ``outcome`` (:data:`grasplan.clutter.execute.OUTCOMES`
    or :data:`NO_PLAN`), the pose error of the target as planned (``pose_error_mm``, ``_deg``),
    the pick's frames and the execution's record."""

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

    @property
    def executed(self) -> bool:
        return self.execution is not None

    def to_json(self) -> dict:
        d: dict[str, Any] = {"instance": self.instance or None, "part": self.part or None, "plan_ms": self.plan_ms,
                             "cold": self.cold, "outcome": self.outcome, "reason": self.reason}
        if self.execution is not None:
            d.update(pose_error_mm=self.pose_error_mm, pose_error_deg=self.pose_error_deg, pick=self.pick,
                     execution=self.execution.to_json(), fell_out=list(self.fell_out), seconds=self.seconds)
        return d


@dataclass(frozen=True)
class RoundResult:
    """One round: its index ``r``, drop ``seed``, the pile as dropped (``scene``), the planning
    calls in order (``attempts``: executed picks and a final nothing-feasible call), how it
    ``ended`` (:data:`ENDS`), parts that left the bin, wall-clock ``seconds`` (drop included),
    ``drop_s`` of it, the process's CPU seconds ``cpu_s`` (user + system: what a round costs on a
    shared machine, whose load stretches wall time) and simulated seconds ``sim_s``; ``replay``: per executed attempt the poses
    before it and the samples (only when recorded)."""

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


# ------------------------------------------------------------------------------------------------
# the round
# ------------------------------------------------------------------------------------------------
PlanFn = Callable[[Scene], Any]


def _jaw_torsion(part: Part, gripper: Gripper, pick: Pick, mu: float) -> np.ndarray | None:
    """Each jaw's torsional friction (m, ``mu`` included) from the pick's contact patches; None
    when the pick does not carry its part-frame grasp (``T_part_tcp``, ``contacts``)."""
    from ..grasps.patches import contact_patches
    from ..grasps.wrench import torsion_length

    T = getattr(pick, "T_part_tcp", None)
    C = getattr(pick, "contacts", None)
    if T is None or C is None:
        return None
    area = contact_patches(part.mesh, gripper, np.asarray(T)[None], np.asarray(C)[None])[0][0]
    return mu * torsion_length(area)


def _in_bin(cell: Cell, com_world: np.ndarray) -> bool:
    b = cell.bin
    assert b is not None  # drop_pile refused a cell without one
    T = np.asarray(b.T_world_bin)
    p = T[:3, :3].T @ (com_world - T[:3, 3])
    return bool(abs(p[0]) <= 0.5 * b.inner[0] + OUT_OF_BIN and abs(p[1]) <= 0.5 * b.inner[1] + OUT_OF_BIN
                and p[2] >= -OUT_OF_BIN)


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


def run_round(cell: Cell, items: Sequence[PileItem], gripper: Gripper, plan_fn: PlanFn, *, r: int = 0,
              drop: DropParams = DropParams(), noise: tuple[float, float] = (0.0, 0.0), cell_ref: str | None = None,
              record: bool = False, cold: bool = False, cache: bool = True,
              progress: Callable[[str], None] | None = None) -> RoundResult:
    """Run clutter-removal round ``r``: drop a pile with seed ``drop.seed + r``, then
    :func:`clear_pile` (pose noise seeded with ``(drop.seed, r)``). ``cold`` marks the first
    planning call as the run's cold one; ``record`` keeps the replay samples.

    1. **Drop** a pile (:func:`grasplan.sim.drop.drop_pile`, seed ``seed + r`` for round ``r``: the same
       pile as ``grasplan scene drop --seed S+r``) into a world that also holds the gripper
       (:class:`grasplan.clutter.world.ClutterWorld`).
    2. **Perceive**: the poses of the parts still in the bin, exact (ground truth) or each moved by the
       pose noise (:func:`perturb`: ``noise_m`` in a random direction and turned ``noise_deg`` about a
       random axis through its centre of mass, drawn from a generator seeded with ``(seed, r)``).
    3. **Plan** with the caller's ``plan_fn(scene) -> PickResult`` (``grasplan.Picker.plan``): a
       ``grasplan.scene/1`` scene of those instances; the first pick is executed. No pick: the round
       ends (*nothing feasible*; not an attempt, as in VGN).
    4. **Execute** it (:func:`grasplan.clutter.execute.execute_pick`): success removes the part; the
       others stay where the physics left them (settled). A part whose centre of mass ends outside the
       bin's inner box (pushed or dropped over a wall) leaves the round, not counted as removed.
    5. Repeat from 2 until the bin is empty, two attempts in a row failed (:data:`MAX_FAILURES_IN_ROW`)
       or nothing is feasible.
    """
    t0, c0 = time.perf_counter(), time.process_time()
    seed = int(drop.seed) + int(r)
    holder: dict[str, ClutterWorld] = {}

    def make(bodies: list[PartBody]) -> PileWorld:
        holder["cw"] = ClutterWorld(cell, bodies, gripper, mu=drop.mu)
        return holder["cw"].world

    res = drop_pile(cell, items, params=replace(drop, seed=seed), cell_ref=cell_ref, make_world=make, cache=cache)
    rr = clear_pile(holder["cw"], res.scene, {it.name: it.part for it in items}, plan_fn, r=r, seed=seed,
                    noise=noise, noise_seed=(int(drop.seed), int(r)), record=record, cold=cold, progress=progress)
    return replace(rr, seconds=time.perf_counter() - t0, drop_s=time.perf_counter() - t0 - rr.seconds,
                   sim_s=rr.sim_s + res.sim_s, cpu_s=time.process_time() - c0)


def clear_pile(cw: ClutterWorld, scene: Scene, parts: Mapping[str, Part], plan_fn: PlanFn, *, r: int = 0,
               seed: int = 0, noise: tuple[float, float] = (0.0, 0.0), noise_seed: Sequence[int] = (0, 0),
               record: bool = False, cold: bool = False,
               progress: Callable[[str], None] | None = None) -> RoundResult:
    """Steps 2-5 of a round (:func:`run_round`) on the pile now in ``cw`` (``scene``: its instances,
    whose ids are the world's body names, and its parts; ``parts``: the meshes by part name)."""
    t0, c0 = time.perf_counter(), time.process_time()
    world = cw.world
    gripper = cw.gripper
    cell = world.cell
    part_of = {inst.id: inst.part for inst in scene.instances}
    coms = [b.mass.com for b in world.bodies]
    rng = np.random.default_rng(list(noise_seed))
    sim_s = 0.0
    attempts: list[Attempt] = []
    replay: list[dict] = []
    fell_all: list[str] = []
    fails = 0
    ended = ""
    while True:
        present = [int(i) for i in np.flatnonzero(world.present)]
        if not present:
            ended = "empty"
            break
        truth = {world.bodies[i].name: world.pose(i) for i in present}
        seen = {k: (perturb(T, coms[world.index(k)], noise[0], noise[1], rng) if noise[0] > 0 or noise[1] > 0 else T)
                for k, T in truth.items()}
        now = Scene(instances=tuple(Instance(k, part_of[k], seen[k]) for k in truth), cell=scene.cell,
                    parts=scene.parts, base=scene.base)
        t = time.perf_counter()
        result = plan_fn(now)
        plan_ms = 1e3 * (time.perf_counter() - t)
        first_cold, cold = cold, False
        picks = tuple(getattr(result, "picks", ()) or ())
        if not picks:
            attempts.append(Attempt("", "", plan_ms, first_cold, NO_PLAN, _no_pick_reason(result)))
            ended = "nothing_feasible"
            break
        pick = picks[0]
        i = world.index(pick.instance)
        t = time.perf_counter()
        before = {world.bodies[j].name: truth[world.bodies[j].name] for j in present}
        out = execute_pick(cw, i, pick, jaw_torsion=_jaw_torsion(parts[part_of[pick.instance]], gripper, pick, cw.mu),
                           record=record)
        sim_s += out.sim_s
        fell = []
        for j in np.flatnonzero(world.present):
            if not _in_bin(cell, world.pose(int(j))[:3, :3] @ coms[j] + world.pose(int(j))[:3, 3]):
                world.park(int(j))
                fell.append(world.bodies[j].name)
        fell_all += fell
        err = pose_error(truth[pick.instance], seen[pick.instance])
        attempts.append(Attempt(pick.instance, part_of[pick.instance], plan_ms, first_cold, out.outcome, out.reason,
                                pose_error_mm=1e3 * err[0], pose_error_deg=math.degrees(err[1]), pick=_pick_json(pick),
                                execution=out, fell_out=tuple(fell), seconds=time.perf_counter() - t))
        if record:
            replay.append({"before": before, "seen": seen[pick.instance], "track": out.track})
        if progress is not None:
            progress(f"round {r + 1}: attempt {len([a for a in attempts if a.executed])} {pick.instance}: "
                     f"{out.outcome} ({out.reason}); planned in {plan_ms:.0f} ms, executed in "
                     f"{time.perf_counter() - t:.1f} s")
        fails = 0 if out.success else fails + 1
        if fails >= MAX_FAILURES_IN_ROW:
            ended = "two_failures"
            break
    return RoundResult(r=int(r), seed=int(seed), scene=scene, attempts=tuple(attempts), ended=ended,
                       fell_out=tuple(fell_all), seconds=time.perf_counter() - t0, drop_s=0.0, sim_s=sim_s,
                       cpu_s=time.process_time() - c0, replay=tuple(replay))

