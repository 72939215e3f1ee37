"""MoveIt grasps export: the planned grasps as a YAML list of ``moveit_msgs/Grasp`` messages
(:func:`moveit_grasps`; its docstring describes each field). Every number is checked finite
(:class:`~grasplan.errors.InputError` otherwise). See ``docs/robot_programs.md``.
"""
from __future__ import annotations

import math
import re
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError
from ..geometry.transforms import check_transform, quaternions
from .program import is_sequence, motion_program, safe_text
from ..results.export_registry import ExportFormat, ExportOptions, register

if TYPE_CHECKING:
    from ..results.joint_motion import Motion
    from ..results.plan_result import PlanResult

#: seconds after which a finger posture is reached (time_from_start of its single point)
POSTURE_TIME_S = 1.0
#: frame of every pose and direction
FRAME_ID = "world"

__all__ = ["finger_joint_names", "moveit_grasps", "render", "ros_name"]


def ros_name(text: str, fallback: str) -> str:
    """``text`` reduced to a ROS name: ``[A-Za-z0-9_]``, starting with a letter (else ``fallback``)."""
    s = re.sub(r"[^A-Za-z0-9_]", "_", safe_text(str(text)))
    s = re.sub(r"_+", "_", s).strip("_")
    return s if s[:1].isalpha() else (f"{fallback}_{s}" if s else fallback)


def finger_joint_names(gripper_name: str) -> list[str]:
    """``[<gripper>_finger_joint_left, <gripper>_finger_joint_right]``."""
    g = ros_name(gripper_name, "gripper")
    return [f"{g}_finger_joint_left", f"{g}_finger_joint_right"]


def _finite(x: float, what: str) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected a number, got {x!r}") from None
    if not math.isfinite(v):
        raise InputError(f"{what}: {v!r} is not finite; the plan is corrupt, plan again")
    return v


def _vec3(v: np.ndarray) -> dict:
    return {"x": float(v[0]) + 0.0, "y": float(v[1]) + 0.0, "z": float(v[2]) + 0.0}  # + 0.0: no -0.0


def _duration(t: float) -> dict:
    sec = math.floor(t)
    return {"sec": int(sec), "nanosec": round((t - sec) * 1e9)}


def _posture(joints: list[str], opening: float) -> dict:
    half = 0.5 * opening
    return {"header": {"frame_id": ""}, "joint_names": list(joints),
            "points": [{"positions": [half, half], "time_from_start": _duration(POSTURE_TIME_S)}]}


def _translation(direction: np.ndarray, distance: float) -> dict:
    return {"direction": {"header": {"frame_id": FRAME_ID}, "vector": _vec3(direction)},
            "desired_distance": float(distance), "min_distance": float(distance)}


def moveit_grasps(plan: PlanResult, grasp_id: int | None = None) -> list[dict]:
    """``moveit_msgs/Grasp`` dicts for the planned grasps of ``plan`` (a PlanResult), best first;
    only ``grasp_id`` when given (it must be planned). Lengths m, quaternions x, y, z, w.

    The field layout of ``moveit_msgs/msg/Grasp`` (ROS 2 names: ``builtin_interfaces/Duration`` is
    ``{sec, nanosec}``):

    ``id``
        ``"grasp_<id>"`` (the grasplan grasp id).
    ``pre_grasp_posture`` / ``grasp_posture``
        ``trajectory_msgs/JointTrajectory`` of the two finger joints ``<gripper>_finger_joint_left`` and
        ``<gripper>_finger_joint_right`` (prismatic, metres, each jaw's distance from the TCP's centre
        plane: half the opening): the pre-grasp opening ``Gripper.pregrasp_opening(width)``, then the
        part's width between the contacts. One point each, reached after :data:`POSTURE_TIME_S`.
        Rename the joints to your gripper's (the names come from the gripper file's ``name``, reduced
        to ``[A-Za-z0-9_]``).
    ``grasp_pose``
        ``geometry_msgs/PoseStamped`` of the TCP in frame ``world`` (the plan's world frame): position
        m, orientation quaternion ``x, y, z, w``. The TCP convention (x closing axis, z approach) is
        grasplan's; MoveIt's ``end_effector`` link must be the TCP (or offset by ``T_flange_tcp``).
    ``grasp_quality``
        the grasp's score (0 when the plan has none).
    ``pre_grasp_approach``
        direction = the TCP's +z in ``world`` (the fingers point along it), ``desired_distance`` =
        ``min_distance`` = the plan's back-off (the planner verified the whole approach).
    ``post_grasp_retreat``
        a plan with a lift (pick-and-place plans): direction and distance of the planned lift in
        ``world`` (the cell's ``retreat: {direction, distance}``, measured on the plan's path by FK and
        cross-checked against the cell: :func:`_sequence_retreats`). An old pick-only plan: the TCP's
        -z in ``world`` (straight back out), distance = the plan's retreat distance
        (``PlanResult.retreat_distance``: the back-off).
    ``post_place_retreat``
        a plan with a place: direction and distance of the planned retreat after the release (the TCP's
        -z at the place, by the back-off), in ``world``. Otherwise: the TCP's -z at the grasp by the
        plan's retreat distance (what a place would do).
    ``max_contact_force``
        the gripper's ``grip_force`` (N).
    ``allowed_touch_objects``
        ``[<part>]``: the part's file stem reduced to ``[A-Za-z0-9_]``; name the part's collision object so.
    """
    if grasp_id is None:
        plan.select(None)  # InputError naming the statuses when nothing is planned
        ids = plan.planned_ids()
    else:
        ids = [plan.select(grasp_id).id]
    gripper = plan.gripper
    joints = finger_joint_names(gripper.name)
    backoff = _finite(plan.params.planning.backoff, "plan back-off")
    retreat = _finite(plan.retreat_distance, "retreat distance")
    force = _finite(getattr(gripper, "grip_force", 0.0), "gripper grip_force")
    part = ros_name(Path(plan.part.label).stem, "part")
    out = []
    for i in ids:
        g = plan.grasp(i)
        T = check_transform(g.T_world_tcp, f"grasp {g.id}: T_world_tcp")
        width = _finite(g.width, f"grasp {g.id}: width")
        opening = _finite(gripper.pregrasp_opening(width), f"grasp {g.id}: pre-grasp opening")
        score = 0.0 if g.score is None else _finite(g.score, f"grasp {g.id}: score")
        z = T[:3, 2]
        q = quaternions(T[:3, :3], order="xyzw")
        grasp_retreat, place_retreat = _translation(-z, retreat), _translation(-z, retreat)
        if is_sequence(cast("Motion", g.motion)):  # a planned grasp has its motion
            grasp_retreat, place_retreat = _sequence_retreats(plan, g.id, grasp_retreat, place_retreat)
        out.append({
            "id": f"grasp_{int(g.id)}",
            "pre_grasp_posture": _posture(joints, opening),
            "grasp_posture": _posture(joints, width),
            "grasp_pose": {"header": {"frame_id": FRAME_ID},
                           "pose": {"position": _vec3(T[:3, 3]),
                                    "orientation": {"x": float(q[0]), "y": float(q[1]), "z": float(q[2]),
                                                    "w": float(q[3])}}},
            "grasp_quality": score,
            "pre_grasp_approach": _translation(z, backoff),
            "post_grasp_retreat": grasp_retreat,
            "post_place_retreat": place_retreat,
            "max_contact_force": force,
            "allowed_touch_objects": [part],
        })
    return out


