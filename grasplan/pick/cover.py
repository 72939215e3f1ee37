"""The gripper's pairs a grasp's approach need not check again: what the Cartesian check of the
whole approach decided (:meth:`grasplan.pick.world.PickWorld.gripper_swept_free`).

Once IK has found the grasp reachable, and before any of its solutions is checked, the picker
sweeps each of the gripper's shapes (jaws at the pre-grasp opening) along the straight approach as
an oriented box grown by :data:`APPROACH_PAD` and checks those boxes against every body of the
pile (the grasped part included). When all are apart, the gripper touches nothing at any TCP pose
whose shapes lie inside them, whatever the arm does: at such a configuration the robot scene skips
the gripper's pairs with the world (:func:`grasplan.motion.lift_check.gripper_world_pairs`) and checks the arm's alone
(:func:`covered_check`). That covers the grasp configuration and every configuration of the
approach's path, the ones between waypoints included.
"""
from __future__ import annotations

import weakref
from collections.abc import Callable
from typing import Any

import numpy as np

from ..robot.model import Robot
from ..motion.collision_scene import CollisionScene
from ..motion.lift_check import gripper_world_pairs
from .gripboxes import SweptGripper
from ..robot.ik.lines import world_fk

#: the approach's swept boxes are this much (m) larger than the shapes' boxes along the line, so
#: that the configurations between waypoints (micrometres off the line) lie inside them too
APPROACH_PAD = 2e-4


_PAIRS: "weakref.WeakKeyDictionary[Any, np.ndarray]" = weakref.WeakKeyDictionary()


def covered_check(robot: Robot, T_flange_tcp: np.ndarray, scene: CollisionScene, swept: SweptGripper
                  ) -> tuple[Callable[[np.ndarray], np.ndarray], np.ndarray]:
    """``(covered, drop)`` for :meth:`grasplan.motion.collision_scene.CollisionScene.path_free`'s ``reduced``:
    ``covered(qs)`` is True at the configurations (k, n) whose gripper shapes lie inside
    ``swept`` (forward kinematics, then the containment test of
    :meth:`grasplan.pick.gripboxes.SweptGripper.holds`; the configurations between the approach's
    waypoints stray from the line by micrometres, within :data:`APPROACH_PAD`; one whose shapes
    leave the boxes is checked with every pair); ``drop``: the active pairs of ``scene`` between
    the gripper and the world."""
    mask = _PAIRS.get(scene._shared)
    if mask is None:
        mask = _PAIRS[scene._shared] = gripper_world_pairs(scene)
    drop = np.flatnonzero(scene._active & mask)
    T_ft = np.asarray(T_flange_tcp, dtype=np.float64)
    return (lambda qs: swept.holds(world_fk(robot, np.asarray(qs, dtype=np.float64).reshape(-1, robot.nq)) @ T_ft)), drop


def approach_cover(world: Any, robot: Robot, T_flange_tcp: np.ndarray, scene: CollisionScene
                   ) -> Callable[[np.ndarray, np.ndarray, float], Any]:
    """``MotionContext.approach_sweep`` of a pick: ``(T_pre, T_grasp, opening) -> (covered, drop)``
    (:func:`covered_check`) when the open gripper swept along the approach by
    :meth:`grasplan.pick.world.PickWorld.gripper_swept_free` (``world``, pad :data:`APPROACH_PAD`)
    touches nothing, else None."""

    def cover(T_pre: np.ndarray, T_grasp: np.ndarray, opening: float) -> Any:
        swept = world.gripper_swept_free(T_pre, T_grasp, opening, APPROACH_PAD)
        return None if swept is None else covered_check(robot, T_flange_tcp, scene, swept)
    return cover
