"""Clutter protocols (docs/clutter.md): ``pile`` releases over the bin floor's central third and
takes the walls away, ``packed`` places parts upright at free spots, ``bin`` is the drop of
``grasplan scene drop``; the planner's cell, the success height, the workspace test and the wall
distance follow each protocol's rules. The example parts collide through their convex hulls."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from grasplan.cell.model import BIN_NAMES, load_cell
from grasplan.clutter.protocols import (PACK_REGION, PROTOCOLS, TABLE_CLEARANCE, BIN_BOXES, in_workspace, make_pile,
                                        protocol, wall_distance)
from grasplan.errors import InputError
from grasplan.part.mesh import load_part
from grasplan.part.stability import stable_poses
from grasplan.sim.drop import WALL_CLEARANCE, DropParams, PileItem, drop_pile
from grasplan.sim.pileworld import PileWorld

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "parts"
PARAMS = DropParams(seed=3, decomposition="hull", material="plastic")


@pytest.fixture(scope="module")
def cell():
    return load_cell("bin")


@pytest.fixture(scope="module")
def items():
    return [PileItem("box", load_part(EXAMPLES / "box.stl"), 3), PileItem("bracket", load_part(EXAMPLES / "bracket.stl"), 2)]


def _world(cell):
    return lambda bodies: PileWorld(cell, bodies, mu=PARAMS.mu)


def _bin_xy(cell, p_world):
    T = np.asarray(cell.bin.T_world_bin)
    return ((np.asarray(p_world) - T[:3, 3]) @ T[:3, :3])[..., :2]


def test_central_release_puts_every_footprint_centre_over_the_central_third(cell, items):
    res = drop_pile(cell, items, params=PARAMS, release="central")
    inner = np.asarray(cell.bin.inner)
    for d in res.drops:
        body = res.world.bodies[res.world.index(d.id)]
        hull = body.hull @ d.T_release[:3, :3].T + d.T_release[:3, 3]
        xy = _bin_xy(cell, hull)
        centre = 0.5 * (xy.min(axis=0) + xy.max(axis=0))
        assert np.all(np.abs(centre) <= inner / 6.0 + 1e-9), (d.id, centre)
    spread = drop_pile(cell, items, params=PARAMS)
    assert not np.allclose(spread.drops[0].T_release, res.drops[0].T_release)
    with pytest.raises(ValueError, match="central"):
        drop_pile(cell, items, params=PARAMS, release="middle")


def test_pile_takes_the_walls_away_and_keeps_only_parts_in_the_workspace(cell, items):
    made = make_pile(PROTOCOLS["pile"], cell, items, params=PARAMS, make_world=_world(cell))
    w = made.world
    import mujoco

    m = w.model
    names = set()
    for g in range(m.ngeom):
        name = (mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or "").split("#")[0]
        names.add(name)
        if name in BIN_BOXES:
            assert m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0, name
        if name == "#table":
            assert m.geom_contype[g] != 0
    assert set(BIN_BOXES) <= names
    ids = {i.id for i in made.scene.instances}
    lowest = min(w.hull_world(w.index(i))[:, 2].min() for i in ids)
    assert lowest < float(cell.bin.T_world_bin[2, 3]) - 0.005  # the floor gone: the pile lies on the table
    assert len(ids) + len(made.outside) == 5 and not ids & set(made.outside)
    for j in range(len(w.bodies)):
        name = w.bodies[j].name
        T = w.pose(j)
        com = T[:3, :3] @ w.bodies[j].mass.com + T[:3, 3]
        assert w.present[j] == (name in ids)
        if name in ids:
            assert in_workspace(cell.bin, com, cell.table_z)
            np.testing.assert_allclose(T, next(i.T_world_part for i in made.scene.instances if i.id == name))


def test_packed_places_parts_upright_apart_in_the_central_region(cell, items):
    made = make_pile(PROTOCOLS["packed"], cell, items, params=PARAMS, make_world=_world(cell))
    w = made.world
    assert len(made.scene.instances) + len(made.outside) == 5 and len(made.scene.instances) >= 3
    up = {it.name: stable_poses(it.part.mesh)[0][0] for it in items}
    inner = np.asarray(cell.bin.inner)
    for inst in made.scene.instances:
        R = np.asarray(inst.T_world_part)[:3, :3]
        # upright: the world's up seen in the part frame is the most probable pose's (any turn about z)
        cos = float(R[2] @ np.asarray(up[inst.part])[2])
        assert math.degrees(math.acos(min(1.0, cos))) < 10.0, inst.id
        j = w.index(inst.id)
        xy = _bin_xy(cell, w.hull_world(j))
        assert np.all(np.abs(0.5 * (xy.min(axis=0) + xy.max(axis=0))) <= 0.5 * PACK_REGION * inner + 0.01)
        assert wall_distance(cell.bin, w.hull_world(j)) >= WALL_CLEARANCE - 0.003
    # apart: no two parts' convex hulls share a point (a separating axis among the xy box axes or a contact-free world)
    m, d = w.model, w.data
    parts = set(int(b) for b in w.body_ids)
    touching = [(int(m.geom_bodyid[d.contact.geom1[k]]), int(m.geom_bodyid[d.contact.geom2[k]])) for k in range(d.ncon)]
    assert not [t for t in touching if t[0] in parts and t[1] in parts]


def test_a_protocol_sets_the_planners_cell_and_the_success_height(cell):
    floor = float(cell.bin.T_world_bin[2, 3])
    assert PROTOCOLS["bin"].planner_cell(cell) is cell
    assert PROTOCOLS["bin"].clear_z(cell) == pytest.approx(floor + cell.bin.height)
    assert PROTOCOLS["bin"].floor_z(cell) == pytest.approx(floor)
    for name in ("pile", "packed"):
        c = PROTOCOLS[name].planner_cell(cell)
        assert c.bin is None and c.table_z == pytest.approx(cell.table_z)
        assert not {o.name for o in c.obstacles} & set(BIN_NAMES)
        assert PROTOCOLS[name].clear_z(cell) == pytest.approx(cell.table_z + TABLE_CLEARANCE)
        assert PROTOCOLS[name].floor_z(cell) == pytest.approx(cell.table_z)
    with pytest.raises(InputError, match="bin, pile, packed"):
        protocol("heap")


def test_the_wall_distance_and_the_workspace_follow_the_bin_frame(cell):
    b = cell.bin
    T = np.asarray(b.T_world_bin)
    hx, hy = 0.5 * b.inner[0], 0.5 * b.inner[1]
    pts = np.array([[hx - 0.004, 0.0, 0.01], [0.0, -hy + 0.03, 0.02]]) @ T[:3, :3].T + T[:3, 3]
    assert wall_distance(b, pts) == pytest.approx(0.004)
    assert wall_distance(b, pts[1:]) == pytest.approx(min(hx, 0.03))
    assert in_workspace(b, pts[0]) and not in_workspace(b, pts[0] + T[:3, 0] * 0.005)
    assert not in_workspace(b, T[:3, 3] - T[:3, 2] * 0.001)  # below the floor's top
    assert in_workspace(b, T[:3, 3] - T[:3, 2] * 0.001, floor_z=cell.table_z)  # above the table


def test_remove_statics_names_what_exists(cell):
    w = PileWorld(cell, [], mu=0.3)
    assert sorted(w.remove_statics(BIN_BOXES)) == sorted(BIN_BOXES)
    with pytest.raises(ValueError, match="bin_floor"):
        w.remove_statics(["bin_lid"])


@pytest.mark.parametrize("name", ["pile", "packed"])
def test_a_protocols_pile_is_the_same_for_the_same_seed_and_differs_for_another(cell, items, name):
    def poses(seed: int) -> dict:
        made = make_pile(PROTOCOLS[name], cell, items, params=DropParams(seed=seed, decomposition="hull",
                                                                         material="plastic"),
                         make_world=_world(cell))
        return {i.id: np.asarray(i.T_world_part) for i in made.scene.instances}

    a, b, c = poses(5), poses(5), poses(6)
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    assert a.keys() != c.keys() or any(not np.allclose(a[k], c[k]) for k in a)