def _sequence_retreats(plan: PlanResult, grasp_id: int, grasp_retreat: dict, place_retreat: dict) -> tuple[dict, dict]:
    """``post_grasp_retreat`` = the cell's retreat (direction, distance; world) that the plan's lift
    follows and, with a place, ``post_place_retreat`` = the TCP's -z at the place by the plan's
    back-off (the planned retreat after the release). Both are cross-checked against the planned
    segment's TCP displacement (FK, 1 mm); a plan without the cell's retreat fields uses the
    measured displacement."""
    mp = motion_program(plan, grasp_id)  # checks: straight segments, the lift vs the cell, the place pose
    T_world_ctrl = np.asarray(mp.T_world_base, dtype=np.float64)
    segs = {s.label: s for s in mp.segments}

    def measured(label: str) -> np.ndarray:
        s = segs[label]
        prev = [x for x in mp.segments if x.end == s.start]
        p0 = (T_world_ctrl @ (prev[0].T_base_tcp_end if prev else mp.T_base_tcp_pregrasp))[:3, 3]
        return (T_world_ctrl @ s.T_base_tcp_end)[:3, 3] - p0

    def translation(label: str, direction: ArrayLike | None, distance: float | None) -> dict:
        d = measured(label)
        if direction is None or distance is None:
            distance = float(np.linalg.norm(d))
            direction = d / distance if distance > 0 else d
        direction = np.asarray(direction, dtype=np.float64)
        distance = _finite(distance, f"grasp {grasp_id}: {label} distance")
        if not (distance > 0 and abs(np.linalg.norm(direction) - 1.0) < 1e-6):
            raise InputError(f"grasp {grasp_id}: the {label} has no direction (distance {distance}); the plan is corrupt")
        if np.linalg.norm(d - distance * direction) > 1e-3:
            raise InputError(f"grasp {grasp_id}: the planned {label} moves the TCP by {np.round(d, 4).tolist()} m, "
                             f"not {distance:.4f} m along {np.round(direction, 4).tolist()}; the plan is inconsistent")
        return _translation(direction, distance)

    cell = plan.cell
    lift = translation("lift", getattr(cell, "retreat_direction", None), getattr(cell, "retreat_distance", None))
    if "retreat" not in segs:
        return lift, place_retreat
    m = cast("Motion", plan.grasp(grasp_id).motion)  # a planned grasp (motion_program checked it)
    T_place = check_transform(np.asarray(m.T_world_part_place) @ np.linalg.inv(np.asarray(m.T_tcp_part)),
                              f"grasp {grasp_id}: place TCP")
    backoff = _finite(plan.params.planning.backoff, "plan back-off")
    return lift, translation("retreat", -T_place[:3, 2], backoff)


def render(plan: PlanResult, options: ExportOptions) -> dict[str, str]:
    """Registry entry: ``{".yaml": text}``, a YAML list of ``moveit_msgs/Grasp``."""
    import yaml

    grasps = moveit_grasps(plan, options.grasp_id)
    head = [
        "# grasplan: planned grasps as moveit_msgs/Grasp (ROS 2 field names), best first",
        (f"# plan: {safe_text(options.source) or '(in memory)'}; part: {safe_text(plan.part.label)} "
        f"(sha256 {safe_text(plan.part.sha256)[:16]}...)"),
        f"# robot: {safe_text(getattr(plan.robot, 'name', ''))}; gripper: {safe_text(plan.gripper.name)}",
        "# Units: metres, seconds, newtons; quaternions x, y, z, w; frame 'world' = the plan's world frame.",
    ]
    body = yaml.safe_dump(grasps, sort_keys=False, default_flow_style=None, allow_unicode=False, width=100)
    return {".yaml": "\n".join(head) + "\n" + body}


register(ExportFormat(
    name="moveit-grasp", extension=".yaml",
    description="MoveIt grasps: YAML list of moveit_msgs/Grasp (world frame, approach/retreat, finger postures)",
    render=render, per_grasp=False))
