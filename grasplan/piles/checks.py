"""Geometric checks of a scene's instances against the cell and each other (``grasplan pick``).

:func:`check_instances` needs the meshes (the scene file's own checks, :mod:`grasplan.piles.scene_file`,
do not): a part below the table top or inside an obstacle (:func:`check_cell`), two instances in
the same place (:func:`check_coincident`) and two instances interpenetrating
(:func:`overlap_warnings`).
"""
from __future__ import annotations

import weakref
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import coal
import numpy as np

from ..cell.model import Cell, Obstacle
from ..geometry.containment import RayGrid, crossing_counts, placed_in_box, points_inside, surface_samples
from ..errors import InputError
from ..cell.shapes import bvh, convex_geometry
from ..geometry.insidegrid import InsideGrid, inside_grid
from ..geometry.meshdata import MeshData
from .scene_file import Instance

#: surface samples of a mesh probed inside another one: spacing (m) and how many at most per pair
PROBE_SPACING = 0.003
MAX_PROBES = 600
#: a probe point within this of a surface sample of the other mesh is at most this deep in it
#: (m, below ``tol``: float rounding of the distances)
_ROUNDING = 1e-9
#: instances interpenetrating deeper than this many ``tol`` (and than MIN_DEEP_M, m) are refused
MAX_OVERLAP_TOLS = 5.0
MIN_DEEP_M = 0.010
#: a point the ray test cannot decide that lies within this (m) of a mesh's surface is outside it
#: for a depth (:func:`inside_for_depth`)
ON_SURFACE = 1e-9
#: points per batch of ray crossings in :func:`inside_for_depth`
_RAY_CHUNK = 2048


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


def inside_for_depth(grid: InsideGrid, ray: RayGrid, mesh: MeshData, mesh_bvh: coal.BVHModelOBBRSS,
                     points: np.ndarray, check: Callable[[], None] | None = None) -> np.ndarray:
    """(k,) bool: which points (the mesh's frame) lie inside the mesh, for a penetration depth: the
    voxel grid's verdict where it has one, else the signed crossing count of
    :func:`grasplan.geometry.containment.points_inside_tree`, except that a point on the surface counts as
    outside instead of going to the generalised winding number: one whose ray meets a triangle at
    the point itself, well inside the triangle's edges, and among the others the crossing count
    cannot decide, one within :data:`ON_SURFACE` of the surface (coal's distance). Such a point is
    at most that deep, so no depth beyond it changes; but a part whose faces lie exactly in the
    planes of another's (a copy moved along a face, two parts resting on one floor) does not send
    thousands of points through the winding number (points x faces). The rest of the undecided
    points (a ray grazing an edge or a vertex) get the winding number as there. ``check``: called
    between chunks of the work (a planning budget's, which raises when spent)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    state, _ = grid.lookup(pts)
    out = state == 1
    todo = np.flatnonzero(state == 0)
    if not len(todo):
        return out
    p0 = pts[todo]
    wind, tie, surface = crossing_counts(ray, p0 @ ray.Q.T, check=check, chunk=_RAY_CHUNK)
    inside = (wind != 0) & ~surface
    k = np.flatnonzero(tie & ~surface)
    if len(k):
        req, res = coal.DistanceRequest(), coal.DistanceResult()
        probe, tf, eye = coal.Sphere(1e-12), coal.Transform3s(), coal.Transform3s()
        far = np.ones(len(k), dtype=bool)
        for n, i in enumerate(k.tolist()):
            if check is not None and n % 256 == 255:
                check()
            tf.setTranslation(p0[i])
            res.clear()
            far[n] = coal.distance(probe, tf, mesh_bvh, eye, req, res) > ON_SURFACE
        inside[k[~far]] = False
        if far.any():
            inside[k[far]] = points_inside(mesh, p0[k[far]])
    out[todo] = inside
    return out


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
    grid = inside_grid(b)  # the voxel grid decides most points (grasplan.geometry.insidegrid)
    state, _ = grid.lookup(local)
    local = local[state >= 0]  # outside b
    if floor > _ROUNDING and len(local):
        near, _ = prep_b.tree.query(local, distance_upper_bound=floor - _ROUNDING)
        local = local[~np.isfinite(near)]  # no probe of b within floor: possibly deeper than floor
    if not len(local):
        return 0.0
    inside = local[inside_for_depth(grid, prep_b.grid, b, b_bvh, local)]
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


def _hull_vertices(m: MeshData) -> np.ndarray:
    """``m``'s convex hull vertices (every vertex of a flat or degenerate mesh)."""
    try:
        return np.asarray(m.convex_hull.vertices, dtype=np.float64)
    except Exception:  # scipy's QhullError
        return np.unique(np.asarray(m.vertices, dtype=np.float64), axis=0)


