"""Piles made in physics: parts dropped into a bin one after another in MuJoCo (``grasplan scene
drop``), written as a ``grasplan.scene/1`` scene of settled poses.

:func:`drop_pile` (the world is :class:`grasplan.sim.pileworld.PileWorld`): refuse a pile that
cannot fit (:func:`check_fit`), then drop the parts in a seeded random order, each from a random
pose above the pile (:func:`_release_pose`), settle, check the pile (:func:`_problem`) and retry a
failed drop (:func:`_give_up`). The physics: :class:`DropParams`.

Deterministic: the pile's ``seed`` drives one NumPy generator (order, orientations, positions);
MuJoCo runs single-threaded; the same inputs give the same scene bits.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..cell.model import BinSpec, Cell
from ..errors import InputError, PlanningError
from ..part.mesh import Part
from ..config.option_kinds import spec
from ..config.materials import (CUSTOM, DEFAULT_DENSITY, DEFAULT_MATERIAL, MATERIAL_HELP, MATERIAL_NAMES,
                                resolve_material)
from ..config.params import CandidateParams, MaterialOptions, OptionSet
from .pileworld import PartBody, PileWorld, Settled, part_body
from ..piles.scene_file import MAX_INSTANCES, NAME_RE, Instance, Scene, ScenePart, name_parts

#: a released part's lowest point starts this far (m) above the pile under it
DROP_GAP = 0.03
#: at rest: centre-of-mass speed (m/s) and turning rate (rad/s) below these for REST_HOLD_S (s)
REST_LIN, REST_ANG, REST_HOLD_S = 0.005, 0.05, 0.2
#: most simulated seconds a drop may take to come to rest
MAX_SETTLE_S = 10.0
#: a drop that leaves the pile moving or a part outside the bin is undone and tried again from a
#: new random pose, at most this many times in all
DROP_TRIES = 5
#: a settled part may reach this far (m) into or beyond the bin's walls, floor and rim
FIT_TOL = 0.001
#: a released part's footprint keeps this far (m) from every inner wall
WALL_CLEARANCE = 0.002
#: random orientations tried for a part's footprint to fit the bin
ORIENT_TRIES = 200
#: the parts' convex hulls may fill at most this share of the bin's inner volume: random piles of
#: convex bodies pack below ~0.6 (random close packing of spheres is 0.64), dropped ones looser
MAX_FILL = 0.6
#: parts whose footprints overlap within this margin (m) count as under a released part
FOOTPRINT_MARGIN = 0.005
#: largest count of one part in a pile
MAX_COUNT = MAX_INSTANCES
#: where :func:`drop_pile` lets parts go: anywhere over the floor, or over its central third
RELEASES = ("spread", "central")


class PileError(InputError):
    """The pile does not fit the bin (before simulating, or a part ended outside it). Exit 3."""


class SettleError(PlanningError):
    """The pile did not come to rest within :data:`MAX_SETTLE_S`. Exit 4."""


@dataclass(frozen=True, kw_only=True)
class DropParams(MaterialOptions, OptionSet):
    """Options of a drop (validated here; ``grasplan scene drop`` builds its options from them).

    Physics: uniform density (``material`` or ``density``, default steel as in every command,
    :mod:`grasplan.config.materials`; a :class:`PileItem` may have its own),
    friction ``mu`` (default: the candidates' ``mu``, 0.3), each part colliding through its CoACD
    convex pieces (:func:`grasplan.sim.simulate.convex_pieces`, seed 0 whatever the pile's seed, cached
    where ``grasplan simulate`` caches them), the bin and table exact boxes."""

    seed: int = spec(0, "int", "Seed of the drop order, orientations and positions (same seed, same pile).",
                     lo=0, hi=2**31 - 1)
    material: str = spec(None, "choice", MATERIAL_HELP, choices=(*MATERIAL_NAMES, CUSTOM), record="never",
                         show=DEFAULT_MATERIAL, metavar="NAME")
    density: float = spec(None, "float", "Part density, kg/m^3 (uniform; 7850 steel, 2700 aluminium, ~1200 "
                          "plastic); by default --material's.", lo=0.0, lo_open=True, hi=1e5,
                          show=f"{DEFAULT_DENSITY:g}")
    mu: float = spec(CandidateParams.default("mu"), "float", "Friction coefficient of every contact.", lo=0.0,
                     hi=10.0)
    drop_gap: float = spec(DROP_GAP, "length", "Release height: a part's lowest point starts this far above the "
                           "pile under it.", hi=1.0, show="30mm")
    decomposition: str = spec("coacd", "choice", "Part collision shape: CoACD convex pieces (cached) or the convex "
                              "hull (fast, exact only for convex parts).", choices=("coacd", "hull"))

    def __post_init__(self) -> None:
        self._resolve_material()
        super().__post_init__()


@dataclass(frozen=True)
class PileItem:
    """One kind of part in a pile: ``count`` instances of ``part`` named ``name`` (ids
    ``<name>_<k>``). ``mesh`` and ``units`` are what the scene file records (default the part's
    path and the units it was read in); ``material`` / ``density``: this part's (None: the drop's
    :class:`DropParams`)."""

    name: str
    part: Part
    count: int
    mesh: str | None = None
    units: str | None = None
    material: str | None = None
    density: float | None = None

    def physics(self, params: DropParams) -> tuple[str, float]:
        """``(material, density kg/m^3)`` this part is dropped with: its own, else ``params``'."""
        if self.material is None and self.density is None:
            return params.material, params.density
        material, density = resolve_material(self.material, self.density, where=f"part {self.name}: ")
        return material, float(density)

    def scene_part(self, params: DropParams | None = None) -> ScenePart:
        """The scene's record of the part: mesh, units, material and density, the mesh's sha256."""
        material, density = self.physics(params if params is not None else DropParams())
        return ScenePart(name=self.name, mesh=self.mesh if self.mesh is not None else self.part.path,
                         units=self.units if self.units is not None else self.part.units,
                         material=material, density=density, sha256=self.part.sha256)


