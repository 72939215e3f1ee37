"""IK: closed-form UR solver (8 branches) and CLIK, checked by FK round trips."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from grasplan.errors import InputError
from grasplan.robot.ik.solve import IKResult, get_solver, solve_ik, wrap_to_limits
from grasplan.geometry.transforms import pose_error
from grasplan.robot.description import load_robot

ROBOTS = Path(__file__).resolve().parents[1] / "robots"


def _random_reachable(robot, n, seed):
    rng = np.random.default_rng(seed)
    Q = rng.uniform(robot.lower, robot.upper, size=(n, robot.nq))
    return Q, np.stack([robot.fk(q) for q in Q])


def _assert_solutions(robot, res: IKResult, T, tol=1e-6):
    assert res.q.shape[1] == robot.nq
    for q in res.q:
        assert robot.within_limits(q, tol=0.0)
        dp, dr = pose_error(robot.fk(q), T)
        assert dp <= tol and dr <= tol


@pytest.mark.slow
def test_ur5_analytic_1000_random_poses():
    r = load_robot("ur5")
    Q, Ts = _random_reachable(r, 1000, seed=0)
    ok = 0
    n_found_original = 0
    for q, T in zip(Q, Ts):
        res = solve_ik(r, T)
        if res.ok:
            ok += 1
            assert res.reason == "ok" and res.method == "analytic"
            _assert_solutions(r, res, T)
            # the configuration we came from is one of the branches (modulo 2 pi per joint)
            d = np.abs((res.q - q + math.pi) % (2 * math.pi) - math.pi)
            n_found_original += bool(np.any(np.all(d < 1e-6, axis=1)))
    assert ok >= 990
    assert n_found_original >= 990


def test_ur5_eight_branches_are_distinct_and_sorted():
    r = load_robot("ur5")
    q = np.array([0.4, -1.6, 1.4, -1.2, -1.5, 0.3])  # generic, near home, all 8 branches in reach
    T = r.fk(q)
    res = solve_ik(r, T)
    assert len(res) == 8
    _assert_solutions(r, res, T)
    # distinct shoulder/elbow/wrist branches: the sign pattern of (theta3, theta5) and 2 values of theta1
    assert len({(round(float(s[0]) % (2 * math.pi), 6), np.sign(s[2]), np.sign(math.sin(s[4]))) for s in res.q}) == 8
    dist = np.linalg.norm(res.q - r.q_home, axis=1)
    assert np.all(np.diff(dist) >= 0)
    # the closest solution is also the closest to q_home among all 2 pi-equivalents within limits
    res_ref = solve_ik(r, T, q_ref=q)
    np.testing.assert_allclose(res_ref.q[0], q, atol=1e-8)


def test_ur5_analytic_agrees_with_clik():
    r = load_robot("ur5")
    Q, Ts = _random_reachable(r, 30, seed=5)
    for q, T in zip(Q, Ts):
        a = solve_ik(r, T, method="analytic")
        c = solve_ik(r, T, method="clik", max_solutions=1, q_ref=q)
        if c.ok:
            # every CLIK solution is one of the closed-form branches (modulo 2 pi)
            d = np.abs((a.q - c.q[0] + math.pi) % (2 * math.pi) - math.pi)
            assert np.any(np.all(d < 1e-5, axis=1))


def test_ur5_clik_success_rate():
    r = load_robot("ur5")
    Q, Ts = _random_reachable(r, 60, seed=11)
    ok = 0
    for T in Ts:
        res = solve_ik(r, T, method="clik", max_solutions=1)
        ok += res.ok
        _assert_solutions(r, res, T)
    assert ok >= 0.95 * len(Ts)


@pytest.mark.slow
def test_panda_clik_100_random_poses():
    r = load_robot("panda")
    Q, Ts = _random_reachable(r, 100, seed=2)
    ok = 0
    for T in Ts:
        res = solve_ik(r, T, max_solutions=1)
        assert res.method == "clik"
        ok += res.ok
        _assert_solutions(r, res, T)
    assert ok >= 95


@pytest.mark.parametrize("name,kw", [("ur5", {}), ("ur5", {"method": "clik"}), ("panda", {})])
def test_deterministic(name, kw):
    r = load_robot(name)
    _, Ts = _random_reachable(r, 3, seed=9)
    for T in Ts:
        a = solve_ik(r, T, seed=4, **kw)
        b = solve_ik(r, T, seed=4, **kw)
        np.testing.assert_array_equal(a.q, b.q)
        assert a.reason == b.reason


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_unreachable_returns_reason_not_exception(name):
    r = load_robot(name)
    T = np.eye(4)
    T[:3, 3] = [3.0, 0.0, 0.5]
    res = solve_ik(r, T, n_random_seeds=2)
    assert not res.ok and res.q.shape == (0, r.nq)
    assert res.reason != "ok" and res.reason
    assert res.best is None


def test_joint_limits_respected_and_reported():
    r = load_robot("ur5")
    q = np.array([0.4, -1.2, 1.1, -1.4, 1.0, 0.3])
    T = r.fk(q)
    full = solve_ik(r, T)
    assert np.any(full.q[:, 2] < 0) and np.any(full.q[:, 2] > 0)
    # the limit filter itself: an elbow that may only bend one way has no equivalent of -0.5 rad
    lower, upper = r.lower.copy(), r.upper.copy()
    lower[2] = 0.0
    assert wrap_to_limits(np.array([0, 0, -0.5, 0, 0, 0.0]), lower, upper, np.zeros(6)) is None


def test_bad_input_raises():
    r = load_robot("ur5")
    with pytest.raises(InputError):
        solve_ik(r, np.eye(3))
    bad = np.eye(4)
    bad[0, 0] = 2.0
    with pytest.raises(InputError):
        solve_ik(r, bad)
    with pytest.raises(InputError):
        solve_ik(load_robot("panda"), np.eye(4), method="analytic")


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-20, 20, allow_nan=False), min_size=6, max_size=6),
       st.lists(st.floats(-6, 6, allow_nan=False), min_size=6, max_size=6))
def test_wrap_to_limits_properties(q, ref):
    r = load_robot("ur5")
    q, ref = np.array(q), np.array(ref)
    w = wrap_to_limits(q, r.lower, r.upper, ref)
    assert w is not None
    assert np.all(w >= r.lower) and np.all(w <= r.upper)
    # same angles
    np.testing.assert_allclose(np.cos(w), np.cos(q), atol=1e-9)
    np.testing.assert_allclose(np.sin(w), np.sin(q), atol=1e-9)
    # no 2 pi-equivalent within the limits is closer to ref
    for j in range(6):
        for k in (-1, 1):
            alt = w[j] + 2 * math.pi * k
            if r.lower[j] <= alt <= r.upper[j]:
                assert abs(w[j] - ref[j]) <= abs(alt - ref[j]) + 1e-9


@settings(max_examples=25, deadline=None)
@given(rpy=st.lists(st.floats(-math.pi, math.pi), min_size=3, max_size=3),
       xyz=st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3),
       qseed=st.integers(0, 10_000))
def test_ik_invariant_under_rigid_motion_of_the_cell(rpy, xyz, qseed):
    """Moving the robot base and the target by the same rigid motion leaves the joint solutions
    unchanged (T_world_base is honoured by IK as by FK)."""
    import dataclasses
    import pinocchio as pin
    M = np.eye(4)
    M[:3, :3] = pin.rpy.rpyToMatrix(*rpy)
    M[:3, 3] = xyz
    ref = load_robot("ur5")
    moved = dataclasses.replace(ref, T_world_base=M)
    q = np.random.default_rng(qseed).uniform(ref.lower, ref.upper)
    T = ref.fk(q)
    np.testing.assert_allclose(moved.fk(q), M @ T, atol=1e-12)
    for kw in ({}, {"method": "clik", "max_solutions": 1, "q_ref": q}):
        a = solve_ik(ref, T, **kw)
        b = solve_ik(moved, M @ T, **kw)
        assert len(a) == len(b)
        np.testing.assert_allclose(a.q, b.q, atol=1e-7)


def test_solver_owns_its_data_and_analytic_self_check():
    r = load_robot("ur5")
    s = get_solver(r)
    assert s.analytic is not None and s.analytic.ok, s.analytic.why
    assert s.data is not s.clik.data
    # DH lengths read from the model equal the UR5's published values
    np.testing.assert_allclose([s.analytic.d1, s.analytic.a2, s.analytic.a3, s.analytic.d4, s.analytic.d5,
                                s.analytic.d6], [0.089159, -0.425, -0.39225, 0.10915, 0.09465, 0.0823])
    # DH frame 6 is tool0 itself
    np.testing.assert_allclose(s.analytic.T_dh6_tool, np.eye(4), atol=1e-9)


# --------------------------------------------------------------------------------------------
# the IK family registry
# --------------------------------------------------------------------------------------------


def _robot_with_kind(tmp_path, name, kind, *, drop=()):
    """Robot ``name`` with its YAML's ``kind`` replaced (and the fields ``drop`` removed)."""
    lines = [f"kind: {kind}" if line.startswith("kind:") else line
             for line in (ROBOTS / f"{name}.yaml").read_text().splitlines()
             if not line.startswith(tuple(f"{f}:" for f in drop))]
    p = tmp_path / f"{name}_{kind}_{len(drop)}.yaml"
    p.write_text("\n".join(lines) + "\n")
    return load_robot(p)


