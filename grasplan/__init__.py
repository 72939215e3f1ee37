"""grasplan: verified parallel-jaw grasps from a part's CAD mesh.

Pipeline (one module per stage): :mod:`grasplan.mesh` -> :mod:`grasplan.blm` ->
:mod:`grasplan.convexity` -> :mod:`grasplan.antipodal` -> :mod:`grasplan.frames` ->
:mod:`grasplan.collision` -> :mod:`grasplan.ik` -> :mod:`grasplan.paths` ->
:mod:`grasplan.export` / :mod:`grasplan.viewer`.

The whole pipeline in three lines::

    import grasplan
    result = grasplan.plan("part.stl", "ur5")              # or a Part from grasplan.load_part
    result.export("urscript", "grasp.script")              # any name in grasplan.export.FORMATS

Options are three frozen dataclasses (``CandidateParams``, ``GraspParams``, ``PlanParams``)::

    grasplan.plan(part, "ur5", candidates=grasplan.CandidateParams(spacing=0.003),
                  planning=grasplan.PlanParams(top=5, seed=1))

A saved result comes back typed, with its gripper, cell and robot rebuilt from the file::

    plan = grasplan.load_result("plan.json")

Heavy modules (Pinocchio, OMPL) load only when a function that needs them is first used.
"""
from __future__ import annotations

import importlib

from .errors import ConfigError, GrasplanError, InputError, MeshError, PlanningError

__version__ = "0.2.0"

# public name -> (module, attribute), imported on first use
_LAZY = {
    "Part": ("grasplan.mesh", "Part"),
    "load_part": ("grasplan.mesh", "load_part"),
    "CandidateParams": ("grasplan.params", "CandidateParams"),
    "GraspParams": ("grasplan.params", "GraspParams"),
    "PlanParams": ("grasplan.params", "PlanParams"),
    "PlanResult": ("grasplan.result", "PlanResult"),
    "load_result": ("grasplan.result_reader", "load_result"),
    "use_config_dirs": ("grasplan.config_files", "use_config_dirs"),
    "export": ("grasplan.export", None),
    "compute_candidates": ("grasplan.candidates", "compute_candidates"),
    "compute_grasps": ("grasplan.grasps", "compute_grasps"),
    "load_gripper": ("grasplan.gripper", "load_gripper"),
    "load_robot": ("grasplan.robot", "load_robot"),
    "load_cell": ("grasplan.cell", "load_cell"),
    "solve_ik": ("grasplan.ik", "solve_ik"),
    "plan": ("grasplan.planning", "plan"),
    "write_viewer": ("grasplan.viewer", "write_viewer"),
    "Picker": ("grasplan.pick.picker", "Picker"),
    "PickParams": ("grasplan.pick.params", "PickParams"),
    "PickResult": ("grasplan.pick.result", "PickResult"),
    "load_picks": ("grasplan.pick.reader", "load_picks"),
}

__all__ = ["GrasplanError", "InputError", "MeshError", "ConfigError", "PlanningError", "__version__", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        module, attr = _LAZY[name]
        mod = importlib.import_module(module)
        value = mod if attr is None else getattr(mod, attr)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'grasplan' has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