@dataclass(frozen=True)
class PartDrop:
    """One released part: ``index`` (0-based) of ``total`` drops, instance ``id`` and ``part`` name,
    ``T_release`` (4, 4) its pose when let go (the accepted try), the simulated seconds
    ``settle_s`` until the pile was at rest again (the accepted try), the physics ``steps`` and
    wall-clock ``seconds`` of every try, the height ``top`` (m) of the pile's highest point
    afterwards and the ``attempts`` it took (:data:`DROP_TRIES`)."""

    index: int
    total: int
    id: str
    part: str
    T_release: np.ndarray
    settle_s: float
    steps: int
    seconds: float
    top: float
    attempts: int = 1

    def to_json(self) -> dict:
        return {"id": self.id, "part": self.part, "T_release": self.T_release.tolist(), "settle_s": self.settle_s,
                "steps": self.steps, "seconds": self.seconds, "top": self.top, "attempts": self.attempts}


@dataclass(frozen=True, eq=False)
class DropResult:
    """A settled pile: the ``scene`` (instances in drop order), each drop's record, the parts'
    records (``parts``: name -> {path, sha256, scale_to_m, units, count, material, density, pieces,
    mass_kg, volume_m3}),
    the parameters, wall-clock ``seconds`` (total, including the convex decompositions) and the
    simulated seconds ``sim_s``."""

    scene: Scene
    drops: tuple[PartDrop, ...]
    parts: dict[str, dict[str, Any]]
    params: DropParams
    seconds: float
    sim_s: float
    #: the world the pile settled in (its state is the settled pile), for a caller that goes on
    #: simulating it (the clutter loop)
    world: PileWorld | None = None

    def to_json(self) -> dict:
        return {"params": self.params.to_json(), "parts": self.parts, "drops": [d.to_json() for d in self.drops],
                "seconds": self.seconds, "sim_s": self.sim_s}


# ------------------------------------------------------------------------------------------------
# names and items
# ------------------------------------------------------------------------------------------------
def load_items(specs: Sequence[tuple], *, units: str = "auto", info: Callable[[str], None] | None = None,
               warn: Callable[[str], None] | None = None) -> list[PileItem]:
    """:class:`PileItem` s from ``(mesh path, count[, material])`` (``--part PATH:COUNT[:MATERIAL]``;
    material None: the drop's), named by :func:`grasplan.piles.scene_file.part_name` (the file's
    stem); InputError (exit 3) for a file given twice, two files that give one name or an
    unreadable mesh."""
    from ..part.mesh import load_part

    seen: dict[str, str] = {}
    for path, *_ in specs:
        key = str(Path(path).resolve())
        if key in seen:
            raise InputError(f"--part {path}: given twice (also as {seen[key]}); give each part once with the total "
                             f"count")
        seen[key] = path
    names = list(name_parts((spec[0] for spec in specs), where="--part"))
    items: list[PileItem] = []
    for name, (path, n, *rest) in zip(names, specs):
        p = load_part(path, units=units)
        for w in p.warnings:
            if warn is not None:
                warn(w)
        if info is not None:
            info(f"part {name}: {path} ({p.units_note}; sha256 {p.sha256[:16]}, scale_to_m {p.scale_to_m:g})")
        items.append(PileItem(name=name, part=p, count=n, material=rest[0] if rest else None))
    return items