def test_unknown_family_is_a_config_error_listing_the_registered_ones(tmp_path):
    from grasplan.errors import ConfigError
    from grasplan.robot.ik.registry import FAMILIES

    with pytest.raises(ConfigError) as e:
        _robot_with_kind(tmp_path, "ur5", "kuka_kr6")
    msg = str(e.value)
    assert "kuka_kr6" in msg and "field 'kind'" in msg
    assert {"ur", "generic"} <= set(FAMILIES)
    assert f"available: {', '.join(sorted(FAMILIES))}" in msg


def test_a_new_family_is_one_registration(tmp_path):
    """A family registered from outside the package (a closed form wrapping the UR one and
    counting its calls) is picked by a YAML's kind with no edit elsewhere."""
    from grasplan.robot.ik.registry import FAMILIES, IKFamily, register
    from grasplan.robot.ik.ur import URAnalytic, ur_eligibility

    calls = []

    class Counting(URAnalytic):
        def solve(self, T_base_tool):
            calls.append(1)
            return super().solve(T_base_tool)

    fam = register(IKFamily(name="ur_counting", description="test", closed_form=Counting, eligible=ur_eligibility))
    try:
        assert register(fam) is fam  # idempotent
        with pytest.raises(ValueError, match="twice"):
            register(IKFamily(name="ur_counting", description="another"))
        r = _robot_with_kind(tmp_path, "ur5", "ur_counting")
        assert r.kind == "ur_counting"
        # the controller's base frame defaults to the family's (ur: "base"; this one names none)
        assert _robot_with_kind(tmp_path, "ur5", "ur_counting", drop=["controller_base_frame"]).controller_base_frame is None
        assert _robot_with_kind(tmp_path, "ur5", "ur", drop=["controller_base_frame"]).controller_base_frame == "base"
        ref = load_robot("ur5")
        q = np.array([0.4, -1.6, 1.4, -1.2, -1.5, 0.3])
        T = ref.fk(q)
        np.testing.assert_array_equal(r.fk(q), T)
        res, res_ref = solve_ik(r, T), solve_ik(ref, T)
        assert calls and res.method == res_ref.method == "analytic" and len(res) == 8
        np.testing.assert_array_equal(res.q, res_ref.q)
    finally:
        FAMILIES.pop("ur_counting", None)


def test_family_without_closed_form_and_ineligible_robot_fall_back_to_clik(tmp_path):
    panda = load_robot("panda")
    q = np.array([0.3, -0.5, 0.2, -2.0, 0.1, 1.8, 0.6])
    T = panda.fk(q)
    with pytest.raises(InputError, match="IK family 'generic' has no closed form .*ur"):
        solve_ik(panda, T, method="analytic")
    # a 7-joint arm that claims the UR family: the closed form refuses it, CLIK solves it
    claimed = _robot_with_kind(tmp_path, "panda", "ur")
    s = get_solver(claimed)
    assert s.analytic is None and s.no_closed_form == "7 joints, not 6"
    with pytest.raises(InputError, match="7 joints, not 6"):
        solve_ik(claimed, T, method="analytic")
    res = solve_ik(claimed, T, max_solutions=1, q_ref=q)
    assert res.ok and res.method == "clik"
    _assert_solutions(claimed, res, T)
