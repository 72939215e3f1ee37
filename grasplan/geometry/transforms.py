"""Homogeneous transforms: every pose helper of grasplan lives here.

- the one boundary check (:func:`check_transform`, in the spirit of pytransform3d's): every
  public function that takes a ``T_<parent>_<child>`` from outside checks it here, with the error
  type its caller's contract wants;
- construction: :func:`rpy_matrix` (R = Rz(yaw) Ry(pitch) Rx(roll)), :func:`xyz_rpy`,
  :func:`translation`; :func:`inv_rigid` (the inverse of a rigid transform);
- comparison: :func:`pose_error` (position m, rotation rad), the one definition;
- conversion: :func:`to_se3` (Pinocchio), :func:`quaternions` and :func:`pose7` for file formats;
- parsing: :func:`parse_pose_text` (``x,y,z,roll,pitch,yaw`` on a command line, lengths with
  units) and :func:`parse_place`; a YAML field's pose and ``--part-pose`` files:
  :mod:`grasplan.config.poses`.

NumPy only at import; SciPy and Pinocchio load inside the functions that need them.
"""
from __future__ import annotations

import math
import re
from collections.abc import Iterable
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError
from .units import parse_angle_deg, parse_length

if TYPE_CHECKING:
    import pinocchio as pin

#: rotation/last-row tolerance for transforms read from files (JSON/YAML keep about 16 digits)
RIGID_TOL = 1e-6


def check_transform(T: object, name: str = "T", *, batch: bool = False, error: type[Exception] = InputError,
                    tol: float = RIGID_TOL) -> np.ndarray:
    """``T`` as float64 if it is a rigid transform ``(4, 4)`` (or ``(N, 4, 4)`` with ``batch``).

    Checks shape, finiteness, last row ``0 0 0 1``, orthonormal rotation with det +1; raises
    ``error`` with a message naming ``name`` and what is wrong.
    """
    if not batch and type(T) is np.ndarray and T.shape == (4, 4) and T.dtype == np.float64:
        # one matrix, in floats (a NaN fails every comparison; x + y + z is finite only if each is)
        (r0, r1, r2, x), (r3, r4, r5, y), (r6, r7, r8, z), (l0, l1, l2, l3) = T.tolist()
        if (abs(r0 * r0 + r1 * r1 + r2 * r2 - 1.0) <= tol and abs(r3 * r3 + r4 * r4 + r5 * r5 - 1.0) <= tol
                and abs(r6 * r6 + r7 * r7 + r8 * r8 - 1.0) <= tol and abs(r0 * r3 + r1 * r4 + r2 * r5) <= tol
                and abs(r0 * r6 + r1 * r7 + r2 * r8) <= tol and abs(r3 * r6 + r4 * r7 + r5 * r8) <= tol
                and abs(l0) <= tol and abs(l1) <= tol and abs(l2) <= tol and abs(l3 - 1.0) <= tol
                and math.isfinite(x + y + z)
                and r0 * (r4 * r8 - r5 * r7) - r1 * (r3 * r8 - r5 * r6) + r2 * (r3 * r7 - r4 * r6) >= 0.0):
            return T
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
    r0, r1, r2 = B[:, 0, :3], B[:, 1, :3], B[:, 2, :3]
    bad = np.abs(B[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1) > tol
    # the rows orthonormal (the six entries of R R^T) and det R = r0 . (r1 x r2) >= 0, entry by entry
    for a, b, dot in ((r0, r0, 1.0), (r1, r1, 1.0), (r2, r2, 1.0), (r0, r1, 0.0), (r0, r2, 0.0), (r1, r2, 0.0)):
        bad |= np.abs(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2] - dot) > tol
    bad |= (r0[:, 0] * (r1[:, 1] * r2[:, 2] - r1[:, 2] * r2[:, 1]) - r0[:, 1] * (r1[:, 0] * r2[:, 2] - r1[:, 2] * r2[:, 0])
            + r0[:, 2] * (r1[:, 0] * r2[:, 1] - r1[:, 1] * r2[:, 0])) < 0.0
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


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """(3, 3) rotation R_z(yaw) R_y(pitch) R_x(roll), angles in radians."""
    cr, sr, cp, sp, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def xyz_rpy(xyz: ArrayLike, rpy: Iterable[float]) -> np.ndarray:
    """(4, 4) transform with translation ``xyz`` (m) and rotation :func:`rpy_matrix` of ``rpy`` (rad)."""
    T = np.eye(4)
    T[:3, :3] = rpy_matrix(*(float(a) for a in rpy))
    T[:3, 3] = np.asarray(xyz, dtype=np.float64)
    return T


