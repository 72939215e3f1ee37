"""Polygons integrated, vectorised over polygons (the contact patches' geometry).

Polygons are padded arrays: ``Y``, ``Z`` (K, N) with the first ``n[k]`` vertices of polygon ``k``
valid, in order. :func:`polygon_moments` integrates their area and first and second moments in a
plane, and :func:`equivalent_widths` turns moments into the sides of the uniform rectangle with
the same second moments. The clipping of polygons to a finger pad is compiled
(:mod:`grasplan.grasps.quality_kernels`).
"""
from __future__ import annotations

import numpy as np


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


#: a patch of at most this area (m^2) is empty: its widths are 0
MIN_AREA = 1e-24


def equivalent_widths(mom: np.ndarray) -> np.ndarray:
    """(..., 2) sorted widths of the uniform rectangle with the moments ``mom`` (..., 6)."""
    has = mom[..., 0] > MIN_AREA
    A = np.where(has, mom[..., 0], 1.0)  # an empty patch: any finite divisor (its widths are 0)
    my, mz = mom[..., 1] / A, mom[..., 2] / A
    cyy = mom[..., 3] / A - my * my
    czz = mom[..., 4] / A - mz * mz
    cyz = mom[..., 5] / A - my * mz
    C = np.stack([np.stack([cyy, cyz], -1), np.stack([cyz, czz], -1)], -2)
    lam = np.linalg.eigvalsh(C)
    w = np.sqrt(12.0 * np.maximum(lam, 0.0))
    return np.where(has[..., None], w, 0.0)

