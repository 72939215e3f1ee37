"""Options of ``grasplan pick`` / :class:`grasplan.Picker`: one frozen dataclass, an
:class:`~grasplan.config.params.OptionSet` like the pipeline's (CLI options, validation, JSON record).

Lengths m, user-facing angles degrees (``*_deg``), times s."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config.option_kinds import spec
from ..config.params import OptionSet


@dataclass(frozen=True, kw_only=True)
class PickParams(OptionSet):
    """Ranking, accessibility, motion and tolerances of a pick (docs/pick.md)."""

    seed: int = spec(0, "int", "Seed of IK and OMPL (same seed, same picks).", lo=0, hi=2**31 - 1)
    backoff: float = spec(0.05, "length", "Pre-grasp back-off along the TCP's -z (the straight approach).",
                          lo=0.0, hi=0.5, show="50mm")
    max_dev: float = spec(0.002, "length", "Straight approach and lift: largest TCP distance from the line.",
                          hi=0.05, show="2mm")
    max_tilt_deg: float = spec(75.0, "angle", "Grasps whose approach direction (TCP z) is more than this many "
                               "degrees from straight down are not tried.", cli="--max-tilt", lo=0.0, hi=180.0)
    vertical_weight: float = spec(0.25, "float", "Ranking: key = score + this x cos(tilt of the approach).",
                                  lo=0.0, hi=10.0)
    grasps_per_instance: int = spec(12, "int", "Grasps motion-planned per instance (best ranked collision-free "
                                    "first) before the instance is reported unreachable.", lo=1, hi=10000)
    max_checked: int = spec(2048, "int", "Grasps gripper-checked per instance (best ranked first); when all of "
                            "them collide the instance is blocked.", lo=1, hi=10**6)
    max_ik_solutions: int = spec(4, "int", "IK solutions tried per grasp (closest to q_home first).", lo=1, hi=64)
    time_limit_per_query: float = spec(0.2, "seconds", "RRTConnect time per attempt when the straight transit "
                                       "collides, seconds.", cli="--time-limit", hi=600.0)
    path_attempts: int = spec(1, "int", "RRTConnect attempts per transit query.", lo=1, hi=20)
    max_path_queries: int = spec(1, "int", "RRTConnect queries per grasp (distinct IK solutions).", lo=1, hi=64)
    lift_contact: float = spec(0.002, "length0", "Lift: within this TCP travel from the grasp the part in the jaws "
                               "may touch the bin, the table or a neighbour it rests on (beyond it, only contacts "
                               "with neighbours within --lift-depth: a part dragged through its neighbour is no "
                               "pick).", hi=0.05,
                               show="2mm")
    lift_depth: float = spec(0.001, "length0", "Lift: all along it the part in the jaws may touch a neighbour "
                             "when they interpenetrate by at most this much (a part sliding up beside the one it "
                             "rests against in a settled pile), deeper than the two already interpenetrate at rest (pose "
                             "noise; counted up to --overlap-tol); deeper is a collision (dragged through it). 0: any "
                             "contact beyond --lift-contact is a collision.", hi=0.01, show="1mm")
    lift_carry: bool = spec(True, "bool", "Lift: when the part's straight lift is blocked by a neighbour, a "
                            "neighbour lying on the part (its own straight lift free of the part and of everything "
                            "else) may be raised with it: pushed up, not dragged through; such picks come after "
                            "every clean one and name it (lift_carries); needs --lift-depth > 0. --no-lift-carry: "
                            "every neighbour blocks.")
    max_lift_tilt_deg: float = spec(45.0, "angle", "Lift: when the straight lift along the cell's retreat is "
                                    "blocked (by a neighbour, or for a grasp's gripper or arm), lifts tilted "
                                    "15/30/45 deg from it up to this many degrees are tried (docs/pick.md, the "
                                    "lift); 0: the straight lift only.", cli="--max-lift-tilt", lo=0.0, hi=60.0)
    overlap_tol: float = spec(0.002, "length0", "Scene checks: instances interpenetrating by more than this are "
                              "a warning; a part more than this below the bin floor, the table or inside an "
                              "obstacle is an error.", hi=0.05, show="2mm")
    place: tuple[tuple[float, ...], ...] | None = spec(
        None, "pose", "Pick-and-place: every picked part's pose after release, 'x,y,z,roll,pitch,yaw' (lengths m or "
        "with units, angles deg, R = Rz(yaw) Ry(pitch) Rx(roll)); the lifted part is carried there (OMPL, part in "
        "the jaws), lowered, released and the gripper retreats. Default: the cell's place, if any.", optional=True)
    min_gravity_margin: float = spec(0.0, "float", "Grasps whose gravity margin at the instance's pose is below "
                                     "this are not planned (1: only grasps predicted to hold the part's weight and "
                                     "the shared load at the gripper's force; 0: off). docs/quality.md.",
                                     lo=0.0, hi=100.0)
    budget_s: float | None = spec(None, "seconds", "Wall-clock budget of one plan() call, seconds, counted from the "
                                  "loaded parts and cell: a hard limit, checked inside every long stage; the instance "
                                  "being planned and those not reached are 'not_tried'.", cli="--budget", hi=86400.0,
                                  optional=True)

    def place_matrix(self) -> np.ndarray | None:
        """:attr:`place` as a (4, 4) ``T_world_part`` (None: the cell's place, if any)."""
        return None if self.place is None else np.asarray(self.place, dtype=np.float64)

    @property
    def cos_max_tilt(self) -> float:
        return math.cos(math.radians(self.max_tilt_deg))
