"""Geometric checks of a scene's instances against the cell and each other (``grasplan pick``).

:func:`check_instances` needs the meshes (the scene file's own checks, :mod:`grasplan.scenefile`,
do not):

* a part reaching more than ``tol`` below the table top, or more than ``tol`` into a box, cylinder
  or sphere obstacle (the bin's floor and walls among them): :class:`~grasplan.errors.InputError`
  naming the instance, the body and the depth (a pose estimate that cannot be: exit 3);
* two instances interpenetrating by more than ``tol`` (pose-estimator noise): a warning naming
  the pairs and the depth. The depth is estimated from surface samples of each mesh (its vertices
  and a grid of :data:`PROBE_SPACING` on its faces, :func:`grasplan.containment.surface_samples`)
  inside the other (its voxel grid, :mod:`grasplan.insidegrid`, and near its surface signed ray
  crossings) and their distance to the other's surface (coal): a lower
  bound, within about the sample spacing of the true depth.
"""
from __future__ import annotations

import weakref
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import coal
import numpy as np

from .cell import Cell, Obstacle
from .containment import RayGrid, placed_in_box, surface_samples
from .errors import InputError
from .geometry import bvh, convex_geometry
from .insidegrid import inside_grid
from .meshdata import MeshData
from .scenefile import Instance

#: surface samples of a mesh probed inside another one: spacing (m) and how many at most per pair
PROBE_SPACING = 0.003
MAX_PROBES = 600
#: a probe point within this of a surface sample of the other mesh is at most this deep in it
#: (m, below ``tol``: float rounding of the distances)
_ROUNDING = 1e-9


@dataclass(frozen=True)
class _Prepared:
    """Per mesh: its ray grid (inside tests), probe points (:func:`surface_samples`) and a k-d tree
    of them (the nearest probe bounds a point's distance to the surface from above)."""

    grid: RayGrid
    probes: np.ndarray
    tree: Any
    lo: np.ndarray  #: the mesh's bounding box (part frame): no point outside it is inside the mesh
    hi: np.ndarray
    columns: np.ndarray  #: the probes as (3, k) rows x, y, z
    convex: coal.ConvexBase  #: the mesh's convex hull (two hulls apart: the meshes are apart)


#: the same for every scene, so a warm planner (the pick service) builds them once per part, not
#: once per request; dropped with the mesh
_PREPARED: weakref.WeakKeyDictionary[MeshData, _Prepared] = weakref.WeakKeyDictionary()


def _prepared(m: MeshData) -> _Prepared:
    """``m``'s :class:`_Prepared`, built on first use."""
    out = _PREPARED.get(m)
    if out is None:
        from scipy.spatial import cKDTree

        probes = surface_samples(m, spacing=PROBE_SPACING, max_samples=20_000)
        V = np.asarray(m.vertices, dtype=np.float64)
        out = _PREPARED[m] = _Prepared(RayGrid(m.vertices, m.faces), probes, cKDTree(probes), V.min(axis=0),
                                       V.max(axis=0), np.ascontiguousarray(probes.T), convex_geometry(V))
    return out


def prepare(m: MeshData) -> None:
    """Build ``m``'s probe data and voxel grid now (they are kept while the mesh lives)."""
    _prepared(m)
    inside_grid(m)


def _inside_depth(o: Obstacle, pts: np.ndarray) -> float:
    """Largest depth (m) of ``pts`` (world) inside a box, cylinder or sphere obstacle (0: none)."""
    T = np.asarray(o.T_world_obstacle, dtype=np.float64)
    local = (pts - T[:3, 3]) @ T[:3, :3]
    if o.kind == "box":
        d = 0.5 * np.asarray(o.box_size()) - np.abs(local)
        depth = d.min(axis=1)
    elif o.kind == "sphere":
        depth = o.dimension("radius") - np.linalg.norm(local, axis=1)
    elif o.kind == "cylinder":
        depth = np.minimum(o.dimension("radius") - np.linalg.norm(local[:, :2], axis=1),
                           0.5 * o.dimension("length") - np.abs(local[:, 2]))
    else:
        return 0.0
    return float(max(depth.max(initial=0.0), 0.0))


