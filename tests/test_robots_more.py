"""The robots beyond the UR5 and Panda (issue 23): UR3, UR10 (closed-form UR IK, one solver for the
family) and the UFactory xArm7 (7 DoF, CLIK).

* FK: grasplan's ``Robot.fk`` against a Pinocchio model built here straight from the URDF (no
  grasplan code) and against an independent chain read from the URDF XML (no Pinocchio);
* UR family: the closed form's DH lengths come from each URDF (the UR3, UR5 and UR10 differ), every
  branch verified by FK, and the sampled configuration is among the branches;
* every new robot plans the bracket example (``grasplan plan ... --units mm``) end to end with
  >= 5 planned grasps, each path re-checked by the independent python-fcl checker
  (tests/fcl_recheck.py: URDF collision geometry, self-collision, table, part).

The full plans take a few seconds per robot: the default suite plans ONE of them (``ur10``); set
``GRASPLAN_ALL_ROBOTS=1`` to plan every new robot (docs/robots.md, "Tests").
"""
from __future__ import annotations

import json
import math
import os

import numpy as np
import pinocchio as pin
import pytest

from grasplan.robot.ik.solve import get_solver, solve_ik
from grasplan.robot.description import load_robot
from test_robot import urdf_fk

NEW_ROBOTS = ["ur3", "ur10", "xarm7"]
UR_FAMILY = ["ur3", "ur5", "ur10"]
#: the robot whose full bracket plan runs in the default suite; the others need GRASPLAN_ALL_ROBOTS=1
DEFAULT_PLANNED = "ur10"
ALL = os.environ.get("GRASPLAN_ALL_ROBOTS", "") not in ("", "0")


def _planned_robots():
    out = []
    for name in NEW_ROBOTS:
        marks = [] if (ALL or name == DEFAULT_PLANNED) else [pytest.mark.skip(
            reason="full bracket plan of every robot: set GRASPLAN_ALL_ROBOTS=1 (docs/robots.md)")]
        out.append(pytest.param(name, marks=marks))
    return out


# --------------------------------------------------------------------------------------------------
# loading and FK
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", NEW_ROBOTS)
def test_loads_with_home_in_limits_and_tool_frame(name):
    r = load_robot(name)
    assert r.name == name
    assert r.nq == (6 if name.startswith("ur") else 7)
    assert r.within_limits(r.q_home)
    assert r.kind == ("ur" if name.startswith("ur") else "generic")
    # the home pose holds the flange pointing down, above the table
    T = r.fk(r.q_home)
    assert T[2, 2] == pytest.approx(-1.0, abs=1e-6)
    assert T[2, 3] > 0.1
    assert r.disabled_pairs  # the SRDF was read


@pytest.mark.parametrize("name", NEW_ROBOTS)
def test_fk_matches_pinocchio_from_the_urdf_and_the_xml_chain(name):
    r = load_robot(name)
    model = pin.buildModelFromUrdf(str(r.urdf_path))  # Pinocchio alone, not grasplan's loader
    data = model.createData()
    fid = model.getFrameId(r.tool_frame)
    rng = np.random.default_rng(7)
    for q in rng.uniform(r.lower, r.upper, size=(25, r.nq)):
        pin.framesForwardKinematics(model, data, q)
        T_pin = data.oMf[fid].homogeneous
        T_me = r.fk(q)
        np.testing.assert_allclose(T_me, r.T_world_base @ T_pin, atol=1e-10)
        T_xml = urdf_fk(r.urdf_path, dict(zip(r.joint_names, q)), r.tool_frame)
        np.testing.assert_allclose(T_me, r.T_world_base @ T_xml, atol=1e-9)


# --------------------------------------------------------------------------------------------------
# one closed-form solver for the UR family
# --------------------------------------------------------------------------------------------------
def test_ur_family_dh_lengths_come_from_each_model():
    dh = {n: get_solver(load_robot(n)).analytic for n in UR_FAMILY}
    assert all(s is not None and s.ok for s in dh.values()), {n: s and s.why for n, s in dh.items()}
    # datasheet DH lengths of each arm (Universal Robots' "DH parameters" page), m
    expect = {"ur3": (0.1519, -0.24365, -0.21325, 0.11235, 0.08535, 0.0819),
              "ur5": (0.089159, -0.425, -0.39225, 0.10915, 0.09465, 0.0823),
              "ur10": (0.1273, -0.612, -0.5723, 0.163941, 0.1157, 0.0922)}
    for n, s in dh.items():
        got = (s.d1, s.a2, s.a3, s.d4, s.d5, s.d6)
        np.testing.assert_allclose(got, expect[n], atol=1e-6, err_msg=n)