def translation(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    """(4, 4) pure translation."""
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def inv_rigid(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid (4, 4) transform: ``[R^T, -R^T p]``."""
    Ti = np.eye(4)
    Ti[:3, :3] = T[:3, :3].T
    Ti[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return Ti


def pose_error(T_a: np.ndarray, T_b: np.ndarray) -> tuple[float, float]:
    """(position error m, rotation angle rad) between two (4, 4) poses (:func:`pose_errors`)."""
    dp, dr = pose_errors(np.asarray(T_a, dtype=np.float64)[None], T_b)
    return float(dp[0]), float(dr[0])


def pose_errors(T_a: np.ndarray, T_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(position errors (k,) m, rotation angles (k,) rad)`` of each of the poses ``T_a`` (k, 4, 4)
    against ``T_b`` (4, 4).

    The angle is ``atan2(|skew part|, (trace - 1) / 2)`` of ``R_a^T R_b``: accurate near 0 and pi,
    where ``arccos`` of the trace alone loses half the digits."""
    A = np.asarray(T_a, dtype=np.float64).reshape(-1, 4, 4)
    B = np.asarray(T_b, dtype=np.float64)
    d = A[:, :3, 3] - B[:3, 3]
    dp = np.sqrt(np.sum(d * d, axis=1))
    Rr = np.swapaxes(A[:, :3, :3], 1, 2) @ B[:3, :3]
    c = (Rr[:, 0, 0] + Rr[:, 1, 1] + Rr[:, 2, 2] - 1.0) / 2.0
    v = np.stack([Rr[:, 2, 1] - Rr[:, 1, 2], Rr[:, 0, 2] - Rr[:, 2, 0], Rr[:, 1, 0] - Rr[:, 0, 1]], axis=1)
    s = 0.5 * np.sqrt(np.sum(v * v, axis=1))
    return dp, np.arctan2(s, np.clip(c, -1.0, 1.0))


def to_se3(T: np.ndarray) -> pin.SE3:
    """A Pinocchio ``SE3`` of a (4, 4) transform (copies: the SE3 owns its arrays)."""
    import pinocchio as pin  # loads with the robot; importing this module stays cheap

    T = np.asarray(T, dtype=float)
    return pin.SE3(T[:3, :3].copy(), T[:3, 3].copy())


#: positions in cell YAMLs and on the command line lie within this distance of the world origin (m)
MAX_CELL_COORD_M = 10.0
#: angles in degrees in YAMLs and on the command line: at most this magnitude
MAX_ANGLE_DEG = 3600.0


_POSE_SPLIT = re.compile(r"\s*,\s*")


def parse_pose_text(s: str, option: str, alt: str = "") -> np.ndarray:
    """(4, 4) from ``"x,y,z,roll,pitch,yaw"`` (lengths with optional units, bare = metres; angles in
    degrees; R = Rz(yaw) Ry(pitch) Rx(roll)); InputError naming ``option`` (``alt``: other forms it takes)."""
    parts = _POSE_SPLIT.split(s.strip())
    if len(parts) != 6:
        raise InputError(f"{option}: expected 'x,y,z,roll,pitch,yaw' (m or with units; degrees){' ' + alt if alt else ''}, "
                         f"got {s[:80]!r}")
    xyz = [parse_length(v, name=f"{option} {n}", allow_negative=True) for v, n in zip(parts[:3], "xyz")]
    deg = [parse_angle_deg(v, name=f"{option} {n}") for v, n in zip(parts[3:], ("roll", "pitch", "yaw"))]
    if max(abs(a) for a in deg) > MAX_ANGLE_DEG:  # the limit cell YAMLs have: 1e308 deg is no angle
        raise InputError(f"{option}: angles in degrees, at most {MAX_ANGLE_DEG:g} in magnitude, got "
                         f"{', '.join(f'{a:g}' for a in deg)}")
    rpy = [math.radians(a) for a in deg]
    if max(abs(x) for x in xyz) > MAX_CELL_COORD_M:
        raise InputError(f"{option}: the position must be within {MAX_CELL_COORD_M} m of the world origin")
    T = np.eye(4)
    T[:3, :3] = rpy_matrix(*rpy)
    T[:3, 3] = xyz
    return T


def parse_place(text: str) -> np.ndarray:
    """``T_world_part`` (4, 4) of the part after release, from ``--place x,y,z,roll,pitch,yaw``
    (:func:`parse_pose_text`); read-only."""
    s = str(text)
    if len(s) > 4096 or "\x00" in s:
        raise InputError("--place: expected 'x,y,z,roll,pitch,yaw' (m or with units; degrees)")
    T = parse_pose_text(s, "--place")
    T.flags.writeable = False
    return T