def thickness(hull: np.ndarray) -> float:
    """The extent (m) of hull vertices ``hull`` (k, 3) along their shortest principal axis."""
    c = np.asarray(hull, dtype=np.float64) - np.mean(hull, axis=0)
    if len(c) < 2:
        return 0.0
    axes = np.linalg.svd(c, full_matrices=False)[2]
    return float(np.ptp(c @ axes.T, axis=0).min())


def check_coincident(instances: Sequence[Instance], meshes: Mapping[str, MeshData], *, tol: float,
                     hulls: Mapping[str, np.ndarray] | None = None) -> None:
    """InputError naming the first two instances (scene order) that lie in the same place: every
    vertex of either one's convex hull (placed) within ``tol`` (m), and within half the thinner
    part's :func:`thickness`, of a vertex of the other's: the symmetric Hausdorff distance of the
    two vertex sets (so a symmetric part turned onto itself counts too). Within pose noise such a
    pair is one part seen twice: no two solids can be there (a thin part lying flat on its twin is
    its thickness away, so it is not refused).

    Only pairs whose world boxes (of the hull vertices) differ by at most ``tol`` in every bound
    are measured (a smaller Hausdorff distance moves no bound further). ``hulls``: each part's hull
    vertices when known (else computed from the mesh)."""
    n = len(instances)
    if n < 2:
        return
    from scipy.spatial import cKDTree

    known = hulls or {}
    hull = {name: known[name] if name in known else _hull_vertices(meshes[name])
            for name in {i.part for i in instances}}
    half = {name: 0.5 * thickness(h) for name, h in hull.items()}
    world = [hull[i.part] @ i.T_world_part[:3, :3].T + i.T_world_part[:3, 3] for i in instances]
    bounds = np.array([np.concatenate([w.min(axis=0), w.max(axis=0)]) for w in world])
    trees: dict[int, Any] = {}

    def tree(k: int) -> Any:
        if k not in trees:
            trees[k] = cKDTree(world[k])
        return trees[k]

    for i in range(n - 1):
        near = np.abs(bounds[i + 1:] - bounds[i]).max(axis=1) <= tol + 1e-12
        for j in (i + 1 + np.flatnonzero(near)).tolist():
            a, b = instances[i], instances[j]
            lim = min(tol, half[a.part], half[b.part]) + 1e-12
            d_ij = float(tree(j).query(world[i], distance_upper_bound=lim)[0].max())
            if not np.isfinite(d_ij):
                continue
            d = max(d_ij, float(tree(i).query(world[j], distance_upper_bound=lim)[0].max()))
            if np.isfinite(d):
                raise InputError(
                    f"scene: instances {a.id!r} ({a.part}) and {b.id!r} ({b.part}) lie in the same place: every "
                    f"point of either one's convex hull is within {d * 1e3:.2f} mm of the other's (within "
                    f"--overlap-tol {tol * 1e3:g} mm, and half the part's thickness, it is one part reported "
                    f"twice); remove one of them or correct its T")


def deep_limit(tol: float) -> float:
    """The interpenetration (m) beyond which two instances are refused, for the tolerance ``tol``."""
    return max(MAX_OVERLAP_TOLS * tol, MIN_DEEP_M)


