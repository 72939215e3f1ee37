"""The fast paths of the collision filter checked against slower independent ones: the ray-crossing
inside test against the generalised winding number, the surface samples against the mesh, and the
part statuses of real grasp poses (where the coal-free certificates fire) against python-fcl."""
from __future__ import annotations

import fcl
import numpy as np
import pytest
import trimesh

from grasplan.cell.model import load_cell
from grasplan.grasps.collision import GripperCollider
from grasplan.geometry.containment import RayGrid, points_inside, points_inside_tree, surface_samples
from grasplan.cell.resting import stable_pose
from grasplan.grasps.frames import grasp_frames
from grasplan.gripper.load import load_gripper
from grasplan.part.mesh import load_part, part_from_trimesh


def _points(mesh, n, seed):
    rng = np.random.default_rng(seed)
    lo, hi = mesh.bounds
    pad = 0.1 * (hi - lo)
    return rng.uniform(lo - pad, hi + pad, (n, 3))


@pytest.mark.parametrize("name", ["gear.stl", "box.stl", "bracket.stl"])
def test_ray_crossing_inside_matches_winding_number(example_part, name):
    mesh = load_part(example_part(name)).mesh
    pts = _points(mesh, 1500, 0)
    # points on round coordinates: rays along the part's own grid lines (ties for an axis ray)
    lo, hi = mesh.bounds
    g = np.stack(np.meshgrid(*[np.linspace(lo[i], hi[i], 9) for i in range(3)], indexing="ij"), -1).reshape(-1, 3)
    pts = np.concatenate([pts, g])
    wind = points_inside(mesh, pts)
    ours = points_inside_tree(RayGrid(mesh.vertices, mesh.faces), mesh, pts)
    assert 0.05 < wind.mean() < 0.95  # both inside and outside points are tested
    # points on the surface (winding 1/2) may go either way in both methods; none of these are
    assert np.array_equal(ours, wind)


def test_ray_crossing_inside_of_nested_shells_matches_winding_number():
    """Two nested outward shells: winding 2 inside the inner one (inside for both methods)."""
    outer = trimesh.creation.box(extents=(0.04, 0.03, 0.02))
    inner = trimesh.creation.box(extents=(0.01, 0.01, 0.01))
    mesh = trimesh.util.concatenate([outer, inner])
    pts = np.concatenate([_points(mesh, 2000, 1), [[0.0011, 0.0007, 0.0003], [0.013, 0.002, 0.001]]])
    wind = points_inside(mesh, pts)
    ours = points_inside_tree(RayGrid(mesh.vertices, mesh.faces), mesh, pts)
    assert ours[-2] and ours[-1]
    assert np.array_equal(ours, wind)


def test_surface_samples_lie_on_the_surface(example_part):
    mesh = load_part(example_part("bracket.stl")).mesh
    s = surface_samples(mesh, spacing=0.003)
    assert len(s) > 3 * len(mesh.vertices)  # the big faces got interior samples
    # each sample lies in the plane of some triangle and inside it (barycentric coordinates >= 0)
    tri = mesh.triangles  # (F, 3, 3), a few dozen
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(b - a, c - a)
    plane = np.abs(np.einsum("fi,sfi->sf", n / np.linalg.norm(n, axis=1)[:, None], s[:, None, :] - a[None]))
    bary = np.stack([np.einsum("fi,sfi->sf", n, np.cross(q - s[:, None, :], r - s[:, None, :]))
                     for q, r in ((b, c), (c, a), (a, b))], axis=2) / np.einsum("fi,fi->f", n, n)[None, :, None]
    on = (plane < 1e-12) & np.all(bary >= -1e-9, axis=2)
    assert on.any(axis=1).all()
    # every vertex is a sample
    assert np.all(np.isin(np.round(mesh.vertices, 12).view("f8,f8,f8"), np.round(s, 12).view("f8,f8,f8")))
    # the sample count is bounded
    assert len(surface_samples(mesh, spacing=1e-5, max_samples=5000)) <= 5000 + len(mesh.vertices)


def _fcl_part(mesh):
    m = fcl.BVHModel()
    m.beginModel(len(mesh.vertices), len(mesh.faces))
    m.addSubModel(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int32))
    m.endModel()
    return fcl.CollisionObject(m, fcl.Transform())


