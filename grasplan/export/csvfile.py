"""CSV export: one row per grasp of a plan.

Columns (header row, in this order; lengths in metres, angles in radians):

``id, status, width, score, rank,
part_x, part_y, part_z, part_qw, part_qx, part_qy, part_qz,
world_x, world_y, world_z, world_qw, world_qx, world_qy, world_qz,
q_<joint name> ... (one column per robot joint)``

- ``part_*``: the TCP pose in the part frame (``T_part_tcp``); ``world_*``: in the world frame
  (``T_world_part @ T_part_tcp``). Orientation as a unit quaternion (w first), sign chosen so
  ``qw >= 0``.
- ``q_<joint>``: ``q_grasp``; empty when the grasp is not planned. ``score``/``rank`` are empty
  when the plan has none for that grasp.
- Rows in the plan's grasp order. Numbers are written with up to 9 significant digits.
"""
from __future__ import annotations

import csv
import io

import numpy as np

from ..errors import InputError
from ..transforms import pose7

POSE_COLS = ("x", "y", "z", "qw", "qx", "qy", "qz")


def header(joint_names) -> list[str]:
    # issue 5's columns in its order; the part's scale last (a constant column: "record the part's
    # scale in every output", without moving any contracted column)
    return (["id", "status", "width", "score"] + [f"part_{c}" for c in POSE_COLS]
            + [f"world_{c}" for c in POSE_COLS] + [f"q_{j}" for j in joint_names] + ["part_scale_to_m"])


def _num(v) -> str:
    return "" if v is None else f"{float(v) + 0.0:.9g}"


def grasps_csv(plan_json: dict, *, grasp_id: int | None = None) -> str:
    """The CSV text: every grasp (or only ``grasp_id``, which may have any status). Poses vectorised."""
    joints = list(plan_json["robot"]["joint_names"])
    T_world_part = np.asarray(plan_json["part"]["T_world_part"], dtype=np.float64)
    grasps = plan_json["grasps"]
    if grasp_id is not None:
        grasps = [g for g in grasps if int(g["id"]) == grasp_id]
        if not grasps:
            ids = [g["id"] for g in plan_json["grasps"]]
            raise InputError(f"unknown grasp id {grasp_id}; the plan has ids {min(ids)}..{max(ids)}" if ids
                             else f"unknown grasp id {grasp_id}; the plan has no grasps")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header(joints))
    if not grasps:
        return buf.getvalue()
    T_part_tcp = np.asarray([g["T_part_tcp"] for g in grasps], dtype=np.float64)
    if T_part_tcp.shape != (len(grasps), 4, 4):
        raise InputError("every grasp's T_part_tcp must be a 4x4 matrix")
    poses = np.concatenate([pose7(T_part_tcp), pose7(T_world_part @ T_part_tcp)], axis=1) + 0.0  # no "-0"
    scale = _num(plan_json["part"]["scale_to_m"])
    fmt = ",".join(["{:.9g}"] * 14)
    empty_q = "," * (len(joints) - 1)
    lines = [buf.getvalue().rstrip("\n")]
    for g, p in zip(grasps, poses.tolist()):
        q = g.get("q_grasp") if g["status"] == "planned" else None
        if q is not None and len(q) != len(joints):
            raise InputError(f"grasp {g['id']}: q_grasp has {len(q)} values, the robot has {len(joints)} joints")
        qtxt = ",".join(_num(v) for v in q) if q is not None else empty_q
        lines.append(f"{int(g['id'])},{_csv_text(g['status'])},{_num(g['width'])},{_num(g.get('score'))},"
                     f"{fmt.format(*p)},{qtxt},{scale}")
    return "\n".join(lines) + "\n"


def _csv_text(s: str) -> str:
    s = str(s)
    return '"' + s.replace('"', '""') + '"' if any(c in s for c in ',"\n') else s
