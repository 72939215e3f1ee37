"""Robots: descriptions (a YAML around a URDF/SRDF pair) loaded into an immutable, shared
:class:`Robot` (Pinocchio model), the files they name, and inverse kinematics (:mod:`.ik`).

Every name below is imported from its module on first use (:mod:`grasplan._lazy`).
"""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "load_robot": ".description", "available_robots": ".description", "robot_from_json": ".description",
    "Robot": ".model",
})
