"""CSV export: one row per grasp of a plan (:func:`grasps_csv`; its docstring lists the columns).
"""
from __future__ import annotations

import csv
import io
from collections.abc import Iterable
from typing import TYPE_CHECKING, cast

import numpy as np

from ..errors import InputError
from ..geometry.transforms import pose7
from ..results.export_registry import ExportFormat, ExportOptions, register

if TYPE_CHECKING:
    from ..results.grasp_table import GraspTable
    from ..results.plan_result import PlanResult
    from ..robot.model import Robot

POSE_COLS = ("x", "y", "z", "qw", "qx", "qy", "qz")


def header(joint_names: Iterable[str]) -> list[str]:
    # the contracted columns in their order; the part's scale last (a constant column: "record the part's
    # scale in every output", without moving any contracted column)
    return (["id", "status", "width", "score"] + [f"part_{c}" for c in POSE_COLS]
            + [f"world_{c}" for c in POSE_COLS] + [f"q_{j}" for j in joint_names] + ["part_scale_to_m"]
            + list(QUALITY_COLS))


#: grasp quality and simulation columns, after every earlier column
QUALITY_COLS = ("gravity_margin", "epsilon", "contact0_area_m2", "contact0_type", "contact1_area_m2", "contact1_type",
                "sim_success", "sim_slip_m", "sim_turn_deg", "hold_force_N")


def _quality_text(t: GraspTable, ids: np.ndarray, grip_force: float) -> list[str]:
    """The QUALITY_COLS cells (comma-joined, no leading comma) of grasp rows ``ids``; ``grip_force``
    (N): the gripper's, for ``hold_force_N``."""
    from ..results.quality_json import CONTACT_TYPES, hold_force

    n = len(ids)
    gm = t.gravity_margin[ids] if t.gravity_margin is not None else np.full(n, np.nan)
    eps = t.epsilon[ids] if t.epsilon is not None else np.full(n, np.nan)
    area = t.contact_area[ids] if t.contact_area is not None else np.full((n, 2), np.nan)
    kind = t.contact_type[ids] if t.contact_type is not None else np.full((n, 2), -1)
    succ = t.sim_success[ids] if t.sim_success is not None else np.full(n, -1)
    slip = t.sim_slip_m[ids] if t.sim_slip_m is not None else np.full(n, np.nan)
    turn = t.sim_turn_deg[ids] if t.sim_turn_deg is not None else np.full(n, np.nan)

    def num(a: np.ndarray) -> list[str]:
        return ["" if v != v else f"{v + 0.0:.9g}" for v in np.asarray(a, dtype=np.float64).tolist()]

    def typ(a: np.ndarray) -> list[str]:
        return ["" if v < 0 else CONTACT_TYPES[v] for v in np.asarray(a).tolist()]

    cols = [num(gm), num(eps), num(area[:, 0]), typ(kind[:, 0]), num(area[:, 1]), typ(kind[:, 1]),
            ["" if v < 0 else str(v) for v in np.asarray(succ).tolist()], num(slip), num(turn),
            num(hold_force(gm, grip_force))]
    return [",".join(c) for c in zip(*cols)]


def _num(v: float | None) -> str:
    return "" if v is None else f"{float(v) + 0.0:.9g}"


def grasps_csv(plan: PlanResult, *, grasp_id: int | None = None) -> str:
    """The CSV text of a :class:`~grasplan.results.plan_result.PlanResult`: every grasp (or only ``grasp_id``).
    Vectorised over grasps (TLess20: ~1e5 rows).

    Columns (header row, in this order; lengths in metres, angles in radians)::

        id, status, width, score, rank,
        part_x, part_y, part_z, part_qw, part_qx, part_qy, part_qz,
        world_x, world_y, world_z, world_qw, world_qx, world_qy, world_qz,
        q_<joint name> ... (one column per robot joint), part_scale_to_m,
        gravity_margin, epsilon, contact0_area_m2, contact0_type, contact1_area_m2, contact1_type,
        sim_success, sim_slip_m, sim_turn_deg, hold_force_N

    (the quality columns are appended after every earlier column: no column moves)

    - ``part_*``: the TCP pose in the part frame (``T_part_tcp``); ``world_*``: in the world frame
      (``T_world_part @ T_part_tcp``). Orientation as a unit quaternion (w first), sign chosen so
      ``qw >= 0``.
    - ``q_<joint>``: ``q_grasp``; empty when the grasp is not planned. ``score``/``rank`` are empty
      when the plan has none for that grasp.
    - Grasp quality (docs/quality.md): ``gravity_margin`` (< 1 slips), ``epsilon`` (Ferrari-Canny),
      per jaw the contact patch area (m^2) and type (point, line, surface); empty for grasps without
      quality (collisions). ``sim_*``: the MuJoCo lift-and-shake result (``success`` 1 held / 0
      slipped, ``slip_m`` m, ``turn_deg`` deg), empty when the grasp was not simulated. ``hold_force_N``:
      the grip force (N) at which the grasp just holds (grip_force / gravity_margin), empty without quality.
    - Rows in the plan's grasp order: the grasps the plan file keeps (a compact plan: the collision-free
      ones; ``grasplan plan --keep all`` keeps every pose). Numbers have up to 9 significant digits.
    """
    t = plan.grasps
    joints = list(cast("Robot", plan.robot).joint_names)  # exports refuse a result without a robot
    rows = np.arange(len(t)) if grasp_id is None else np.asarray([t.index_of(plan.select(grasp_id).id)])
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(header(joints))
    lines = [buf.getvalue().rstrip("\n")]
    if len(rows) == 0:
        return lines[0] + "\n"
    T_part_tcp = t.T_part_tcp[rows]
    poses = np.concatenate([pose7(T_part_tcp), pose7(plan.T_world_part @ T_part_tcp)], axis=1) + 0.0  # no "-0"
    if not np.all(np.isfinite(poses)) or not np.all(np.isfinite(t.width[rows])):
        raise InputError("the plan has non-finite poses or widths; it is corrupt")
    scale = _num(plan.part.scale_to_m)
    fmt = ",".join(["{:.9g}"] * 14)
    empty_q = "," * (len(joints) - 1)
    status = t.status[rows].astype(str).tolist()
    width = t.width[rows].tolist()
    score = t.score[rows].tolist()
    quality = _quality_text(t, rows, float(plan.gripper.grip_force))
    for k, (i, p) in enumerate(zip(t.ids[rows].tolist(), poses.tolist())):
        m = plan.motions.get(i)
        qtxt = ",".join(_num(v) for v in m.q_grasp) if m is not None else empty_q
        sc = None if score[k] != score[k] else score[k]
        lines.append(f"{i},{_csv_text(status[k])},{_num(width[k])},{_num(sc)},{fmt.format(*p)},{qtxt},{scale},"
                     f"{quality[k]}")
    return "\n".join(lines) + "\n"


def _csv_text(s: str) -> str:
    s = str(s)
    return '"' + s.replace('"', '""') + '"' if any(c in s for c in ',"\n\r') else s


def _render(plan: PlanResult, opts: ExportOptions) -> dict[str, str]:
    return {".csv": grasps_csv(plan, grasp_id=opts.grasp_id)}


register(ExportFormat(name="csv", extension=".csv", per_grasp=False, render=_render,
                      description="One row per grasp: status, width, score, TCP pose (part, world), q_grasp."))
