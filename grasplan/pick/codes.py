"""The status of a pick's instance (:class:`PickStatus`, the ``status`` of ``grasplan.picks/1``) and
the reason codes carried beside each human-readable reason (:class:`Reason`): code branches on the
codes, the text is for people."""
from __future__ import annotations

import enum


class _Word(str, enum.Enum):
    """A str-valued enum whose ``str()`` and f-string form are its value (as the JSON holds it)."""

    def __str__(self) -> str:
        return str(self.value)

    def __format__(self, spec: str) -> str:
        return format(str(self.value), spec)

    def __hash__(self) -> int:  # the value's: a member and its string are the same dict key
        return str.__hash__(self)


class PickStatus(_Word):
    """An instance's status, in the order a picks file's ``counts`` lists them: ``picked``;
    ``blocked`` (its grasps or its lift hit a neighbour), ``cloud`` (they hit the cloud), ``bin``
    (they hit the bin, the table or an obstacle); ``unreachable`` / ``ik_collision`` /
    ``lift_collision`` / ``no_path`` / ``place`` (collision-free grasps exist but no motion: the
    best one's); ``no_grasp`` (no grasp approaches from above); ``not_tried`` (budget or
    ``max_picks``). A grasp's motion (:class:`grasplan.pick.motion.Outcome`) has the status it
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


class Reason(_Word):
    """Why a grasp's motion (:class:`grasplan.pick.motion.Outcome`) or an instance's report
    (:class:`grasplan.pick.result.InstanceReport`) came out as it did."""

    #: a motion planned (the instance picked)
    PLANNED = "planned"
    #: the closed gripper hits something along the lift, whatever the IK solution
    LIFT_GRIPPER = "lift_gripper"
    #: no IK solution within the joint limits at the grasp
    NO_IK = "no_ik"
    #: every IK solution collides at the grasp or on the approach
    IK_COLLISION = "ik_collision"
    #: no IK solution can follow the straight approach or the lift (kinematics, no collision)
    LINE_NOT_FOLLOWED = "line_not_followed"
    #: with the part in the jaws the lift collides
    LIFT_COLLISION = "lift_collision"
    #: no transit home -> pre-grasp found
    NO_TRANSIT = "no_transit"
    #: the place (pick-and-place) cannot be reached or has no transfer path
    PLACE = "place"
    #: no grasp of the part approaches from above at the instance's pose
    NO_GRASP_FROM_ABOVE = "no_grasp_from_above"
    #: the part's grasp database is empty
    EMPTY_DATABASE = "empty_database"
    #: every lift drags the part through a neighbour or the cloud, whatever the grasp
    LIFT_BLOCKED = "lift_blocked"
    #: every one of the best-ranked grasps collides (gripper check)
    GRASPS_COLLIDE = "grasps_collide"
    #: not tried: the planning budget was spent
    BUDGET_SPENT = "budget_spent"
    #: not tried: ``max_picks`` was reached
    MAX_PICKS = "max_picks"


#: the status a grasp's motion outcome gives its instance, per reason code
GRASP_STATUS: dict[Reason, PickStatus] = {
    Reason.PLANNED: PickStatus.PICKED, Reason.LIFT_GRIPPER: PickStatus.LIFT_COLLISION,
    Reason.NO_IK: PickStatus.UNREACHABLE, Reason.IK_COLLISION: PickStatus.IK_COLLISION,
    Reason.LINE_NOT_FOLLOWED: PickStatus.UNREACHABLE, Reason.LIFT_COLLISION: PickStatus.LIFT_COLLISION,
    Reason.NO_TRANSIT: PickStatus.NO_PATH, Reason.PLACE: PickStatus.PLACE}
#: grasp outcomes another lift direction may plan: its lift collided or could not be followed
#: (not: no IK solution, a collision at the grasp or on the approach, no transit, the place)
LIFT_MAY_HELP: frozenset[Reason] = frozenset({Reason.LIFT_GRIPPER, Reason.LIFT_COLLISION, Reason.LINE_NOT_FOLLOWED})