def parts_record(items: Sequence[PileItem], params: DropParams | None = None) -> dict[str, dict[str, Any]]:
    """What an output records of each part: path, sha256, scale_to_m, units, count, material and
    density (kg/m^3, :meth:`PileItem.physics` with ``params``, default ``DropParams()``)."""
    p = params if params is not None else DropParams()
    return {it.name: {"path": it.part.path, "sha256": it.part.sha256, "scale_to_m": float(it.part.scale_to_m),
                      "units": it.part.units, "count": it.count,
                      **dict(zip(("material", "density"), it.physics(p)))} for it in items}


def _items(items: Sequence[PileItem | tuple]) -> list[PileItem]:
    out = [it if isinstance(it, PileItem) else PileItem(*it) for it in items]
    if not out:
        raise InputError("drop: no parts given; give at least one PATH:COUNT")
    names = [it.name for it in out]
    for it in out:
        if not NAME_RE.match(it.name):
            raise InputError(f"drop: part name {it.name!r} is not valid (letters, digits, '_', '.', '+', '-')")
        if isinstance(it.count, bool) or not isinstance(it.count, int) or not 1 <= it.count <= MAX_COUNT:
            raise InputError(f"drop: part {it.name!r}: count must be a whole number in 1..{MAX_COUNT}, "
                             f"got {it.count!r}")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"drop: part names must be unique; repeated: {', '.join(dup)} (give one PATH:COUNT per part)")
    total = sum(it.count for it in out)
    if total > MAX_INSTANCES:
        raise InputError(f"drop: {total} parts; a scene holds at most {MAX_INSTANCES}")
    return out


# ------------------------------------------------------------------------------------------------
# geometry of the bin
# ------------------------------------------------------------------------------------------------
def _bin(cell: Cell) -> BinSpec:
    if cell.bin is None:
        raise InputError(f"drop: cell {cell.name!r} has no bin to drop parts into; use a cell with a bin "
                         f"(e.g. --cell bin; docs/cells.md)")
    return cell.bin


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix (a normalised Gaussian quaternion w, x, y, z)."""
    q = rng.standard_normal(4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _room(b: BinSpec) -> np.ndarray:
    """The box (3,) a released part must fit in, m: the bin's inner floor less the wall clearance,
    and its wall height."""
    return np.array([b.inner[0] - 2 * WALL_CLEARANCE, b.inner[1] - 2 * WALL_CLEARANCE, b.height + FIT_TOL])


def flat_rotation(hull: np.ndarray, b: BinSpec) -> np.ndarray:
    """``R_bin_part`` (3, 3) laying the part's oriented bounding box (trimesh's) along the bin: its
    shortest side up, its longest along the bin's longer inner side."""
    from trimesh.bounds import oriented_bounds

    to_obb, ext = oriented_bounds(hull)
    R_obb_part = np.asarray(to_obb)[:3, :3]
    order = np.argsort(ext)  # obb axes: shortest, middle, longest
    long_x = b.inner[0] >= b.inner[1]
    targets = (2, 1, 0) if long_x else (2, 0, 1)  # bin axis for the shortest, middle, longest side
    P = np.zeros((3, 3))
    for k, t in zip(order, targets):
        P[t, k] = 1.0
    if np.linalg.det(P) < 0:
        P[targets[1]] *= -1.0
    return P @ R_obb_part


def _orientation_fits(hull: np.ndarray, R: np.ndarray, room: np.ndarray, dims: int) -> bool:
    p = hull @ R.T
    return bool(np.all(np.ptp(p, axis=0)[:dims] <= room[:dims]))


