"""Inverse kinematics: IK families (closed-form UR, CLIK) in a registry, one solver per robot (:mod:`.solve`)."""
from __future__ import annotations

from ..._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "CLIK": ".clik",
    "FAMILIES": ".registry",
    "ClosedFormIK": ".registry",
    "IKFamily": ".registry",
    "get_family": ".registry",
    "BUILTIN_FAMILIES": ".solve",
    "TWO_PI": ".solve",
    "IKResult": ".solve",
    "wrap_to_limits": ".solve",
    "wrap_many": ".solve",
    "DEDUP_TOL": ".solve",
    "IKSolver": ".solve",
    "get_solver": ".solve",
    "solve_ik": ".solve",
})
