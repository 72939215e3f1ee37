"""Clutter-removal protocols (:data:`PROTOCOLS`, docs/clutter.md): how a round's pile is made
(:func:`make_pile`), what the planner's cell is, where the workspace ends and how high a picked
part must be lifted (:class:`Protocol`).

- ``bin`` (default): dropped anywhere over the bin's floor, picked from the walled bin, lifted
  above its rim.
- ``pile`` (VGN's and GIGA's): dropped over the floor's central third, then the bin (walls and
  floor) is taken away and the pile settles on the table; lifted 10 cm above the table.
- ``packed`` (VGN's and GIGA's): no bin; parts placed upright on the table at free spots.

Parts outside the workspace (:func:`in_workspace`) when a round starts are not in it;
:func:`wall_distance` is a part's distance to the bin's inner walls, or where they stood.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..cell.model import BIN_NAMES, BinSpec, Cell
from ..cell.regions import Workspace
from ..errors import InputError
from ..piles.scene_file import Instance, Scene
from ..sim.drop import (REST_ANG, REST_HOLD_S, REST_LIN, WALL_CLEARANCE, DropParams, PileItem, check_fit,
                        drop_pile, instance_bodies, pile_bodies)
from ..sim.pileworld import PartBody, PileWorld

#: without the bin, success needs the part's lowest point this far (m) above the table
TABLE_CLEARANCE = 0.10
#: the bin's five boxes (floor and walls), taken away by the protocols without a bin
BIN_BOXES = BIN_NAMES
#: packed: each part's footprint centre falls in this central share of the floor (each side; the
#: footprint stays inside the floor). VGN's packed scenes use the central 14 of 30 cm for 5 small
#: objects; five paper parts need the whole 30 x 20 cm floor
PACK_REGION = 1.0
#: packed: random spots tried per part before it is left out of the round; its lowest point starts
#: this far (m) above the floor
PACK_TRIES, PACK_GAP = 50, 0.001
#: after the walls are taken away, the pile settles for at most this long (simulated s)
SETTLE_MAX_S = 5.0


@dataclass(frozen=True)
class Protocol:
    """One way of making and clearing a pile: its ``name``, whether the bin's ``walls`` stay while
    picking, where the drop lets parts go (``release``: :data:`grasplan.sim.drop.RELEASES`, or
    ``"packed"``) and a one-line ``summary``."""

    name: str
    walls: bool
    release: str
    summary: str

    def planner_cell(self, cell: Cell) -> Cell:
        """The cell the planner sees: ``cell`` itself with the bin; otherwise without the bin's
        five boxes (the parts lie on the table) and with the workspace (:func:`workspace_of`) as
        its ``workspace``, which pushes keep the parts in."""
        b = _bin(cell)
        if self.walls:
            return cell
        return replace(cell, bin=None, obstacles=tuple(o for o in cell.obstacles if o.name not in BIN_NAMES),
                       workspace=workspace_of(b))

    def floor_z(self, cell: Cell) -> float:
        """World height (m) of what the parts lie on while picking: the bin floor's top, else the table."""
        b = _bin(cell)
        return float(b.T_world_bin[2, 3]) if self.walls else float(cell.table_z)

    def clear_z(self, cell: Cell) -> float:
        """World height (m) a picked part's lowest point must reach for a success: the bin's rim
        with the bin, else :data:`TABLE_CLEARANCE` above the table."""
        b = _bin(cell)
        if self.walls:
            return float(b.T_world_bin[2, 3]) + float(b.height)
        return float(cell.table_z) + TABLE_CLEARANCE


PROTOCOLS: dict[str, Protocol] = {
    "bin": Protocol("bin", True, "spread", "dropped anywhere into the bin, picked from the walled bin, "
                    "lifted above its rim"),
    "pile": Protocol("pile", False, "central", "dropped over the central third, bin removed (VGN's pile), "
                     "lifted 10 cm above the table"),
    "packed": Protocol("packed", False, "packed", "placed upright at free spots, no bin (VGN's packed), "
                       "lifted 10 cm above the table"),
}


