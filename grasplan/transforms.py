"""Homogeneous transforms: the one boundary check, and quaternion poses for the file formats.

Every public function that takes a ``T_<parent>_<child>`` from outside checks it here (in the
spirit of pytransform3d's ``check_transform``), with the error type its caller's contract wants.
"""
from __future__ import annotations

from typing import Literal

import numpy as np

from .errors import InputError

#: rotation/last-row tolerance for transforms read from files (JSON/YAML keep about 16 digits)
RIGID_TOL = 1e-6


def check_transform(T, name: str = "T", *, batch: bool = False, error: type[Exception] = InputError,
                    tol: float = RIGID_TOL) -> np.ndarray:
    """``T`` as float64 if it is a rigid transform ``(4, 4)`` (or ``(N, 4, 4)`` with ``batch``).

    Checks shape, finiteness, last row ``0 0 0 1``, orthonormal rotation with det +1; raises
    ``error`` with a message naming ``name`` and what is wrong.
    """
    try:
        A = np.asarray(T, dtype=np.float64)
    except (TypeError, ValueError):
        raise error(f"{name}: expected a 4x4 matrix of numbers") from None
    want = "(N, 4, 4)" if batch else "(4, 4)"
    if (A.ndim != (3 if batch else 2)) or A.shape[-2:] != (4, 4):
        raise error(f"{name}: expected shape {want}, got {A.shape}")
    if not np.all(np.isfinite(A)):
        raise error(f"{name}: has NaN or infinite entries")
    B = A.reshape(-1, 4, 4)
    R = B[:, :3, :3]
    bad_row = np.abs(B[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1) > tol
    bad_rot = np.abs(R @ R.transpose(0, 2, 1) - np.eye(3)).max(axis=(1, 2)) > tol
    bad_det = np.linalg.det(R) < 0 if len(B) else np.zeros(0, dtype=bool)
    bad = bad_row | bad_rot | bad_det
    if bad.any():
        where = f"{name}[{int(np.flatnonzero(bad)[0])}]" if batch else name
        raise error(f"{where}: not a rigid transform (rotation must be orthonormal with det +1, "
                    f"last row 0 0 0 1)")
    return A


def quaternions(R: np.ndarray, *, order: Literal["wxyz", "xyzw"] = "wxyz") -> np.ndarray:
    """Unit quaternions ``(..., 4)`` of rotation matrices ``(..., 3, 3)``, scalar part >= 0."""
    from scipy.spatial.transform import Rotation  # scipy loads on first use: importing stays cheap

    R = np.asarray(R, dtype=np.float64)
    xyzw = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat().reshape(-1, 4)
    xyzw[xyzw[:, 3] < 0] *= -1.0
    q = xyzw if order == "xyzw" else xyzw[:, [3, 0, 1, 2]]
    return q.reshape(R.shape[:-2] + (4,))


def pose7(T: np.ndarray, *, order: Literal["wxyz", "xyzw"] = "wxyz") -> np.ndarray:
    """``(x, y, z, quaternion)`` of transforms ``(..., 4, 4)`` -> ``(..., 7)``."""
    T = np.asarray(T, dtype=np.float64)
    return np.concatenate([T[..., :3, 3], quaternions(T[..., :3, :3], order=order)], axis=-1)
