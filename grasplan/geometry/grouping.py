"""Vectorised grouping of integer keys and index ranges (NumPy only, no Python loop over rows).

Small building blocks of the region search (:mod:`grasplan.candidates.regions` and its modules): dense ids and
sortable keys of integer rows, all matches of two key arrays, per-group maxima, ``0 .. n - 1``
ranges per owner and batches of bounded weight.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def flat_keys(cols: Sequence[np.ndarray]) -> np.ndarray | None:
    """The rows' flat index in the box of their ranges (lexicographic order; equal rows, equal
    keys), or None when that box does not fit an int64. ``cols``: non-empty int64 columns."""
    lo = [c.min() for c in cols]
    dims = [int(c.max() - m) + 1 for c, m in zip(cols, lo)]
    if np.prod(np.array(dims, dtype=np.float64)) >= 2.0**62:
        return None
    return np.ravel_multi_index([c - m for c, m in zip(cols, lo)], dims)


def row_ids(*columns: np.ndarray) -> np.ndarray:
    """(k,) int64 dense ids of the distinct rows of integer columns (equal rows, equal ids): one flat
    int64 key when the ranges fit (a 1D unique is ~10x faster than ``unique(axis=0)``)."""
    cols = [np.asarray(c, dtype=np.int64) for c in columns]
    if len(cols[0]) == 0:
        return np.zeros(0, dtype=np.int64)
    flat = flat_keys(cols)
    if flat is not None:
        _, inv = np.unique(flat, return_inverse=True)
    else:
        _, inv = np.unique(np.column_stack(cols), axis=0, return_inverse=True)
    return inv.ravel().astype(np.int64)


def row_keys(*columns: np.ndarray) -> np.ndarray:
    """(k,) int64 keys of the rows of integer columns, ordered as the rows lexicographically (equal
    rows, equal keys): the flat index when the ranges fit, else :func:`row_ids`. Enough for sorting
    and matching (:func:`group_pairs`) without the dense renumbering's extra sort."""
    cols = [np.asarray(c, dtype=np.int64) for c in columns]
    if len(cols[0]) == 0:
        return np.zeros(0, dtype=np.int64)
    flat = flat_keys(cols)
    return flat if flat is not None else row_ids(*cols)


def unique_values(x: np.ndarray) -> np.ndarray:
    """Sorted distinct values of a 1D array, by one sort (``np.unique`` of NumPy 2 hashes a plain 1D
    call, which is tens of times slower on millions of widely spread int64 keys)."""
    y = np.sort(np.asarray(x).ravel())
    if len(y) < 2:
        return y
    return y[np.r_[True, y[1:] != y[:-1]]]


def group_pairs(key_a: np.ndarray, key_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All ``(ia, ib)`` with ``key_a[ia] == key_b[ib]`` (int64 keys), by sorting."""
    oa, ob = np.argsort(key_a, kind="stable"), np.argsort(key_b, kind="stable")
    ka, kb = key_a[oa], key_b[ob]
    lo = np.searchsorted(kb, ka, side="left")
    hi = np.searchsorted(kb, ka, side="right")
    ia, k = expand(hi - lo)
    return oa[ia], ob[lo[ia] + k]


def group_max(key: np.ndarray, val: np.ndarray, n: int) -> np.ndarray:
    """(n,) max of ``val`` per ``key`` (0 where a key has none), by one sort (``np.maximum.at`` is slow)."""
    out = np.zeros(n)
    if len(key) == 0:
        return out
    o = np.argsort(key, kind="stable")
    k = key[o]
    st = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    out[k[st]] = np.maximum.reduceat(val[o], st)
    return out


def expand(cnt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(owner, k)``: for every owner o, ``k = 0 .. cnt[o] - 1``."""
    cnt = np.asarray(cnt, dtype=np.int64)
    owner = np.repeat(np.arange(len(cnt)), cnt)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    return owner, k


def max3(a: np.ndarray) -> np.ndarray:
    """``a.max(axis=1)`` for ``a`` (k, 3, ...) by two elementwise maxima (NumPy reduces a length-3 axis slowly)."""
    return np.maximum(np.maximum(a[:, 0], a[:, 1]), a[:, 2])


def min3(a: np.ndarray) -> np.ndarray:
    """``a.min(axis=1)`` for ``a`` (k, 3, ...), see :func:`max3`."""
    return np.minimum(np.minimum(a[:, 0], a[:, 1]), a[:, 2])


def weight_batches(weight: np.ndarray, limit: int) -> list[tuple[int, int]]:
    """Consecutive index ranges whose summed weight stays near ``limit`` (at least one item each)."""
    cs = np.cumsum(weight)
    out, s = [], 0
    while s < len(weight):
        base = cs[s - 1] if s else 0
        e = int(np.searchsorted(cs, base + limit, side="right"))
        e = max(e, s + 1)
        out.append((s, e))
        s = e
    return out
