"""Stages 5-6b: gripper frames from contact pairs, the full-jaw collision filter, contact patches,
wrench quality and the score, composed by :mod:`.pipeline`; grasp databases (a part's grasps
computed once).

Every name below is imported from its module on first use (:mod:`grasplan._lazy`).
"""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "compute_grasps": ".pipeline", "GraspResult": ".pipeline",
    "grasp_frames": ".frames", "GraspFrames": ".frames",
    "check_grasps": ".collision",
    "Quality": ".quality", "quality_and_score": ".quality",
    "GraspDatabase": ".graspdb", "build_database": ".graspdb", "load_database": ".graspdb", "database_for": ".graspdb",
})
