"""Compiled candidate facets of the exact Ferrari-Canny epsilon of two soft-finger contacts.

:func:`grasplan.grasps.wrench.ferrari_canny_pair` maps each grasp's two wrench bipyramids to the
level set ``u . w = 1`` (NumPy: the SVD, ``A``, ``GE``, ``h``, ``g0``); :func:`facet_pairs` then
solves every candidate hyperplane of one grasp at a time: the 16 x 16 (triangle, triangle) pairs
and, per contact, the 24 (edge, whole of the other contact) pairs, each a 2 x 2 linear solve. A
candidate supports the hull (a facet, the origin inside) when every primitive wrench has ``u . w
<= 1``: epsilon is the least ``1 / |u|`` over them; it separates the origin when every one has
``u . w >= 1`` (epsilon 0). The arithmetic is the vectorised form's, grasp by grasp, so no array
grows with grasps x candidates. Used by :mod:`grasplan.grasps.wrench` (``cache=True``: compiled
once, at install by :mod:`grasplan.cli.warmup`).
"""
from __future__ import annotations

import numpy as np

from ..compiled.jit import kernel


@kernel(cache=True, nogil=True)
def _triangle_pairs(A: np.ndarray, GE: np.ndarray, h0: float, h1: float, g0: np.ndarray, tri: np.ndarray,
                    tol: float) -> tuple[float, bool]:
    """(least ``1 / |u|`` over the supporting (triangle, triangle) candidates (inf: none), whether
    one separates the origin or holds it on its plane) of one grasp: ``A`` (2, 2, 4), ``GE`` (2, 6,
    4), ``g0`` (6,), ``tri`` (2, 16, 4) at the grasp's torsion radii.

    phi_k = e_alpha + lambda_k k_k: supporting iff both lambda >= 0, separating iff both <= 0; a
    singular pair with anti-parallel (or zero) columns puts the origin on a supporting plane
    (epsilon 0); with parallel ones a facet through both is found from another pair."""
    nt = tri.shape[1]
    a = np.empty((2, nt, 2))
    nrm = np.empty((2, nt))
    gt = np.empty((2, nt, 6))
    big = 1e-300
    for k in range(2):
        for s in range(nt):
            for j in range(2):
                x = 0.0
                for c in range(4):
                    x += tri[k, s, c] * A[k, j, c]
                a[k, s, j] = x
            nrm[k, s] = np.sqrt(a[k, s, 0] * a[k, s, 0] + a[k, s, 1] * a[k, s, 1])
            big = max(big, nrm[k, s])
            for j in range(6):
                x = 0.0
                for c in range(4):
                    x += tri[k, s, c] * GE[k, j, c]
                gt[k, s, j] = x
    lo = 1e-12 * big
    bst = np.inf
    out = False
    for s in range(nt):
        p0 = a[0, s, 0]
        p1 = a[0, s, 1]
        for t in range(nt):
            q0 = a[1, t, 0]
            q1 = a[1, t, 1]
            det = p0 * q1 - p1 * q0
            if abs(det) <= 1e-12 * (nrm[0, s] * nrm[1, t]):
                if p0 * q0 + p1 * q1 < 0.0 or nrm[0, s] <= lo or nrm[1, t] <= lo:
                    out = True
                continue
            l1 = (-h0 * q1 + h1 * q0) / det
            l2 = (-p0 * h1 + p1 * h0) / det
            if l1 <= tol and l2 <= tol:
                out = True
            if l1 >= -tol and l2 >= -tol:
                un = 0.0
                for j in range(6):
                    u = g0[j] + l1 * gt[0, s, j] + l2 * gt[1, t, j]
                    un += u * u
                bst = min(bst, 1.0 / np.sqrt(un))
    return bst, out


