"""The compiled box pre-pass of the collision filter (grasplan.grasps.collision_boxes): the collider
with it gives the same status, element and body per pose as the plain coal path (on real grasp
poses, under rigid motions, with mesh shapes), and its own answers agree with python-fcl."""
from __future__ import annotations

import fcl
import numpy as np
from types import SimpleNamespace
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from grasplan.cell.model import Cell
from grasplan.geometry.containment import RayGrid, obb_aabb_separated, points_inside, points_inside_tree
from grasplan.grasps.collision import SAMPLE_DEPTH, GripperCollider
from grasplan.grasps.collision_boxes import APART, HIT, UNSURE, PartBoxes, points_inside_compiled, prefilter
from grasplan.grasps.pipeline import compute_grasps
from grasplan.gripper.load import load_gripper
from grasplan.part.mesh import load_part


@pytest.fixture(scope="module")
def bracket_poses(example_part):
    part = load_part(example_part("bracket.stl"))
    gr = compute_grasps(part, gripper="long_stroke_50")  # the poses, the cell and the resting pose
    ev = SimpleNamespace(gripper=gr.gripper, cell=gr.cell, T=gr.T_world_part, T_part_tcp=gr.frames.T_part_tcp,
                         width=gr.width)
    return part, ev


def _both(mesh, gripper, cell, T_world_part, T, w):
    fast = GripperCollider(mesh, gripper, cell, T_world_part)
    plain = GripperCollider(mesh, gripper, cell, T_world_part, prepass=False)
    return fast, fast.check_detail(T, w), plain, plain.check_detail(T, w)


def test_prepass_gives_the_plain_coal_statuses_on_the_bracket(bracket_poses):
    part, ev = bracket_poses
    fast, a, plain, b = _both(part.mesh, ev.gripper, ev.cell, ev.T, ev.T_part_tcp, ev.width)
    for x, y in zip(a, b):
        assert np.array_equal(x, y)
    assert np.array_equal(fast.reasons(*a), plain.reasons(*b))
    assert len(set(a[0].tolist())) >= 3  # ok, part and table hits all occur
    counts = fast.prepass_counts
    decided = counts["apart"] + counts["hit"]
    assert counts["hit"] > 0 and decided > 0.9 * (decided + counts["unsure"])  # the pre-pass did decide pairs
    assert fast.coal_calls < 0.2 * plain.coal_calls


def test_timing_split_in_the_grasp_result(bracket_poses):
    part, _ = bracket_poses
    t = compute_grasps(part).timing_s
    for k in ("collision_shapes", "collision_part", "collision_part_boxes", "collision_part_coal", "collision_table",
              "collision_obstacle"):
        assert t[k] >= 0.0
    assert t["collision_part_boxes"] + t["collision_part_coal"] <= t["collision_part"] <= t["collision"]
    parts = [t[k] for k in ("quality_patches", "quality_margin", "quality_epsilon")]
    assert min(parts) > 0.0 and sum(parts) <= t["quality"]


@settings(max_examples=6, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_prepass_gives_the_plain_coal_statuses_under_rigid_motion(bracket_poses, seed):
    """The part and its poses moved together (the table with them): the pre-pass still changes nothing."""
    part, ev = bracket_poses
    rng = np.random.default_rng(seed)
    M = np.eye(4)
    M[:3, :3] = Rotation.random(random_state=seed % 2**31).as_matrix()
    M[:3, 3] = rng.uniform(-0.5, 0.5, 3)
    moved = trimesh.Trimesh(part.mesh.vertices @ M[:3, :3].T + M[:3, 3], part.mesh.faces, process=False)
    idx = rng.choice(len(ev.width), size=min(1500, len(ev.width)), replace=False)
    T = M @ ev.T_part_tcp[idx]
    _, a, _, b = _both(moved, ev.gripper, ev.cell, ev.T @ np.linalg.inv(M), T, ev.width[idx])
    for x, y in zip(a, b):
        assert np.array_equal(x, y)


def test_prepass_with_mesh_shapes_gives_the_plain_coal_statuses(example_part):
    """Hull-swept mesh jaws: the pre-pass proves only apart pairs for them (on their bounding boxes)."""
    part = load_part(example_part("gear.stl"))
    g = load_gripper("round_mesh_jaws")
    rng = np.random.default_rng(4)
    n = 400
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=4).as_matrix()
    lo, hi = part.mesh.bounds
    T[:, :3, 3] = rng.uniform(lo - 0.03, hi + 0.03, (n, 3))
    w = np.round(rng.uniform(0.003, 0.049, n), 2)
    fast, a, _, b = _both(part.mesh, g, Cell("table"), np.eye(4), T, w)
    for x, y in zip(a, b):
        assert np.array_equal(x, y)
    assert fast.prepass_counts["apart"] > 0
    assert any(not s.is_box for s in fast.shape_sets(w))  # mesh shapes were checked


