"""Straight TCP lines for a UR arm in one NumPy pass: the closed form of :mod:`grasplan.robot.ik.ur`
evaluated for every waypoint of a line at once, on the one branch the start configuration is on.

:func:`closed_form_line` is what every straight TCP line of ``plan`` and ``pick`` runs on a UR arm
(:func:`grasplan.motion.joint_paths.approach_path_reason`; other arms: its CLIK tracker), through
:func:`ur_line`: the branch (shoulder, wrist and elbow signs) is the one whose solution at the first pose
equals the start configuration (modulo 2 pi); each waypoint's joints are wrapped to the previous
waypoint's, so the path is continuous unless the branch passes a singularity (then a joint jumps
and the line is refused). Forward kinematics of the same DH chain (proven against Pinocchio when
the closed form is built) measures the joint-linear motion's distance from the line.
"""
from __future__ import annotations

import math

import numpy as np

from .solve import get_solver
from .ur import URAnalytic
from .ur_batch import BRANCHES, fk_many, follow, line_deviation, solve_one
from ..model import Robot
from ...geometry.transforms import inv_rigid

TWO_PI = 2.0 * np.pi
#: the start configuration must match its branch's solution within this (rad)
BRANCH_TOL = 1e-6


#: a start configuration this close (sine of the wrist or elbow angle, shoulder distance in m) to a
#: singularity gets every branch compared (:func:`ur_line`), not the one its signs name
SINGULAR = 1e-3


def start_branch(ur: URAnalytic, q0: np.ndarray, T0_base_tool: np.ndarray) -> int | None:
    """The branch (index into :data:`BRANCHES`) configuration ``q0`` lies on, named by its signs
    (the shoulder solution nearer ``q0[0]``, the signs of ``sin q5`` and ``sin q3``), or None
    within :data:`SINGULAR` of a singularity (where two branches meet)."""
    s5, s3 = math.sin(float(q0[4])), math.sin(float(q0[2]))
    T = ur.chain.T_dh0_urdf @ T0_base_tool @ ur.chain.T_tool_dh6
    px, py = float(T[0, 3] - ur.d6 * T[0, 2]), float(T[1, 3] - ur.d6 * T[1, 2])
    r = math.hypot(px, py)
    if abs(s5) < SINGULAR or abs(s3) < SINGULAR or r < abs(ur.d4) + SINGULAR:
        return None
    phi, s = math.atan2(py, px), math.asin(max(-1.0, min(1.0, ur.d4 / r)))
    gap = [abs((th - float(q0[0]) + math.pi) % TWO_PI - math.pi) for th in (phi + s, phi + math.pi - s)]
    return BRANCHES.index((0 if gap[0] <= gap[1] else 1, 1.0 if s5 > 0 else -1.0, 1.0 if s3 > 0 else -1.0))


def fk_base_tool(ur: URAnalytic, q: np.ndarray) -> np.ndarray:
    """Tool poses (m, 4, 4) in the robot's base frame for configurations ``q`` (m, 6)
    (:func:`grasplan.robot.ik.ur_batch.fk_many`)."""
    return fk_many(ur.chain, q)


def ur_line(ur: URAnalytic, T_base_tool: np.ndarray, q_from: np.ndarray, lower: np.ndarray, upper: np.ndarray,
            max_joint_step: float) -> tuple[np.ndarray | None, str]:
    """Joint path (m + 1, 6) starting at ``q_from`` through the tool poses ``T_base_tool`` (m, 4, 4)
    (the first reached by ``q_from`` itself is not included), or ``(None, why)``: ``start`` (no
    branch matches ``q_from``), ``ik``, ``jump``, ``limits``. The branch is the one
    :func:`start_branch` names when it matches ``q_from`` (away from singularities, the only one
    that can), else the best match of all eight."""
    q0 = np.asarray(q_from, dtype=np.float64)
    T0 = fk_many(ur.chain, q0[None])[0]
    guess = start_branch(ur, q0, T0)
    Q0, ok_r, ok3 = solve_one(ur.chain, T0)  # every branch at the start
    valid0 = ok_r & ok3
    d0 = Q0 - q0
    d0 = np.max(np.abs(d0 - TWO_PI * np.round(d0 / TWO_PI)), axis=1)
    if guess is not None and valid0[guess] and d0[guess] <= BRANCH_TOL:
        b = guess
    else:  # not where its signs say (or near a singularity): the best match of all eight
        b = int(np.argmin(np.where(valid0, d0, np.inf)))
    if not valid0[b] or d0[b] > BRANCH_TOL:
        return None, "start"
    q, code = follow(ur.chain, T_base_tool, q0, b, lower, upper, max_joint_step)
    if code:
        return None, ("ik", "jump", "limits")[code - 1]
    return q, "ok"


def ur_closed_form(robot: Robot) -> URAnalytic | None:
    """The robot's UR closed form when it has a working one, else None."""
    closed = get_solver(robot).analytic
    return closed if isinstance(closed, URAnalytic) and closed.ok else None


def world_fk(robot: Robot, qs: np.ndarray) -> np.ndarray:
    """``robot.fk_batch(qs)`` (T_world_tool (k, 4, 4)): with the UR closed form compiled (within
    2e-11 m of Pinocchio's, tested), else Pinocchio's."""
    closed = ur_closed_form(robot)
    if closed is not None:
        return np.asarray(robot.T_world_base, dtype=np.float64) @ fk_base_tool(closed, np.asarray(qs, dtype=np.float64))
    return robot.fk_batch(qs)


def closed_form_line(closed: URAnalytic, robot: Robot, T_from: np.ndarray, T_to: np.ndarray, q_from: np.ndarray, *,
                     max_dev: float, T_flange_tcp: np.ndarray, sample: float,
                     max_joint_step: float) -> tuple[np.ndarray | None, str]:
    """Joint waypoints (k, 6) moving the TCP straight ``T_from -> T_to`` (world, same orientation)
    from ``q_from`` (which reaches ``T_from``), TCP waypoints every ``sample`` m, each solved
    exactly on ``q_from``'s branch (:func:`ur_line`), the joint-linear motion between waypoints
    held to ``max_dev`` (m) from the line: ``(path, "ok")`` or ``(None, why)``, why in ``start``,
    ``ik``, ``limits``, ``jump``, ``deviation``."""
    T_base = inv_rigid(np.asarray(robot.T_world_base, dtype=np.float64))
    T_tcp_flange = inv_rigid(np.asarray(T_flange_tcp, dtype=np.float64))
    a, b = T_from[:3, 3], T_to[:3, 3]
    m = max(1, int(np.ceil(float(np.linalg.norm(b - a)) / sample - 1e-12)))
    T = np.broadcast_to(np.asarray(T_from, dtype=np.float64), (m, 4, 4)).copy()
    T[:, :3, 3] = a + (b - a) * (np.arange(1, m + 1) / m)[:, None]
    T0 = fk_base_tool(closed, np.asarray(q_from, dtype=np.float64)[None])[0]
    T0_want = T_base @ np.asarray(T_from, dtype=np.float64) @ T_tcp_flange
    if np.linalg.norm(T0[:3, 3] - T0_want[:3, 3]) > 0.5 * max_dev or np.max(np.abs(T0[:3, :3] - T0_want[:3, :3])) > 1e-4:
        return None, "start"
    path, why = ur_line(closed, T_base @ T @ T_tcp_flange, q_from, robot.lower, robot.upper, max_joint_step)
    if path is None:
        return None, why
    if line_deviation(closed.chain, path, robot.T_world_base, T_flange_tcp, a, b) > max_dev:
        return None, "deviation"
    return path, "ok"
