"""The motion of one planned grasp, resolved for a robot program (URScript, KRL, RAPID, ...).

:func:`motion_program` turns a :class:`grasplan.result.PlanResult` and a grasp id into a
:class:`MotionProgram`: joint path, approach, TCP poses in the controller's base frame, tool,
openings, and labels reduced to a safe character set. Every program exporter renders from it, so
the pre-grasp opening, the FK of the poses and the joint checks exist once.

Safety: text that comes from inputs (file names, gripper and robot names) only ever reaches a
program through :func:`safe_text`, which keeps ``[A-Za-z0-9 _.,:/+=()-]`` and replaces everything
else (newlines, CR, U+2028, quotes, ``;``, ``!``, ``#``, ``<``) by ``_``: such a label cannot leave
the comment or string it is placed in.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..errors import InputError

_UNSAFE = re.compile(r"[^A-Za-z0-9 _.,:/+=()\-]")


def safe_text(s, max_len: int = 80) -> str:
    """``s`` reduced to ``[A-Za-z0-9 _.,:/+=()-]`` (others -> ``_``), at most ``max_len`` characters."""
    s = _UNSAFE.sub("_", str(s))
    return s if len(s) <= max_len else s[: max_len - 3] + "..."


@dataclass(frozen=True)
class MotionProgram:
    """Everything one planned grasp's robot program needs, checked: finite, within the joint
    limits, FK-consistent. Lengths m, joint angles rad, transforms 4x4.

    ``path`` (k, n): q_home -> ... -> q_pregrasp (joint moves, verified with straight joint
    interpolation: do not blend); ``approach`` (a, n): q_pregrasp -> q_grasp (the straight
    Cartesian approach, joint samples). ``T_base_tcp_*``: TCP poses in the controller's base frame
    (``T_world_base``: the robot YAML's ``controller_base_frame``, else the model root). Controller
    joint angle [deg] = ``joint_sign * degrees(q) + joint_offset_deg`` (robot YAML
    ``controller_joint_map``)."""

    grasp_id: int
    score: float | None
    robot_name: str
    joint_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    joint_sign: np.ndarray
    joint_offset_deg: np.ndarray
    path: np.ndarray
    approach: np.ndarray
    q_home: np.ndarray
    q_pregrasp: np.ndarray
    q_grasp: np.ndarray
    T_world_base: np.ndarray
    T_flange_tcp: np.ndarray
    T_base_tcp_pregrasp: np.ndarray
    T_base_tcp_grasp: np.ndarray
    T_base_tcp_retreat: np.ndarray
    backoff: float
    retreat_distance: float
    pregrasp_opening: float
    width: float
    gripper_name: str
    part_label: str
    part_sha256: str
    part_scale_to_m: float
    source: str

    def controller_deg(self, q: np.ndarray) -> np.ndarray:
        """Joint angles (rad, (..., n)) as the controller counts them, degrees."""
        return self.joint_sign * np.degrees(np.asarray(q, dtype=np.float64)) + self.joint_offset_deg


def motion_program(plan, grasp_id: int | None = None, *, source: str = "") -> MotionProgram:
    """The :class:`MotionProgram` of planned grasp ``grasp_id`` (default: the best) of ``plan``."""
    g = plan.select(grasp_id)
    m = g.motion
    robot = plan.robot
    gripper = plan.gripper
    k = int(m.pregrasp_index)
    path = np.asarray(m.path, dtype=np.float64)
    if not np.all(np.isfinite(path)) or not np.all(robot.within_limits(path, tol=1e-6)):
        raise InputError(f"grasp {g.id}: the path has non-finite values or leaves the joint limits of {robot.name!r}")
    T_world_ctrl = robot.T_world_controller_base()
    T_ctrl_world = np.linalg.inv(T_world_ctrl)
    T_flange_tcp = np.asarray(gripper.T_flange_tcp, dtype=np.float64)
    fk_grasp = robot.fk(m.q_grasp) @ T_flange_tcp
    dp = float(np.linalg.norm(fk_grasp[:3, 3] - g.T_world_tcp[:3, 3]))
    if dp > 1e-3:
        raise InputError(f"grasp {g.id}: FK(q_grasp) is {dp * 1e3:.1f} mm from the grasp TCP; the plan does not "
                         f"belong to robot {robot.name!r} with gripper {gripper.name!r}")
    T_pre = T_ctrl_world @ robot.fk(m.q_pregrasp) @ T_flange_tcp
    sign = robot.joint_sign if robot.joint_sign is not None else np.ones(robot.nq)
    offset = robot.joint_offset_deg if robot.joint_offset_deg is not None else np.zeros(robot.nq)
    width = float(g.width)
    return MotionProgram(
        grasp_id=int(g.id), score=g.score, robot_name=safe_text(robot.name, 40),
        joint_names=tuple(safe_text(j, 40) for j in robot.joint_names), lower=np.asarray(robot.lower),
        upper=np.asarray(robot.upper), joint_sign=np.asarray(sign, dtype=np.float64),
        joint_offset_deg=np.asarray(offset, dtype=np.float64), path=path[: k + 1], approach=path[k:],
        q_home=path[0], q_pregrasp=np.asarray(m.q_pregrasp), q_grasp=np.asarray(m.q_grasp),
        T_world_base=T_world_ctrl, T_flange_tcp=T_flange_tcp, T_base_tcp_pregrasp=T_pre,
        T_base_tcp_grasp=T_ctrl_world @ g.T_world_tcp, T_base_tcp_retreat=T_pre,
        backoff=float(plan.params.planning.backoff), retreat_distance=float(plan.params.planning.backoff),
        pregrasp_opening=float(gripper.pregrasp_opening(width)), width=width,
        gripper_name=safe_text(gripper.name, 40), part_label=safe_text(plan.part.label, 80),
        part_sha256=safe_text(plan.part.sha256, 64), part_scale_to_m=float(plan.part.scale_to_m),
        source=safe_text(source, 80))
