"""Grippers: kinds in a registry (parallel jaws, linkages), their shapes, loaded by name or YAML (:mod:`.load`)."""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "PARALLEL_JAW": ".model",
    "Gripper": ".model",
    "GripperKind": ".registry",
    "get_kind": ".registry",
    "BUILTIN_KINDS": ".load",
    "GRIPPER_DIR": ".load",
    "available_grippers": ".load",
    "gripper_from_dict": ".load",
    "gripper_from_json": ".load",
    "load_gripper": ".load",
})