@pytest.mark.parametrize("name", ["ur3", "ur10"])
def test_ur_closed_form_recovers_random_configurations(name):
    r = load_robot(name)
    rng = np.random.default_rng(3)
    n_ok = 0
    for q in rng.uniform(-math.pi, math.pi, size=(60, 6)):
        T = r.fk(q)
        res = solve_ik(r, T, method="analytic", q_ref=q)
        assert res.ok, res.reason
        assert res.method == "analytic"
        for s in res.q:  # every branch reproduces the target (checked here by FK, not by the solver)
            np.testing.assert_allclose(r.fk(s), T, atol=1e-6)
        # the sampled configuration is one of the branches (closest to q_ref = q)
        d = np.abs((res.q[0] - q + math.pi) % (2 * math.pi) - math.pi)
        n_ok += bool(np.all(d < 1e-5))
        assert 1 <= len(res.q) <= 8
    assert n_ok == 60


def test_ur_closed_form_differs_between_arms():
    """A UR10 target beyond a UR3's reach: the UR3's closed form says out of reach, the UR10's solves."""
    ur3, ur10 = load_robot("ur3"), load_robot("ur10")
    T = ur10.fk(np.array([0.3, -1.0, 0.6, -1.2, -1.5, 0.2]))
    assert np.linalg.norm(T[:3, 3]) > 0.8
    assert solve_ik(ur10, T, method="analytic").ok
    res = solve_ik(ur3, T, method="analytic")
    assert not res.ok and res.reason.startswith("out_of_reach")


def test_xarm7_clik_reaches_random_poses():
    r = load_robot("xarm7")
    rng = np.random.default_rng(11)
    hits = 0
    for q in rng.uniform(r.lower * 0.8, r.upper * 0.8, size=(20, 7)):
        T = r.fk(q)
        res = solve_ik(r, T, seed=1)
        if res.ok:
            hits += 1
            assert res.method == "clik"
            np.testing.assert_allclose(r.fk(res.q[0]), T, atol=1e-5)
            assert r.within_limits(res.q[0])
    assert hits >= 18


# --------------------------------------------------------------------------------------------------
# the bracket example, planned end to end and re-checked independently
# --------------------------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("name", _planned_robots())
def test_bracket_plan_end_to_end_independently_verified(name, tmp_path, example_part):
    from click.testing import CliRunner

    import fcl_recheck
    from grasplan.cli import main
    from grasplan.results.reader import load_result

    out = tmp_path / f"bracket_{name}.json"
    r = CliRunner().invoke(main, ["plan", str(example_part("bracket.stl")), "--units", "mm", "--robot", name,
                                  "--top", "6", "-o", str(out)])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    assert doc["robot"]["name"] == name
    planned = [g for g in doc["grasps"] if g["status"] == "planned"]
    assert len(planned) >= 5, f"{name}: {len(planned)} planned"
    res = load_result(out)
    assert res.robot.name == name
    reports = fcl_recheck.recheck_result(res, step=0.01)
    assert len(reports) == len(planned) and all(rep.configs > 10 for rep in reports.values())
    bad = {i: rep.problems for i, rep in reports.items() if rep.problems}
    assert not bad, bad
    # each grasp pose is reached: FK of q_grasp (Pinocchio, built here) @ T_flange_tcp = the grasp TCP
    model = pin.buildModelFromUrdf(str(res.robot.urdf_path))
    data = model.createData()
    fid = model.getFrameId(res.robot.tool_frame)
    T_flange_tcp = np.asarray(doc["gripper"]["T_flange_tcp"])
    for g in planned:
        pin.framesForwardKinematics(model, data, np.asarray(g["q_grasp"]))
        T_tcp = res.robot.T_world_base @ data.oMf[fid].homogeneous @ T_flange_tcp
        np.testing.assert_allclose(T_tcp, np.asarray(doc["part"]["T_world_part"]) @ np.asarray(g["T_part_tcp"]),
                                   atol=1e-4)


def test_recheck_can_fail_for_a_new_robot(example_part):
    """The checker is not vacuous on these models: the UR10 driven through the table is flagged."""
    import fcl_recheck
    from grasplan.cell.model import load_cell
    from grasplan.gripper.load import load_gripper
    from grasplan.part.mesh import load_part

    r = load_robot("ur10")
    part = load_part(example_part("bracket.stl"), units="mm")
    world = fcl_recheck.FclWorld(r, load_gripper(), load_cell("table"), part.mesh)
    assert world.check(r.q_home, 0.05, "none", np.eye(4)) == []
    q = r.q_home.copy()
    q[1] = 0.3  # shoulder lifted below the horizontal: the forearm dives into the table
    assert any("table" in h for h in world.check(q, 0.05, "none", np.eye(4)))
