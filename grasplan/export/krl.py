"""KUKA KRL export: one planned grasp as a ``.src`` program and its ``.dat`` data list.

The program (``DEF <program_name>( )``; KUKA requires the files to be named ``<program_name>.src`` /
``<program_name>.dat``):

1. ``BAS(#INITMOV,0)``, then ``$TOOL`` = the gripper's ``T_flange_tcp`` and ``$BASE`` = the plan's
   ``T_world_base`` (both ``FRAME`` s in the ``.dat``), joint speed ``$VEL_AXIS`` (percent) and path
   speed ``$VEL.CP`` (m/s).
2. ``GRASPLAN_GRIPPER(opening_mm)`` opens the jaws: a subroutine stub at the end of the ``.src`` to fill
   in with the gripper's I/O.
3. ``PTP XP1`` ... ``PTP XPk``: the planned joint path ``q_home -> q_pregrasp`` as ``E6AXIS`` targets
   (degrees), exact stops (no ``C_PTP``: the planner verified straight joint interpolation between
   waypoints, blending would cut corners).
4. ``LIN XGRASP``: the straight approach to the grasp TCP; ``GRASPLAN_GRIPPER(width_mm)`` closes;
   ``LIN XRETREAT``: the straight retreat. Cartesian targets are ``E6POS`` in ``$BASE``: X, Y, Z in
   mm, A, B, C in degrees (KUKA convention: rotation = Rz(A) Ry(B) Rx(C)). No S/T: LIN ignores them.

Joint values: ``controller angle [deg] = joint_sign * degrees(q) + joint_offset_deg`` per joint (the
robot YAML's ``controller_joint_map``; default sign 1, offset 0). Axes A1..A6 are joints 1..6; a 7-joint
arm (Panda) puts joint 7 in ``E1`` (also in the ``E6POS`` targets: its value at the grasp for
``XGRASP``, at the pre-grasp for ``XRETREAT`` when the retreat ends there, else held). With 6 joints the ``E`` components are
left out, so external axes of the cell keep their positions. Other joint counts are refused.

Every text that comes from an input (part file name, gripper and robot names, plan label) is reduced
to :func:`grasplan.export.program.safe_text`'s character set and appears only inside ``;`` comments:
it can never start a program line. Non-finite numbers and joint values outside the robot's limits
are refused with :class:`~grasplan.errors.InputError`. See ``docs/robot_programs.md``.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from ..transforms import check_transform
from .program import MotionProgram, motion_program, safe_text
from .registry import ExportFormat, ExportOptions, register

#: PTP joint speed, percent of each axis' maximum ($VEL_AXIS) and acceleration ($ACC_AXIS)
PTP_VEL_PERCENT = 20
PTP_ACC_PERCENT = 20
#: LIN path speed ($VEL.CP, m/s) and acceleration ($ACC.CP, m/s^2)
LIN_VEL = 0.05
LIN_ACC = 0.5
#: seconds the gripper stub waits (placeholder for the gripper's "done" signal)
GRIPPER_WAIT_S = 0.5
#: slack (deg) when checking controller angles against the limits: the URDF limits are rad and the
#: plan's joint values may sit exactly on a limit
LIMIT_TOL_DEG = 1e-6

__all__ = ["controller_joint_deg", "krl_program", "kuka_abc_deg", "redundant_joint_deg", "render"]


# -- shared with the RAPID export ---------------------------------------------------------------

def controller_joint_deg(mp: MotionProgram, qs, what: str) -> np.ndarray:
    """Controller joint angles, degrees ``(k, n)``, of joint vectors ``qs`` ``(k, n)`` or ``(n,)`` rad.

    ``MotionProgram.controller_deg``: ``sign * degrees(q) + offset_deg`` per joint.
    Raises :class:`InputError` (naming ``what``, the waypoint and the joint) for a wrong shape, a
    non-finite value or a value outside the URDF limits mapped the same way.
    """
    n = len(mp.joint_names)
    q = np.atleast_2d(np.asarray(qs, dtype=np.float64))
    sign = np.asarray(mp.joint_sign, dtype=np.float64)
    offset = np.asarray(mp.joint_offset_deg, dtype=np.float64)
    lower = np.asarray(mp.lower, dtype=np.float64)
    upper = np.asarray(mp.upper, dtype=np.float64)
    for name, a in (("joint_sign", sign), ("joint_offset_deg", offset), ("lower", lower), ("upper", upper)):
        if a.shape != (n,) or not np.all(np.isfinite(a)):
            raise InputError(f"robot {mp.robot_name}: {name} must be {n} finite numbers (one per joint); "
                             "fix controller_joint_map / the joint limits in the robot YAML")
    if not np.all(np.abs(sign) == 1.0):
        raise InputError(f"robot {mp.robot_name}: controller_joint_map signs must be +1 or -1, got {sign.tolist()}")
    if q.ndim != 2 or q.shape[1] != n:
        raise InputError(f"{what}: expected joint vectors of {n} values, got shape {q.shape}")
    bad = ~np.isfinite(q)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise InputError(f"{what}: waypoint {i} joint {mp.joint_names[j]} is not finite; the plan is corrupt, "
                         "plan again")
    deg = mp.controller_deg(q)
    lo = np.minimum(sign * np.degrees(lower), sign * np.degrees(upper)) + offset
    hi = np.maximum(sign * np.degrees(lower), sign * np.degrees(upper)) + offset
    out = (deg < lo - LIMIT_TOL_DEG) | (deg > hi + LIMIT_TOL_DEG)
    if out.any():
        i, j = np.argwhere(out)[0]
        raise InputError(f"{what}: waypoint {i} joint {mp.joint_names[j]} = {deg[i, j]:.4f} deg is outside the "
                         f"robot's limits [{lo[j]:.4f}, {hi[j]:.4f}] deg; plan again with this robot")
    return deg + 0.0  # no -0.0


def kuka_abc_deg(R: np.ndarray) -> np.ndarray:
    """KUKA ``A, B, C`` (degrees) of rotation matrices ``(..., 3, 3)``: ``R = Rz(A) Ry(B) Rx(C)``."""
    R = np.asarray(R, dtype=np.float64)
    return Rotation.from_matrix(R.reshape(-1, 3, 3)).as_euler("ZYX", degrees=True).reshape(R.shape[:-2] + (3,))


def num(x: float, digits: int = 6) -> str:
    """A finite number as a fixed-point literal (no exponent, no ``-0``): valid in KRL and RAPID."""
    x = float(x)
    if not np.isfinite(x):
        raise InputError(f"refusing to write a non-finite number ({x!r}) into a robot program")
    s = f"{x:.{digits}f}"
    return s.lstrip("-") if float(s) == 0.0 else s  # "-0.000" -> "0.000"


def redundant_joint_deg(mp: MotionProgram, q_grasp_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Controller degrees of the joints beyond 6 (joint 7 of a 7-joint arm; ``(0,)`` for 6 joints)
    for the grasp and the retreat target: at the retreat, the pre-grasp value when the retreat ends
    at the pre-grasp pose (1 um, 1e-6 rad), else the grasp value (held)."""
    ext_grasp = q_grasp_deg[6:]
    T_r, T_p = np.asarray(mp.T_base_tcp_retreat), np.asarray(mp.T_base_tcp_pregrasp)
    if np.allclose(T_r[:3, 3], T_p[:3, 3], rtol=0, atol=1e-6) and np.allclose(T_r[:3, :3], T_p[:3, :3], rtol=0, atol=1e-6):
        return ext_grasp, controller_joint_deg(mp, mp.q_pregrasp, "q_pregrasp")[0, 6:]
    return ext_grasp, ext_grasp


