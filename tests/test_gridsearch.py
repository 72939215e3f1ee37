"""The NumPy fixed-radius grid search (issue 10: candidates without importing scipy) against
scipy's cKDTree, an independent implementation."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from grasplan.geometry.gridsearch import all_pairs_within, any_within, pairs_within


def _kd_pairs(X, Y, r):
    res = cKDTree(X).sparse_distance_matrix(cKDTree(Y), r, output_type="ndarray")
    return set(zip(res["i"].tolist(), res["j"].tolist()))


@pytest.mark.parametrize("d,n,m,r", [(2, 400, 600, 0.05), (3, 1500, 1200, 0.03), (6, 800, 900, 0.25),
                                     (6, 50, 5, 10.0), (3, 2000, 2000, 1e-4), (1, 300, 300, 0.01)])
def test_pairs_match_kdtree(d, n, m, r):
    rng = np.random.default_rng(d * 1000 + n)
    X, Y = rng.random((n, d)), rng.random((m, d))
    i, j = all_pairs_within(X, Y, r)
    got = set(zip(i.tolist(), j.tolist()))
    assert len(got) == len(i)  # each pair once
    assert got == _kd_pairs(X, Y, r)
    # small blocks (bounded memory) give the same pairs, rows ascending over the chunks
    chunks = list(pairs_within(X, Y, r, max_pairs=500))
    assert set(zip(np.concatenate([a for a, _ in chunks] or [np.zeros(0, int)]).tolist(),
                   np.concatenate([b for _, b in chunks] or [np.zeros(0, int)]).tolist())) == got
    firsts = [int(a[0]) for a, _ in chunks]
    assert firsts == sorted(firsts)


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 60), st.integers(1, 60), st.floats(0.0, 0.6), st.integers(0, 2**31 - 1), st.sampled_from([2, 3, 6]))
def test_pairs_property(n, m, r, seed, d):
    rng = np.random.default_rng(seed)
    X = np.round(rng.random((n, d)), 2)  # repeated coordinates and exact-distance ties
    Y = np.round(rng.random((m, d)), 2)
    i, j = all_pairs_within(X, Y, r)
    D = np.linalg.norm(X[:, None] - Y[None], axis=2)
    want = {(a, b) for a, b in zip(*np.nonzero(D <= r))}
    got = set(zip(i.tolist(), j.tolist()))
    # exact up to rounding at |x - y| == r
    assert {p for p in got ^ want if abs(D[p] - r) > 1e-12} == set()


def test_any_within_with_per_row_radii_matches_kdtree():
    rng = np.random.default_rng(7)
    X, Y = rng.random((3000, 3)), rng.random((1500, 3))
    rad = rng.random(3000) * 0.06
    d, _ = cKDTree(Y).query(X, k=1)
    assert np.array_equal(any_within(X, Y, rad), d <= rad)
    assert np.array_equal(any_within(X, Y, 0.02), d <= 0.02)
    assert not any_within(X, np.zeros((0, 3)), 1.0).any()


def test_bad_input():
    with pytest.raises(ValueError, match="radius"):
        list(pairs_within(np.zeros((2, 3)), np.zeros((2, 3)), -1.0))
    with pytest.raises(ValueError, match="expected X"):
        list(pairs_within(np.zeros((2, 3)), np.zeros((2, 2)), 1.0))