def overlap_warnings(instances: Sequence[Instance], meshes: Mapping[str, MeshData], *, tol: float,
                     bvhs: Mapping[str, coal.BVHModelOBBRSS] | None = None,
                     spent: Callable[[], bool] | None = None, refuse: float | None = None) -> list[str]:
    """One warning per pair of instances interpenetrating by more than ``tol`` (m); InputError for
    the first pair deeper than ``refuse`` (m; None: none). ``spent``: asked before each pair's depth
    estimate; when it answers True (a planning budget spent) the pairs left are not estimated and
    the last warning says how many.

    The depth is estimated from surface samples of each mesh (its vertices and a grid of
    :data:`PROBE_SPACING` on its faces, :func:`grasplan.geometry.containment.surface_samples`) inside the
    other (its voxel grid, :mod:`grasplan.geometry.insidegrid`, and near its surface signed ray crossings,
    :func:`inside_for_depth`) and their distance to the other's surface (coal): a lower bound,
    within about the sample spacing of the true depth (:func:`_depth_into`)."""
    bvhs = dict(bvhs or {})
    for name in meshes:
        if name not in bvhs:
            bvhs[name] = bvh(meshes[name].vertices, meshes[name].faces)
    lo_hi = []
    for inst in instances:
        T = inst.T_world_part
        w = np.asarray(meshes[inst.part].vertices) @ T[:3, :3].T + T[:3, 3]
        lo_hi.append((w.min(axis=0), w.max(axis=0)))
    lows = np.array([b[0] for b in lo_hi]).reshape(-1, 3)
    highs = np.array([b[1] for b in lo_hi]).reshape(-1, 3)
    # the pairs whose world boxes meet, in scene order (i, then j)
    meet = np.all(np.maximum(lows[:, None], lows[None]) <= np.minimum(highs[:, None], highs[None]), axis=2)
    pending = [(int(i), int(j)) for i, j in zip(*np.nonzero(np.triu(meet, k=1)))]
    req, res = coal.CollisionRequest(), coal.CollisionResult()
    hreq, hres = coal.CollisionRequest(), coal.CollisionResult()
    out = []
    for n_done, (i, j) in enumerate(pending):
        if spent is not None and spent():
            out.append(f"scene checks stopped with the planning budget spent: {len(pending) - n_done} pairs of "
                       f"instances whose boxes meet were not checked for interpenetration")
            break
        a, b = instances[i], instances[j]
        lo = np.maximum(lo_hi[i][0], lo_hi[j][0])
        hi = np.minimum(lo_hi[i][1], lo_hi[j][1])
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
        if refuse is not None and d > refuse:
            raise InputError(f"scene: instances {a.id!r} ({a.part}) and {b.id!r} ({b.part}) interpenetrate by at "
                             f"least {d * 1e3:.1f} mm; more than {refuse * 1e3:g} mm cannot be pose noise: check "
                             f"their T or remove one of them")
        if d > tol:
            out.append(f"instances {a.id!r} and {b.id!r} interpenetrate by about {d * 1e3:.1f} mm (more than "
                       f"{tol * 1e3:g} mm of pose noise); their picks are planned as given")
    return out


def check_instances(instances: Sequence[Instance], meshes: Mapping[str, MeshData], cell: Cell, *, tol: float,
                    bvhs: Mapping[str, coal.BVHModelOBBRSS] | None = None,
                    spent: Callable[[], bool] | None = None, hulls: Mapping[str, np.ndarray] | None = None
                    ) -> list[str]:
    """:func:`check_cell` and :func:`check_coincident` (raise) then :func:`overlap_warnings` (returned;
    raises for a pair deeper than :func:`deep_limit`):

    * a part reaching more than ``tol`` below the table top, or more than ``tol`` into a box, cylinder
      or sphere obstacle (the bin's floor and walls among them): :class:`~grasplan.errors.InputError`
      naming the instance, the body and the depth (a pose estimate that cannot be: exit 3);
    * two instances in the same place (every vertex of either one's convex hull within ``tol``, and
      half the part's thickness, of a hull vertex of the other, such as one part reported twice by a
      pose estimator): :class:`~grasplan.errors.InputError` naming both ids;
    * two instances interpenetrating by more than ``tol`` (pose-estimator noise): a warning naming
      the pairs and the depth; by more than :func:`deep_limit` (:data:`MAX_OVERLAP_TOLS` times ``tol``,
      at least :data:`MIN_DEEP_M`): InputError naming both (no pose estimate is that wrong).
    """
    check_cell(instances, meshes, cell, tol=tol)
    check_coincident(instances, meshes, tol=tol, hulls=hulls)
    return overlap_warnings(instances, meshes, tol=tol, bvhs=bvhs, spent=spent, refuse=deep_limit(tol))
