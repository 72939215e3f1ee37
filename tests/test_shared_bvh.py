"""``grasplan.cell.shapes.shared_bvh``: one BVH per mesh content for every scene and filter of the
process, bounded in triangles, answering as a freshly built one does."""
from __future__ import annotations

import coal
import numpy as np
import trimesh

from grasplan.cell import shapes


def _mesh(r: float):
    m = trimesh.creation.icosphere(subdivisions=2, radius=r)
    return np.asarray(m.vertices), np.asarray(m.faces)


def _distance(model, p: np.ndarray) -> float:
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    tf = coal.Transform3s(np.eye(3), np.asarray(p, dtype=np.float64))
    return float(coal.distance(model, coal.Transform3s(), coal.Sphere(0.001), tf, req, res))


def test_the_same_content_shares_one_bvh_and_answers_as_a_fresh_one(monkeypatch):
    monkeypatch.setattr(shapes, "_SHARED", type(shapes._SHARED)())
    v, f = _mesh(0.02)
    a = shapes.shared_bvh(v, f)
    assert shapes.shared_bvh(v.copy(), f.copy()) is a  # content, not identity
    w, g = _mesh(0.03)
    b = shapes.shared_bvh(w, g)
    assert b is not a
    fresh = shapes.bvh(v, f)
    for p in np.random.default_rng(0).uniform(-0.05, 0.05, (20, 3)):
        assert _distance(a, p) == _distance(fresh, p)


def test_the_kept_bvhs_stay_within_their_triangle_bound(monkeypatch):
    monkeypatch.setattr(shapes, "_SHARED", type(shapes._SHARED)())
    v, f = _mesh(0.02)
    monkeypatch.setattr(shapes, "SHARED_BVH_TRIANGLES", 2 * len(f))
    first = shapes.shared_bvh(v, f)
    shapes.shared_bvh(*_mesh(0.03))
    assert shapes.shared_bvh(v, f) is first  # two meshes fit
    shapes.shared_bvh(*_mesh(0.04))  # a third drops the least recently used (r = 0.03)
    assert sum(n for _, n in shapes._SHARED.values()) <= 2 * len(f) and len(shapes._SHARED) == 2
    assert shapes.shared_bvh(v, f) is first
    big_v, big_f = trimesh.creation.icosphere(subdivisions=3).vertices, trimesh.creation.icosphere(subdivisions=3).faces
    assert shapes.shared_bvh(big_v, big_f) is not shapes.shared_bvh(big_v, big_f)  # over the bound: never kept


def test_a_grippers_jaw_sweeps_are_shared_by_its_colliders_and_bounded(example_part, monkeypatch):
    """Colliders of one gripper object in different poses share one sweeps table (each sweep built
    once) and give the statuses a collider with a table of its own gives; the table starts again
    once it holds ``MAX_SHARED_SWEEPS``."""
    from grasplan.cell.model import load_cell
    from grasplan.cell.resting import stable_pose
    from grasplan.grasps import collision_shapes
    from grasplan.grasps.collision import GripperCollider
    from grasplan.grasps.frames import grasp_frames
    from grasplan.gripper.load import load_gripper
    from grasplan.part.mesh import load_part
    from grasplan.candidates.pipeline import compute_candidates

    monkeypatch.setattr(collision_shapes, "_SHARED", type(collision_shapes._SHARED)())
    part = load_part(example_part("bracket.stl"), units="mm")
    g, cell = load_gripper("long_stroke_50"), load_cell()
    cand = compute_candidates(part).candidates
    fr = grasp_frames(cand, roll_step_deg=30.0)
    width = cand.width[fr.candidate]
    T = stable_pose(part.mesh, cell)
    a = GripperCollider(part.mesh, g, cell, T)
    status_a = a.check(fr.T_part_tcp, width)
    n = len(collision_shapes.shared_sweeps(g))
    assert n >= 3  # the bracket has a few distinct widths
    T2 = T.copy()
    T2[2, 3] -= 0.004  # the part 4 mm lower: more table hits
    b = GripperCollider(part.mesh, g, cell, T2)
    assert b._sweeps is a._sweeps and len(b._sweeps) == n  # nothing rebuilt for the same widths
    own = GripperCollider(part.mesh, g, cell, T2)
    own._sweeps = collision_shapes.Sweeps(g)
    assert np.array_equal(b.check(fr.T_part_tcp, width), own.check(fr.T_part_tcp, width))
    assert not np.array_equal(b.check(fr.T_part_tcp, width), status_a)  # the check saw the pose
    # the widths' rows: the last answer again for the same widths (read-only), a new one for others
    rows = b._sweeps.rows_for(width)
    assert b._sweeps.rows_for(width.copy()) is rows and not rows.flags.writeable
    assert np.array_equal(rows, own._sweeps.rows_for(width))
    other = width.copy()
    other[0] += 0.001
    rows2 = b._sweeps.rows_for(other)
    assert rows2 is not rows and np.array_equal(rows2[1:], rows[1:]) and np.array_equal(rows2, own._sweeps.rows_for(other))
    monkeypatch.setattr(collision_shapes, "MAX_SHARED_SWEEPS", n)
    assert collision_shapes.shared_sweeps(g) is not a._sweeps  # full: a new table
    assert collision_shapes.shared_sweeps(load_gripper("schunk_egp_c_40")) is not collision_shapes.shared_sweeps(g)
