"""The transform boundary check and the quaternion poses every file format uses."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from grasplan.errors import ConfigError, InputError
from grasplan.geometry.transforms import check_transform, pose7, quaternions


def _matrix_from_wxyz(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion, written out by hand (independent of scipy)."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _rotation(axis, angle) -> np.ndarray:
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


@settings(max_examples=60, deadline=None)
@given(axis=st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda v: np.linalg.norm(v) > 1e-3),
       angle=st.one_of(st.floats(-np.pi, np.pi), st.sampled_from([np.pi, -np.pi, np.pi - 1e-9, 0.0])))
def test_quaternions_rebuild_the_rotation(axis, angle):
    R = _rotation(axis, angle)
    wxyz = quaternions(R)
    xyzw = quaternions(R, order="xyzw")
    assert np.isclose(np.linalg.norm(wxyz), 1.0) and wxyz[0] >= 0
    assert np.allclose(xyzw, wxyz[[1, 2, 3, 0]])
    assert np.allclose(_matrix_from_wxyz(wxyz), R, atol=1e-9)


def test_pose7_batches_and_orders():
    rng = np.random.default_rng(0)
    T = np.tile(np.eye(4), (5, 2, 1, 1))
    for idx in np.ndindex(5, 2):
        T[idx][:3, :3] = _rotation(rng.normal(size=3), rng.uniform(-np.pi, np.pi))
        T[idx][:3, 3] = rng.normal(size=3)
    P = pose7(T)
    assert P.shape == (5, 2, 7)
    assert np.allclose(P[..., :3], T[..., :3, 3])
    for idx in np.ndindex(5, 2):
        assert np.allclose(_matrix_from_wxyz(P[idx][3:]), T[idx][:3, :3], atol=1e-9)
    assert np.allclose(pose7(T, order="xyzw")[..., 3:], P[..., [4, 5, 6, 3]])


def test_check_transform_accepts_rigid_and_names_what_is_wrong():
    T = np.eye(4)
    T[:3, :3] = _rotation([1, 2, 3], 0.7)
    assert check_transform(T.tolist(), "T_world_part").shape == (4, 4)
    assert check_transform(np.stack([T, T]), "T_part_tcp", batch=True).shape == (2, 4, 4)
    cases = {
        "shape": (np.eye(3), r"expected shape \(4, 4\), got \(3, 3\)"),
        "nan": (np.where(np.eye(4) == 1, np.nan, 0.0), "NaN"),
        "last row": (np.vstack([T[:3], [0, 0, 1, 1]]), "not a rigid transform"),
        "scaled": (np.diag([2.0, 1, 1, 1]), "not a rigid transform"),
        "mirror": (np.diag([-1.0, 1, 1, 1]), "not a rigid transform"),
        "text": ("abc", "expected a 4x4 matrix of numbers|expected shape"),
    }
    for what, (bad, msg) in cases.items():
        with pytest.raises(InputError, match=f"T_world_part: .*(?:{msg})") as err:
            check_transform(bad, "T_world_part")
        assert err.value.exit_code == 3, what
    with pytest.raises(ConfigError, match="T_flange_tcp"):
        check_transform(np.diag([2.0, 1, 1, 1]), "T_flange_tcp", error=ConfigError)
    batch = np.stack([T, T, np.diag([1.0, 1, 1, 2])])
    with pytest.raises(ValueError, match=r"T_part_tcp\[2\]"):
        check_transform(batch, "T_part_tcp", batch=True, error=ValueError)
    with pytest.raises(InputError, match=r"expected shape \(N, 4, 4\)"):
        check_transform(T, "T_part_tcp", batch=True)


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), where=st.integers(0, 15),
       bad=st.sampled_from([0.0, 3e-7, 3e-6, -3e-6, 1e-3, np.nan, np.inf, -np.inf]), mirror=st.booleans())
def test_one_matrix_is_judged_as_a_batch_of_one(seed, where, bad, mirror):
    """The single-matrix path (plain floats) accepts exactly what the array path accepts, and both
    what the definition (NumPy's matrix product and determinant) accepts, for one entry disturbed
    by a small, large, NaN or infinite amount, with or without a mirror."""
    rng = np.random.default_rng(seed)
    T = np.eye(4)
    T[:3, :3] = _rotation(rng.normal(size=3), rng.uniform(-np.pi, np.pi)) @ np.diag([1.0, 1.0, -1.0 if mirror else 1.0])
    T[:3, 3] = rng.uniform(-2.0, 2.0, 3)
    T.flat[where] += bad
    try:
        check_transform(T[None], "T", batch=True)
        batch_ok = True
    except InputError:
        batch_ok = False
    try:
        assert check_transform(T, "T") is T
        one_ok = True
    except InputError:
        one_ok = False
    assert one_ok == batch_ok
    # both against the definition, with NumPy's own matrix product and determinant
    R = T[:3, :3]
    with np.errstate(invalid="ignore"):
        ref_ok = bool(np.all(np.isfinite(T)) and np.abs(R @ R.T - np.eye(3)).max() <= 1e-6
                      and np.abs(T[3] - [0, 0, 0, 1]).max() <= 1e-6 and np.linalg.det(R) >= 0)
    assert batch_ok == ref_ok


def test_pose_errors_of_many_poses_are_the_offsets_and_angles_made():
    """Poses made by a known offset and a known rotation (angle from 0 to pi) from a random base:
    ``pose_errors`` gives them back for all at once (SciPy's rotation magnitude checks the angle),
    and ``pose_error`` of each one the same numbers."""
    from scipy.spatial.transform import Rotation

    from grasplan.geometry.transforms import pose_error, pose_errors

    rng = np.random.default_rng(5)
    B = np.eye(4)
    B[:3, :3] = Rotation.random(random_state=1).as_matrix()
    B[:3, 3] = rng.normal(size=3)
    angles = np.concatenate([[0.0, 1e-9, np.pi - 1e-9, np.pi], rng.uniform(0, np.pi, 20)])
    axes = rng.normal(size=(len(angles), 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    offsets = rng.normal(size=(len(angles), 3)) * rng.uniform(0, 0.1, (len(angles), 1))
    A = np.tile(B, (len(angles), 1, 1))
    A[:, :3, :3] = B[:3, :3] @ Rotation.from_rotvec(axes * angles[:, None]).as_matrix()
    A[:, :3, 3] += offsets
    dp, dr = pose_errors(A, B)
    np.testing.assert_allclose(dp, np.linalg.norm(offsets, axis=1), atol=1e-15)
    np.testing.assert_allclose(dr, angles, atol=1e-9)
    ref = Rotation.from_matrix(np.swapaxes(A[:, :3, :3], 1, 2) @ B[:3, :3]).magnitude()
    np.testing.assert_allclose(dr, ref, atol=1e-9)
    for k in range(len(A)):
        assert pose_error(A[k], B) == (dp[k], dr[k])