def _world_box(o: Obstacle) -> tuple[np.ndarray, np.ndarray] | None:
    """An axis-aligned box (world) holding a box, cylinder or sphere obstacle, a nanometre larger
    (rounding); None for other kinds."""
    T = np.asarray(o.T_world_obstacle, dtype=np.float64)
    if o.kind == "box":
        half = np.abs(T[:3, :3]) @ (0.5 * np.asarray(o.box_size(), dtype=np.float64))
    elif o.kind == "sphere":
        half = np.full(3, o.dimension("radius"))
    elif o.kind == "cylinder":
        half = np.full(3, float(np.hypot(o.dimension("radius"), 0.5 * o.dimension("length"))))
    else:
        return None
    return T[:3, 3] - half - 1e-9, T[:3, 3] + half + 1e-9


def check_cell(instances: Sequence[Instance], meshes: Mapping[str, MeshData], cell: Cell, *, tol: float) -> None:
    """InputError when an instance lies below the table or inside an obstacle by more than ``tol``
    (an obstacle whose bounding box the instance's does not meet holds none of its points)."""
    boxes = [_world_box(o) for o in cell.obstacles]
    for inst in instances:
        m = meshes[inst.part]
        T = inst.T_world_part
        pts = np.asarray(m.vertices) @ T[:3, :3].T + T[:3, 3]
        below = float(cell.table_z) - float(pts[:, 2].min())
        if below > tol:
            raise InputError(f"scene: instance {inst.id!r} ({inst.part}) reaches {below * 1e3:.1f} mm below the "
                             f"table top (z = {cell.table_z:g} m); at most {tol * 1e3:g} mm is pose noise: check its T")
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        for o, box in zip(cell.obstacles, boxes):
            if box is not None and (np.any(hi < box[0]) or np.any(lo > box[1])):
                continue
            d = _inside_depth(o, pts)
            if d > tol:
                where = "below the bin floor" if o.name == "bin_floor" else f"inside obstacle {o.name}"
                raise InputError(f"scene: instance {inst.id!r} ({inst.part}) lies {d * 1e3:.1f} mm {where}; at most "
                                 f"{tol * 1e3:g} mm is pose noise: check its T (z up, metres)")


def _depth_into(prep_a: _Prepared, Ta: np.ndarray, b: MeshData, prep_b: _Prepared, b_bvh: coal.BVHModelOBBRSS,
                Tb: np.ndarray, lo: np.ndarray, hi: np.ndarray, floor: float) -> float:
    """Largest distance to ``b``'s surface of the probe points of a part (``prep_a``) at pose ``Ta``
    inside ``b`` (pose ``Tb``) among those in the world box ``lo``..``hi`` when it is more than
    ``floor``; otherwise some value at most ``floor``.

    Points outside ``b``'s bounding box are not inside it. A point's distance to ``b``'s surface is
    at most its distance to ``b``'s nearest probe point (which lies on that surface), so the points
    within ``floor`` of one are skipped: none of them can be deeper than ``floor``, and the largest
    depth beyond it is found among the others."""
    pts = placed_in_box(prep_a.probes, Ta, lo, hi, columns=prep_a.columns)
    if not len(pts):
        return 0.0
    local = (pts - Tb[:3, 3]) @ Tb[:3, :3]
    if len(local) > MAX_PROBES:
        local = local[np.linspace(0, len(local) - 1, MAX_PROBES).astype(np.int64)]
    local = local[np.all((local >= prep_b.lo) & (local <= prep_b.hi), axis=1)]  # outside b's box: not in b
    if not len(local):
        return 0.0
    grid = inside_grid(b)  # the voxel grid decides most points (grasplan.insidegrid)
    state, _ = grid.lookup(local)
    local = local[state >= 0]  # outside b
    if floor > _ROUNDING and len(local):
        near, _ = prep_b.tree.query(local, distance_upper_bound=floor - _ROUNDING)
        local = local[~np.isfinite(near)]  # no probe of b within floor: possibly deeper than floor
    if not len(local):
        return 0.0
    inside = local[grid.inside(prep_b.grid, b, local)]
    if not len(inside):
        return 0.0
    # measured from the largest upper bound of the depth down (the distance to b's nearest probe),
    # until no bound left exceeds the deepest found: the same largest depth, fewer distances
    upper, _ = prep_b.tree.query(inside)
    best = 0.0
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    probe, tf, eye = coal.Sphere(1e-9), coal.Transform3s(), coal.Transform3s()
    for k in np.argsort(-upper, kind="stable"):
        if upper[k] + _ROUNDING < best:
            break
        tf.setTranslation(inside[k])
        res.clear()
        best = max(best, float(coal.distance(probe, tf, b_bvh, eye, req, res)))
    return best


