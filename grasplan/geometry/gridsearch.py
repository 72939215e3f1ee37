"""Fixed-radius neighbour search on a uniform grid, with NumPy alone.

The candidate stages need three neighbour queries: all pairs within a radius (the 6D line search of
:func:`grasplan.candidates.antipodal_base.stream_pairs`; the 2D face-pair search of the regions reference in the tests),
and "is any point within r" (crease proximity). ``scipy.spatial.cKDTree`` answers them, but
importing it costs about 0.3 s, a third of ``grasplan candidates`` on a 14k-triangle part. A uniform grid answers a fixed radius exactly: points are binned into cells of side
``>= r`` on (at most) three coordinates, those of widest spread; every pair within ``r`` lies in the same or an
adjacent cell, so the candidates are the pairs of the ``3^g`` neighbouring cells, filtered by the
exact distance over all coordinates.

Memory is bounded: the candidate pairs are expanded for blocks of query rows holding at most
``max_pairs`` of them (a single row with more neighbours than that is its own block: its output is
that large anyway). Results are exact (the same pairs as ``cKDTree.sparse_distance_matrix`` with
``p = 2``, up to rounding at exactly ``r``; tests compare the two).
"""
from __future__ import annotations

from collections.abc import Iterator

import numpy as np

#: candidate pairs expanded at once (each costs ~ 8 (d + 3) bytes)
MAX_PAIRS = 1_000_000
#: grid dimensions: the first GRID_DIMS coordinates are binned (3^g neighbouring cells per query)
GRID_DIMS = 3
#: cells per axis at most (so that a cell key fits an int64 for up to GRID_DIMS axes)
_MAX_CELLS = 1 << 20


class _Grid:
    """The points ``Y`` binned on a grid of side ``cell`` (>= the search radius)."""

    def __init__(self, Y: np.ndarray, r: float, cols: np.ndarray, lo: np.ndarray, hi: np.ndarray):
        span = np.maximum(hi - lo, 0.0)
        cell = max(float(r), float(span.max()) / (_MAX_CELLS - 4), 1e-300)
        self.cell, self.lo, self.cols, self.g = cell, lo, cols, len(cols)
        self.dims = (np.floor(span / cell).astype(np.int64) + 3)  # one spare cell each side
        order, self.keys, self.start, self.count = self._bin(Y)
        self.order = order

    def coords(self, P: np.ndarray) -> np.ndarray:
        return np.floor((P[:, self.cols] - self.lo) / self.cell).astype(np.int64) + 1

    def key(self, C: np.ndarray) -> np.ndarray:
        k = C[:, 0].copy()
        for d in range(1, self.g):
            k *= self.dims[d]
            k += C[:, d]
        return k

    def _bin(self, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        k = self.key(self.coords(Y))
        order = np.argsort(k, kind="stable")
        ks = k[order]
        first = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]]) if len(ks) else np.zeros(0, dtype=np.int64)
        count = np.diff(np.r_[first, len(ks)])
        return order, ks[first], first, count

    def offsets(self) -> np.ndarray:
        """(3^g, g) neighbour cell offsets."""
        return np.stack(np.meshgrid(*([np.array([-1, 0, 1])] * self.g), indexing="ij"), -1).reshape(-1, self.g)

    def ranges(self, CX: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, 3^g) start and count (into ``order``) of each query cell's neighbouring cells."""
        n = len(CX)
        offs = self.offsets()
        start = np.zeros((n, len(offs)), dtype=np.int64)
        count = np.zeros((n, len(offs)), dtype=np.int64)
        if len(self.keys) == 0:
            return start, count
        for o, off in enumerate(offs):
            k = self.key(CX + off)
            pos = np.minimum(np.searchsorted(self.keys, k), len(self.keys) - 1)
            hit = self.keys[pos] == k
            start[hit, o] = self.start[pos[hit]]
            count[hit, o] = self.count[pos[hit]]
        return start, count