def protocol(name: str) -> Protocol:
    """The protocol named ``name``; InputError listing the valid names."""
    try:
        return PROTOCOLS[name]
    except KeyError:
        raise InputError(f"--protocol {name!r}: valid protocols are {', '.join(PROTOCOLS)} "
                         f"(docs/clutter.md)") from None


def _bin(cell: Cell) -> BinSpec:
    if cell.bin is None:
        raise InputError(f"cell {cell.name!r} has no bin; clutter rounds need one (e.g. --cell bin; docs/cells.md)")
    return cell.bin


def workspace_of(b: BinSpec) -> Workspace:
    """The workspace as a cell's :class:`~grasplan.cell.regions.Workspace`: the bin's inner floor
    (its centre, size and yaw)."""
    T = np.asarray(b.T_world_bin, dtype=np.float64)
    hx, hy = 0.5 * b.inner[0], 0.5 * b.inner[1]
    cx, cy = float(T[0, 3]), float(T[1, 3])
    return Workspace((cx - hx, cy - hy), (cx + hx, cy + hy), math.degrees(math.atan2(T[1, 0], T[0, 0])))


def in_workspace(b: BinSpec, com_world: np.ndarray, floor_z: float | None = None) -> bool:
    """Whether a part's centre of mass (3,) is over the bin's inner floor area and above
    ``floor_z`` (world, m; default the bin floor's top)."""
    p = b.to_bin(com_world)
    z = float(b.T_world_bin[2, 3]) if floor_z is None else float(floor_z)
    return bool(abs(p[0]) <= 0.5 * b.inner[0] and abs(p[1]) <= 0.5 * b.inner[1] and com_world[2] >= z)


def wall_distance(b: BinSpec, hull_world: np.ndarray) -> float:
    """How far (m) a part's convex-hull vertices (h, 3) keep from the bin's nearest inner wall (or
    where it stood); negative when they reach beyond it."""
    return float(b.wall_gaps(hull_world)[0].min())


@dataclass(frozen=True)
class MadePile:
    """A round's pile, ready to clear: ``scene`` (the instances in the workspace, poses as settled),
    the ``world`` holding it, the instances left out of the round (``outside``: ended outside the
    workspace, or found no free spot when packed) and the simulated seconds ``sim_s``."""

    scene: Scene
    world: PileWorld
    outside: tuple[str, ...]
    sim_s: float


def make_pile(proto: Protocol, cell: Cell, items: Sequence[PileItem], *, params: DropParams,
              make_world: Callable[[list[PartBody]], PileWorld], cell_ref: str | None = None,
              cache: bool = True) -> MadePile:
    """Make the pile of one round by ``proto``'s rules in the world ``make_world`` builds;
    ``params.seed`` draws everything random.

    - ``bin``: :func:`grasplan.sim.drop.drop_pile` (the pile of ``grasplan scene drop``).
    - ``pile``: the drop with ``release="central"`` (each footprint's centre over the floor's
      central third), then the bin's five boxes are taken out of the world (:data:`BIN_BOXES`)
      and the pile settles on the table (at most :data:`SETTLE_MAX_S`).
    - ``packed``: each part placed upright (its most probable stable pose, a random turn about the
      vertical) :data:`PACK_GAP` above the table at a random spot of the workspace
      (:data:`PACK_REGION`) where it touches no other part, then settled; after
      :data:`PACK_TRIES` spots a part is left out.

    Parts whose centre of mass is then outside the workspace are parked and listed in
    ``outside`` (not in the round)."""
    if proto.release == "packed":
        return _packed(cell, items, params=params, make_world=make_world, cell_ref=cell_ref, cache=cache)
    res = drop_pile(cell, items, params=params, cell_ref=cell_ref, make_world=make_world, cache=cache,
                    release=proto.release)
    world = res.world
    assert world is not None  # drop_pile returns the world it dropped into
    sim_s = res.sim_s
    if not proto.walls:
        world.remove_statics(BIN_BOXES)
        sim_s += world.settle(lin=REST_LIN, ang=REST_ANG, hold=REST_HOLD_S, max_s=SETTLE_MAX_S).sim_s
    return _in_round(world, res.scene, sim_s, proto.floor_z(cell))