def check_fit(cell: Cell, items: Sequence[PileItem], bodies: dict[str, PartBody], *, seed: int = 0) -> None:
    """Refuse, before simulating, a pile that cannot fit the cell's bin: :class:`PileError` (exit 3)
    naming the part or the volumes. Every part's convex hull must fit inside the bin (between its
    walls, :data:`WALL_CLEARANCE` from each, and below their top) in some orientation: lying flat
    along the bin (:func:`flat_rotation`) or one of :data:`ORIENT_TRIES` random ones; and the parts'
    convex hulls together may fill at most :data:`MAX_FILL` of the bin's inner volume (floor area x
    wall height)."""
    b = _bin(cell)
    inner = np.asarray(b.inner, dtype=np.float64)
    room = _room(b)
    rng = np.random.default_rng(seed)
    for it in items:
        hull = bodies[it.name].hull
        if not (_orientation_fits(hull, flat_rotation(hull, b), room, 3)
                or any(_orientation_fits(hull, _random_rotation(rng), room, 3) for _ in range(ORIENT_TRIES))):
            ext = np.sort(np.ptp(hull @ flat_rotation(hull, b).T, axis=0))
            raise PileError(f"part {it.name!r} ({it.part.path}, {ext[0] * 1e3:.0f} x {ext[1] * 1e3:.0f} x "
                            f"{ext[2] * 1e3:.0f} mm) does not fit in the bin ({inner[0] * 1e3:.0f} x "
                            f"{inner[1] * 1e3:.0f} mm inside, walls {b.height * 1e3:.0f} mm high) in any orientation "
                            f"tried; use a larger bin (or check --units)")
    vol = sum(_hull_volume(bodies[it.name]) * it.count for it in items)
    box = float(inner[0] * inner[1] * b.height)
    if vol > MAX_FILL * box:
        raise PileError(f"the pile does not fit the bin: the parts' convex hulls take {vol * 1e6:.0f} cm^3, "
                        f"{100 * vol / box:.0f} % of the bin's inner volume ({box * 1e6:.0f} cm^3); a dropped "
                        f"pile fills at most {100 * MAX_FILL:.0f} %: drop fewer parts "
                        f"(at most ~{MAX_FILL * box * 1e6:.0f} cm^3 of hulls) or use a larger bin")


def _hull_volume(body: PartBody) -> float:
    from ..geometry.meshdata import convex_hull

    return abs(float(convex_hull(body.hull).volume))


def outside_bin(cell: Cell, hull_world: np.ndarray) -> tuple[float, str]:
    """How far (m) a part's convex-hull vertices (h, 3, world) reach beyond the bin's inner walls,
    below its floor's top or above its rim, and which of these it is (the worst); (<= 0, '')
    when inside."""
    b = _bin(cell)
    p = b.to_bin(hull_world)  # bin frame: floor top at z = 0
    hx, hy = 0.5 * b.inner[0], 0.5 * b.inner[1]
    over = {"beyond the walls (x)": float(np.abs(p[:, 0]).max() - hx),
            "beyond the walls (y)": float(np.abs(p[:, 1]).max() - hy),
            "below the floor": float(-p[:, 2].min()),
            "above the walls": float(p[:, 2].max() - b.height)}
    worst = max(over, key=lambda k: over[k])
    return over[worst], (worst if over[worst] > 0 else "")


# ------------------------------------------------------------------------------------------------
# the drop
# ------------------------------------------------------------------------------------------------
def _release_pose(world: PileWorld, i: int, rng: np.random.Generator, gap: float,
                  release: str = "spread") -> np.ndarray:
    """A random ``T_world_part`` above the bin for body ``i``. The instances (ids ``<part>_<k>``, k
    counting from 0 per part in the order given) are dropped in a seeded random order, each in a
    uniformly random orientation whose footprint fits the bin's inner area (:data:`WALL_CLEARANCE`
    from each wall; after :data:`ORIENT_TRIES` misses, lying flat), at a uniformly random xy where
    it does (``release="spread"``) or, ``release="central"`` (VGN's pile), with its footprint's
    centre uniformly random over the central third of the inner floor (each side's middle third),
    moved inwards where the footprint would cross the wall clearance. Release height: the part's
    lowest point starts ``gap`` (``drop_gap``, default :data:`DROP_GAP`) above the highest point of
    the parts already in the bin whose footprint overlaps its own (the floor's top when none
    does), at rest."""
    b = _bin(world.cell)
    T_bin = np.asarray(b.T_world_bin)  # z up, a yaw only: bin-frame z is height above the floor's top
    inner = np.asarray(b.inner, dtype=np.float64)
    hull = world.bodies[i].hull
    for _ in range(ORIENT_TRIES):
        R = _random_rotation(rng)  # R_bin_part
        if _orientation_fits(hull, R, _room(b), 2):
            break
    else:  # a part that fits only lying flat (check_fit said it fits)
        R = flat_rotation(hull, b)
    p = hull @ R.T
    lo, hi = p.min(axis=0), p.max(axis=0)
    room = np.maximum(inner - 2 * WALL_CLEARANCE - (hi - lo)[:2], 0.0)
    if release == "central":
        centre = inner * (rng.random(2) - 0.5) / 3.0  # the footprint's centre, bin frame
        free = 0.5 * room  # how far the footprint's centre may go from the floor's centre
        xy = np.clip(centre, -free, free) - 0.5 * (lo[:2] + hi[:2])
    else:
        xy = -0.5 * inner + WALL_CLEARANCE + room * rng.random(2) - lo[:2]  # the part origin, bin frame
    foot_lo, foot_hi = lo[:2] + xy - FOOTPRINT_MARGIN, hi[:2] + xy + FOOTPRINT_MARGIN
    top = 0.0  # the floor's top
    for j in np.flatnonzero(world.present):
        q = b.to_bin(world.hull_world(int(j)))
        if np.all(q[:, :2].min(axis=0) <= foot_hi) and np.all(q[:, :2].max(axis=0) >= foot_lo):
            top = max(top, float(q[:, 2].max()))
    T_bin_part = np.eye(4)
    T_bin_part[:3, :3] = R
    T_bin_part[:3, 3] = [xy[0], xy[1], top + gap - lo[2]]
    return T_bin @ T_bin_part