def _fcl_part_hits(obj, mesh, gripper, T, w):
    """Any gripper shape (body, both swept jaws) hits the part: python-fcl on the surface, the
    winding number of the shape's centre for a shape wholly inside the closed part."""
    out = np.zeros(len(w), dtype=bool)
    for i in range(len(w)):
        shapes = list(gripper.body) + list(gripper.swept_fingers(gripper.pregrasp_opening(w[i]),
                                                                 gripper.close_to_opening(w[i])))
        for s in shapes:
            Tb = T[i] @ s.T_tcp_box
            box = fcl.CollisionObject(fcl.Box(*s.extents), fcl.Transform(Tb[:3, :3], Tb[:3, 3]))
            if fcl.collide(box, obj, fcl.CollisionRequest(), fcl.CollisionResult()) or \
                    points_inside(mesh, Tb[None, :3, 3])[0]:
                out[i] = True
                break
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", ["IPAGearShaft.stl", "TLess20.stl"])
def test_grasp_pose_part_hits_agree_with_python_fcl(paper, name):
    """Real grasp poses (every roll of the candidates), where the centre-inside and surface-sample
    certificates decide many poses without coal: part hits equal python-fcl's on 2000 of them."""
    from grasplan.candidates.pipeline import compute_candidates
    from grasplan.config.params import CandidateParams

    part = load_part(paper(name))
    g, cell = load_gripper("long_stroke_50"), load_cell("table")
    T_world_part = stable_pose(part.mesh, cell)
    cands = compute_candidates(part, CandidateParams(max_opening=g.max_opening)).candidates
    fr = grasp_frames(cands, roll_step_deg=15, max_width=g.max_opening, reference=T_world_part[:3, :3].T @ [0, 0, -1.0])
    w = cands.width[fr.candidate]
    col = GripperCollider(part.mesh, g, cell, T_world_part)
    ours = col.part_collision(fr.T_part_tcp, w)
    assert col.certified["sample"] > 0.1 * len(w)  # the certificates did decide poses
    idx = np.random.default_rng(0).choice(len(w), size=2000, replace=False)
    ref = _fcl_part_hits(_fcl_part(part.mesh), part.mesh, g, fr.T_part_tcp[idx], w[idx])
    assert 0.05 < ref.mean() < 0.999
    assert np.array_equal(ours[idx], ref)


def test_box_wholly_inside_a_closed_part_found_by_the_centre_test(example_part):
    """A jaw box wholly inside a closed part crosses no triangle; the ray-crossing test finds it."""
    big = part_from_trimesh(trimesh.creation.box(extents=(0.3, 0.3, 0.3)))
    col = GripperCollider(big.mesh, load_gripper("long_stroke_50"), load_cell("table"), np.eye(4))
    T = np.tile(np.eye(4), (3, 1, 1))
    T[:, :3, 3] = [[0.0, 0.0, 0.05], [0.001, -0.002, 0.04], [0.0, 0.0, 0.4]]
    hit = col.part_collision(T, np.full(3, 0.02))
    assert hit.tolist() == [True, True, False]
    assert col.coal_calls == 0 or col.certified["centre"] >= 2


def test_placed_in_box_is_the_whole_transform_then_the_box():
    """containment.placed_in_box (one axis at a time) gives exactly the rows of moving every point
    and keeping those in the box, in their order, for boxes of every size and turned poses."""
    from grasplan.geometry.containment import placed_in_box
    from grasplan.geometry.transforms import rpy_matrix

    rng = np.random.default_rng(7)
    pts = rng.uniform(-0.05, 0.05, (5000, 3))
    for k in range(40):
        T = np.eye(4)
        T[:3, :3] = rpy_matrix(*rng.uniform(-np.pi, np.pi, 3))
        T[:3, 3] = rng.normal(size=3) * 0.1
        c, h = T[:3, 3] + rng.normal(size=3) * 0.02, rng.uniform(0.0, 0.06, 3)
        lo, hi = c - h, c + h
        w = pts @ T[:3, :3].T + T[:3, 3]
        want = w[np.all((w >= lo) & (w <= hi), axis=1)]
        got = placed_in_box(pts, T, lo, hi)
        assert got.shape == want.shape and np.array_equal(got, want), k
