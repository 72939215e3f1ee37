"""The robot cell: table, bin and obstacles (:class:`Cell`, loaded by name or YAML), their coal
collision shapes, and the part resting on the table.

Every name below is imported from its module on first use (:mod:`grasplan._lazy`).
"""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "Cell": ".model", "Obstacle": ".model", "BinSpec": ".model", "load_cell": ".model",
    "available_cells": ".model", "cell_from_dict": ".model",
    "stable_pose": ".resting", "place_on_table": ".resting",
    "bvh": ".shapes", "convex_geometry": ".shapes", "obstacle_geometry": ".shapes",
})
