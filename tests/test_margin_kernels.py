"""The compiled gravity margin and table test against their definitions written out plainly:
``margin_of_loads`` is the bisection that tests every load at every step (its shortcut, one load per
step then every load at the result, gives the same bits), ``margin_summary`` is the count of margins
>= 1 and their maximum, and ``boxes_below`` is the NumPy world-z test of a box's lowest corner."""
from __future__ import annotations

import numpy as np
import pytest

from grasplan.grasps import collision_boxes, quality_kernels
from test_compiled import _rotations


def _margin_args(rng: np.random.Generator, M: int, D: int, force: float) -> tuple:
    """``margin_of_loads``'s arguments for M grasps and D loads, with the grip force ``force`` N:
    margins from 0 (slips at the bracket's bottom) to the bracket's top."""
    one = [np.abs(rng.normal(size=M)) * 0.01 + 0.001 for _ in range(5)]
    one[0][: M // 8] = 0.0  # point contacts: no pad moment
    return (_rotations(rng, M), rng.normal(size=(M, 3)) * 0.02, rng.normal(size=3) * 0.01,
            rng.normal(size=(D, 3)) * 10.0, *one, force, 0.3, 1e-3, np.log(1e-4), np.log(1e4), 36)


def _definition(args: tuple) -> np.ndarray:
    """The margin as defined: bisection on log s, every load tested at every step, exp(lo) at the
    end when every load holds there, else 0 (the per-load test is the kernel's own, run as Python)."""
    R, p, com, f, arm0, arm1, inv_w, L0, L1, F, mu, lmin, log_lo, log_hi, iterations = args
    holds = quality_kernels._load_holds.py_func
    D = len(f)
    out = np.zeros(len(R))
    for m in range(len(R)):
        fx, fy, fz, tau, tp, uy, uz = (np.empty(D) for _ in range(7))
        quality_kernels._tcp_loads.py_func(m, R, p, com, f, fx, fy, fz, tau, tp, uy, uz)

        def all_hold(s: float) -> bool:
            return all(holds(s, d, fx, fy, fz, tau, tp, uy, uz, arm0[m], arm1[m], inv_w[m], L0[m], L1[m], F, mu, lmin)
                       for d in range(D))
        lo, hi = log_lo, log_hi
        for _ in range(iterations):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if all_hold(np.exp(mid)) else (lo, mid)
        out[m] = np.exp(lo) if all_hold(np.exp(lo)) else 0.0
    return out


@pytest.mark.parametrize("seed", range(4))
def test_margin_of_loads_is_the_bisection_over_every_load(seed):
    rng = np.random.default_rng(seed)
    for force in (5.0, 70.0, 2000.0):
        args = _margin_args(rng, 60, 17, force)
        got, want = quality_kernels.margin_of_loads(*args), _definition(args)
        assert np.array_equal(got.view(np.int64), want.view(np.int64)), force
        assert np.any(got > 0) or force == 5.0


@pytest.mark.parametrize("seed", range(6))
def test_margin_summary_counts_and_tops_the_margins(seed):
    rng = np.random.default_rng(100 + seed)
    seen_both = False
    for force in (1.0, 30.0, 70.0, 300.0, 5000.0):
        args = _margin_args(rng, 200, 17, force)
        margins = quality_kernels.margin_of_loads(*args)
        n, best = quality_kernels.margin_summary(*args)
        assert n == int(np.count_nonzero(margins >= 1.0)) and best == margins.max()
        seen_both |= 0 < n < len(margins)
    assert seen_both, "some forces put margins on both sides of 1"
    empty = tuple(a[:0] if isinstance(a, np.ndarray) and a.ndim and a.shape[0] == 200 else a for a in args)
    assert quality_kernels.margin_summary(*empty) == (0, 0.0)


def _below_definition(zrow, T, Tg, half, index, limit):
    zr_tcp = np.einsum("j,mjk->mk", zrow, T)
    v = np.zeros(len(T), dtype=np.int64) if not len(index) else index
    zr = np.einsum("mj,mjk->mk", zr_tcp, Tg[v])
    return zr[:, 3] - np.sum(np.abs(zr[:, :3]) * half[v], axis=1) < limit


@pytest.mark.parametrize("seed", range(4))
def test_boxes_below_is_the_lowest_corner_test(seed):
    rng = np.random.default_rng(seed)
    M, V = 500, 7
    T = np.zeros((M, 4, 4))
    T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = _rotations(rng, M), rng.normal(size=(M, 3)) * 0.05, 1.0
    Tg = np.zeros((V, 4, 4))
    Tg[:, :3, :3], Tg[:, :3, 3], Tg[:, 3, 3] = _rotations(rng, V), rng.normal(size=(V, 3)) * 0.02, 1.0
    half = rng.uniform(0.001, 0.03, size=(V, 3))
    zrow = np.array([*_rotations(rng, 1)[0, 2], 0.01])
    index = rng.integers(0, V, size=M)
    for idx in (index, np.zeros(0, dtype=np.int64)):
        # limits at the boxes' own lowest corners: every pose sits on the boundary of the test
        zr = np.einsum("mj,mjk->mk", np.einsum("j,mjk->mk", zrow, T), Tg[idx if len(idx) else np.zeros(M, int)])
        lows = zr[:, 3] - np.sum(np.abs(zr[:, :3]) * half[idx if len(idx) else np.zeros(M, int)], axis=1)
        for limit in (0.0, float(np.median(lows)), float(lows[3]), float(np.nextafter(lows[5], np.inf))):
            got = collision_boxes.boxes_below(zrow, T, Tg, half, idx, limit)
            want = _below_definition(zrow, T, Tg, half, idx, limit)
            assert got.dtype == bool and np.array_equal(got, want), limit
            assert 0 < got.sum() < M or limit == 0.0