def _problem(world: PileWorld, s: Settled) -> PileError | SettleError | None:
    """Why the settled pile is not acceptable, None when it is. Settled: every part in the bin at
    rest for :data:`REST_HOLD_S` (centre-of-mass speed below :data:`REST_LIN` and turning rate below
    :data:`REST_ANG`) within :data:`MAX_SETTLE_S` simulated seconds. In the bin: every part's whole
    mesh (its convex hull) within the bin's inner walls, above its floor and below the top of its
    walls, each within :data:`FIT_TOL`."""
    if not s.at_rest:
        return SettleError(f"{s.moving} moving at {s.lin * 1e3:.1f} mm/s, {math.degrees(s.ang):.1f} deg/s")
    for j in np.flatnonzero(world.present):
        by, where = outside_bin(world.cell, world.hull_world(int(j)))
        if by > FIT_TOL:
            return PileError(f"{world.bodies[j].name} {by * 1e3:.1f} mm {where}")
    return None


def _give_up(problem: PileError | SettleError, name: str, i: int, n: int) -> PileError | SettleError:
    """The error once a drop failed :data:`DROP_TRIES` times. A drop that fails (:func:`_problem`: a
    part leaning out above the rim, bounced out, still moving) is undone
    (:meth:`PileWorld.snapshot`/``restore``) and tried again from a new random pose, DROP_TRIES
    times in all; then :class:`PileError` (exit 3: the pile does not fit) or :class:`SettleError`
    (exit 4: it does not come to rest), naming the part and by how much."""
    where = f"dropping {name} ({i + 1} of {n}) from {DROP_TRIES} random poses, the last left {problem}"
    if isinstance(problem, SettleError):
        return SettleError(f"the pile did not come to rest within {MAX_SETTLE_S:g} s: {where}; try another --seed")
    return PileError(f"the pile does not fit the bin: {where}; drop fewer parts or use a larger bin")


def pile_bodies(items: Sequence[PileItem], params: DropParams, *, cache: bool = True,
                log: Callable[[str], None] | None = None) -> dict[str, PartBody]:
    """Each part's :class:`PartBody` (its convex pieces, mass at its density), by part name; ``log``
    is called with a line per part once its collision shape is ready."""
    shared: dict[str, PartBody] = {}
    for it in items:
        t = time.perf_counter()
        material, density = it.physics(params)
        shared[it.name] = body = part_body(it.name, it.part.mesh, density=density,
                                           decomposition=params.decomposition, cache=cache)
        if log is not None:
            log(f"{it.name}: {len(body.pieces)} convex pieces ({params.decomposition}, "
                f"{time.perf_counter() - t:.1f} s), {body.mass.mass * 1e3:.0f} g ({material}, {density:g} kg/m^3)")
    return shared


def instance_bodies(items: Sequence[PileItem], shared: dict[str, PartBody],
                    rng: np.random.Generator) -> tuple[list[PartBody], list[str]]:
    """One body per instance (ids ``<part>_<k>``) in a random order drawn from ``rng`` (one
    permutation), and each body's part name."""
    ids = [(f"{it.name}_{k}", it.name) for it in items for k in range(it.count)]
    order = rng.permutation(len(ids))
    bodies = [PartBody(name=ids[k][0], pieces=shared[ids[k][1]].pieces, mass=shared[ids[k][1]].mass,
                       hull=shared[ids[k][1]].hull) for k in order]
    return bodies, [ids[k][1] for k in order]