def test_box_answers_agree_with_python_fcl(example_part):
    """Random boxes around the gear: every apart box is free and every hit box collides for
    python-fcl, and most boxes are decided."""
    mesh = load_part(example_part("gear.stl")).mesh
    rng = np.random.default_rng(7)
    n = 3000
    lo, hi = mesh.bounds
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=7).as_matrix()
    T[:, :3, 3] = rng.uniform(lo - 0.01, hi + 0.01, (n, 3))
    h = rng.uniform(0.0005, 0.01, (n, 3))
    code = PartBoxes(mesh.vertices, mesh.faces).classify(T, h, prove_hit=True, tol=SAMPLE_DEPTH)
    m = fcl.BVHModel()
    m.beginModel(len(mesh.vertices), len(mesh.faces))
    m.addSubModel(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int32))
    m.endModel()
    part = fcl.CollisionObject(m, fcl.Transform())
    truth = np.array([fcl.collide(fcl.CollisionObject(fcl.Box(*(2 * h[i])), fcl.Transform(T[i, :3, :3], T[i, :3, 3])),
                                  part, fcl.CollisionRequest(), fcl.CollisionResult()) > 0 for i in range(n)])
    assert not np.any(truth[code == APART])
    assert np.all(truth[code == HIT])
    assert np.count_nonzero(code == APART) > 0.2 * n and np.count_nonzero(code == HIT) > 0.1 * n
    assert np.count_nonzero(code == UNSURE) < 0.05 * n


def test_box_against_one_triangle():
    """A triangle through a box with no corner inside it is a hit; one just beyond the tolerance is
    apart; one within it is unsure; a box wholly inside a closed mesh crosses nothing (apart)."""
    tol = 1e-5
    big = np.array([[-1.0, -1.0, 0.0], [3.0, -1.0, 0.0], [-1.0, 3.0, 0.0]])  # the plane z = 0, far beyond the box
    T = np.tile(np.eye(4), (4, 1, 1))
    T[:, 2, 3] = [0.0, 0.01 + 2 * tol, 0.01 + 0.5 * tol, -(0.01 + 2 * tol)]
    R = Rotation.from_euler("xyz", [0.3, -0.2, 0.1]).as_matrix()
    T[0, :3, :3] = R  # tilted, through the plane
    h = np.full((4, 3), 0.01)
    h[0] = [0.01, 0.02, 0.005]
    code = PartBoxes(big, np.array([[0, 1, 2]])).classify(T, h, prove_hit=True, tol=tol)
    assert code.tolist() == [HIT, APART, UNSURE, APART]
    assert PartBoxes(big, np.array([[0, 1, 2]])).classify(T[:1], h[:1], prove_hit=False, tol=tol).tolist() == [UNSURE]
    shell = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    inner = np.eye(4)[None]
    code = PartBoxes(shell.vertices, shell.faces).classify(inner, np.full((1, 3), 0.02), prove_hit=True)
    assert code.tolist() == [APART]


def test_compiled_prefilter_is_the_numpy_separating_axis_test():
    rng = np.random.default_rng(3)
    n = 20000
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=3).as_matrix()
    T[:, :3, 3] = rng.uniform(-0.1, 0.1, (n, 3))
    h = rng.uniform(0.001, 0.05, (n, 3))
    a, e = np.array([0.01, -0.02, 0.0]), np.array([0.06, 0.05, 0.04])
    near, within = prefilter(T, h, a, e)
    assert np.array_equal(near, ~obb_aabb_separated(T[:, :3, 3], T[:, :3, :3], h, a, e))
    ext = np.einsum("mij,mj->mi", np.abs(T[:, :3, :3]), h)
    assert np.array_equal(within, np.all(np.abs(T[:, :3, 3] - a) + ext <= e, axis=1))
    assert 0.05 < near.mean() < 0.95 and within.any()


@pytest.mark.parametrize("name", ["gear.stl", "bracket.stl"])
def test_compiled_ray_crossings_are_the_numpy_inside_test(example_part, name):
    """Random points, points on round coordinates (rays along the part's grid lines: ties) and the
    vertices: the compiled count decides as the NumPy one, and both as the winding number."""
    mesh = load_part(example_part(name)).mesh
    lo, hi = mesh.bounds
    rng = np.random.default_rng(5)
    grid = np.stack(np.meshgrid(*[np.linspace(lo[i], hi[i], 9) for i in range(3)], indexing="ij"), -1).reshape(-1, 3)
    pts = np.concatenate([rng.uniform(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo), (3000, 3)), grid])
    g = RayGrid(mesh.vertices, mesh.faces)
    ours = points_inside_compiled(g, mesh, pts)
    assert np.array_equal(ours, points_inside_tree(g, mesh, pts))
    assert np.array_equal(ours, points_inside(mesh, pts))
    assert 0.05 < ours.mean() < 0.95
    assert np.array_equal(points_inside_compiled(g, mesh, mesh.vertices), points_inside_tree(g, mesh, mesh.vertices))
