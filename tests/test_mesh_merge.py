"""The vectorised vertex merge, duplicate-face search and signed volume of grasplan.part.mesh against
trimesh's own (the load must give the same mesh as trimesh's processing did)."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from trimesh.grouping import unique_rows

import grasplan.part.mesh as gm


def _soup(seed, n_faces=400, grid=6, scale=1e-3):
    """A triangle soup whose vertices repeat (a coarse grid), with unreferenced vertices."""
    rng = np.random.default_rng(seed)
    v = rng.integers(0, grid, (3 * n_faces + 50, 3)).astype(np.float64) * scale
    v += rng.normal(0, 1e-13, v.shape)  # below the merge precision
    f = rng.choice(3 * n_faces + 50, size=(n_faces, 3), replace=False)
    return v, f


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("digits", [6, 9, 11])
def test_merge_vertices_equals_trimesh(seed, digits):
    v, f = _soup(seed)
    ref = np.zeros(len(v), dtype=bool)
    ref[f.ravel()] = True
    ours_v, ours_f = gm.merge_vertices(v, f, ref, digits)
    m = trimesh.Trimesh(vertices=v, faces=f, process=False, validate=False)
    m.merge_vertices(merge_tex=True, merge_norm=True, digits_vertex=digits)
    assert len(ours_v) < ref.sum()  # something was merged
    assert np.array_equal(ours_v, m.vertices)
    assert np.array_equal(ours_f, m.faces)


def test_group_rows_with_hash_collisions_falls_back_exactly(monkeypatch):
    """A hash that collides for different rows: the verified fallback gives trimesh's result."""
    rng = np.random.default_rng(3)
    q = rng.integers(-4, 4, (3000, 3))
    monkeypatch.setattr(gm, "_row_hash", lambda rows: (rows[:, 0] % 2).astype(np.uint64))
    first, inv = gm._group_rows(q)
    tfirst, tinv = unique_rows(q, keep_order=True)
    assert np.array_equal(first, tfirst) and np.array_equal(inv, tinv)


def test_group_rows_large_coordinates():
    """Rows beyond 21 bits per coordinate (a 1 m part at 1e-9 m) group exactly."""
    rng = np.random.default_rng(4)
    base = rng.integers(-(10 ** 9), 10 ** 9, (2000, 3))
    q = base[rng.integers(0, 2000, 7000)]
    first, inv = gm._group_rows(q)
    tfirst, tinv = unique_rows(q, keep_order=True)
    assert np.array_equal(first, tfirst) and np.array_equal(inv, tinv)


def test_first_unique_rows_and_signed_volume():
    rng = np.random.default_rng(5)
    rows = np.sort(rng.integers(0, 40, (5000, 3)), axis=1)
    ours = gm._first_unique_rows(rows, 40)
    _, ref = np.unique(rows, axis=0, return_index=True)
    assert np.array_equal(np.sort(ours), np.sort(ref))
    box = trimesh.creation.box(extents=(0.02, 0.03, 0.05))
    assert gm.signed_volume(box.vertices, box.faces) == pytest.approx(box.volume, rel=1e-12)
    assert gm.signed_volume(box.vertices, box.faces[:, ::-1]) == pytest.approx(-box.volume, rel=1e-12)
