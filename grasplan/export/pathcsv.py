"""Path CSV export: the whole motion of one planned grasp, one row per path waypoint
(:func:`path_csv`; :func:`path_rows` describes the columns).
"""
from __future__ import annotations

import csv
import io
from collections.abc import Iterable
from typing import TYPE_CHECKING, cast

import numpy as np

from ..errors import InputError
from ..geometry.transforms import pose7
from .program import motion_segments
from ..results.export_registry import ExportFormat, ExportOptions, register

if TYPE_CHECKING:
    from ..results.joint_motion import Motion
    from ..results.plan_result import PlanResult
    from ..robot.model import Robot

POSE_COLS = ("x", "y", "z", "qw", "qx", "qy", "qz")


def header(joint_names: Iterable[str]) -> list[str]:
    return (["row", "segment", "gripper", "gripper_width", "attached"] + [f"q_{j}" for j in joint_names]
            + [f"tcp_{c}" for c in POSE_COLS])


def path_rows(plan: PlanResult, grasp_id: int | None = None) -> list[dict]:
    """The rows of the path CSV as dicts (column -> value), for tests and the API.

    Columns (header row, in this order; lengths m, angles rad)::

        row, segment, gripper, gripper_width, attached, q_<joint> ... (one per robot joint),
        tcp_x, tcp_y, tcp_z, tcp_qw, tcp_qx, tcp_qy, tcp_qz

    - ``row``: the path row (0 = ``q_home``). ``segment``: the label of the segment the robot is in
      when it arrives at the row (``transit``, ``approach``, ``lift``, ``transfer``, ``descend``,
      ``retreat``; row 0 belongs to the first segment; a boundary row to the segment that ends there).
      How each segment is driven: ``transit``/``transfer`` joint moves through every row, the others
      one straight TCP move (see docs/export.md).
    - ``gripper``: ``close`` / ``open`` on the row where the jaws are commanded, once the robot stands
      there (an old pick-only plan: ``close`` at the grasp row); ``gripper_width``: the commanded
      opening, m. Empty elsewhere.
    - ``attached``: 1 when the robot arrives at the row with the part in the jaws (the rows after the
      close row up to and including the open row), else 0.
    - ``tcp_*``: the TCP pose in the world frame by forward kinematics (``FK(q) @ T_flange_tcp_at(width)``),
      quaternion w first with ``qw >= 0``.

    :func:`path_csv` writes numbers with up to 12 significant digits (joint values round-trip to 1e-12 rad).
    """
    g = plan.select(grasp_id)
    m = cast("Motion", g.motion)        # select() returns a planned grasp: it has its motion
    robot = cast("Robot", plan.robot)   # select() refuses a result without a robot
    path = np.asarray(m.path, dtype=np.float64)
    if not np.all(np.isfinite(path)) or not np.all(robot.within_limits(path, tol=1e-6)):
        raise InputError(f"grasp {g.id}: the path has non-finite values or leaves the joint limits of {robot.name!r}")
    segs = motion_segments(m)
    k = len(path)
    seg_of = np.empty(k, dtype=object)
    for lab, s, e in segs:
        seg_of[s + 1:e + 1] = lab
    seg_of[0] = segs[0][0]
    events = list(getattr(m, "gripper", ()))
    if not events:  # an old pick-only plan: the jaws close at the grasp
        events = [type("Ev", (), {"index": segs[1][2], "action": "close", "width": float(g.width)})()]
    grip = {int(e.index): (str(e.action), float(e.width)) for e in events}
    c0 = min((int(e.index) for e in events if e.action == "close"), default=k)
    c1 = min((int(e.index) for e in events if e.action == "open"), default=k - 1)
    # the TCP of this grasp's width (it moves with the opening on a Robotiq 2F: Gripper.T_flange_tcp_at)
    tcp = pose7(robot.fk_batch(path) @ np.asarray(plan.gripper.T_flange_tcp_at(float(g.width)), dtype=np.float64)) + 0.0
    joints = list(robot.joint_names)
    out = []
    for r in range(k):
        a, w = grip.get(r, ("", None))
        row = {"row": r, "segment": seg_of[r], "gripper": a, "gripper_width": w,
               "attached": int(c0 < r <= c1)}
        row.update({f"q_{j}": float(v) for j, v in zip(joints, path[r])})
        row.update({f"tcp_{c}": float(v) for c, v in zip(POSE_COLS, tcp[r])})
        out.append(row)
    return out


def _num(v: float | str | None) -> str:
    return "" if v is None or v == "" else f"{float(v) + 0.0:.12g}"


def path_csv(plan: PlanResult, grasp_id: int | None = None) -> str:
    """The path CSV text of ``grasp_id`` (default: the best planned grasp) of a PlanResult."""
    joints = list(cast("Robot", plan.robot).joint_names)  # exports refuse a result without a robot
    cols = header(joints)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for row in path_rows(plan, grasp_id):
        w.writerow([row["row"], row["segment"], row["gripper"], _num(row["gripper_width"]), row["attached"]]
                   + [_num(row[c]) for c in cols[5:]])
    return buf.getvalue()


def _render(plan: PlanResult, opts: ExportOptions) -> dict[str, str]:
    return {".csv": path_csv(plan, opts.grasp_id)}


register(ExportFormat(name="path-csv", extension=".csv", render=_render,
                      description="One row per path waypoint of a grasp: segment, gripper event, attached, joints, TCP pose."))
