"""Results: the typed :class:`PlanResult` of the grasps and plan stages, its one writer and reader
(``grasplan.grasps/1``, ``grasplan.plan/1``), the per-grasp table and column-wise JSON.

Every name below is imported from its module on first use (:mod:`grasplan._lazy`).
"""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "PlanResult": ".plan_result",
    "load_result": ".reader",
    "write_result": ".writer",
    "GraspTable": ".grasp_table",
    "write_pose_plans": ".pose_plans",
})