def park_outside(world: PileWorld, floor_z: float | None = None) -> list[str]:
    """Park the present parts whose centre of mass is outside the workspace (:func:`in_workspace`
    of the world's bin, above ``floor_z``); their names."""
    b = _bin(world.cell)
    out = []
    for j in np.flatnonzero(world.present):
        T = world.pose(int(j))
        if not in_workspace(b, T[:3, :3] @ world.bodies[j].mass.com + T[:3, 3], floor_z):
            world.park(int(j))
            out.append(world.bodies[j].name)
    return out


def _in_round(world: PileWorld, scene: Scene, sim_s: float, floor_z: float) -> MadePile:
    """Park the parts outside the workspace; the scene of the others at their poses now."""
    outside = park_outside(world, floor_z)
    part_of = {inst.id: inst.part for inst in scene.instances}
    inside = tuple(Instance(world.bodies[j].name, part_of[world.bodies[j].name], world.pose(int(j)))
                   for j in np.flatnonzero(world.present))
    return MadePile(scene=replace(scene, instances=inside), world=world, outside=tuple(outside), sim_s=sim_s)


def _touches_part(world: PileWorld, i: int) -> bool:
    """Whether body ``i`` overlaps another part body now (after ``mj_forward``)."""
    m, d = world.model, world.data
    mine = int(world.body_ids[i])
    parts = set(int(x) for x in world.body_ids) - {mine}
    for k in range(d.ncon):
        b1, b2 = int(m.geom_bodyid[d.contact.geom1[k]]), int(m.geom_bodyid[d.contact.geom2[k]])
        if (b1 == mine and b2 in parts) or (b2 == mine and b1 in parts):
            if d.contact.dist[k] < 0.0:
                return True
    return False


def _packed(cell: Cell, items: Sequence[PileItem], *, params: DropParams,
            make_world: Callable[[list[PartBody]], PileWorld], cell_ref: str | None, cache: bool) -> MadePile:
    from ..part.stability import stable_poses

    b = _bin(cell)
    its = list(items)
    shared = pile_bodies(its, params, cache=cache)
    check_fit(cell, its, shared, seed=params.seed)
    rng = np.random.default_rng(params.seed)
    bodies, part_names = instance_bodies(its, shared, rng)
    world = make_world(bodies)
    world.remove_statics(BIN_BOXES)
    upright = {it.name: np.asarray(stable_poses(it.part.mesh)[0][0], dtype=np.float64) for it in its}
    T_bin = np.asarray(b.T_world_bin)
    inner = np.asarray(b.inner, dtype=np.float64)
    sim_s = 0.0
    left_out = []
    for i, body in enumerate(bodies):
        for _ in range(PACK_TRIES):
            yaw = rng.uniform(0.0, 2.0 * math.pi)
            c, s = math.cos(yaw), math.sin(yaw)
            R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ upright[part_names[i]]  # R_bin_part
            p = body.hull @ R.T
            lo, hi = p.min(axis=0), p.max(axis=0)
            free = np.maximum(0.5 * (inner - 2 * WALL_CLEARANCE - (hi - lo)[:2]), 0.0)
            centre = np.clip(PACK_REGION * inner * (rng.random(2) - 0.5), -free, free)
            T = np.eye(4)
            T[:3, :3] = R
            T[:3, 3] = [*(centre - 0.5 * (lo[:2] + hi[:2])), float(cell.table_z) - T_bin[2, 3] + PACK_GAP - lo[2]]
            world.place(i, T_bin @ T)
            if not _touches_part(world, i):
                sim_s += world.settle(lin=REST_LIN, ang=REST_ANG, hold=REST_HOLD_S, max_s=SETTLE_MAX_S).sim_s
                break
            world.park(i)
        else:
            left_out.append(body.name)
    scene = Scene(instances=tuple(Instance(bd.name, part_names[i], world.pose(i))
                                  for i, bd in enumerate(bodies) if world.present[i]),
                  cell=cell_ref if cell_ref is not None else cell.name,
                  parts=tuple(it.scene_part(params) for it in its))
    made = _in_round(world, scene, sim_s, float(cell.table_z))
    return replace(made, outside=tuple(left_out) + made.outside)
