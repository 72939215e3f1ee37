"""The pile's hull pre-check (grasplan/pick/world.py, grasplan/piles/checks.py): a pair whose convex
hulls coal calls apart is skipped without the mesh test. Checked against the mesh test alone on
random close placements of a concave part: the same first hits, and never a mesh contact between
hulls called apart."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import coal
import numpy as np

from grasplan.cell.model import load_cell
from grasplan.gripper.load import load_gripper
from grasplan.part.mesh import load_part
from grasplan.pick.world import PickWorld
from grasplan.piles.scene_file import Instance
from grasplan.geometry.transforms import rpy_matrix

BRACKET = Path(__file__).resolve().parents[1] / "examples" / "parts" / "bracket.stl"


def _pose(rng, spread):
    T = np.eye(4)
    T[:3, :3] = rpy_matrix(*rng.uniform(-np.pi, np.pi, 3))
    T[:3, 3] = [0.45, 0.0, 0.05] + rng.uniform(-spread, spread, 3)
    return T


def test_hull_precheck_changes_no_lift_hit():
    part = load_part(BRACKET)
    world = PickWorld(load_gripper("schunk_egp_c_40"), load_cell("bin"))
    g = world.add_part("bracket", part)
    rng = np.random.default_rng(5)
    extent = float(np.ptp(part.mesh.vertices, axis=0).max())
    hits = apart = 0
    for k in range(30):
        insts = [Instance(f"i{j}", "bracket", _pose(rng, 0.6 * extent)) for j in range(4)]
        world.set_instances(insts)
        bodies = world.bodies("i0")
        plain = [dataclasses.replace(b, convex=None) for b in bodies]
        shifts = np.linspace(0.0, 1.5 * extent, 12)[:, None] * rng.normal(size=3) / np.sqrt(3)
        with_hulls = world.part_hits("bracket", insts[0].T_world_part, shifts, bodies)
        meshes_only = world.part_hits("bracket", insts[0].T_world_part, shifts, plain)
        assert np.array_equal(with_hulls, meshes_only), k
        hits += int(np.sum(with_hulls >= 0))
        # and pairwise: hulls apart never hides a mesh contact
        req, res = coal.CollisionRequest(), coal.CollisionResult()
        for b in bodies[:3]:
            tf = coal.Transform3s(insts[0].T_world_part[:3, :3].copy(), insts[0].T_world_part[:3, 3].copy())
            res.clear()
            hull = coal.collide(g.convex, tf, b.convex, b.tf, req, res)
            res.clear()
            mesh = coal.collide(g.bvh, tf, b.geometry, b.tf, req, res)
            assert hull or not mesh
            apart += int(not hull)
    assert hits > 5 and apart > 5  # both kinds of cases were met


def test_box_bodies_decided_without_coal_agree_with_coal():
    """A gripper box deep in one of the bin's boxes or the table is a hit without a coal call
    (grasplan/pick/world.py, CERTAIN_OVERLAP); the first body hit per pose is the one coal names
    when every box body goes through coal, on random poses around the floor and the walls, some
    grazing them within a micrometre."""
    part = load_part(BRACKET)
    world = PickWorld(load_gripper("schunk_egp_c_40"), load_cell("bin"))
    world.add_part("bracket", part)
    rng = np.random.default_rng(11)
    world.set_instances([Instance(f"i{j}", "bracket", _pose(rng, 0.05)) for j in range(3)])  # meshes, first in order
    bodies = world.bodies(None)
    assert [b.box for b in bodies] == [False] * 3 + [True] * 6  # the bin's floor and four walls, the table
    plain = [dataclasses.replace(b, box=False) for b in bodies]
    M = 3000
    T = np.zeros((M, 4, 4))
    for m in range(M):
        T[m] = _pose(rng, 0.2)
    # every third pose points down with a fingertip on the floor's top (z = 0.01) +- 1 um, or 3 mm into it
    tip = np.array([0.0, 0.0, 0.008])  # the fingertip's centre, TCP frame (schunk_egp_c_40: 8 mm beyond it)
    for m in range(0, M, 3):
        T[m, :3, :3] = rpy_matrix(np.pi, 0.0, rng.uniform(-np.pi, np.pi))  # pointing down
        z_tip = 0.01 + rng.choice([-1e-6, 0.0, 1e-6, -0.003])
        T[m, 2, 3] = z_tip - (T[m, :3, :3] @ tip)[2]
    width = rng.uniform(0.0, 0.05, M)
    fast, slow, coal_fast, coal_slow = _with_and_without_prepass(world, T, width, bodies, plain)
    names = {bodies[i].name for i in fast[fast >= 0]}
    assert {"instance:i0", "obstacle:bin_floor", "table"} <= names, names
    assert coal_slow - coal_fast > 500  # most box hits were decided without coal


def _with_and_without_prepass(world, T, width, bodies, plain):
    """The first body hit per pose with the bodies' box pre-pass (``bodies``) and without it
    (``plain``), asserted equal, and the coal calls each took: ``(fast, slow, coal_fast, coal_slow)``."""
    c0 = world.coal_calls
    fast, _ = world.gripper_hits("bracket", None, T, width, bodies)
    c1 = world.coal_calls
    slow, _ = world.gripper_hits("bracket", None, T, width, plain)
    assert np.array_equal(fast, slow)
    return fast, slow, c1 - c0, world.coal_calls - c1


def test_instance_pairs_decided_on_boxes_agree_with_coal():
    """The compiled box pre-pass decides most (gripper shape, neighbour) pairs before coal
    (grasplan/pick/world.py, ``Body.part_boxes``): the first body hit per pose is the one coal names
    when every instance pair goes through coal, on random poses among five instances."""
    part = load_part(BRACKET)
    world = PickWorld(load_gripper("schunk_egp_c_40"), load_cell("bin"))
    world.add_part("bracket", part)
    rng = np.random.default_rng(5)
    world.set_instances([Instance(f"i{j}", "bracket", _pose(rng, 0.05)) for j in range(5)])
    bodies = world.bodies(None)
    assert sum(b.part_boxes is not None for b in bodies) == 5
    plain = [dataclasses.replace(b, part_boxes=None) for b in bodies]
    M = 3000
    T = np.stack([_pose(rng, 0.12) for _ in range(M)])
    width = rng.uniform(0.0, 0.05, M)
    fast, slow, coal_fast, coal_slow = _with_and_without_prepass(world, T, width, bodies, plain)
    names = {bodies[i].name for i in fast[fast >= 0]}
    assert sum(n.startswith("instance:") for n in names) >= 3, names
    assert coal_slow > 3 * max(1, coal_fast)  # most instance pairs were decided without coal
