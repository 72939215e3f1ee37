"""Candidate thinning: one representative per (grasp-centre cell, axis direction) cluster."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from grasplan.candidates.antipodal_base import Candidates
from grasplan.candidates.thinning import thin_candidates


def _candidates(centres: np.ndarray, axes: np.ndarray, half_width: float = 0.01) -> Candidates:
    axes = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    c0, c1 = centres - half_width * axes, centres + half_width * axes
    contacts = np.stack([c0, c1], axis=1)
    normals = np.stack([-axes, axes], axis=1)
    n = len(centres)
    return Candidates(contacts, normals, np.full(n, 2 * half_width), np.column_stack([np.arange(n), np.arange(n) + n]))


def _brute_force(cands: Candidates, spacing: float, step_deg: float) -> set[tuple]:
    """Cluster keys computed one by one, independently of the vectorised code."""
    keys = set()
    for c in cands.contacts:
        centre = c.mean(axis=0)
        a = (c[1] - c[0]) / np.linalg.norm(c[1] - c[0])
        if a[np.argmax(np.abs(a))] < 0:
            a = -a
        off = 0.5 * (np.sqrt(5.0) - 1.0)
        keys.add(tuple(np.floor(centre / spacing + off).astype(int))
                 + tuple(np.floor(a / np.radians(step_deg) + 0.5 + off).astype(int)))
    return keys


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), spacing=st.sampled_from([0.001, 0.003, 0.01]))
def test_one_representative_per_cluster(seed, spacing):
    rng = np.random.default_rng(seed)
    n = 400
    centres = rng.uniform(-0.02, 0.02, (n, 3))
    axes = rng.normal(size=(n, 3)) * rng.choice([1, -1], size=(n, 1))
    cands = _candidates(centres, axes)
    keep = thin_candidates(cands, spacing=spacing, axis_step_deg=10.0)
    assert np.all(np.diff(keep) > 0)  # sorted, unique
    expected = _brute_force(cands, spacing, 10.0)
    assert len(keep) == len(expected)
    assert _brute_force(cands.subset(keep), spacing, 10.0) == expected  # every cluster represented once


def test_contact_order_does_not_matter():
    rng = np.random.default_rng(1)
    cands = _candidates(rng.uniform(-0.02, 0.02, (200, 3)), rng.normal(size=(200, 3)))
    swapped = Candidates(cands.contacts[:, ::-1].copy(), cands.normals[:, ::-1].copy(), cands.width, cands.faces[:, ::-1].copy())
    assert np.array_equal(thin_candidates(cands), thin_candidates(swapped))


def test_near_duplicates_collapse_and_distinct_grasps_survive():
    base = np.array([[0.0, 0.0, 0.0], [0.0005, 0.0, 0.0], [0.0, 0.0004, 0.0], [0.02, 0.0, 0.0]])
    axes = np.array([[1.0, 0, 0], [1.0, 0.001, 0], [-1.0, 0, 0], [1.0, 0, 0]])
    # the first three are within 0.5 mm of the origin: one cell (the grid walls are not at round coordinates)
    keep = thin_candidates(_candidates(base, axes), spacing=0.003)
    assert len(keep) == 2 and keep[-1] == 3
    # a perpendicular axis at the same place is a different grasp
    keep = thin_candidates(_candidates(np.zeros((2, 3)), np.array([[1.0, 0, 0], [0, 1.0, 0]])), spacing=0.003)
    assert len(keep) == 2


def test_float_noise_at_round_coordinates_does_not_split_a_grasp():
    # the same grasp twice, its centre at z = 0 give or take float noise (as CAD parts produce)
    centres = np.array([[0.0, 0.0, 6e-18], [0.0, 0.0, -1e-33], [0.015, 0.0, 0.0], [0.015 - 1e-17, 0.0, 0.0]])
    axes = np.array([[1.0, 0, 0], [1.0, 0, 1e-17], [0, 1.0, 0], [0, 1.0, -1e-17]])
    assert len(thin_candidates(_candidates(centres, axes), spacing=0.003)) == 2


def test_zero_spacing_keeps_all_and_bad_values_raise():
    rng = np.random.default_rng(2)
    cands = _candidates(rng.uniform(-0.02, 0.02, (50, 3)), rng.normal(size=(50, 3)))
    assert np.array_equal(thin_candidates(cands, spacing=0.0), np.arange(50))
    assert len(thin_candidates(Candidates.empty())) == 0
    with pytest.raises(ValueError):
        thin_candidates(cands, spacing=float("inf"))
    with pytest.raises(ValueError):
        thin_candidates(cands, axis_step_deg=0.0)
