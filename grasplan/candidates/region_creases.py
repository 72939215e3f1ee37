"""Regions method, admission: faces the convexity stage calls concave only across a shallow crease.

A face is admitted when the convexity stage calls it convex, or when it is concave only because
neighbours rise above it across some (not all) of its edges -- a shallow crease the BLM does not
split (within ``180 - gamma``). Samples closer than :data:`CONCAVE_MARGIN` (the BLM's 0.1 mm strip)
to such a rising edge are dropped (:func:`near_creases`).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .antipodal_base import FaceGeometry
from ..geometry.meshdata import edge_adjacency
from ..geometry.gridsearch import any_within
from ..geometry.grouping import expand
from ..geometry.tolerance import Tolerance

if TYPE_CHECKING:
    from ..geometry.meshdata import TriangleMesh


#: samples closer than this to a rising (concave) edge of an admitted face are dropped, m (the BLM's
#: default boundary-layer width: the strip the BLM would have split off and called concave)
CONCAVE_MARGIN = 1e-4
#: a neighbour whose far corner lies more than this above a face's plane makes that edge rising, m
#: (the convexity stage's default d_shift)
RISE = 1e-5


def concave_edges(mesh: TriangleMesh, geo: FaceGeometry, tol: Tolerance, adjacency: tuple | None = None
                  ) -> np.ndarray:
    """(m, 3) bool: edge k (corner k -> k+1) of each face is *rising*: the face across it has its far
    corner more than :data:`RISE` above this face's plane (a concave edge seen from this face)."""
    F = np.asarray(mesh.faces, dtype=np.int64)
    m = len(F)
    out = np.zeros((m, 3), dtype=bool)
    adj, edges, far, slot = edge_adjacency(F, slots=True) if adjacency is None else adjacency
    if len(adj) == 0:
        return out
    V = np.asarray(mesh.vertices, dtype=np.float64)
    flat = out.reshape(-1)
    for side in (0, 1):
        f, g_far = adj[:, side], far[:, 1 - side]
        h = np.einsum("ij,ij->i", geo.n[f], V[g_far] - V[edges[:, 0]])
        flat[slot[h > RISE + tol.distance, side]] = True
    return out


def admitted_faces(mesh: TriangleMesh, convex: np.ndarray, geo: FaceGeometry, tol: Tolerance,
                   adjacency: tuple | None = None) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """Faces that hold contact areas, and the rising edges samples must keep away from.

    A face the paper calls concave only because some neighbours rise above it (a shallow crease the
    BLM does not split, its surfaces being within 180 - gamma) still has convex points away from
    those edges: it is admitted, and samples closer than :data:`CONCAVE_MARGIN` to one of its rising
    edges are dropped (the strip the BLM would have split off, applied per point). A face rising on
    all three sides stays out. Returns ``admit (m,) bool`` and the crease segments ``(a, b)`` (s, 3)."""
    convex = np.asarray(convex, dtype=bool)
    rising = concave_edges(mesh, geo, tol, adjacency)
    admit = convex | (geo.valid & ~rising.all(axis=1))
    bad = rising & ~convex[:, None] & admit[:, None]
    f, k = np.nonzero(bad)
    V = np.asarray(mesh.vertices, dtype=np.float64)
    F = np.asarray(mesh.faces, dtype=np.int64)
    return admit, (V[F[f, k]], V[F[f, (k + 1) % 3]])


def near_creases(p0: np.ndarray, p1: np.ndarray, creases: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """(k,) bool: either contact within :data:`CONCAVE_MARGIN` of a crease segment."""
    a, b = creases
    if len(a) == 0 or len(p0) == 0:
        return np.zeros(len(p0), dtype=bool)
    near = _near_segments(np.vstack([p0, p1]), a, b, CONCAVE_MARGIN)
    return near[:len(p0)] | near[len(p0):]


def _near_segments(p: np.ndarray, a: np.ndarray, b: np.ndarray, r: float) -> np.ndarray:
    """(k,) bool: points ``p`` (k, 3) within about ``r`` of any segment ``a -> b`` (s, 3) (segments
    sampled every r / 2; error below r / 4)."""
    L = np.linalg.norm(b - a, axis=1)
    # segments whose midpoint lies further than L/2 + r from every point cannot be within r of one
    # (margin 1.5 r): dropped before they are sampled (the result is the same)
    near = any_within(0.5 * (a + b), p, 0.5 * L + 1.5 * r)
    if not near.any():
        return np.zeros(len(p), dtype=bool)
    a, b, L = a[near], b[near], L[near]
    n = np.ceil(L / (0.5 * r)).astype(np.int64) + 1
    row, k = expand(n)
    t = k / np.maximum(n[row] - 1, 1)
    pts = a[row] + t[:, None] * (b[row] - a[row])
    return any_within(p, pts, r)
