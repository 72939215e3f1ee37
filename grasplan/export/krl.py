"""KUKA KRL export: one planned grasp as a ``.src`` program and its ``.dat`` data list
(:func:`krl_program`; its docstring describes the program). See ``docs/robot_programs.md``.

Every text that comes from an input (part file name, gripper and robot names, plan label) is reduced
to :func:`grasplan.export.program.safe_text`'s character set and appears only inside ``;`` comments:
it can never start a program line. Non-finite numbers and joint values outside the robot's limits
are refused with :class:`~grasplan.errors.InputError`.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .program import (
    SEGMENT_TEXT,
    MotionProgram,
    ProgramTargets,
    header_lines,
    motion_program,
    num,
    program_steps,
    program_targets,
    row_label,
    waypoint_labels,
)
from ..results.export_registry import ExportFormat, ExportOptions, register

if TYPE_CHECKING:
    from ..results.plan_result import PlanResult

#: PTP joint speed, percent of each axis' maximum ($VEL_AXIS) and acceleration ($ACC_AXIS)
PTP_VEL_PERCENT = 20
PTP_ACC_PERCENT = 20
#: LIN path speed ($VEL.CP, m/s) and acceleration ($ACC.CP, m/s^2)
LIN_VEL = 0.05
LIN_ACC = 0.5
#: seconds the gripper stub waits (placeholder for the gripper's "done" signal)
GRIPPER_WAIT_S = 0.5
__all__ = ["krl_program", "kuka_abc_deg", "render"]


def kuka_abc_deg(R: np.ndarray) -> np.ndarray:
    """KUKA ``A, B, C`` (degrees) of rotation matrices ``(..., 3, 3)``: ``R = Rz(A) Ry(B) Rx(C)``."""
    from scipy.spatial.transform import Rotation  # SciPy loads when a program is written, not with the registry

    R = np.asarray(R, dtype=np.float64)
    return Rotation.from_matrix(R.reshape(-1, 3, 3)).as_euler("ZYX", degrees=True).reshape(R.shape[:-2] + (3,))


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
    robot YAML's ``controller_joint_map``; default sign 1, offset 0). Axes A1..A6 are joints 1..6; a
    7-joint arm (Panda) puts joint 7 in ``E1`` (also in the ``E6POS`` targets: its value at the grasp
    for ``XGRASP``, at the pre-grasp for ``XRETREAT`` when the retreat ends there, else held). With 6
    joints the ``E`` components are left out, so external axes of the cell keep their positions.
    Other joint counts are refused.
    """
    t = program_targets(mp, program_name, "KRL", "(A1..A6) or 7 (joint 7 as E1)")
    name, n, path = t.name, len(mp.joint_names), t.path_deg
    T_tool, T_base, T_grasp, T_retreat = t.T_tool, t.T_base, t.T_grasp, t.T_retreat
    ext_grasp, ext_retreat = t.ext_grasp, t.ext_retreat

    k = len(path)
    targets = [f"XP{i + 1}" for i in range(k)]
    if mp.sequence:
        seq_dat, seq_src = _sequence(mp, t)
    dat = [
        "&ACCESS RVP",
        "&REL 1",
        f"DEFDAT {name}",
        *header_lines(mp, ";", "Units: X Y Z mm, A B C and joint angles degrees; A B C = rotation Rz(A) Ry(B) Rx(C)."),
        "; $TOOL: the gripper's TCP in the flange frame (T_flange_tcp)",
        f"DECL FRAME TOOL_GL={_frame(T_tool)}",
        "; $BASE: the robot's base frame in the world (T_world_base); Cartesian targets are in it",
        f"DECL FRAME BASE_GL={_frame(T_base)}",
        *(seq_dat if mp.sequence else [
            f"; joint path q_home -> q_pregrasp ({k} waypoints)" + ("; joint 7 is E1" if n == 7 else ""),
            *(f"DECL E6AXIS {t}={_e6axis(q)}" for t, q in zip(targets, path)),
            "; straight approach and retreat targets (TCP in $BASE)",
            f"DECL E6POS XGRASP={_e6pos(T_grasp, ext_grasp)}",
            f"DECL E6POS XRETREAT={_e6pos(T_retreat, ext_retreat)}"]),
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
        *(seq_src if mp.sequence else [
            *(f"PTP {t} ; {lab}" for t, lab in zip(targets, waypoint_labels(k))),
            "; straight approach to the grasp TCP (jaws open)",
            "LIN XGRASP",
            "; close on the part (width between the contacts, mm)",
            f"GRASPLAN_GRIPPER({num(mp.width * 1000, 3)})",
            f"; straight retreat ({num(mp.retreat_distance * 1000, 1)} mm)",
            "LIN XRETREAT"]),
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


#: KRL target of each linear segment's end (XGRASP as in the pick-only program)
LINEAR_TARGETS = {"approach": "XGRASP", "lift": "XLIFT", "descend": "XPLACE", "retreat": "XRETREAT"}


def _sequence(mp: MotionProgram, t: ProgramTargets) -> tuple[list[str], list[str]]:
    """``.dat`` declarations and ``.src`` motion lines of a pick(-and-place) sequence: ``PTP XPi``
    (E6AXIS) per joint-move row, ``LIN X<TARGET>`` (E6POS, joint 7 as E1 at the segment's end) per
    straight segment, ``GRASPLAN_GRIPPER(mm)`` at the events."""
    from ..geometry.transforms import check_transform

    dat: list[str] = ["; sequence targets in path order (joint 7 is E1)" if len(mp.joint_names) == 7
                      else "; sequence targets in path order"]
    src: list[str] = []
    p = 0
    for step in program_steps(mp):
        kind = step[0]
        if kind == "segment":
            seg = step[1]
            src.append(f"; segment {seg.label} (path rows {seg.start}-{seg.end}): {SEGMENT_TEXT[seg.label]}")
            dat.append(f"; segment {seg.label}")
        elif kind == "joint":
            p += 1
            dat.append(f"DECL E6AXIS XP{p}={_e6axis(t.sequence_deg()[step[1]])}")
            src.append(f"PTP XP{p} ; {row_label(mp, step[1])}")
        elif kind == "linear":
            seg = step[2]
            name = LINEAR_TARGETS[seg.label]
            T = check_transform(seg.T_base_tcp_end, f"{seg.label} target")
            dat.append(f"DECL E6POS {name}={_e6pos(T, t.sequence_deg()[seg.end, 6:])}")
            src.append(f"LIN {name} ; {row_label(mp, seg.end)}")
        else:
            ev = step[1]
            src.append(f"; {ev.action} the jaws ({'width between the contacts' if ev.action == 'close' else 'release'}, mm)")
            src.append(f"GRASPLAN_GRIPPER({num(ev.width * 1000, 3)})")
    return dat, src


def render(plan: PlanResult, options: ExportOptions) -> dict[str, str]:
    """Registry entry: the KRL ``.src``/``.dat`` of ``options.grasp_id`` (default the best planned grasp)."""
    mp = motion_program(plan, options.grasp_id, source=options.source)
    return krl_program(mp, options.program_name)


register(ExportFormat(
    name="krl", extension=".src",
    description="KUKA KRL program (.src + .dat): PTP E6AXIS path, LIN approach/retreat, $TOOL/$BASE, gripper stub",
    render=render, extra_extensions=(".dat",), program_named_by_file=True))
