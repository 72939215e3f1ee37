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