def drop_pile(cell: Cell, items: Sequence[PileItem | tuple], *, params: DropParams | None = None,
              cell_ref: str | None = None, progress: Callable[[PartDrop], None] | None = None,
              log: Callable[[str], None] | None = None, cache: bool = True,
              make_world: Callable[[list[PartBody]], PileWorld] | None = None,
              release: str = "spread") -> DropResult:
    """Drop the parts into the cell's bin and return the settled pile (module docstring).

    Parameters
    ----------
    cell : Cell
        A cell with a bin (``load_cell("bin")``).
    items : sequence of PileItem or (name, Part, count[, mesh, units])
        The parts and how many of each.
    params : DropParams
        Seed, density, friction, release gap, decomposition (default ``DropParams()``).
    cell_ref : str
        What the scene records as its ``cell`` (default ``cell.name``).
    progress : callable
        Called with each :class:`PartDrop` once the pile has settled after it.
    log : callable
        Called with a line of text per part once its collision shape is ready.
    cache : bool
        Read and write the convex-decomposition cache.
    make_world : callable
        Builds the world from the part bodies (in drop order), e.g. with a gripper added
        (:class:`grasplan.clutter.world.ClutterWorld`); default ``PileWorld(cell, bodies, mu=params.mu)``.
        The drop runs at the world's timestep as built; the result's ``world`` is it, settled.
    release : str
        Where parts are let go (:data:`RELEASES`): ``"spread"`` anywhere over the bin's floor,
        ``"central"`` over its central third (VGN's pile; :func:`_release_pose`).

    Raises
    ------
    PileError (exit 3)
        The pile does not fit the bin: before simulating, or a part ended outside it.
    SettleError (exit 4)
        A drop did not come to rest within :data:`MAX_SETTLE_S` simulated seconds.
    """
    from . import simulate  # noqa: F401 - imported (trimesh, coacd's caller) before the per-part timings

    t0 = time.perf_counter()
    p = params if params is not None else DropParams()
    if release not in RELEASES:
        raise ValueError(f"drop_pile: release {release!r}; valid: {', '.join(RELEASES)}")
    its = _items(items)
    _bin(cell)
    shared = pile_bodies(its, p, cache=cache, log=log)
    check_fit(cell, its, shared, seed=p.seed)
    rng = np.random.default_rng(p.seed)
    bodies, part_names = instance_bodies(its, shared, rng)
    world = PileWorld(cell, bodies, mu=p.mu) if make_world is None else make_world(bodies)
    drops = []
    sim_s = 0.0
    for i, b in enumerate(bodies):
        t_part = time.perf_counter()
        snap = world.snapshot()
        steps, attempt = 0, 0
        while True:
            T = _release_pose(world, i, rng, p.drop_gap, release)
            world.place(i, T)
            s = world.settle(lin=REST_LIN, ang=REST_ANG, hold=REST_HOLD_S, max_s=MAX_SETTLE_S)
            sim_s += s.sim_s
            steps += s.steps
            attempt += 1
            problem = _problem(world, s)
            if problem is None:
                break
            if attempt == DROP_TRIES:
                raise _give_up(problem, b.name, i, len(bodies))
            world.restore(snap)
        top = max(float(world.hull_world(int(j))[:, 2].max()) for j in np.flatnonzero(world.present))
        d = PartDrop(index=i, total=len(bodies), id=b.name, part=part_names[i], T_release=T, settle_s=s.sim_s,
                     steps=steps, seconds=time.perf_counter() - t_part, top=top, attempts=attempt)
        drops.append(d)
        if progress is not None:
            progress(d)
    instances = tuple(Instance(b.name, part_names[i], world.pose(i)) for i, b in enumerate(bodies))
    scene = Scene(instances=instances, cell=cell_ref if cell_ref is not None else cell.name,
                  parts=tuple(it.scene_part(p) for it in its))
    parts = {name: {**rec, "pieces": len(shared[name].pieces), "mass_kg": float(shared[name].mass.mass),
                    "volume_m3": float(shared[name].mass.volume)} for name, rec in parts_record(its, p).items()}
    return DropResult(scene=scene, drops=tuple(drops), parts=parts, params=p, seconds=time.perf_counter() - t0,
                      sim_s=sim_s, world=world)