@kernel(cache=True, nogil=True)
def _edge_pairs(A: np.ndarray, GE: np.ndarray, h0: float, h1: float, g0: np.ndarray, edge: np.ndarray,
                pts: np.ndarray, tol: float) -> tuple[float, bool, bool]:
    """(least ``1 / |u|`` over the supporting (edge of contact k, whole of the other) candidates,
    whether one separates the origin, whether one's 2 x 2 system is singular) of one grasp: ``edge``
    (2, 24, 2, 4) and ``pts`` (2, 10, 4) at its torsion radii; phi_k = e_alpha + lambda k + sigma k'."""
    ne = edge.shape[1]
    npt = pts.shape[1]
    bst = np.inf
    out = False
    sing = False
    for k in range(2):
        for e in range(ne):
            m00 = 0.0
            m01 = 0.0
            m10 = 0.0
            m11 = 0.0
            for c in range(4):
                m00 += edge[k, e, 0, c] * A[k, 0, c]
                m01 += edge[k, e, 0, c] * A[k, 1, c]
                m10 += edge[k, e, 1, c] * A[k, 0, c]
                m11 += edge[k, e, 1, c] * A[k, 1, c]
            det = m00 * m11 - m01 * m10
            if abs(det) <= 1e-12 * (np.sqrt(m00 * m00 + m01 * m01) * np.sqrt(m10 * m10 + m11 * m11)):
                sing = True
                continue
            lam = (-h0 * m11 + h1 * m10) / det
            sig = (-m00 * h1 + m01 * h0) / det
            vmax = -np.inf
            vmin = np.inf
            for p in range(npt):
                val = 0.0
                for c in range(4):
                    val += (lam * edge[k, e, 0, c] + sig * edge[k, e, 1, c]) * pts[k, p, c]
                vmax = max(vmax, val)
                vmin = min(vmin, val)
            if vmin >= -tol:
                out = True
            if vmax <= tol:
                un = 0.0
                for j in range(6):
                    g_0 = 0.0
                    g_1 = 0.0
                    for c in range(4):
                        g_0 += edge[k, e, 0, c] * GE[k, j, c]
                        g_1 += edge[k, e, 1, c] * GE[k, j, c]
                    u = g0[j] + lam * g_0 + sig * g_1
                    un += u * u
                bst = min(bst, 1.0 / np.sqrt(un))
    return bst, out, sing


@kernel(cache=True, nogil=True)
def facet_pairs(A: np.ndarray, GE: np.ndarray, h: np.ndarray, g0: np.ndarray, tri0: np.ndarray, edge0: np.ndarray,
                pts0: np.ndarray, tau: np.ndarray, tol: float, best: np.ndarray, outside: np.ndarray,
                singular: np.ndarray) -> None:
    """Candidate facets of ``B`` grasps, written into ``best`` (B,) (least ``1 / |u|`` over the
    supporting candidates; inf: none), ``outside`` (B,) bool (a candidate separates the origin, or
    the origin lies on a supporting plane through it) and ``singular`` (B,) bool (an edge candidate's
    2 x 2 system is singular: the closed form does not decide the grasp).

    Per grasp ``b`` and contact ``k``: ``A[b, k]`` (2, 4) maps the contact's local wrench
    coordinates to the null-space conditions, ``GE[b, k]`` (6, 4) to ``u``; ``h[b]`` (2,) and
    ``g0[b]`` (6,) are both contacts' ``alpha`` columns summed; ``tri0`` (16, 4) the triangle
    directions, ``edge0`` (24, 2, 4) the edge direction pairs and ``pts0`` (10, 4) the local points
    at unit torsion radius (:func:`grasplan.grasps.wrench._bipyramid_dirs`), scaled here by each
    contact's torsion radius ``tau[b, k]``; ``tol`` the support test's tolerance."""
    tri = np.empty((2,) + tri0.shape)
    edge = np.empty((2,) + edge0.shape)
    pts = np.empty((2,) + pts0.shape)
    for k in range(2):
        tri[k] = tri0
        edge[k] = edge0
        pts[k] = pts0
    for b in range(A.shape[0]):
        for k in range(2):  # the torsion coordinate at this contact's radius
            inv_t = 1.0 / tau[b, k]
            for s in range(tri0.shape[0]):
                tri[k, s, 3] = tri0[s, 3] * inv_t
            for e in range(edge0.shape[0]):
                edge[k, e, 0, 3] = edge0[e, 0, 3] * inv_t
            for p in range(pts0.shape[0]):
                pts[k, p, 3] = pts0[p, 3] * tau[b, k]
        bt, out_t = _triangle_pairs(A[b], GE[b], h[b, 0], h[b, 1], g0[b], tri, tol)
        be, out_e, sing = _edge_pairs(A[b], GE[b], h[b, 0], h[b, 1], g0[b], edge, pts, tol)
        best[b] = min(bt, be)
        outside[b] = out_t or out_e
        singular[b] = sing