def header_lines(mp: MotionProgram, comment: str, units: str) -> list[str]:
    """The header comment lines every robot program starts with (inputs only through ``safe_text``)."""
    score = "none" if mp.score is None else f"{float(mp.score):.4f}"
    lines = [
        f"grasplan: pick program for grasp {int(mp.grasp_id)} (score {score})",
        f"plan: {safe_text(mp.source) or '(in memory)'}",
        (f"part: {safe_text(mp.part_label)} (sha256 {safe_text(mp.part_sha256)[:16]}..., "
        f"scale_to_m {num(mp.part_scale_to_m, 9)})"),
        f"robot: {safe_text(mp.robot_name)}; gripper: {safe_text(mp.gripper_name)}",
        f"grasp width {num(mp.width * 1000, 2)} mm, pre-grasp opening {num(mp.pregrasp_opening * 1000, 2)} mm",
        units,
        "Joint angles: controller = sign * URDF angle + offset (controller_joint_map in the robot YAML).",
    ]
    return [f"{comment} {line}" for line in lines]


def check_program_name(name: str) -> str:
    """``name`` if it is a valid program name (the rule of :class:`ExportOptions`: a letter, then
    letters, digits or ``_``, at most 24 characters: a KRL name, and a RAPID one with a suffix)."""
    return ExportOptions(program_name=name).program_name


