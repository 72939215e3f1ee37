"""URScript program for one planned grasp (Universal Robots arms only): :func:`urscript_program`,
whose docstring describes the program. Rotations are rotation vectors (axis * angle, rad), lengths
in metres. Every label from an input (file and gripper names) passes through ``safe_text``.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError
from .program import (
    SEGMENT_TEXT,
    MotionProgram,
    motion_program,
    program_kind,
    program_steps,
    row_label,
    sequence_lines,
)
from ..results.export_registry import ExportFormat, ExportOptions, register

if TYPE_CHECKING:
    from ..results.plan_result import PlanResult

#: joint order of every UR arm (URScript's joint vector order)
UR_JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
             "wrist_1_joint", "wrist_2_joint", "wrist_3_joint")
#: the formats an arm other than a UR runs (named when a URScript export is refused): ROS/MoveIt
#: read them whatever the robot's vendor
NON_UR_FORMATS = ("joint-trajectory", "path-csv", "moveit-grasp")

#: URScript defaults: joint moves (rad/s, rad/s^2) and the linear approach/retreat (m/s, m/s^2)
JOINT_SPEED = 1.05
JOINT_ACCEL = 1.4
LINEAR_SPEED = 0.05
LINEAR_ACCEL = 0.5

def rotvec(R: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) of a rotation matrix (3, 3), robust near pi (via the quaternion)."""
    from scipy.spatial.transform import Rotation  # SciPy loads when a program is written, not with the registry

    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=np.float64))
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt  # nearest rotation
    return Rotation.from_matrix(R).as_rotvec()


def pose_vector(T: np.ndarray) -> np.ndarray:
    """URScript pose ``[x, y, z, rx, ry, rz]`` (6,) of a transform (4, 4)."""
    return np.concatenate([T[:3, 3], rotvec(T[:3, :3])])


def fmt_list(v: ArrayLike, digits: int = 6) -> str:
    return "[" + ", ".join(f"{x:.{digits}f}" for x in np.asarray(v, dtype=float)) + "]"


def fmt_pose(T: np.ndarray) -> str:
    return "p" + fmt_list(pose_vector(T))


