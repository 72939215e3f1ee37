"""The status of a pick's instance (:class:`PickStatus`, the ``status`` of ``grasplan.picks/1``), the
status each grasp motion's reason code (:class:`grasplan.motion.codes.Reason`) gives it and the codes
another lift direction may help."""
from __future__ import annotations

from ..motion.codes import Reason, _Word


class PickStatus(_Word):
    """An instance's status, in the order a picks file's ``counts`` lists them: ``picked``;
    ``blocked`` (its grasps or its lift hit a neighbour), ``cloud`` (they hit the cloud), ``bin``
    (they hit the bin, the table or an obstacle); ``unreachable`` / ``ik_collision`` /
    ``lift_collision`` / ``no_path`` / ``place`` (collision-free grasps exist but no motion: the
    best one's); ``no_grasp`` (no grasp approaches from above); ``not_tried`` (budget or
    ``max_picks``). A grasp's motion (:class:`grasplan.motion.grasp_motion.Outcome`) has the status it
    gives its instance: ``picked`` when planned."""

    PICKED = "picked"
    BLOCKED = "blocked"
    CLOUD = "cloud"
    BIN = "bin"
    UNREACHABLE = "unreachable"
    IK_COLLISION = "ik_collision"
    LIFT_COLLISION = "lift_collision"
    NO_PATH = "no_path"
    PLACE = "place"
    NO_GRASP = "no_grasp"
    NOT_TRIED = "not_tried"


#: instance statuses, in the order the counts list them
INSTANCE_STATUSES: tuple[str, ...] = tuple(s.value for s in PickStatus)


#: the status a grasp's motion outcome gives its instance, per reason code
GRASP_STATUS: dict[Reason, PickStatus] = {
    Reason.PLANNED: PickStatus.PICKED, Reason.LIFT_GRIPPER: PickStatus.LIFT_COLLISION,
    Reason.NO_IK: PickStatus.UNREACHABLE, Reason.IK_COLLISION: PickStatus.IK_COLLISION,
    Reason.LINE_NOT_FOLLOWED: PickStatus.UNREACHABLE, Reason.LIFT_COLLISION: PickStatus.LIFT_COLLISION,
    Reason.NO_TRANSIT: PickStatus.NO_PATH, Reason.PLACE: PickStatus.PLACE}
#: grasp outcomes another lift direction may plan: its lift collided or could not be followed
#: (not: no IK solution, a collision at the grasp or on the approach, no transit, the place)
LIFT_MAY_HELP: frozenset[Reason] = frozenset({Reason.LIFT_GRIPPER, Reason.LIFT_COLLISION, Reason.LINE_NOT_FOLLOWED})


#: the statuses of an instance a push may help: its grasps or its motion hit a neighbour or the cell
PUSHABLE = frozenset({PickStatus.BLOCKED, PickStatus.BIN, PickStatus.IK_COLLISION, PickStatus.LIFT_COLLISION})


def pushable(status: PickStatus, code: object) -> bool:
    """Whether a push may help an instance reported with ``status`` and reason ``code``: one of
    :data:`PUSHABLE`, or every collision-free grasp predicted to slip (``grasps_weak``: the better
    ones collided; in the open they may not)."""
    return status in PUSHABLE or str(code) == "grasps_weak"
