"""The reason codes carried beside each human-readable reason (:class:`Reason`) of a grasp's
motion (:class:`grasplan.motion.grasp_motion.Outcome`) and of a pick's instance report: code
branches on the codes, the text is for people."""
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


class Reason(_Word):
    """Why a grasp's motion (:class:`grasplan.motion.grasp_motion.Outcome`) or an instance's report
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
    #: the place (pick-and-place) cannot be reached or has no transfer path (``Outcome.place_status``
    #: says which)
    PLACE = "place"
    #: no grasp of the part approaches from above at the instance's pose
    NO_GRASP_FROM_ABOVE = "no_grasp_from_above"
    #: the part's grasp database is empty
    EMPTY_DATABASE = "empty_database"
    #: every lift drags the part through a neighbour or the cloud, whatever the grasp
    LIFT_BLOCKED = "lift_blocked"
    #: every one of the best-ranked grasps collides (gripper check)
    GRASPS_COLLIDE = "grasps_collide"
    #: every collision-free grasp is predicted to slip (gravity margin below ``min_gravity_margin``)
    GRASPS_WEAK = "grasps_weak"
    #: not tried: the planning budget was spent
    BUDGET_SPENT = "budget_spent"
    #: not tried: ``max_picks`` was reached
    MAX_PICKS = "max_picks"
