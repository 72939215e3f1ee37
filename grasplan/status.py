"""The per-grasp status vocabulary of the grasp and plan stages (:class:`Status`), one definition
for every stage, writer, reader and command that produces or compares a status."""
from __future__ import annotations

import enum


class Status(str, enum.Enum):
    """Per-grasp status: the grasp stage gives ``ok`` / ``collision_*``; the plan stage splits
    ``ok`` into ``planned``, ``unreachable``, ``ik_collision``, ``no_path`` and ``not_tried``;
    ``not_checked``: read from older plan files only (grasplan 0.2's rank-order evaluation never
    collision-checked the pose); plans now check every pose."""

    OK = "ok"
    PLANNED = "planned"
    COLLISION_PART = "collision_part"
    COLLISION_TABLE = "collision_table"
    COLLISION_OBSTACLE = "collision_obstacle"
    UNREACHABLE = "unreachable"
    IK_COLLISION = "ik_collision"
    NO_PATH = "no_path"
    PLACE_UNREACHABLE = "place_unreachable"
    PLACE_NO_PATH = "place_no_path"
    NOT_TRIED = "not_tried"
    NOT_CHECKED = "not_checked"


#: statuses of the grasp stage (``grasplan.grasps/1``)
GRASP_STATUSES: tuple[str, ...] = (Status.OK.value, Status.COLLISION_PART.value, Status.COLLISION_TABLE.value,
                                   Status.COLLISION_OBSTACLE.value)
#: statuses of the plan stage (``grasplan.plan/1``), in report order
PLAN_STATUSES: tuple[str, ...] = tuple(s.value for s in (
    Status.PLANNED, Status.COLLISION_PART, Status.COLLISION_TABLE, Status.COLLISION_OBSTACLE, Status.UNREACHABLE, Status.IK_COLLISION,
    Status.NO_PATH, Status.PLACE_UNREACHABLE, Status.PLACE_NO_PATH, Status.NOT_TRIED, Status.NOT_CHECKED))