def pairs_within(X: np.ndarray, Y: np.ndarray, r: float, *, max_pairs: int = MAX_PAIRS
                 ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Chunks ``(i, j)`` (int64) of every pair with ``|X[i] - Y[j]| <= r`` (Euclidean over all ``d``
    columns), each pair once, ``i`` ascending over the chunks. ``X`` (n, d), ``Y`` (m, d), ``r >= 0``."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    Y = np.ascontiguousarray(Y, dtype=np.float64)
    if X.ndim != 2 or Y.ndim != 2 or X.shape[1] != Y.shape[1]:
        raise ValueError(f"pairs_within: expected X (n, d) and Y (m, d), got {X.shape} and {Y.shape}")
    if not (np.isfinite(r) and r >= 0):
        raise ValueError(f"pairs_within: radius must be finite and >= 0, got {r!r}")
    if len(X) == 0 or len(Y) == 0:
        return
    lo_all = np.minimum(X.min(axis=0), Y.min(axis=0))
    hi_all = np.maximum(X.max(axis=0), Y.max(axis=0))
    # bin on the (at most GRID_DIMS) columns of widest spread: the most cells, the fewest candidates
    cols = np.sort(np.argsort(hi_all - lo_all, kind="stable")[::-1][:min(GRID_DIMS, X.shape[1])])
    grid = _Grid(Y, r, cols, lo_all[cols], hi_all[cols])
    r2 = float(r) * float(r)
    # query rows in blocks whose expanded candidate pairs stay under max_pairs
    rows_per_probe = max(1, max_pairs // max(1, 4 * len(grid.offsets())))
    for s in range(0, len(X), rows_per_probe):
        xs = np.arange(s, min(len(X), s + rows_per_probe))
        start, count = grid.ranges(grid.coords(X[xs]))
        per_row = count.sum(axis=1)
        cut = np.searchsorted(np.cumsum(per_row), np.arange(1, per_row.sum() // max_pairs + 2) * max_pairs)
        bounds = np.unique(np.r_[0, np.minimum(cut + 1, len(xs)), len(xs)])
        for b0, b1 in zip(bounds[:-1], bounds[1:]):
            st, ct = start[b0:b1].ravel(), count[b0:b1].ravel()
            keep = ct > 0
            st, ct = st[keep], ct[keep]
            owner = np.repeat(np.arange(b0, b1), count.shape[1])[keep]
            total = int(ct.sum())
            if total == 0:
                continue
            rep = np.repeat(np.arange(len(ct)), ct)
            pos = st[rep] + (np.arange(total) - np.repeat(np.cumsum(ct) - ct, ct))
            i = xs[owner[rep]]
            j = grid.order[pos]
            d = X[i] - Y[j]
            ok = np.einsum("ij,ij->i", d, d) <= r2
            i, j = i[ok], j[ok]
            if len(i):
                o = np.lexsort((j, i))
                yield i[o], j[o]


def all_pairs_within(X: np.ndarray, Y: np.ndarray, r: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`pairs_within` concatenated: ``(i, j)``."""
    got = list(pairs_within(X, Y, r))
    if not got:
        z = np.zeros(0, dtype=np.int64)
        return z, z
    return np.concatenate([a for a, _ in got]), np.concatenate([b for _, b in got])


def any_within(X: np.ndarray, Y: np.ndarray, r: np.ndarray | float) -> np.ndarray:
    """(n,) bool: some ``Y`` point lies within ``r`` (a radius, or one per ``X`` row) of ``X[i]``.
    Per-row radii are searched in classes within a factor 2 of each other."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    Y = np.ascontiguousarray(Y, dtype=np.float64)
    out = np.zeros(len(X), dtype=bool)
    rad = np.broadcast_to(np.asarray(r, dtype=np.float64), (len(X),))
    if len(X) == 0 or len(Y) == 0:
        return out
    pos = rad > 0
    base = float(rad[pos].min()) if pos.any() else 0.0
    cls = np.where(pos, np.floor(np.log2(np.maximum(rad, base) / base)) if base > 0 else 0, -1).astype(np.int64)
    for c in np.unique(cls):
        rows = np.flatnonzero(cls == c)
        rmax = float(rad[rows].max())
        for i, j in pairs_within(X[rows], Y, rmax):
            d = X[rows[i]] - Y[j]
            ok = np.einsum("ij,ij->i", d, d) <= rad[rows[i]] ** 2
            out[rows[i[ok]]] = True
    return out
