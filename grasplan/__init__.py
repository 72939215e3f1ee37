"""grasplan: verified parallel-jaw grasps from a part's CAD mesh.

Stages, one module each: :mod:`grasplan.part.mesh` -> :mod:`grasplan.candidates.blm` ->
:mod:`grasplan.candidates.convexity` -> :mod:`grasplan.candidates.antipodal` -> :mod:`grasplan.grasps.frames` ->
:mod:`grasplan.grasps.collision` -> :mod:`grasplan.robot.ik` -> :mod:`grasplan.motion.joint_paths` ->
:mod:`grasplan.export` / :mod:`grasplan.viewer`. Options are three frozen dataclasses (``CandidateParams``,
``GraspParams``, ``PlanParams``); heavy modules (Pinocchio, OMPL) load when first needed::

    import grasplan
    result = grasplan.plan("part.stl", "ur5", planning=grasplan.PlanParams(top=5))  # or a grasplan.load_part Part
    result.export("urscript", "grasp.script")             # any name in grasplan.export.FORMATS
    plan = grasplan.load_result("plan.json")              # typed; gripper, cell and robot rebuilt from the file
"""
from __future__ import annotations

from ._lazy import lazy_exports
from .errors import ConfigError, GrasplanError, InputError, MeshError, PlanningError

__version__ = "0.2.0"

# public name -> its module, imported on first use
_LAZY = {
    "Part": ".part.mesh", "load_part": ".part.mesh",
    "CandidateParams": ".config.params", "GraspParams": ".config.params", "PlanParams": ".config.params",
    "PlanResult": ".results.plan_result", "load_result": ".results.reader",
    "use_config_dirs": ".config.lookup",
    "export": ".export",
    "compute_candidates": ".candidates.pipeline", "compute_grasps": ".grasps.pipeline",
    "load_gripper": ".gripper", "load_robot": ".robot.description", "load_cell": ".cell.model",
    "solve_ik": ".robot.ik", "plan": ".motion.planning", "write_viewer": ".viewer",
    "Picker": ".pick.picker", "PickParams": ".pick.params", "PickResult": ".pick.result", "load_picks": ".pick.reader",
}

__all__ = ["GrasplanError", "InputError", "MeshError", "ConfigError", "PlanningError", "__version__", *_LAZY]

__getattr__, _dir = lazy_exports(globals(), _LAZY)


def __dir__() -> list[str]:
    return sorted(__all__)