def overlap_warnings(instances: Sequence[Instance], meshes: Mapping[str, MeshData], *, tol: float,
                     bvhs: Mapping[str, coal.BVHModelOBBRSS] | None = None) -> list[str]:
    """One warning per pair of instances interpenetrating by more than ``tol`` (m)."""
    bvhs = dict(bvhs or {})
    for name in meshes:
        if name not in bvhs:
            bvhs[name] = bvh(meshes[name].vertices, meshes[name].faces)
    boxes = []
    for inst in instances:
        T = inst.T_world_part
        w = np.asarray(meshes[inst.part].vertices) @ T[:3, :3].T + T[:3, 3]
        boxes.append((w.min(axis=0), w.max(axis=0)))
    req, res = coal.CollisionRequest(), coal.CollisionResult()
    hreq, hres = coal.CollisionRequest(), coal.CollisionResult()
    out = []
    for i, a in enumerate(instances):
        for j in range(i + 1, len(instances)):
            b = instances[j]
            lo = np.maximum(boxes[i][0], boxes[j][0])
            hi = np.minimum(boxes[i][1], boxes[j][1])
            if np.any(lo > hi):
                continue
            pa, pb = _prepared(meshes[a.part]), _prepared(meshes[b.part])
            tfa = coal.Transform3s(a.T_world_part[:3, :3].copy(), a.T_world_part[:3, 3].copy())
            tfb = coal.Transform3s(b.T_world_part[:3, :3].copy(), b.T_world_part[:3, 3].copy())
            hres.clear()
            if not coal.collide(pa.convex, tfa, pb.convex, tfb, hreq, hres):  # hulls apart: meshes apart
                continue
            res.clear()
            if not coal.collide(bvhs[a.part], tfa, bvhs[b.part], tfb, req, res):
                continue
            d = max(_depth_into(pa, a.T_world_part, meshes[b.part], pb, bvhs[b.part], b.T_world_part, lo, hi, tol),
                    _depth_into(pb, b.T_world_part, meshes[a.part], pa, bvhs[a.part], a.T_world_part, lo, hi, tol))
            if d > tol:
                out.append(f"instances {a.id!r} and {b.id!r} interpenetrate by about {d * 1e3:.1f} mm (more than "
                           f"{tol * 1e3:g} mm of pose noise); their picks are planned as given")
    return out


def check_instances(instances: Sequence[Instance], meshes: Mapping[str, MeshData], cell: Cell, *, tol: float,
                    bvhs: Mapping[str, coal.BVHModelOBBRSS] | None = None) -> list[str]:
    """:func:`check_cell` (raises) then :func:`overlap_warnings` (returned)."""
    check_cell(instances, meshes, cell, tol=tol)
    return overlap_warnings(instances, meshes, tol=tol, bvhs=bvhs)
