"""Straight TCP lines for a UR arm: the closed form of :mod:`grasplan.robot.ik.ur` evaluated for
every waypoint of a line in one compiled pass, on the one branch the start configuration is on.

:func:`closed_form_line` is what every straight TCP line of ``plan`` and ``pick`` runs on a UR arm
(:func:`grasplan.motion.joint_paths.approach_path_reason`; other arms: its CLIK tracker), through
:func:`grasplan.robot.ik.ur_batch.line`: the branch (shoulder, wrist and elbow signs) is the one
whose solution at the first pose equals the start configuration (modulo 2 pi); each waypoint's
joints are wrapped to the previous waypoint's, so the path is continuous unless the branch passes a
singularity (then a joint jumps and the line is refused). Forward kinematics of the same DH chain
(proven against Pinocchio when the closed form is built) measures the joint-linear motion's
distance from the line.
"""
from __future__ import annotations

import numpy as np

from .solve import get_solver
from .ur import URAnalytic
from .ur_batch import fk_many, line
from ..model import Robot


def ur_closed_form(robot: Robot) -> URAnalytic | None:
    """The robot's UR closed form when it has a working one, else None."""
    closed = get_solver(robot).analytic
    return closed if isinstance(closed, URAnalytic) and closed.ok else None


def world_fk(robot: Robot, qs: np.ndarray) -> np.ndarray:
    """``robot.fk_batch(qs)`` (T_world_tool (k, 4, 4)): with the UR closed form compiled (within
    2e-11 m of Pinocchio's, tested), else Pinocchio's."""
    closed = ur_closed_form(robot)
    if closed is not None:
        return np.asarray(robot.T_world_base, dtype=np.float64) @ fk_many(closed.chain, qs)
    return robot.fk_batch(qs)


def closed_form_line(closed: URAnalytic, robot: Robot, T_from: np.ndarray, T_to: np.ndarray, q_from: np.ndarray, *,
                     max_dev: float, T_flange_tcp: np.ndarray, sample: float,
                     max_joint_step: float) -> tuple[np.ndarray | None, str]:
    """Joint waypoints (k, 6) moving the TCP straight ``T_from -> T_to`` (world, same orientation)
    from ``q_from`` (which reaches ``T_from``), TCP waypoints every ``sample`` m, each solved
    exactly on ``q_from``'s branch, the joint-linear motion between waypoints held to ``max_dev``
    (m) from the line: ``(path, "ok")`` or ``(None, why)``, why in ``start``, ``ik``, ``limits``,
    ``jump``, ``deviation`` (:func:`grasplan.robot.ik.ur_batch.line`, one compiled call)."""
    return line(closed.chain, robot.T_world_base, T_flange_tcp, T_from, T_to, q_from, robot.lower, robot.upper,
                sample=sample, max_dev=max_dev, max_step=max_joint_step)
