"""coal collision geometry, built in one place: the BVH of a triangle mesh and the geometry of a
gripper shape. The gripper filter (:mod:`grasplan.collision`) and the robot scene
(:mod:`grasplan.scene`) both build theirs here."""
from __future__ import annotations

from typing import Any

import coal
import numpy as np

from .errors import InputError


def bvh(vertices: np.ndarray, faces: np.ndarray) -> coal.BVHModelOBBRSS:
    """An OBBRSS bounding-volume hierarchy of a triangle mesh (vertices (V, 3) m, faces (F, 3))."""
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    m = coal.BVHModelOBBRSS()
    m.beginModel(len(f), len(v))
    m.addVertices(v)
    m.addTriangles(f)
    m.endModel()
    return m


def shape_geometry(shape: Any) -> tuple[coal.CollisionGeometry, np.ndarray]:
    """(coal geometry, T_tcp_geom (4, 4)) for a gripper shape.

    Duck-typed: a box has ``extents`` (3,) and ``T_tcp_box`` (4, 4); a mesh has ``vertices``
    (V, 3) and ``faces`` (F, 3) in the TCP frame (or ``.mesh``, a trimesh).
    """
    if hasattr(shape, "extents") and hasattr(shape, "T_tcp_box"):
        e = np.asarray(shape.extents, dtype=float)
        return coal.Box(float(e[0]), float(e[1]), float(e[2])), np.asarray(shape.T_tcp_box, dtype=float)
    if hasattr(shape, "vertices") and hasattr(shape, "faces"):
        return bvh(np.asarray(shape.vertices), np.asarray(shape.faces)), np.eye(4)
    if hasattr(shape, "mesh"):
        return bvh(np.asarray(shape.mesh.vertices), np.asarray(shape.mesh.faces)), np.eye(4)
    raise InputError(f"gripper shape {type(shape).__name__}: expected a box (extents, T_tcp_box) "
                     f"or a mesh (vertices, faces)")