def urscript_program(prog: MotionProgram, *, joint_speed: float = JOINT_SPEED, joint_accel: float = JOINT_ACCEL,
                     linear_speed: float = LINEAR_SPEED, linear_accel: float = LINEAR_ACCEL) -> str:
    """The URScript program text of a :class:`MotionProgram`.

    The program (one ``def grasplan_pick(): ... end``, the form the controller runs when the file is
    sent to its script port or loaded by ``ur_robot_driver``):

    1. ``grasplan_open_gripper(opening)`` / ``grasplan_close_gripper(width)``: defined at the top, with
       placeholder bodies (a ``textmsg`` and a ``sleep``). **Fill them in** with your gripper's I/O.
    2. ``set_tcp(p[...])``: the gripper's ``T_flange_tcp`` (flange = URDF ``tool0``).
    3. ``movej([...], a=, v=)`` to every waypoint of the planned joint path from ``q_home`` to
       ``q_pregrasp`` without blending (``movej`` moves on a straight line in joint space, which is how
       the planner verified the path; a blend radius would cut corners).
    4. ``movel(p[x, y, z, rx, ry, rz], a=, v=)``: the straight approach to the grasp TCP.
    5. close the gripper; ``movel`` straight back to the pre-grasp pose (the retreat).

    Poses are in the controller's base frame, which is the URDF frame ``base`` (rotated 180 deg about z
    from ``base_link`` in the UR description; the robot YAML's ``controller_base_frame``), resolved by
    :func:`grasplan.export.program.motion_program`, which also cross-checks ``FK(q_grasp) @
    T_flange_tcp`` against the grasp TCP.
    """
    if tuple(prog.joint_names) != UR_JOINTS:
        raise InputError(f"URScript runs only on Universal Robots arms; robot {prog.robot_name!r} has joints "
                         f"{', '.join(prog.joint_names)}. Export --format {', '.join(NON_UR_FORMATS[:-1])} or {NON_UR_FORMATS[-1]} instead "
                         "(robot-neutral: ROS/MoveIt controllers read them)")
    for name, limit in (("joint_speed", joint_speed), ("joint_accel", joint_accel),
                        ("linear_speed", linear_speed), ("linear_accel", linear_accel)):
        if not (np.isfinite(limit) and limit > 0):
            raise InputError(f"{name} must be > 0, got {limit!r}")
    moves = prog.path
    a, v = f"{joint_accel:g}", f"{joint_speed:g}"
    la, lv = f"{linear_accel:g}", f"{linear_speed:g}"
    score = "none" if prog.score is None else f"{prog.score:.4f}"
    L: list[str] = [
        f"# grasplan: {program_kind(prog)} program for grasp {prog.grasp_id} (status planned, score {score})",
        f"# plan: {prog.source or '(in memory)'}; part: {prog.part_label} (sha256 {prog.part_sha256[:16]}..., "
        f"scale_to_m {prog.part_scale_to_m:g}: file units -> metres)",
        f"# robot: {prog.robot_name}; gripper: {prog.gripper_name}; "
        f"grasp width {prog.width * 1000:.2f} mm, pre-grasp opening {prog.pregrasp_opening * 1000:.2f} mm",
        "# Units: metres, radians. Poses p[x, y, z, rx, ry, rz] are in the controller's base frame",
        "# (URDF frame 'base'); rx, ry, rz is a rotation vector. Joint order: base, shoulder, elbow,",
        "# wrist 1, wrist 2, wrist 3.",
        "# The joint path was verified collision-free with straight-line joint interpolation between",
        "# waypoints: keep the movej calls unblended (no r=) so the robot stays on it.",
        *(f"# {line}" for line in sequence_lines(prog)),
        "def grasplan_pick():",
        "  # ---- Gripper I/O: FILL THESE IN for your gripper --------------------------------------",
        "  # grasplan cannot know how your gripper is wired. Replace each body with your gripper's",
        "  # commands, e.g. a tool digital output   set_tool_digital_out(0, True)   or a URCap call,",
        "  # and return only when the jaws have finished moving.",
        "  def grasplan_open_gripper(opening):",
        "    # open the jaws to at least `opening` metres (the pre-grasp opening)",
        "    textmsg(\"grasplan: fill in grasplan_open_gripper(); opening [m] = \", opening)",
        "    sleep(0.5)",
        "  end",
        "  def grasplan_close_gripper(width):",
        "    # close the jaws on the part; `width` is the part's width between the contacts, metres",
        "    textmsg(\"grasplan: fill in grasplan_close_gripper(); width [m] = \", width)",
        "    sleep(0.5)",
        "  end",
        "  # ----------------------------------------------------------------------------------------",
        f"  # TCP = flange (URDF tool0) * T_flange_tcp of gripper {prog.gripper_name}",
        f"  set_tcp({fmt_pose(prog.T_flange_tcp)})",
        f"  grasplan_open_gripper({prog.pregrasp_opening:.6f})",
    ]
    if prog.sequence:
        L += _sequence_lines(prog, f"a={a}, v={v}", f"a={la}, v={lv}")
        return _finish(prog, L)
    L.append(f"  # joint path: q_home -> q_pregrasp ({len(moves)} waypoints)")
    for i, q in enumerate(moves):
        tag = "q_home" if i == 0 else ("q_pregrasp" if i == len(moves) - 1 else f"waypoint {i}")
        L.append(f"  movej({fmt_list(q)}, a={a}, v={v})  # {tag}")
    L += [
        "  # straight approach to the grasp TCP (jaws open)",
        f"  movel({fmt_pose(prog.T_base_tcp_grasp)}, a={la}, v={lv})  # grasp",
        f"  grasplan_close_gripper({prog.width:.6f})",
        "  # straight retreat to the pre-grasp pose",
        f"  movel({fmt_pose(prog.T_base_tcp_retreat)}, a={la}, v={lv})  # pre-grasp",
        "end",
    ]
    return _finish(prog, L)


def _finish(prog: MotionProgram, L: list[str]) -> str:
    text = "\n".join(L) + "\n"
    if "nan" in text or "inf" in text:
        raise InputError(f"grasp {prog.grasp_id}: the program would contain non-finite numbers; the plan is corrupt")
    return text


def _sequence_lines(prog: MotionProgram, joint_av: str, linear_av: str) -> list[str]:
    """The body of a pick(-and-place) sequence: per segment a comment, then ``movej`` to each of
    its rows (transit, transfer) or one ``movel`` to its end (approach, lift, descend, retreat);
    the gripper calls at their events' rows."""
    L: list[str] = []
    for step in program_steps(prog):
        kind = step[0]
        if kind == "segment":
            seg = step[1]
            L.append(f"  # segment {seg.label} (path rows {seg.start}-{seg.end}): {SEGMENT_TEXT[seg.label]}")
        elif kind == "joint":
            L.append(f"  movej({fmt_list(step[2])}, {joint_av})  # {row_label(prog, step[1])}")
        elif kind == "linear":
            L.append(f"  movel({fmt_pose(step[2].T_base_tcp_end)}, {linear_av})  # {row_label(prog, step[1])}")
        else:
            ev = step[1]
            fn = "grasplan_close_gripper" if ev.action == "close" else "grasplan_open_gripper"
            L.append(f"  {fn}({ev.width:.6f})  # {ev.action} at path row {ev.index}")
    L.append("end")
    return L


def _render(plan: PlanResult, opts: ExportOptions) -> dict[str, str]:
    return {".script": urscript_program(motion_program(plan, opts.grasp_id, source=opts.source))}


register(ExportFormat(name="urscript", extension=".script", render=_render,
                      description="URScript program for UR arms: movej along the path, movel approach/retreat."))
