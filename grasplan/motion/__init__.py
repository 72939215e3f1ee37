"""Stages 7-8: the robot cell's collision scene, checks before planning, joint paths (OMPL) and
straight-line approaches, lift/transfer/place, and :func:`plan` composing them per grasp.

Every name below is imported from its module on first use (:mod:`grasplan._lazy`).
"""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "plan": ".planning", "plan_grasps": ".planning", "PlanOutcome": ".planning",
    "CollisionScene": ".collision_scene",
    "plan_joint_path": ".joint_paths", "approach_path": ".joint_paths",
    "plan_pick_motion": ".grasp_motion", "MotionContext": ".grasp_motion",
    "place_candidates": ".pickplace", "transfer_path": ".pickplace",
    "check_start": ".start_checks",
})
