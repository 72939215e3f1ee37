"""Piles: scene files (many parts at known poses in a cell, ``grasplan.scene/1``) read and written,
point clouds of what a scene does not model, and the geometric checks of a pile's instances.

Every name below is imported from its module on first use (:mod:`grasplan._lazy`).
"""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "Scene": ".scene_file", "Instance": ".scene_file", "load_scene": ".scene_file", "scene_from_dict": ".scene_file",
    "write_scene": ".scene_write",
    "Cloud": ".cloud", "read_cloud": ".cloud",
    "check_instances": ".checks",
})
