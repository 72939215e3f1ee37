"""Robot-program exports of a ``grasplan.plan/1`` document (the last pipeline stage).

Formats (``fmt``):

``"urscript"``
    A URScript program for one grasp (UR arms only): gripper I/O stubs to fill in, ``set_tcp``,
    ``movej`` through the planned joint path from ``q_home`` to ``q_pregrasp``, a straight ``movel``
    approach to the grasp TCP, close the gripper, a straight ``movel`` retreat. See
    :mod:`grasplan.export.urscript`.
``"joint-trajectory"``
    A time-parameterised (TOPP-RA) trajectory from ``q_home`` to ``q_grasp`` in the layout of ROS
    ``trajectory_msgs/JointTrajectory`` (JSON), verified collision-free. See
    :mod:`grasplan.export.trajectory`.
``"csv"``
    One row per grasp: status, width, score, TCP pose in the part and world frames, ``q_grasp``.
    See :mod:`grasplan.export.csvfile`.

Python API::

    from grasplan.export import write
    write(plan_json, "urscript", "grasp.script")                  # best planned grasp
    write(plan_json, "joint-trajectory", "traj.json", grasp_id=17, max_accel=2.0)
    write(plan_json, "csv", "grasps.csv")

Every function refuses bad input with :class:`grasplan.errors.InputError` (CLI exit code 3) and
writes nothing in that case: the whole output is built in memory first, then written atomically.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..errors import InputError
from ..transforms import check_transform

Format = Literal["urscript", "joint-trajectory", "csv"]
FORMATS: tuple[str, ...] = ("urscript", "joint-trajectory", "csv")
PLAN_SCHEMA = "grasplan.plan/1"

#: default joint acceleration limit for the joint trajectory, rad/s^2 (all joints). The URDF has
#: no acceleration limits; 1.4 rad/s^2 is the UR controller's default ``movej`` acceleration.
DEFAULT_MAX_ACCEL = 1.4

__all__ = ["write", "render", "load_plan", "check_plan", "select_grasp", "planned_ids", "FORMATS",
           "DEFAULT_MAX_ACCEL", "Format"]


def load_plan(path: str | os.PathLike) -> dict:
    """Read and validate a plan file; :class:`InputError` when it is not a grasplan plan."""
    import json

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file (expected a grasplan.plan/1 JSON file written by `grasplan plan`)")
    try:
        with open(path, "rb") as f:
            doc = json.load(f)
    except (UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"{path}: not a JSON file ({exc}); expected a plan written by `grasplan plan`") from None
    try:
        check_plan(doc)
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None
    return doc


def check_plan(plan_json: Any) -> dict:
    """Check that ``plan_json`` is a valid ``grasplan.plan/1`` document (JSON Schema); returns it."""
    from ..schemas import validate

    if not isinstance(plan_json, dict) or plan_json.get("schema") != PLAN_SCHEMA:
        found = plan_json.get("schema") if isinstance(plan_json, dict) else type(plan_json).__name__
        hint = ""
        if found in ("grasplan.grasps/1", "grasplan.candidates/1"):
            hint = "; run `grasplan plan PART --robot NAME -o plan.json` to get one"
        raise InputError(f"not a grasplan plan: schema is {found!r}, expected {PLAN_SCHEMA!r}{hint}")
    grasps = plan_json.get("grasps")
    if not isinstance(grasps, list) or len(grasps) <= FULL_VALIDATION_MAX:
        validate(plan_json, PLAN_SCHEMA)
        return plan_json
    # A large plan (jsonschema checks ~1000 grasps/s; TLess20 has ~2e5 grasps): the JSON Schema on
    # the planned grasps and an evenly spaced sample, and a vectorised check of what the exports
    # read from every grasp.
    stride = max(1, len(grasps) // FULL_VALIDATION_MAX)
    keep = [g for i, g in enumerate(grasps)
            if i % stride == 0 or (isinstance(g, dict) and g.get("status") == "planned")]
    validate({**plan_json, "grasps": keep}, PLAN_SCHEMA)
    need = ("id", "status", "width", "T_part_tcp")
    bad = next((i for i, g in enumerate(grasps) if not isinstance(g, dict) or any(k not in g for k in need)), None)
    if bad is not None:
        raise InputError(f"invalid {PLAN_SCHEMA}: $.grasps[{bad}] needs {', '.join(need)}")
    statuses = {g["status"] for g in grasps}
    if not statuses <= set(PLAN_STATUSES):
        raise InputError(f"invalid {PLAN_SCHEMA}: unknown grasp status {sorted(statuses - set(PLAN_STATUSES))}; "
                         f"expected one of {', '.join(PLAN_STATUSES)}")
    try:
        ids = np.asarray([g["id"] for g in grasps])
        width = np.asarray([g["width"] for g in grasps], dtype=np.float64)
        T = np.asarray([g["T_part_tcp"] for g in grasps], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"invalid {PLAN_SCHEMA}: malformed grasp fields ({exc})") from None
    if ids.dtype.kind not in "iu" or T.shape != (len(grasps), 4, 4) or not np.all(np.isfinite(T)) \
            or not np.all(np.isfinite(width)) or np.any(width < 0):
        raise InputError(f"invalid {PLAN_SCHEMA}: grasp ids must be integers, widths finite >= 0 and "
                         "T_part_tcp finite 4x4 matrices")
    return plan_json


PLAN_STATUSES = ("planned", "collision_part", "collision_table", "unreachable", "ik_collision", "no_path",
                 "not_tried")
#: plans with more grasps than this get the JSON Schema check on a sample and the planned grasps,
#: and a vectorised structural check on every grasp
FULL_VALIDATION_MAX = 1000


def planned_ids(plan_json: dict) -> list[int]:
    """Ids of the grasps with status ``planned``, best first (highest score, then lowest rank, id)."""
    planned = [g for g in plan_json["grasps"] if g["status"] == "planned"]
    planned.sort(key=_best_key)
    return [int(g["id"]) for g in planned]


def _best_key(g: dict):
    score = g.get("score")
    rank = g.get("rank")
    return (-(score if score is not None else -math.inf), rank if rank is not None else math.inf, g["id"])


def select_grasp(plan_json: dict, grasp_id: int | None = None) -> dict:
    """The grasp entry ``grasp_id`` (must be planned), or the best planned one when ``None``."""
    ids = planned_ids(plan_json)
    if grasp_id is None:
        if not ids:
            counts: dict[str, int] = {}
            for g in plan_json["grasps"]:
                counts[g["status"]] = counts.get(g["status"], 0) + 1
            summary = ", ".join(f"{k}: {v}" for k, v in sorted(counts.items())) or "no grasps at all"
            raise InputError(f"the plan has no planned grasp to export ({summary}); "
                             "try `grasplan plan` with a larger --top or another gripper/cell")
        grasp_id = ids[0]
    by_id = {int(g["id"]): g for g in plan_json["grasps"]}
    if grasp_id not in by_id:
        shown = ", ".join(map(str, ids[:50])) + (" ..." if len(ids) > 50 else "")
        raise InputError(f"unknown grasp id {grasp_id}; planned grasps: {shown or '(none)'}")
    g = by_id[grasp_id]
    if g["status"] != "planned":
        shown = ", ".join(map(str, ids[:20])) + (" ..." if len(ids) > 20 else "")
        raise InputError(f"grasp {grasp_id} is not planned (status: {g['status']}); "
                         f"planned grasps: {shown or '(none)'}")
    return g


def grasp_arrays(plan_json: dict, g: dict) -> dict[str, np.ndarray]:
    """NumPy views of a planned grasp: T_world_part, T_part_tcp, T_world_tcp, q_home, path, ..."""
    n = len(plan_json["robot"]["joint_names"])
    T_world_part = check_transform(plan_json["part"]["T_world_part"], "part.T_world_part")
    T_part_tcp = check_transform(g["T_part_tcp"], f"grasp {g['id']} T_part_tcp")
    path = np.asarray(g["path"], dtype=np.float64)
    q_home = np.asarray(plan_json["robot"]["q_home"], dtype=np.float64)
    q_grasp = np.asarray(g["q_grasp"], dtype=np.float64)
    q_pre = np.asarray(g["q_pregrasp"], dtype=np.float64)
    k = int(g["pregrasp_index"])
    for name, a in (("q_home", q_home), ("q_grasp", q_grasp), ("q_pregrasp", q_pre)):
        if a.shape != (n,):
            raise InputError(f"grasp {g['id']}: {name} has {a.size} values, the robot has {n} joints")
    if path.ndim != 2 or path.shape[1] != n or len(path) < 2:
        raise InputError(f"grasp {g['id']}: path must be a list of >= 2 joint vectors of length {n}")
    if not np.all(np.isfinite(path)):
        raise InputError(f"grasp {g['id']}: path has non-finite values")
    if not 0 <= k < len(path):
        raise InputError(f"grasp {g['id']}: pregrasp_index {k} outside the path (length {len(path)})")
    tol = 1e-6
    checks = (("path[0]", path[0], "q_home", q_home), (f"path[{k}] (pregrasp_index)", path[k], "q_pregrasp", q_pre),
              ("path[-1]", path[-1], "q_grasp", q_grasp))
    for a_name, a, b_name, b in checks:
        if np.max(np.abs(a - b)) > tol:
            raise InputError(f"grasp {g['id']}: {a_name} differs from {b_name} by {np.max(np.abs(a - b)):.3g} rad; "
                             "the plan file is inconsistent")
    return {"T_world_part": T_world_part, "T_part_tcp": T_part_tcp, "T_world_tcp": T_world_part @ T_part_tcp,
            "path": path, "q_home": q_home, "q_grasp": q_grasp, "q_pregrasp": q_pre, "pregrasp_index": k}


def render(plan_json: dict, fmt: Format, *, grasp_id: int | None = None, max_accel: float = DEFAULT_MAX_ACCEL,
           velocity_scale: float = 1.0, robot=None, scene=None, part_path: str | os.PathLike | None = None,
           source: str | None = None, check: bool = True) -> str:
    """The text of the export (nothing written). Arguments as :func:`write`."""
    if check:
        check_plan(plan_json)
    if fmt == "urscript":
        from .urscript import urscript_program

        return urscript_program(plan_json, grasp_id=grasp_id, robot=robot, source=source)
    if fmt == "joint-trajectory":
        from ..io import to_json_text
        from .trajectory import joint_trajectory

        doc = joint_trajectory(plan_json, grasp_id=grasp_id, max_accel=max_accel, velocity_scale=velocity_scale,
                               robot=robot, scene=scene, part_path=part_path)
        return to_json_text(doc, indent=1) + "\n"
    if fmt == "csv":
        from .csvfile import grasps_csv

        if grasp_id is not None:
            select_grasp(plan_json, grasp_id)  # the same rule as the other formats: a planned grasp
        return grasps_csv(plan_json, grasp_id=grasp_id)
    raise InputError(f"unknown export format {fmt!r}; available: {', '.join(FORMATS)}")


def write(plan_json: dict, fmt: Format, path: str | os.PathLike, *, grasp_id: int | None = None,
          max_accel: float = DEFAULT_MAX_ACCEL, velocity_scale: float = 1.0, robot=None, scene=None,
          part_path: str | os.PathLike | None = None, source: str | None = None, check: bool = True) -> Path:
    """Write ``plan_json`` (a ``grasplan.plan/1`` dict) as ``fmt`` to ``path``; returns the path.

    Parameters
    ----------
    grasp_id
        The grasp to export (must have status ``planned``); default: the best planned grasp
        (highest score, then lowest rank). For ``csv``, ``None`` writes every grasp and an id writes
        only that (planned) grasp's row.
    max_accel
        Joint acceleration limit, rad/s^2, for ``joint-trajectory`` (scalar or one per joint).
    velocity_scale
        Fraction (0, 1] of the URDF velocity limits the joint trajectory may use.
    robot
        A loaded :class:`grasplan.robot.Robot` (default: ``load_robot(plan["robot"]["name"])``).
    scene
        Object with ``path_free(qs, opening, *, step)`` used to verify the timed trajectory
        (default: a :class:`grasplan.scene.CollisionScene` rebuilt from the plan's part, gripper,
        cell and robot).
    part_path
        The part's mesh file when it moved since planning (default: the plan's ``part.path``).
    source
        A label for the plan (e.g. its file name), recorded in the URScript header.
    check
        Validate ``plan_json`` against the plan schema first (skip only when already done, e.g.
        by :func:`load_plan`).

    Raises :class:`~grasplan.errors.InputError` (nothing written) for a document that is not a
    plan, an unknown grasp id (the message lists the planned ids) or a grasp that is not planned
    (the message says its status); :class:`~grasplan.errors.PlanningError` when no timed trajectory
    within the limits stays collision-free.
    """
    from ..io import write_atomic_text

    text = render(plan_json, fmt, grasp_id=grasp_id, max_accel=max_accel, velocity_scale=velocity_scale,
                  robot=robot, scene=scene, part_path=part_path, source=source, check=check)
    return write_atomic_text(path, text)
