"""coal collision geometry, built in one place: the BVH of a triangle mesh, the geometry of a
gripper shape and of a cell obstacle. The gripper filter (:mod:`grasplan.grasps.collision`) and the robot scene
(:mod:`grasplan.motion.collision_scene`) both build theirs here."""
from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import coal
import numpy as np

from .model import Obstacle
from ..errors import InputError
from ..gripper.model import Box, MeshShape, Shape


#: m: the table, a box this wide, deep and high whose top face lies on the table plane, centred
#: under the world origin (a half-space within reach of any arm; coal prunes BVH nodes against a box)
TABLE_SIZE = (20.0, 20.0, 2.0)


def table_pose(table_z: float, shrink: float = 0.0) -> np.ndarray:
    """``T_world_table`` (4, 4) of the :data:`TABLE_SIZE` box whose top face lies at ``table_z``,
    lowered by ``shrink`` (m: the copy the part held in the jaws may touch by that much)."""
    T = np.eye(4)
    T[2, 3] = float(table_z) - TABLE_SIZE[2] / 2
    if shrink:
        T[2, 3] -= shrink
    return T


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


#: triangles of the part structures :func:`shared_bvh` and :func:`shared_mesh_structure` keep for
#: reuse, per kind (least recently used dropped first)
SHARED_BVH_TRIANGLES = 400_000
_SHARED: OrderedDict[bytes, tuple[Any, int]] = OrderedDict()
_SHARED_LOCK = threading.Lock()


def shared_mesh_structure(kind: str, vertices: np.ndarray, faces: np.ndarray,
                          build: Callable[[np.ndarray, np.ndarray], Any]) -> Any:
    """``build(vertices, faces)`` (a read-only structure over a part mesh: a coal BVH, the compiled
    box hierarchy of :class:`grasplan.grasps.collision_boxes.PartBoxes`) built once per ``kind`` and
    content and shared by every scene and filter of the process; a warm plan or pick builds none.
    The kept structures of a kind hold at most :data:`SHARED_BVH_TRIANGLES` triangles in all (a
    larger mesh is built and not kept)."""
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    h = hashlib.blake2b(v.tobytes(), digest_size=20)
    h.update(f.tobytes())
    key = kind.encode() + b"\0" + h.digest() + np.asarray(v.shape + f.shape, dtype=np.int64).tobytes()
    with _SHARED_LOCK:
        hit = _SHARED.get(key)
        if hit is not None:
            _SHARED.move_to_end(key)
            return hit[0]
    made = build(v, f)
    if len(f) <= SHARED_BVH_TRIANGLES:
        prefix = kind.encode() + b"\0"
        with _SHARED_LOCK:
            _SHARED[key] = (made, len(f))
            while sum(n for k, (_, n) in _SHARED.items() if k.startswith(prefix)) > SHARED_BVH_TRIANGLES:
                del _SHARED[next(k for k in _SHARED if k.startswith(prefix))]
    return made


def shared_bvh(vertices: np.ndarray, faces: np.ndarray) -> coal.BVHModelOBBRSS:
    """:func:`bvh` of a part mesh, built once per content and shared (read-only: coal's queries do
    not change it; :func:`shared_mesh_structure`)."""
    return shared_mesh_structure("bvh", vertices, faces, bvh)


def convex_geometry(points: np.ndarray) -> coal.ConvexBase:
    """The convex hull of ``points`` (k, 3) as a coal convex shape (GJK against it takes
    microseconds: a mesh whose hull is apart from something is apart from it)."""
    pts = coal.StdVec_Vec3s()
    for v in np.asarray(points, dtype=np.float64).reshape(-1, 3):
        pts.append(v)
    return coal.Convex.convexHull(pts, False, "")


def local_box(geom: coal.CollisionGeometry) -> tuple[np.ndarray, np.ndarray]:
    """``(centre (3,), half extents (3,))`` of coal's local box of ``geom`` (a mesh's vertices' box, a
    primitive's exact extent; not finite for an unbounded shape)."""
    geom.computeLocalAABB()
    lo, hi = np.array(geom.aabb_local.min_, dtype=np.float64), np.array(geom.aabb_local.max_, dtype=np.float64)
    return 0.5 * (lo + hi), 0.5 * (hi - lo)


def shape_geometry(shape: Shape) -> tuple[coal.CollisionGeometry, np.ndarray]:
    """(coal geometry, T_tcp_geom (4, 4)) for a gripper shape (:mod:`grasplan.gripper`): a
    :class:`~grasplan.gripper.Box` (``extents`` (3,), ``T_tcp_box`` (4, 4)) or a
    :class:`~grasplan.gripper.MeshShape` (``vertices`` (V, 3) and ``faces`` (F, 3) in the TCP frame).
    """
    if isinstance(shape, Box):
        e = np.asarray(shape.extents, dtype=float)
        return coal.Box(float(e[0]), float(e[1]), float(e[2])), np.asarray(shape.T_tcp_box, dtype=float)
    if isinstance(shape, MeshShape):
        return bvh(np.asarray(shape.vertices), np.asarray(shape.faces)), np.eye(4)
    raise InputError(f"gripper shape {type(shape).__name__}: expected a box (extents, T_tcp_box) "
                     f"or a mesh (vertices, faces)")


def obstacle_geometry(obstacle: Obstacle, *, shrink: float = 0.0) -> coal.CollisionGeometry:
    """coal geometry of a cell obstacle (:class:`grasplan.cell.model.Obstacle`) in its own frame: a
    ``Box``, a ``Cylinder`` (axis = local z, centred), a ``Sphere`` or the mesh's BVH.

    ``shrink`` (m) moves every face of a box, cylinder or sphere inwards by that much (never below
    a tenth of its size), so that touching it within ``shrink`` is no collision; a mesh is not shrunk."""
    kind = obstacle.kind
    s = float(shrink)

    def cut(x: float, by: float) -> float:
        return max(float(x) - by, 0.1 * float(x))

    if kind == "box":
        return coal.Box(*(cut(x, 2 * s) for x in obstacle.box_size()))
    if kind == "cylinder":
        return coal.Cylinder(cut(obstacle.dimension("radius"), s), cut(obstacle.dimension("length"), 2 * s))
    if kind == "sphere":
        return coal.Sphere(cut(obstacle.dimension("radius"), s))
    if kind == "mesh":
        return bvh(*obstacle.mesh_arrays())
    raise InputError(f"obstacle {obstacle.name}: unknown kind {kind!r}; expected box, cylinder, sphere or mesh")
