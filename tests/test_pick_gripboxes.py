"""The gripper's checks along a straight line before IK (grasplan/pick/gripboxes.py,
grasplan/pick/world.py): the closed gripper's first hit per pose is coal's, checked shape by shape
and body by body at every pose; a sweep the world calls free is free for coal at every pose of the
line and between them; the swept boxes' containment test is the corners' containment."""
from __future__ import annotations

from pathlib import Path

import coal
import numpy as np

from grasplan.cell.model import load_cell
from grasplan.cell.shapes import shape_geometry
from grasplan.gripper.load import load_gripper
from grasplan.part.mesh import load_part
from grasplan.pick.world import PickWorld
from grasplan.piles.scene_file import Instance
from grasplan.geometry.transforms import rpy_matrix

BRACKET = Path(__file__).resolve().parents[1] / "examples" / "parts" / "bracket.stl"


def _world(rng):
    part = load_part(BRACKET)
    world = PickWorld(load_gripper("schunk_egp_c_40"), load_cell("bin"))
    world.add_part("bracket", part)
    insts = []
    for j in range(5):
        T = np.eye(4)
        T[:3, :3] = rpy_matrix(*rng.uniform(-np.pi, np.pi, 3))
        T[:3, 3] = [0.45 + rng.uniform(-0.06, 0.06), rng.uniform(-0.05, 0.05), 0.03]
        insts.append(Instance(f"i{j}", "bracket", T))
    world.set_instances(insts)
    return world


def _line(rng, n=26, travel=0.1):
    """TCP poses of a straight move: a random orientation near pointing down, over the pile."""
    T = np.eye(4)
    T[:3, :3] = rpy_matrix(np.pi + rng.normal(0, 0.3), rng.normal(0, 0.3), rng.uniform(-np.pi, np.pi))
    T[:3, 3] = [0.45 + rng.uniform(-0.07, 0.07), rng.uniform(-0.06, 0.06), rng.uniform(0.02, 0.08)]
    d = np.array([0.0, 0.0, 1.0]) + rng.normal(0, 0.3, 3)
    out = np.broadcast_to(T, (n, 4, 4)).copy()
    out[:, :3, 3] += np.linspace(0.0, travel, n)[:, None] * d / np.linalg.norm(d)
    return out


def _coal_first(world, T_line, opening, bodies):
    """Per pose, the body the first shape (body shapes, then the jaws) that hits anything hits
    first: coal alone, every shape against every body."""
    shapes = [shape_geometry(s) for s in (*world.gripper.body, *world.gripper.fingers(opening))]
    req, res = coal.CollisionRequest(), coal.CollisionResult()
    out = np.full(len(T_line), -1)
    for k, T in enumerate(T_line):
        for geom, T_tcp_geom in shapes:
            Tg = T @ T_tcp_geom
            hit = []
            for bi, b in enumerate(bodies):
                res.clear()
                if coal.collide(geom, coal.Transform3s(Tg[:3, :3].copy(), Tg[:3, 3].copy()), b.geometry, b.tf, req, res):
                    hit.append(bi)
            if hit:
                out[k] = hit[0]
                break
    return out


def test_gripper_at_hits_is_coal_pose_by_pose():
    rng = np.random.default_rng(21)
    world = _world(rng)
    bodies = world.bodies("i0")
    n_hit = n_free = 0
    for _ in range(40):
        T_line = _line(rng)
        opening = float(rng.uniform(0.0, 0.05))
        got = world.gripper_at_hits(T_line, opening, bodies)
        want = _coal_first(world, T_line, opening, bodies)
        np.testing.assert_array_equal(got, want)
        n_hit += int(np.sum(got >= 0))
        n_free += int(np.sum(got < 0))
    assert n_hit > 50 and n_free > 50


def test_a_free_sweep_is_free_everywhere_between():
    rng = np.random.default_rng(22)
    world = _world(rng)
    bodies = world.bodies(None)
    n_free = n_none = 0
    for _ in range(60):
        T_line = _line(rng, n=2, travel=0.06)
        opening = float(rng.uniform(0.0, 0.05))
        swept = world.gripper_swept_free(T_line[0], T_line[1], opening, 2e-4, bodies)
        if swept is None:
            n_none += 1
            continue
        n_free += 1
        dense = np.broadcast_to(T_line[0], (30, 4, 4)).copy()
        dense[:, :3, 3] = T_line[0, :3, 3] + np.linspace(0, 1, 30)[:, None] * (T_line[1, :3, 3] - T_line[0, :3, 3])
        assert np.all(swept.holds(dense))
        assert np.all(_coal_first(world, dense, opening, bodies) < 0)
        # a pose 1 cm beyond the line's end is not held
        off = dense[-1].copy()
        d = T_line[1, :3, 3] - T_line[0, :3, 3]
        off[:3, 3] += 0.01 * d / np.linalg.norm(d)
        assert not swept.holds(off[None])[0]
    assert n_free > 10 and n_none > 10


def test_holds_is_the_corners_inside():
    rng = np.random.default_rng(23)
    world = _world(rng)
    far = [b for b in world.bodies(None) if b.name == "table"]  # a sweep above the bin: free
    n_in = n_out = 0
    for _ in range(30):
        T_line = _line(rng, n=2, travel=0.05)
        T_line[:, 2, 3] += 0.3
        swept = world.gripper_swept_free(T_line[0], T_line[1], 0.03, 1e-3, far)
        assert swept is not None
        for _ in range(20):
            T = T_line[0].copy()
            T[:3, :3] = T[:3, :3] @ rpy_matrix(*rng.normal(0, 0.01, 3))
            T[:3, 3] += rng.uniform(0, 1) * (T_line[1, :3, 3] - T_line[0, :3, 3]) + rng.normal(0, 1e-3, 3)
            inside = True
            for s in range(len(swept.R)):
                Tg = T @ swept.T_tcp_geom[s]
                signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])
                corners = (swept.c_loc[s] + signs * swept.h_loc[s]) @ Tg[:3, :3].T + Tg[:3, 3]
                local = (corners - swept.centre[s]) @ swept.R[s]
                inside &= bool(np.all(np.abs(local) <= swept.half[s] - 1e-9))
            assert swept.holds(T[None])[0] == inside
            n_in += inside
            n_out += not inside
    assert n_in > 50 and n_out > 50
