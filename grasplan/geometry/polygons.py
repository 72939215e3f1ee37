"""Convex polygons clipped and integrated, vectorised over polygons (the contact patches' geometry).

Polygons are padded arrays: ``P`` (K, N, d) with the first ``n[k]`` vertices of polygon ``k``
valid, in order. :func:`clip_polygons` clips them all to an axis-aligned half-space at once
(Sutherland-Hodgman), :func:`polygon_moments` integrates their area and first and second moments
in a plane, and :func:`equivalent_widths` turns moments into the sides of the uniform rectangle
with the same second moments.
"""
from __future__ import annotations

import numpy as np


def _gather(P: np.ndarray, idx: np.ndarray) -> np.ndarray:
    return np.take_along_axis(P, idx[..., None].repeat(P.shape[-1], axis=-1), axis=1)


def clip_polygons(P: np.ndarray, n: np.ndarray, axis: int, bound: np.ndarray,
                  keep_below: bool) -> tuple[np.ndarray, np.ndarray]:
    """Clip convex polygons to a half-space (Sutherland-Hodgman, all polygons at once).

    ``P`` (K, N, d) vertices (the first ``n[k]`` valid, in order), ``n`` (K,) counts; keeps
    ``p[axis] <= bound`` (``keep_below``) or ``p[axis] >= bound``, ``bound`` (K,). Returns the
    clipped ``(P', n')`` with ``P'`` (K, N', d)."""
    K, N, _ = P.shape
    if K == 0 or N == 0:
        return P, n
    sgn = 1.0 if keep_below else -1.0
    # only polygons with a vertex outside the half-space change (most lie inside the pad's box)
    valid = np.arange(N)[None, :] < n[:, None]
    need = np.any(valid & (sgn * (P[..., axis] - bound[:, None]) > 0), axis=1)
    if not need.all():
        if not need.any():
            return P, n
        Pc, nc = _clip_all(P[need], n[need], axis, bound[need], sgn)
        out = np.zeros((K, max(N, Pc.shape[1]), P.shape[2]))
        out[~need, :N] = P[~need]
        out[need, :Pc.shape[1]] = Pc
        n_out = n.copy()
        n_out[need] = nc
        return out, n_out
    return _clip_all(P, n, axis, bound, sgn)


def _clip_all(P: np.ndarray, n: np.ndarray, axis: int, bound: np.ndarray,
              sgn: float) -> tuple[np.ndarray, np.ndarray]:
    K, N, _ = P.shape
    i = np.arange(N)
    valid = i[None, :] < n[:, None]
    nxt = (i[None, :] + 1) % np.maximum(n[:, None], 1)
    Q = _gather(P, nxt)
    dp = sgn * (P[..., axis] - bound[:, None])
    dq = sgn * (Q[..., axis] - bound[:, None])
    in_p = dp <= 0
    cross = valid & (in_p != (dq <= 0))
    t = np.divide(dp, dp - dq, out=np.zeros_like(dp), where=cross)
    X = P + t[..., None] * (Q - P)
    out = np.stack([P, X], axis=2).reshape(K, 2 * N, -1)
    keep = np.stack([valid & in_p, cross], axis=2).reshape(K, 2 * N)
    order = np.argsort(~keep, axis=1, kind="stable")
    n_new = keep.sum(axis=1)
    m = int(n_new.max())
    return _gather(out, order[:, :m]), n_new


def polygon_moments(Y: np.ndarray, Z: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Area integrals of polygons in the (y, z) plane: ``(K, 6)`` = unsigned ``[A, int y, int z,
    int y^2, int z^2, int yz]``. ``Y``, ``Z`` (K, N), the first ``n[k]`` vertices valid."""
    K, N = Y.shape
    out = np.zeros((K, 6))
    if K == 0 or N == 0:
        return out
    i = np.arange(N)
    valid = i[None, :] < n[:, None]
    nxt = (i[None, :] + 1) % np.maximum(n[:, None], 1)
    Y1, Z1 = np.take_along_axis(Y, nxt, 1), np.take_along_axis(Z, nxt, 1)
    c = np.where(valid, Y * Z1 - Y1 * Z, 0.0)
    A = 0.5 * c.sum(1)
    out[:, 0] = A
    out[:, 1] = ((Y + Y1) * c).sum(1) / 6.0
    out[:, 2] = ((Z + Z1) * c).sum(1) / 6.0
    out[:, 3] = ((Y * Y + Y * Y1 + Y1 * Y1) * c).sum(1) / 12.0
    out[:, 4] = ((Z * Z + Z * Z1 + Z1 * Z1) * c).sum(1) / 12.0
    out[:, 5] = ((Y * Z1 + 2 * Y * Z + 2 * Y1 * Z1 + Y1 * Z) * c).sum(1) / 24.0
    return out * np.sign(A)[:, None]


def equivalent_widths(mom: np.ndarray) -> np.ndarray:
    """(..., 2) sorted widths of the uniform rectangle with the moments ``mom`` (..., 6)."""
    A = np.maximum(mom[..., 0], 1e-300)
    my, mz = mom[..., 1] / A, mom[..., 2] / A
    cyy = mom[..., 3] / A - my * my
    czz = mom[..., 4] / A - mz * mz
    cyz = mom[..., 5] / A - my * mz
    C = np.stack([np.stack([cyy, cyz], -1), np.stack([cyz, czz], -1)], -2)
    lam = np.linalg.eigvalsh(C)
    w = np.sqrt(12.0 * np.maximum(lam, 0.0))
    return np.where(mom[..., :1] > 0, w, 0.0)

