"""Geometry helpers with NumPy (and coal where named): transforms, the mesh as arrays, units,
tolerances, neighbour search, exact inside tests, convex polygons, path interpolation and coal's
collision shapes.

Every name below is imported from its module on first use (:mod:`grasplan._lazy`).
"""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "check_transform": ".transforms", "inv_rigid": ".transforms", "xyz_rpy": ".transforms", "rpy_matrix": ".transforms",
    "MeshData": ".meshdata", "TriangleMesh": ".meshdata",
    "Tolerance": ".tolerance",
    "parse_length": ".units", "parse_angle_deg": ".units",
    "interpolate_path": ".interpolation",
})
