"""Between stages 4 and 5: thin the antipodal candidates to a spatially even, non-redundant set.

The BLM multiplies candidates (the paper's point), but neighbouring slivers of one boundary layer
give contact pairs a fraction of a millimetre apart: the same grasp for any real gripper. Posing
every one of them at every roll would make the collision filter, IK and the output files scale
with the tessellation instead of the part (TLess20: 72 k candidates -> 1.7 M poses). The paper
names this as its next step ("to reduce the number of grasps, a clustering algorithm will be
tested").

Clustering: each candidate is keyed by the cell of a grid of pitch ``spacing`` (walls offset by
0.618 of the pitch, away from the round coordinates of CAD parts) that holds its grasp centre (the contacts' midpoint, part frame) and by its closing-axis direction quantised to
``axis_step_deg`` (sign-free: contact order does not matter to a symmetric gripper). Each cluster
keeps one representative: the candidate closest to the cluster's mean grasp centre (ties: lowest
index). Deterministic, vectorised, O(n log n).
"""
from __future__ import annotations

import numpy as np

from .antipodal_base import Candidates
from ..config.params import GraspParams

_GRID_OFFSET = 0.5 * (np.sqrt(5.0) - 1.0)  # 0.618..., far from the round fractions CAD uses


def cluster_ids(centre: np.ndarray, axis: np.ndarray, *, spacing: float, axis_step_deg: float) -> np.ndarray:
    """(n,) int64 dense cluster id of grasp centres ``centre`` (n, 3) with closing axes ``axis``
    (n, 3, any length > 0): the centre's cell of the offset grid of pitch ``spacing`` and the
    sign-free axis direction quantised to ``axis_step_deg`` (ids ordered as the cells)."""
    n = len(centre)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    axis = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    # sign-free direction: make the largest-magnitude component positive
    major = np.abs(axis).argmax(axis=1)
    axis *= np.where(axis[np.arange(n), major] < 0, -1.0, 1.0)[:, None]
    step = np.radians(axis_step_deg)
    # CAD coordinates sit on round numbers (z = 0, x = 15 mm): a grid with cell walls there would
    # split identical grasps by float noise (6e-18 vs -1e-33), so the walls are offset by an
    # irrational fraction of the pitch, and likewise for the axis bins
    key = np.column_stack([np.floor(centre / spacing + _GRID_OFFSET),
                           np.floor(axis / step + 0.5 + _GRID_OFFSET)]).astype(np.int64)
    key -= key.min(axis=0)
    dims = key.max(axis=0) + 1
    if np.prod(dims.astype(np.float64)) < 2.0**62:  # one int64 per key: a flat unique is ~10x faster
        flat = np.ravel_multi_index(key.T, tuple(int(d) for d in dims))
        _, cluster = np.unique(flat, return_inverse=True)
    else:
        _, cluster = np.unique(key, axis=0, return_inverse=True)
    return cluster.ravel().astype(np.int64)


def thin_candidates(candidates: Candidates, *, spacing: float = GraspParams.default("thin_spacing"),
                    axis_step_deg: float = GraspParams.default("thin_axis_deg")) -> np.ndarray:
    """Indices (sorted, int64) of one representative candidate per cluster.

    Parameters
    ----------
    candidates : Candidates
        ``n`` antipodal pairs.
    spacing : float
        Grid pitch for the grasp centre, metres; ``0`` keeps every candidate.
    axis_step_deg : float
        Quantisation of the closing-axis direction, degrees.

    Returns
    -------
    (k,) int64, k <= n
    """
    n = len(candidates)
    if not (np.isfinite(spacing) and spacing >= 0):
        raise ValueError(f"spacing must be a finite length >= 0 in metres, got {spacing!r}")
    if not 0 < axis_step_deg <= 90:
        raise ValueError(f"axis_step_deg must be in (0, 90], got {axis_step_deg!r}")
    if n == 0 or spacing == 0:
        return np.arange(n, dtype=np.int64)
    centre = candidates.contacts.mean(axis=1)
    axis = candidates.contacts[:, 1] - candidates.contacts[:, 0]
    cluster = cluster_ids(centre, axis, spacing=spacing, axis_step_deg=axis_step_deg)
    return closest_to_mean(centre, cluster, per_cluster=1)


def closest_to_mean(centre: np.ndarray, cluster: np.ndarray, *, per_cluster: int) -> np.ndarray:
    """Indices (sorted, int64) of the ``per_cluster`` points ``centre`` (n, 3) of each cluster
    (dense ids, (n,)) closest to their cluster's mean (ties: lowest index)."""
    n = len(centre)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    k = int(cluster.max()) + 1
    counts = np.bincount(cluster, minlength=k).astype(np.float64)
    mean = np.column_stack([np.bincount(cluster, weights=centre[:, d], minlength=k) for d in range(3)]) / counts[:, None]
    dist = np.linalg.norm(centre - mean[cluster], axis=1)
    order = np.lexsort((np.arange(n), dist, cluster))  # by cluster, then distance, then index
    c = cluster[order]
    start = np.flatnonzero(np.r_[True, c[1:] != c[:-1]])
    rank = np.arange(n) - np.repeat(start, np.diff(np.r_[start, n]))
    return np.sort(order[rank < per_cluster]).astype(np.int64)