def waypoint_labels(k: int) -> list[str]:
    """Comments of the ``k`` joint-path waypoints: q_home, waypoint 1, ..., q_pregrasp."""
    if k == 1:
        return ["q_home = q_pregrasp"]
    return ["q_home"] + [f"waypoint {i}" for i in range(1, k - 1)] + ["q_pregrasp"]


# -- KRL ------------------------------------------------------------------------------------------

def _e6axis(deg: np.ndarray) -> str:
    parts = [f"A{i + 1} {num(v)}" for i, v in enumerate(deg[:6])]
    parts += [f"E{i + 1} {num(v)}" for i, v in enumerate(deg[6:])]
    return "{" + ",".join(parts) + "}"


def _frame(T: np.ndarray) -> str:
    xyz = T[:3, 3] * 1000.0
    abc = kuka_abc_deg(T[:3, :3])
    vals = [*xyz, *abc]
    return "{" + ",".join(f"{k} {num(v)}" for k, v in zip("XYZABC", vals)) + "}"


def _e6pos(T: np.ndarray, ext_deg: np.ndarray) -> str:
    return _frame(T)[:-1] + "".join(f",E{i + 1} {num(v)}" for i, v in enumerate(ext_deg)) + "}"


def krl_program(mp: MotionProgram, program_name: str = "grasplan_pick") -> dict[str, str]:
    """``{".src": text, ".dat": text}`` of the KRL program for ``mp``. Units mm and degrees.

    Raises :class:`InputError` for a robot with other than 6 or 7 joints, a non-finite value or a
    joint value outside the limits.
    """
    name = check_program_name(program_name)
    n = len(mp.joint_names)
    if n not in (6, 7):
        raise InputError(f"KRL export supports arms with 6 joints (A1..A6) or 7 (joint 7 as E1); robot "
                         f"{safe_text(mp.robot_name)} has {n}. Use --format joint-trajectory")
    path = controller_joint_deg(mp, mp.path, "path")
    q_grasp = controller_joint_deg(mp, mp.q_grasp, "q_grasp")[0]
    T_tool = check_transform(mp.T_flange_tcp, "T_flange_tcp")
    T_base = check_transform(mp.T_world_base, "T_world_base")
    T_grasp = check_transform(mp.T_base_tcp_grasp, "T_base_tcp_grasp")
    T_retreat = check_transform(mp.T_base_tcp_retreat, "T_base_tcp_retreat")
    ext_grasp, ext_retreat = redundant_joint_deg(mp, q_grasp)  # joint 7 as E1; empty for 6 joints
    for what, v in (("width", mp.width), ("pregrasp_opening", mp.pregrasp_opening)):
        if not (np.isfinite(v) and v >= 0):
            raise InputError(f"{what}: expected a finite length >= 0 m, got {v!r}")

    k = len(path)
    targets = [f"XP{i + 1}" for i in range(k)]
    dat = [
        "&ACCESS RVP",
        "&REL 1",
        f"DEFDAT {name}",
        *header_lines(mp, ";", "Units: X Y Z mm, A B C and joint angles degrees; A B C = rotation Rz(A) Ry(B) Rx(C)."),
        "; $TOOL: the gripper's TCP in the flange frame (T_flange_tcp)",
        f"DECL FRAME TOOL_GL={_frame(T_tool)}",
        "; $BASE: the robot's base frame in the world (T_world_base); Cartesian targets are in it",
        f"DECL FRAME BASE_GL={_frame(T_base)}",
        f"; joint path q_home -> q_pregrasp ({k} waypoints)" + ("; joint 7 is E1" if n == 7 else ""),
        *(f"DECL E6AXIS {t}={_e6axis(q)}" for t, q in zip(targets, path)),
        "; straight approach and retreat targets (TCP in $BASE)",
        f"DECL E6POS XGRASP={_e6pos(T_grasp, ext_grasp)}",
        f"DECL E6POS XRETREAT={_e6pos(T_retreat, ext_retreat)}",
        "ENDDAT",
    ]
    src = [
        "&ACCESS RVP",
        "&REL 1",
        f"DEF {name}( )",
        *header_lines(mp, ";", "Units: mm, degrees, m/s. Targets are declared in the .dat file of the same name."),
        "; The joint path was verified collision-free with straight joint interpolation between",
        "; waypoints: the PTP moves stop exactly (no C_PTP), keep them unblended.",
        "DECL INT I",
        "BAS(#INITMOV,0)",
        "$TOOL=TOOL_GL",
        "$BASE=BASE_GL",
        "FOR I=1 TO 6",
        f"  $VEL_AXIS[I]={PTP_VEL_PERCENT}",
        f"  $ACC_AXIS[I]={PTP_ACC_PERCENT}",
        "ENDFOR",
        *([f"$VEL_EXTAX[1]={PTP_VEL_PERCENT}", f"$ACC_EXTAX[1]={PTP_ACC_PERCENT}"] if n == 7 else []),
        f"$VEL.CP={num(LIN_VEL, 3)}",
        f"$ACC.CP={num(LIN_ACC, 3)}",
        "; open the jaws to the pre-grasp opening (mm)",
        f"GRASPLAN_GRIPPER({num(mp.pregrasp_opening * 1000, 3)})",
        *(f"PTP {t} ; {lab}" for t, lab in zip(targets, waypoint_labels(k))),
        "; straight approach to the grasp TCP (jaws open)",
        "LIN XGRASP",
        "; close on the part (width between the contacts, mm)",
        f"GRASPLAN_GRIPPER({num(mp.width * 1000, 3)})",
        f"; straight retreat ({num(mp.retreat_distance * 1000, 1)} mm)",
        "LIN XRETREAT",
        "END",
        "",
        "DEF GRASPLAN_GRIPPER(OPENING_MM:IN)",
        "  DECL REAL OPENING_MM",
        "  ; FILL IN: move the jaws to OPENING_MM (mm) with your gripper's I/O, e.g. $OUT[1]=TRUE,",
        "  ; and return only when they have finished moving. grasplan cannot know the wiring.",
        f"  WAIT SEC {num(GRIPPER_WAIT_S, 1)}",
        "END",
    ]
    return {".src": "\n".join(src) + "\n", ".dat": "\n".join(dat) + "\n"}


def render(plan, options: ExportOptions) -> dict[str, str]:
    """Registry entry: the KRL ``.src``/``.dat`` of ``options.grasp_id`` (default the best planned grasp)."""
    mp = motion_program(plan, options.grasp_id, source=options.source)
    return krl_program(mp, options.program_name)


register(ExportFormat(
    name="krl", extension=".src",
    description="KUKA KRL program (.src + .dat): PTP E6AXIS path, LIN approach/retreat, $TOOL/$BASE, gripper stub",
    render=render, extra_extensions=(".dat",), program_named_by_file=True))
