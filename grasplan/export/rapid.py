"""ABB RAPID export: one planned grasp as a RAPID program module (``.mod``) (:func:`rapid_module`;
its docstring describes the module). See ``docs/robot_programs.md``.

Every text that comes from an input is reduced by :func:`grasplan.export.program.safe_text` and
appears only in ``!`` comments. Non-finite numbers and joint values outside the limits are refused
with :class:`~grasplan.errors.InputError`.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..geometry.transforms import quaternions
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

#: speeddata of the joint moves and of the linear approach/retreat (predefined RAPID data)
JOINT_SPEED = "v200"
LINEAR_SPEED = "v50"
#: kg, the tload mass written for a gripper file without ``mass`` (:func:`tool_load`)
PLACEHOLDER_MASS_KG = 1.0
#: seconds the gripper stubs wait (placeholder for the gripper's "done" signal)
GRIPPER_WAIT_S = 0.5
#: RAPID value of an unused external axis
NO_AXIS = "9E9"
#: digits of quaternion components (RAPID checks that orientations are normalised)
QUAT_DIGITS = 9

__all__ = ["confdata", "rapid_module", "render", "tool_load"]


def _pose(T: np.ndarray) -> str:
    """RAPID ``pose``: ``[[x, y, z], [q1, q2, q3, q4]]`` in mm, quaternion w first."""
    q = quaternions(T[:3, :3], order="wxyz")
    return ("[[" + ",".join(num(v * 1000.0) for v in T[:3, 3]) + "],["
            + ",".join(num(v, QUAT_DIGITS) for v in q) + "]]")


def _extax(ext_deg: np.ndarray) -> str:
    vals = [num(v) for v in ext_deg] + [NO_AXIS] * (6 - len(ext_deg))
    return "[" + ",".join(vals) + "]"


def confdata(joint_deg: np.ndarray) -> list[int]:
    """``[cf1, cf4, cf6, cfx]``: quarter revolutions ``floor(angle / 90)`` of axes 1, 4, 6; ``cfx`` 0."""
    d = np.asarray(joint_deg, dtype=np.float64)
    return [int(np.floor(d[0] / 90.0)), int(np.floor(d[3] / 90.0)), int(np.floor(d[5] / 90.0)), 0]


def tool_load(mp: MotionProgram, T_tool: np.ndarray) -> list[str]:
    """``[comment, ..., loaddata]``: RAPID ``loaddata`` of the gripper (``[mass, [cog mm], [1,0,0,0],
    0, 0, 0]``) from the gripper YAML's ``mass`` and ``com`` (flange frame); without them the placeholder
    (:data:`PLACEHOLDER_MASS_KG`, cog halfway to the TCP) and comment lines saying so."""
    if mp.gripper_mass is not None and mp.gripper_com is not None:
        cog = np.asarray(mp.gripper_com, dtype=np.float64) * 1000.0
        return ["tload: the gripper's mass and centre of mass (gripper file); point mass, inertia 0.",
                f"[{num(float(mp.gripper_mass), 4)},[{','.join(num(c) for c in cog)}],[1,0,0,0],0,0,0]"]
    cog = 0.5 * T_tool[:3, 3] * 1000.0
    return ["tload is a PLACEHOLDER",
            f"  ! (mass {num(PLACEHOLDER_MASS_KG, 1)} kg, cog halfway to the TCP): the gripper file has no mass;"
            " set your gripper's mass and cog.",
            f"[{num(PLACEHOLDER_MASS_KG, 3)},[{','.join(num(c) for c in cog)}],[1,0,0,0],0,0,0]"]


def rapid_module(mp: MotionProgram, program_name: str = "grasplan_pick") -> dict[str, str]:
    """``{".mod": text}``: the RAPID module for ``mp``. Units mm, degrees, quaternions w first.

    Raises :class:`InputError` for a robot with other than 6 or 7 joints, a non-finite value or a
    joint value outside the limits.

    The module ``MODULE <program_name>`` holds:

    - ``PERS tooldata <program_name>_tool``: the gripper's TCP at the grasp's width
      (``Gripper.T_flange_tcp_at``) as ``tframe`` (mm, quaternion ``[q1, q2, q3, q4]`` = w, x, y, z). The
      load (``tload``) is the gripper YAML's ``mass`` (kg) and ``com`` (``cog``, mm in the flange frame),
      as a point mass (``aom`` = [1, 0, 0, 0], inertia 0 0 0: run LoadIdentify for the inertia); a gripper
      file without ``mass`` gets a **placeholder** (mass :data:`PLACEHOLDER_MASS_KG`, centre of gravity
      halfway to the TCP) and a comment saying so (:func:`tool_load`).
    - ``PERS wobjdata <program_name>_wobj``: ``uframe`` = the plan's ``T_world_base`` (the robot's base
      frame in the world), ``oframe`` identity; the Cartesian targets are in this work object.
    - ``LOCAL CONST jointtarget jt_1 .. jt_k``: the planned joint path ``q_home -> q_pregrasp`` (degrees),
      driven with ``MoveAbsJ ..., fine`` (exact stops: the planner verified straight joint interpolation
      between waypoints; a zone would cut corners).
    - ``LOCAL CONST robtarget rt_grasp, rt_retreat``: TCP poses (mm, quaternion w first) for the straight
      ``MoveL`` approach and retreat. ``confdata`` ``[cf1, cf4, cf6, cfx]``: the quarter revolutions of
      axes 1, 4 and 6 at the grasp (:func:`confdata`), ``cfx`` 0; the procedure runs the linear moves
      with ``ConfL \\Off`` so the controller keeps the configuration the ``MoveAbsJ`` path reached.
    - ``PROC <program_name>_main()``: the pick, and ``LOCAL PROC`` stubs ``grasplan_gripper_open`` /
      ``grasplan_gripper_close`` to fill in with the gripper's I/O.

    Joint values: ``controller angle [deg] = joint_sign * degrees(q) + joint_offset_deg`` per joint (the
    robot YAML's ``controller_joint_map``). ``rax_1 .. rax_6`` are joints 1..6; a 7-joint arm (Panda) puts
    joint 7 in ``eax_a`` (in the robtargets too, as in the KRL export); unused external axes are
    ``9E9``. Other joint counts are refused.
    """
    # the name is <= 24 characters: + "_main" stays within RAPID's 32
    t = program_targets(mp, program_name, "RAPID", "(rax_1..rax_6) or 7 (joint 7 as eax_a)")
    name, n, path, q_grasp = t.name, len(mp.joint_names), t.path_deg, t.q_grasp_deg
    T_tool, T_base, T_grasp, T_retreat = t.T_tool, t.T_base, t.T_grasp, t.T_retreat
    ext_grasp, ext_retreat = t.ext_grasp, t.ext_retreat
    load = tool_load(mp, T_tool)
    conf = ",".join(str(c) for c in confdata(q_grasp))
    tool, wobj = f"{name}_tool", f"{name}_wobj"
    move = f"{tool}\\WObj:={wobj};"

    k = len(path)
    jts = [f"jt_{i + 1}" for i in range(k)]
    labels = waypoint_labels(k)
    if mp.sequence:
        seq_decl, seq_proc = _sequence(mp, t, move)
    L = [
        f"MODULE {name}",
        *header_lines(mp, "  !", "Units: mm, degrees; quaternions [q1,q2,q3,q4] = w, x, y, z."),
        "  ! Joint 7 of a 7-joint arm is eax_a." if n == 7 else "  ! External axes are unused (9E9).",
        f"  ! tooldata: TCP = the gripper's TCP at the grasp width (mm in the flange frame). {load[0]}",
        *load[1:-1],
        f"  PERS tooldata {tool}:=[TRUE,{_pose(T_tool)},{load[-1]}];",
        "  ! wobjdata: uframe = the robot's base frame in the world (T_world_base)",
        f"  PERS wobjdata {wobj}:=[FALSE,TRUE,\"\",{_pose(T_base)},[[0,0,0],[1,0,0,0]]];",
        *(seq_decl if mp.sequence else [
            f"  ! joint path q_home -> q_pregrasp ({k} waypoints)",
            *(f"  LOCAL CONST jointtarget {t}:=[[{','.join(num(v) for v in q[:6])}],{_extax(q[6:])}];"
              for t, q in zip(jts, path)),
            "  ! straight approach and retreat: TCP in the work object",
            f"  LOCAL CONST robtarget rt_grasp:=[{_pose(T_grasp)[1:-1]},[{conf}],{_extax(ext_grasp)}];",
            f"  LOCAL CONST robtarget rt_retreat:=[{_pose(T_retreat)[1:-1]},[{conf}],{_extax(ext_retreat)}];"]),
        "",
        f"  PROC {name}_main()",
        "    ! The joint path was verified collision-free with straight joint interpolation between",
        "    ! waypoints: keep the MoveAbsJ moves at zone fine.",
        f"    grasplan_gripper_open {num(mp.pregrasp_opening * 1000, 3)};",
        *(seq_proc if mp.sequence else [
            *(f"    MoveAbsJ {t}\\NoEOffs,{JOINT_SPEED},fine,{move}  ! {lab}" for t, lab in zip(jts, labels)),
            "    ConfL\\Off;",
            "    ! straight approach to the grasp TCP (jaws open)",
            f"    MoveL rt_grasp,{LINEAR_SPEED},fine,{move}",
            f"    grasplan_gripper_close {num(mp.width * 1000, 3)};",
            f"    ! straight retreat ({num(mp.retreat_distance * 1000, 1)} mm)",
            f"    MoveL rt_retreat,{LINEAR_SPEED},fine,{move}"]),
        "    ConfL\\On;",
        "  ENDPROC",
        "",
        "  LOCAL PROC grasplan_gripper_open(num opening_mm)",
        "    ! FILL IN: open the jaws to opening_mm (mm) with your gripper's I/O, e.g. SetDO,",
        "    ! and return only when they have finished moving. grasplan cannot know the wiring.",
        f"    WaitTime {num(GRIPPER_WAIT_S, 1)};",
        "  ENDPROC",
        "",
        "  LOCAL PROC grasplan_gripper_close(num width_mm)",
        "    ! FILL IN: close the jaws on the part (width_mm between the contacts, mm).",
        f"    WaitTime {num(GRIPPER_WAIT_S, 1)};",
        "  ENDPROC",
        "ENDMODULE",
    ]
    return {".mod": "\n".join(L) + "\n"}


#: RAPID robtarget of each linear segment's end (rt_grasp as in the pick-only module)
LINEAR_TARGETS = {"approach": "rt_grasp", "lift": "rt_lift", "descend": "rt_place", "retreat": "rt_retreat"}


def _sequence(mp: MotionProgram, t: ProgramTargets, move: str) -> tuple[list[str], list[str]]:
    """Declarations and procedure lines of a pick(-and-place) sequence: ``MoveAbsJ jt_i`` per
    joint-move row, ``MoveL rt_<target>`` per straight segment (confdata of the segment's end row),
    the gripper calls at the events. ``ConfL\\Off`` for the linear moves, as in the pick program."""
    from ..geometry.transforms import check_transform

    decl: list[str] = ["  ! sequence targets in path order (TCP in the work object)"]
    proc: list[str] = ["    ConfL\\Off;"]
    p = 0
    for step in program_steps(mp):
        kind = step[0]
        if kind == "segment":
            seg = step[1]
            proc.append(f"    ! segment {seg.label} (path rows {seg.start}-{seg.end}): {SEGMENT_TEXT[seg.label]}")
        elif kind == "joint":
            p += 1
            q = t.sequence_deg()[step[1]]
            decl.append(f"  LOCAL CONST jointtarget jt_{p}:=[[{','.join(num(v) for v in q[:6])}],{_extax(q[6:])}];")
            proc.append(f"    MoveAbsJ jt_{p}\\NoEOffs,{JOINT_SPEED},fine,{move}  ! {row_label(mp, step[1])}")
        elif kind == "linear":
            seg = step[2]
            name = LINEAR_TARGETS[seg.label]
            T = check_transform(seg.T_base_tcp_end, f"{seg.label} target")
            q = t.sequence_deg()[seg.end]
            conf = ",".join(str(c) for c in confdata(q))
            decl.append(f"  LOCAL CONST robtarget {name}:=[{_pose(T)[1:-1]},[{conf}],{_extax(q[6:])}];")
            proc.append(f"    MoveL {name},{LINEAR_SPEED},fine,{move}  ! {row_label(mp, seg.end)}")
        else:
            ev = step[1]
            proc.append(f"    grasplan_gripper_{ev.action} {num(ev.width * 1000, 3)};")
    return decl, proc


def render(plan: PlanResult, options: ExportOptions) -> dict[str, str]:
    """Registry entry: the RAPID module of ``options.grasp_id`` (default the best planned grasp)."""
    mp = motion_program(plan, options.grasp_id, source=options.source)
    return rapid_module(mp, options.program_name)


register(ExportFormat(
    name="rapid", extension=".mod",
    description="ABB RAPID module: MoveAbsJ jointtargets along the path, MoveL approach/retreat, tooldata, wobjdata",
    render=render, program_named_by_file=True))
