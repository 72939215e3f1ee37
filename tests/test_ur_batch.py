"""The compiled UR closed form (grasplan/robot/ik/ur_batch.py) against Pinocchio: every branch it
returns reaches the pose; the stack and the single pose give the same numbers; a straight line
followed on one branch keeps the pose on the line, joint steps small, within the limits, and the
codes name what fails; the line's deviation is the distance Pinocchio's FK gives."""
from __future__ import annotations

import numpy as np
import pytest

from grasplan.robot.ik.solve import get_solver, wrap_many, wrap_to_limits
from grasplan.robot.ik.ur_batch import BRANCHES, branch_many, fk_many, follow, line_deviation, solve_one
from grasplan.robot.description import load_robot
from grasplan.geometry.transforms import pose_error

TWO_PI = 2.0 * np.pi


@pytest.fixture(scope="module")
def ur5():
    robot = load_robot("ur5")
    return robot, get_solver(robot).analytic


def _pin_tool(robot, q):
    """T_base_tool by Pinocchio."""
    return np.linalg.inv(robot.T_world_base) @ robot.fk(q)


def test_every_branch_reaches_the_pose(ur5):
    robot, ur = ur5
    rng = np.random.default_rng(5)
    n_sol = 0
    for q in rng.uniform(-3.0, 3.0, (200, 6)):
        T = _pin_tool(robot, q)
        np.testing.assert_allclose(fk_many(ur.chain, q[None])[0], T, atol=1e-11)
        Q, ok_r, ok3 = solve_one(ur.chain, T)
        assert ok_r
        valid = np.flatnonzero(ok3)
        assert len(valid) >= 1
        for b in valid:
            dp, dr = pose_error(_pin_tool(robot, Q[b]), T)
            assert dp < 1e-9 and dr < 1e-9, (b, dp, dr)
            n_sol += 1
        # q itself is one of them (modulo 2 pi)
        d = Q[valid] - q
        assert np.min(np.max(np.abs(d - TWO_PI * np.round(d / TWO_PI)), axis=1)) < 1e-7
        for b in range(len(BRANCHES)):  # the stack gives the single pose's numbers
            qb, vb = branch_many(ur.chain, np.stack([T, T]), b)
            np.testing.assert_array_equal(qb[1], Q[b])
            assert vb[0] == (ok_r and ok3[b])
    assert n_sol > 1000  # most poses have all eight


def test_out_of_reach_and_the_scalar_reasons(ur5):
    robot, ur = ur5
    T = np.eye(4)
    T[:3, 3] = [2.0, 0.0, 0.3]  # beyond the arm
    sols, why = ur.solve(T)
    assert sols.shape == (0, 6) and why.startswith("out_of_reach: target beyond")
    T[:3, 3] = [0.0, 0.0, 0.5]  # the wrist centre on the base axis
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    sols, why = ur.solve(T)
    assert sols.shape == (0, 6) and "shoulder cylinder" in why


def _line(robot, ur, q0, d, m=25):
    T0 = _pin_tool(robot, q0)
    T = np.broadcast_to(T0, (m, 4, 4)).copy()
    T[:, :3, 3] = T0[:3, 3] + d * (np.arange(1, m + 1) / m)[:, None]
    return T0, T


def test_follow_keeps_the_line(ur5):
    robot, ur = ur5
    rng = np.random.default_rng(9)
    codes = {0: 0, 1: 0, 2: 0, 3: 0}
    for _ in range(150):
        q0 = rng.uniform(-2.5, 2.5, 6)
        d = rng.normal(0.0, 1.0, 3)
        d *= rng.uniform(0.02, 0.6) / np.linalg.norm(d)
        T0, T = _line(robot, ur, q0, d)
        Q0, _, ok3 = solve_one(ur.chain, T0)
        gap = Q0 - q0
        b = int(np.argmin(np.max(np.abs(gap - TWO_PI * np.round(gap / TWO_PI)), axis=1)))
        q, code = follow(ur.chain, T, q0, b, robot.lower, robot.upper, 0.1)
        codes[code] += 1
        if code == 0:
            np.testing.assert_array_equal(q[0], q0)
            assert np.max(np.abs(np.diff(q, axis=0))) <= 0.1
            assert np.all(q >= robot.lower) and np.all(q <= robot.upper)
            for k in range(1, len(q)):
                dp, dr = pose_error(_pin_tool(robot, q[k]), T[k - 1])
                assert dp < 1e-9 and dr < 1e-9
            # the deviation between waypoints: Pinocchio's FK at the midpoints, distance to the segment
            a, bb = T0[:3, 3], T[-1, :3, 3]
            mids = 0.5 * (q[:-1] + q[1:])
            P = np.array([_pin_tool(robot, m)[:3, 3] for m in mids])  # base frame, the identity T_flange_tcp
            t = np.clip((P - a) @ (bb - a) / ((bb - a) @ (bb - a)), 0.0, 1.0)
            want = np.max(np.linalg.norm(P - (a + t[:, None] * (bb - a)), axis=1))
            assert abs(line_deviation(ur.chain, q, np.eye(4), np.eye(4), a, bb) - want) < 1e-9
            Tw = robot.T_world_base  # the same in the world
            got = line_deviation(ur.chain, q, Tw, np.eye(4), Tw[:3, :3] @ a + Tw[:3, 3], Tw[:3, :3] @ bb + Tw[:3, 3])
            assert abs(got - want) < 1e-9
    assert codes[0] > 30 and codes[1] > 3 and codes[2] + codes[3] > 3, codes  # every outcome met


