"""Straight TCP lines and scene checks of grasplan pick, each against an independent computation."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from grasplan.cell.model import load_cell
from grasplan.errors import InputError
from grasplan.gripper.load import load_gripper
from grasplan.robot.ik.solve import get_solver, solve_ik
from grasplan.part.mesh import load_part
from grasplan.motion.joint_paths import approach_path_reason
from grasplan.robot.ik.lines import world_fk
from grasplan.motion.grasp_motion import line_path
from grasplan.piles.checks import check_cell, overlap_warnings
from grasplan.robot.description import load_robot
from grasplan.piles.scene_file import Instance

BOX = Path(__file__).resolve().parents[1] / "examples" / "parts" / "box.stl"


@pytest.fixture(scope="module")
def ur5():
    return load_robot("ur5"), np.asarray(load_gripper("schunk_egp_c_40").T_flange_tcp)


@pytest.mark.parametrize("xyz, up", [((0.45, 0.05, 0.05), 0.10), ((0.35, -0.15, 0.12), 0.05), ((0.55, 0.1, 0.03), 0.10)])
def test_ur_line_matches_the_clik_tracker_and_fk(ur5, xyz, up):
    robot, Tf = ur5
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])  # TCP pointing down
    T[:3, 3] = xyz
    T2 = T.copy()
    T2[2, 3] += up
    sols = solve_ik(robot, T @ np.linalg.inv(Tf)).q
    assert len(sols) >= 4
    fk = get_solver(robot).clik.fk
    compared = 0
    for q in sols:
        p1, w1 = line_path(robot, T, T2, q, max_dev=0.002, T_flange_tcp=Tf)
        p2, w2 = approach_path_reason(robot, None, T, T2, q, opening=0.0, max_dev=0.002, T_flange_tcp=Tf,
                                      sample=0.004)
        if p1 is None or p2 is None:
            continue
        compared += 1
        np.testing.assert_allclose(p1, p2, atol=1e-6)  # closed form on one branch == CLIK seeded waypoint by waypoint
        for i, qi in enumerate(p1):  # every waypoint on the line, the orientation kept (Pinocchio FK)
            Ti = fk(qi) @ Tf
            np.testing.assert_allclose(Ti[:3, 3], T[:3, 3] + (T2[:3, 3] - T[:3, 3]) * i / (len(p1) - 1), atol=1e-9)
            np.testing.assert_allclose(Ti[:3, :3], T[:3, :3], atol=1e-9)
    assert compared >= 2


def test_ur_line_refuses_a_start_off_its_pose(ur5):
    robot, Tf = ur5
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = (0.45, 0.0, 0.05)
    q = solve_ik(robot, T @ np.linalg.inv(Tf)).q[0]
    path, why = line_path(robot, T, T, q + 0.05, max_dev=0.002, T_flange_tcp=Tf)
    assert path is None and why == "start"


def _inst(i, T):
    return Instance(i, "box", T)


def test_scene_checks_depths():
    part = load_part(BOX)  # 30 x 20 x 10 mm, frame at its centre
    meshes = {"box": part.mesh}
    cell = load_cell("bin")  # floor top at z = 0.01
    T = np.eye(4)
    T[:3, 3] = (0.45, 0.0, 0.015)  # resting on the floor
    check_cell([_inst("a", T)], meshes, cell, tol=0.002)
    low = T.copy()
    low[2, 3] -= 0.003
    with pytest.raises(InputError, match=r"'a' \(box\) lies 3.0 mm below the bin floor"):
        check_cell([_inst("a", low)], meshes, cell, tol=0.002)
    wall = T.copy()
    wall[0, 3] = 0.45 + 0.15 - 0.015 + 0.004  # 4 mm into the +x wall
    with pytest.raises(InputError, match="4.0 mm inside obstacle bin_wall_\\+x"):
        check_cell([_inst("w", wall)], meshes, cell, tol=0.002)
    # two boxes side by side, 4 mm into each other along x: warned, the depth about 4 mm
    b = T.copy()
    b[0, 3] += 0.030 - 0.004
    (w,) = overlap_warnings([_inst("a", T), _inst("b", b)], meshes, tol=0.002)
    depth = float(w.split("about ")[1].split(" mm")[0])
    assert "'a' and 'b'" in w and 3.0 <= depth <= 4.0 + 1e-6
    b[0, 3] = T[0, 3] + 0.030 - 0.001  # 1 mm: pose noise, no warning
    assert overlap_warnings([_inst("a", T), _inst("b", b)], meshes, tol=0.002) == []


def test_ur_line_branch_named_by_the_start_signs_is_the_best_match(ur5):
    """The line solves only the branch the start's signs name (start_branch) when it matches the
    start; the paths are those of comparing all eight branches, on random lines from random starts."""
    from grasplan.robot.ik.ur_batch import branch_many, fk_many, line, solve_one, start_branch

    robot, _ = ur5
    ur = get_solver(robot).analytic
    rng = np.random.default_rng(7)
    named = followed = 0
    for _ in range(60):
        q0 = rng.uniform(-3.0, 3.0, 6)
        T0 = fk_many(ur.chain, q0[None])[0]
        d = rng.normal(0.0, 1.0, 3)
        T1 = T0.copy()
        T1[:3, 3] += 0.1 * d / np.linalg.norm(d)
        T = np.broadcast_to(T0, (20, 4, 4)).copy()
        T[:, :3, 3] = T0[:3, 3] + 0.1 * d / np.linalg.norm(d) * (np.arange(1, 21) / 20)[:, None]
        # base = world, flange = TCP; the deviation bound off: the branch alone decides
        got = line(ur.chain, np.eye(4), np.eye(4), T0, T1, q0, robot.lower, robot.upper, sample=0.005,
                   max_dev=1.0, max_step=0.1)
        b_all = [branch_many(ur.chain, np.concatenate([T0[None], T]), b) for b in range(8)]  # every branch
        Q, valid = np.array([q for q, _ in b_all]), np.array([v for _, v in b_all])
        Q0, ok_r, ok3 = solve_one(ur.chain, T0)  # at the start, as IK solves it
        np.testing.assert_array_equal(Q[:, 0], Q0)
        np.testing.assert_array_equal(valid[:, 0], ok_r & ok3)
        gap = Q[:, 0, :] - q0
        b = int(np.argmin(np.where(valid[:, 0], np.abs(gap - 2 * np.pi * np.round(gap / (2 * np.pi))).max(axis=1),
                                   np.inf)))
        named += start_branch(ur.chain, q0, T0) == b
        if got[0] is not None:  # the path runs on the best-matching branch, unwrapped from q0
            followed += 1
            assert len(got[0]) == 21
            np.testing.assert_allclose(np.cos(got[0][1:]), np.cos(Q[b, 1:]), atol=1e-12)
            np.testing.assert_allclose(np.sin(got[0][1:]), np.sin(Q[b, 1:]), atol=1e-12)
    assert named >= 55 and followed >= 10


def test_closed_form_fk_batch_matches_pinocchio(ur5):
    """The lift's coverage test compares poses within 1e-7 m: the closed-form FK it uses must agree
    with Pinocchio's far closer than that (and fall back to Pinocchio for robots without one)."""
    robot, _ = ur5
    qs = np.random.default_rng(3).uniform(robot.lower, robot.upper, (300, robot.nq))
    np.testing.assert_allclose(world_fk(robot, qs), robot.fk_batch(qs), atol=1e-9, rtol=0)
