"""The plan's diversity rule: grasps in rank order, a near-duplicate of a better one (close in
position and rotation) moved behind every distinct grasp (:func:`distinct_order`; the greedy
compiled, :func:`greedy_distinct`, ``cache=True``: built at install by :mod:`grasplan.cli.warmup`)."""
from __future__ import annotations

import numpy as np

from ..compiled.jit import kernel


@kernel(cache=True)
def greedy_distinct(p: np.ndarray, R: np.ndarray, min_distance: float, cos_min: float, cell_size: float) -> np.ndarray:
    """(n,) bool, chosen: grasps ``p`` (n, 3) TCP origins, ``R`` (n, 3, 3) rotations, in rank order;
    grasp ``k`` is chosen unless an earlier chosen grasp lies within ``min_distance`` of it (``<=``)
    with a relative rotation whose cosine ``(trace - 1) / 2`` is at least ``cos_min - 1e-9``. The
    neighbours come from a grid of cells ``cell_size >= min_distance`` wide (the 27 around a grasp's
    cell)."""
    n = len(p)
    chosen = np.zeros(n, dtype=np.bool_)
    dup = np.zeros(n, dtype=np.bool_)
    if n == 0:
        return chosen
    cell = np.empty((n, 3), dtype=np.int64)
    for i in range(n):
        for a in range(3):
            cell[i, a] = np.int64(np.floor(p[i, a] / cell_size))
    lo = np.empty(3, dtype=np.int64)
    span = np.empty(3, dtype=np.int64)
    for a in range(3):
        lo[a] = cell[:, a].min() - 1
        span[a] = cell[:, a].max() - lo[a] + 2
    key = np.empty(n, dtype=np.int64)
    for i in range(n):
        key[i] = ((cell[i, 0] - lo[0]) * span[1] + (cell[i, 1] - lo[1])) * span[2] + (cell[i, 2] - lo[2])
    order = np.argsort(key, kind="mergesort")
    skey = key[order]
    r2 = min_distance * min_distance
    for k in range(n):
        if dup[k]:
            continue
        chosen[k] = True
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                for dz in range(-1, 2):
                    c0, c1, c2 = cell[k, 0] + dx - lo[0], cell[k, 1] + dy - lo[1], cell[k, 2] + dz - lo[2]
                    kk = (c0 * span[1] + c1) * span[2] + c2
                    t = np.searchsorted(skey, kk)
                    while t < n and skey[t] == kk:
                        j = order[t]
                        t += 1
                        if j <= k or dup[j]:
                            continue
                        d2 = 0.0
                        for a in range(3):
                            d = p[j, a] - p[k, a]
                            d2 += d * d
                        if d2 > r2:
                            continue
                        tr = 0.0
                        for a in range(3):
                            for b in range(3):
                                tr += R[k, a, b] * R[j, a, b]
                        if (tr - 1.0) / 2.0 >= cos_min - 1e-9:
                            dup[j] = True
    return chosen


def distinct_order(T_part_tcp: np.ndarray, order: np.ndarray, *, min_distance: float = 0.005,
                   min_angle_deg: float = 15.0) -> tuple[np.ndarray, int]:
    """``(order', n_distinct)``: ``order`` (best first) reordered so that no two of the leading
    grasps are within ``min_distance`` (TCP origins) **and** ``min_angle_deg`` (relative rotation of
    the TCP frames) of each other while distinct grasps remain: a near-duplicate of an already
    chosen grasp moves behind every distinct one (keeping its relative order); ``n_distinct``
    grasps lead. ``min_distance = 0`` keeps ``order``."""
    order = np.asarray(order, dtype=np.int64)
    if min_distance <= 0 or len(order) < 2:
        return order, len(order)
    T = np.asarray(T_part_tcp, dtype=np.float64)[order]
    p = np.ascontiguousarray(T[:, :3, 3])
    cell = max(float(min_distance), float(np.ptp(p, axis=0).max()) / 2.0 ** 20)  # at most 2^60 cells
    chosen = greedy_distinct(p, np.ascontiguousarray(T[:, :3, :3]), float(min_distance),
                             float(np.cos(np.radians(min_angle_deg))), cell)
    return np.concatenate([order[chosen], order[~chosen]]), int(np.count_nonzero(chosen))
