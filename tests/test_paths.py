"""OMPL joint paths against toy validity functions (2-6 DoF), and the straight TCP approach on the UR5.

The toy obstacles are analytic, so every returned path is re-checked here independently at
0.01 rad per joint (our own interpolation, not the module's)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from grasplan.geometry.interpolation import interpolate_path
from grasplan.motion.joint_paths import path_free_fn, plan_joint_path


def dense(path, step=0.01):
    """Independent densification: each segment in ceil(max|dq|/step) equal steps."""
    pts = [path[0]]
    for a, b in zip(path[:-1], path[1:]):
        k = int(np.ceil(np.max(np.abs(b - a)) / step)) or 1
        for i in range(1, k + 1):
            pts.append(a + (b - a) * i / k)
    return np.array(pts)


def wall_2d(q):
    """A thin wall x in [-0.05, 0.05] with a narrow gap at y in [0.9, 1.0]."""
    x, y = q[0], q[1]
    return not (-0.05 <= x <= 0.05 and not (0.9 <= y <= 1.0))


def thin_wall_2d(q):
    """A wall thinner than 2 OMPL check steps: only fine checking sees it (gap at y in [1.5, 1.6])."""
    x, y = q[0], q[1]
    return not (0.0 <= x <= 0.012 and not (1.5 <= y <= 1.6))


def balls_6d(q):
    centres = np.array([[0.0] * 6, [0.6, -0.6, 0.0, 0.6, 0.0, 0.0]])
    return bool(np.all(np.linalg.norm(q[None] - centres, axis=1) > 0.7))


LO2, HI2 = np.array([-2.0, -2.0]), np.array([2.0, 2.0])


def check_path(path, validity, q0, q1, lo, hi):
    assert path is not None
    assert path.ndim == 2 and path.shape[1] == len(q0) and len(path) >= 2
    np.testing.assert_array_equal(path[0], q0)
    np.testing.assert_array_equal(path[-1], q1)
    d = dense(path)
    assert np.all(d >= lo - 1e-12) and np.all(d <= hi + 1e-12)
    bad = [q for q in d if not validity(q)]
    assert not bad, f"{len(bad)} interpolated states collide, e.g. {bad[0]}"


@pytest.mark.parametrize("validity", [wall_2d, thin_wall_2d])
def test_2d_wall_with_gap(validity):
    q0, q1 = np.array([-1.0, -1.5]), np.array([1.0, -1.5])
    assert not path_free_fn(validity, np.stack([q0, q1]))  # the straight line is blocked
    path = plan_joint_path(validity, q0, q1, lower=LO2, upper=HI2, seed=1, time_limit=2.0)
    check_path(path, validity, q0, q1, LO2, HI2)
    # the path must go through the gap
    d = dense(path)
    crossing = d[np.argmin(np.abs(d[:, 0] - 0.006))]
    assert 0.85 <= crossing[1] <= 1.65


def test_6d_balls_and_determinism():
    lo, hi = -np.pi * np.ones(6), np.pi * np.ones(6)
    q0 = np.array([-1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    q1 = np.array([1.0, 0.0, 0.0, 0.2, 0.0, 0.0])
    p1 = plan_joint_path(balls_6d, q0, q1, lower=lo, upper=hi, seed=5, time_limit=2.0)
    check_path(p1, balls_6d, q0, q1, lo, hi)
    p2 = plan_joint_path(balls_6d, q0, q1, lower=lo, upper=hi, seed=5, time_limit=2.0)
    np.testing.assert_array_equal(p1, p2)


def test_direct_segment_when_free():
    q0, q1 = np.array([-1.0, -1.5]), np.array([-0.5, 1.5])
    path = plan_joint_path(wall_2d, q0, q1, lower=LO2, upper=HI2)
    np.testing.assert_array_equal(path, np.stack([q0, q1]))


def test_invalid_or_unreachable_goal_gives_none():
    enclosed = lambda q: not (0.5 < np.max(np.abs(q - 1.0)) < 0.6)
    q0 = np.array([-1.0, -1.0])
    assert plan_joint_path(wall_2d, q0, np.array([0.0, 0.0]), lower=LO2, upper=HI2) is None  # goal in the wall
    assert plan_joint_path(wall_2d, q0, np.array([3.0, 0.0]), lower=LO2, upper=HI2) is None  # outside limits
    assert plan_joint_path(enclosed, q0, np.array([1.0, 1.0]), lower=LO2, upper=HI2, time_limit=0.2, attempts=1) is None


def test_plain_callable_needs_limits():
    with pytest.raises(ValueError):
        plan_joint_path(wall_2d, np.zeros(2), np.ones(2))


@settings(max_examples=50, deadline=None)
@given(st.integers(2, 7), st.integers(1, 6), st.floats(0.002, 0.05), st.integers(0, 2**31 - 1))
def test_interpolate_path_properties(k, n, step, seed):
    rng = np.random.default_rng(seed)
    path = rng.uniform(-1, 1, size=(k, n))
    d = interpolate_path(path, step=step)
    assert np.max(np.abs(np.diff(d, axis=0))) <= step + 1e-12
    np.testing.assert_array_equal(d[0], path[0])
    np.testing.assert_array_equal(d[-1], path[-1])
    for w in path:  # every waypoint is in the densified path
        assert np.min(np.max(np.abs(d - w), axis=1)) < 1e-12
    np.testing.assert_allclose(d, dense(path, step), rtol=0, atol=1e-12)  # the independent densification
    np.testing.assert_allclose(interpolate_path(path[:2], step=step), dense(path[:2], step), rtol=0, atol=1e-12)


@settings(max_examples=50, deadline=None)
@given(st.integers(2, 6), st.integers(1, 6), st.floats(0.002, 0.05), st.integers(0, 2**31 - 1))
def test_interpolate_path_repeated_waypoints_and_index(k, n, step, seed):
    """The one densifier (planner, trajectory export, viewer): a repeated waypoint adds no point,
    ``return_index`` maps every waypoint (repeats included) onto its row, and no segment is split
    more finely than ceil(max |dq| / step)."""
    rng = np.random.default_rng(seed)
    base = rng.uniform(-1, 1, size=(k, n))
    path = np.repeat(base, rng.integers(1, 4, size=k), axis=0)
    d, idx = interpolate_path(path, step=step, return_index=True)
    assert idx.shape == (len(path),) and idx[0] == 0 and idx[-1] == len(d) - 1 and np.all(np.diff(idx) >= 0)
    np.testing.assert_allclose(d[idx], path, atol=1e-12)
    assert np.all(np.max(np.abs(np.diff(d, axis=0)), axis=1) > 0)  # no repeated row
    assert np.max(np.abs(np.diff(d, axis=0))) <= step + 1e-12
    pieces = np.ceil(np.max(np.abs(np.diff(base, axis=0)), axis=1) / step)
    assert len(d) == 1 + int(pieces.sum())


def test_interpolate_path_edges():
    """One waypoint; a chain of waypoints each within 1e-12 rad of the one before (all repeats, even
    where the chain drifts further); a transposed float32 path (any layout and dtype)."""
    q = np.array([[0.3, -1.2, 0.5]])
    d, idx = interpolate_path(q, return_index=True)
    np.testing.assert_array_equal(d, q)
    assert idx.tolist() == [0] and d is not q
    drift = q + np.array([[0.0], [6e-13], [1.2e-12], [1.8e-12]]) * np.array([[1.0, 0.0, 0.0]])
    d, idx = interpolate_path(drift, return_index=True)
    np.testing.assert_array_equal(d, q)
    assert idx.tolist() == [0, 0, 0, 0]
    far = np.vstack([q, q + [0.05, 0.0, 0.0], q + [0.05, 0.0, 0.0], q + [0.05, 0.021, 0.0]])
    d, idx = interpolate_path(np.asfortranarray(far.astype(np.float32).T).T, step=0.01, return_index=True)
    assert len(d) == 1 + 5 + 3 and idx.tolist() == [0, 5, 5, 8]
    np.testing.assert_allclose(d[idx], far, atol=1e-7)


# --------------------------------------------------------------------------------------------------
# straight approach on the UR5 (kinematics only: scene=None)
# --------------------------------------------------------------------------------------------------
def _pin_fk(robot):
    """Independent FK: Pinocchio on a fresh Data, T_world_tool = T_world_base @ oMf."""
    import pinocchio as pin

    data = robot.model.createData()

    def fk(q):
        pin.framesForwardKinematics(robot.model, data, np.asarray(q, dtype=np.float64))
        return np.asarray(robot.T_world_base) @ data.oMf[robot.tool_frame_id].homogeneous

    return fk


def test_approach_path_ur5_straight_line():
    from grasplan.motion.joint_paths import approach_path, approach_path_reason
    from grasplan.robot.description import load_robot

    robot = load_robot("ur5")
    fk = _pin_fk(robot)
    T_flange_tcp = np.eye(4)
    T_flange_tcp[2, 3] = 0.127
    rng = np.random.default_rng(7)
    n_ok = 0
    for _ in range(20):
        q0 = np.clip(robot.q_home + rng.uniform(-0.6, 0.6, 6), robot.lower, robot.upper)
        T_pre = fk(q0) @ T_flange_tcp
        T_grasp = T_pre.copy()
        T_grasp[:3, 3] += T_pre[:3, 2] * 0.05  # 5 cm along the TCP's +z
        path = approach_path(robot, None, T_pre, T_grasp, q0, opening=0.03, T_flange_tcp=T_flange_tcp)
        if path is None:
            continue
        n_ok += 1
        np.testing.assert_array_equal(path[0], q0)
        assert np.all(path >= robot.lower) and np.all(path <= robot.upper)
        # the executed motion: 5 samples inside every segment, independently of the module
        a, b = T_pre[:3, 3], T_grasp[:3, 3]
        u = (b - a) / np.linalg.norm(b - a)
        for qa, qb in zip(path[:-1], path[1:]):
            assert np.max(np.abs(qb - qa)) < 0.1
            for s in np.linspace(0, 1, 5):
                T = fk(qa + s * (qb - qa)) @ T_flange_tcp
                p = T[:3, 3] - a
                t = np.clip(p @ u, 0, np.linalg.norm(b - a))
                assert np.linalg.norm(p - t * u) <= 0.002
                # orientation held (tiny drift only)
                assert np.linalg.norm(T[:3, :3] - T_pre[:3, :3]) < 1e-2
        T_end = fk(path[-1]) @ T_flange_tcp
        np.testing.assert_allclose(T_end, T_grasp, atol=1e-5)
    assert n_ok >= 15
    # a start configuration that does not reach the start pose is refused
    q_bad = robot.q_home + 0.3
    T_pre = fk(robot.q_home) @ T_flange_tcp
    assert approach_path_reason(robot, None, T_pre, T_pre, q_bad, opening=0.03, T_flange_tcp=T_flange_tcp)[1] == "start"