def test_wrap_many_is_wrap_to_limits_row_by_row():
    rng = np.random.default_rng(2)
    lower = np.array([-6.2, -3.1, -3.1, -6.2, -1.0, -0.5])
    upper = np.array([6.2, 3.1, 3.1, 6.2, 1.0, 0.5])
    Q = rng.uniform(-9.0, 9.0, (500, 6))
    ref = rng.uniform(-3.0, 3.0, 6)
    out, ok = wrap_many(Q, lower, upper, ref)
    n_none = 0
    for k, q in enumerate(Q):  # the scalar definition, written out
        want = q + np.round((ref - q) / TWO_PI) * TWO_PI
        bad = False
        for j in np.flatnonzero((want < lower - 1e-12) | (want > upper + 1e-12)):
            c = want[j] + TWO_PI * np.array([-2, -1, 1, 2])
            c = c[(c >= lower[j] - 1e-12) & (c <= upper[j] + 1e-12)]
            if not len(c):
                bad = True
                break
            want[j] = c[np.argmin(np.abs(c - ref[j]))]
        assert ok[k] == (not bad)
        n_none += bad
        if not bad:
            np.testing.assert_array_equal(out[k], np.clip(want, lower, upper))
            np.testing.assert_array_equal(wrap_to_limits(q, lower, upper, ref), out[k])
        else:
            assert wrap_to_limits(q, lower, upper, ref) is None
    assert 20 < n_none < 480


def test_max_solutions_is_a_prefix(ur5):
    """Verifying lazily (nearest first, stop at max_solutions) returns the first solutions of the
    full, deduplicated and sorted list."""
    from grasplan.robot.ik.solve import solve_ik

    robot, _ = ur5
    rng = np.random.default_rng(4)
    for q in rng.uniform(robot.lower, robot.upper, (60, 6)):
        T = robot.fk(q)
        full = solve_ik(robot, T).q
        for k in (1, 2, 4):
            np.testing.assert_array_equal(solve_ik(robot, T, max_solutions=k).q, full[:k])


def test_select_solutions_is_the_sorted_verified_deduplicated_list():
    """The compiled selection against its definition written out in NumPy: poses within the
    tolerances (some rows disturbed beyond them), nearest q_ref first, a row within the dedup
    tolerance of one kept before it dropped, at most max_keep."""
    from scipy.spatial.transform import Rotation

    from grasplan.geometry.transforms import pose_errors
    from grasplan.robot.ik.solution_kernels import select_solutions

    rng = np.random.default_rng(11)
    n_dup = n_bad = 0
    for _ in range(300):
        k = int(rng.integers(1, 9))
        W = rng.uniform(-3.0, 3.0, (k, 6))
        for i in range(1, k):  # near-copies of an earlier row
            if rng.random() < 0.3:
                W[i] = W[int(rng.integers(0, i))] + rng.uniform(-1, 1, 6) * (8e-6 if rng.random() < 0.5 else 3e-5)
        T_want = np.eye(4)
        T_want[:3, :3] = Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix()
        T_want[:3, 3] = rng.uniform(-1, 1, 3)
        T = np.repeat(T_want[None], k, axis=0)
        for i in range(k):  # some miss the pose by a position or an angle
            u = rng.random()
            if u < 0.15:
                T[i, :3, 3] += rng.normal(size=3) * 1e-5
            elif u < 0.3:
                T[i, :3, :3] = Rotation.from_rotvec(rng.normal(size=3) * 1e-5).as_matrix() @ T[i, :3, :3]
        q_ref = rng.uniform(-1, 1, 6)
        max_keep = int(rng.integers(1, 9))
        dp, dr = pose_errors(T, T_want)
        ok = (dp <= 1e-6) & (dr <= 1e-6)
        want: list[int] = []
        for i in np.argsort(np.linalg.norm(W - q_ref, axis=1), kind="stable"):
            if not ok[i]:
                continue
            if any(np.max(np.abs(W[i] - W[j])) <= 1e-5 for j in want):
                n_dup += 1
                continue
            want.append(int(i))
            if len(want) >= max_keep:
                break
        n_bad += int((~ok).sum())
        assert select_solutions(W, T, T_want, q_ref, 1e-6, 1e-6, 1e-5, max_keep).tolist() == want
    assert n_dup > 20 and n_bad > 50
