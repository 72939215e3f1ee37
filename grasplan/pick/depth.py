"""Penetration depth of two part meshes in contact (coal reports mesh-vs-mesh contact, not its
depth): :func:`pair_depth`, over each part's probes (:class:`PartDepth`, built once per part and
kept on the :class:`grasplan.Picker`).

The depth of two placed parts A and B is the largest distance to the other mesh's surface of a
surface point of either one lying inside the other: the points are each mesh's vertices and a
barycentric grid of :data:`SAMPLE_SPACING` on its faces (:func:`grasplan.geometry.containment.surface_samples`),
so a penetration is found to within about that spacing (the deepest point of two touching
polyhedra is a vertex of one of them, except where two edges cross).
"""
from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
from scipy.spatial import cKDTree

from ..geometry.containment import RayGrid, placed_in_box, surface_samples
from ..geometry.insidegrid import InsideGrid, inside_grid
from ..geometry.meshdata import MeshData
from ..piles.checks import inside_for_depth
from .budget import UNLIMITED, Budget

#: surface sample spacing (m) of the depth probes
SAMPLE_SPACING = 0.001
#: at most this many probes per part (coarser spacing beyond)
MAX_SAMPLES = 30_000
#: exact point distances (coal) between two looks at the planning budget
BUDGET_EVERY = 256


@dataclass(frozen=True, eq=False)
class PartDepth:
    """One part's depth probes: mesh, surface samples (part frame), ray grid, BVH and local box."""

    mesh: MeshData
    samples: np.ndarray
    grid: RayGrid
    bvh: coal.BVHModelOBBRSS
    lo: np.ndarray
    hi: np.ndarray
    hull: np.ndarray  #: convex hull vertices (world boxes)
    tree: cKDTree  #: of the samples
    columns: np.ndarray  #: the samples as (3, k) rows x, y, z
    inside: InsideGrid  #: inside / outside / depth bounds on a voxel grid

    @classmethod
    def build(cls, mesh: MeshData, bvh: coal.BVHModelOBBRSS, hull: np.ndarray) -> "PartDepth":
        V = np.asarray(mesh.vertices, dtype=np.float64)
        samples = surface_samples(mesh, spacing=SAMPLE_SPACING, max_samples=MAX_SAMPLES)
        return cls(mesh=mesh, samples=samples, grid=RayGrid(V, np.asarray(mesh.faces)), bvh=bvh, lo=V.min(axis=0),
                   hi=V.max(axis=0), hull=np.asarray(hull, dtype=np.float64), tree=cKDTree(samples),
                   columns=np.ascontiguousarray(samples.T),
                   inside=inside_grid(mesh))


def _into(a: PartDepth, T_a: np.ndarray, b: PartDepth, T_b: np.ndarray, lo: np.ndarray, hi: np.ndarray,
          stop: float, step: int = 1, cap: float = np.inf, budget: Budget = UNLIMITED) -> float:
    """Largest depth of ``a``'s samples (at ``T_a``) inside ``b`` (at ``T_b``), of those in the world
    box ``lo, hi`` (where the two parts' world boxes overlap); stops once above ``stop`` or at
    ``cap`` or beyond (see :func:`pair_depth`).

    The samples kept are those inside ``b``'s own box and the overlap of the two world boxes;
    those ``b``'s voxel grid (:mod:`grasplan.geometry.insidegrid`) puts outside it are dropped (and
    the search stops at once when the grid proves one deeper than ``stop``), then those within
    ``stop`` of ``b``'s surface samples (k-d tree): a point that close to the surface is at most
    that deep whether inside or not. Only the rest (none when two neighbours touch side by side)
    get the exact inside test where the grid is unsure (the crossing count of
    :func:`grasplan.piles.checks.inside_for_depth`: a point on the other's surface, undecided by
    the crossings, is outside: at most rounding deep) and coal's exact point-to-BVH distance, so
    deciding "deeper than the tolerance?" is a few NumPy and k-d tree calls."""
    pts = placed_in_box(a.samples[::step], np.linalg.inv(T_b) @ T_a, b.lo, b.hi,  # b's frame, in b's box
                        columns=a.columns[:, ::step])
    if not len(pts):
        return 0.0
    w = pts @ T_b[:3, :3].T + T_b[:3, 3]
    pts = pts[np.all((w >= lo) & (w <= hi), axis=1)]
    if not len(pts):
        return 0.0
    state, deep = b.inside.lookup(pts)  # the voxel grid decides most points (grasplan.geometry.insidegrid)
    if deep.max() > stop or deep.max() >= cap:
        return float(deep.max())  # a point certainly deeper than stop (a lower bound of its depth)
    pts = pts[state >= 0]  # outside b: not measured
    if len(pts) and np.isfinite(stop):  # within stop of b's surface: at most stop deep, inside or not
        r, _ = b.tree.query(pts, distance_upper_bound=stop)
        pts = pts[~np.isfinite(r)]
    if not len(pts):
        return 0.0
    budget.check()
    inside = pts[inside_for_depth(b.inside, b.grid, b.mesh, b.bvh, pts, budget.check)]
    if not len(inside):
        return 0.0
    # deepest first is unknown: probe the points with the largest upper bound of their depth first
    # (the distance to b's nearest surface sample and to b's box faces: at least that to b's surface)
    upper = np.minimum(b.tree.query(inside)[0], np.minimum(inside - b.lo, b.hi - inside).min(axis=1))
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    probe = coal.Sphere(1e-12)
    tf, eye = coal.Transform3s(), coal.Transform3s()
    best = 0.0
    for n, k in enumerate(np.argsort(-upper).tolist()):
        if upper[k] <= best:  # no point left can be deeper
            break
        if n % BUDGET_EVERY == BUDGET_EVERY - 1:
            budget.check()
        tf.setTranslation(inside[k])
        res.clear()
        best = max(best, float(coal.distance(probe, tf, b.bvh, eye, req, res)))
        if best > stop or best >= cap:
            break
    return best


def pair_depth(a: PartDepth, T_a: np.ndarray, b: PartDepth, T_b: np.ndarray, *, stop: float = np.inf,
               step: int = 1, cap: float = np.inf, budget: Budget = UNLIMITED) -> float:
    """Penetration depth (m, 0 when apart or touching) of ``a`` at ``T_a`` and ``b`` at ``T_b`` (see
    the module docstring). With a finite ``stop`` it answers "deeper than ``stop``?": the result is
    a depth found above ``stop`` (a lower bound: the search stops there) when there is one, else a
    value at most ``stop`` (points within ``stop`` of the other surface are not measured).
    ``step``: only every step-th surface sample of each part is a probe (a lower bound of the depth,
    so a value above ``stop`` found this way is one the full search finds too). ``cap``: exact below
    it, some depth at or beyond it otherwise (``min(pair_depth(..., cap=c), c)`` is the exact
    depth capped at ``c``; the search stops at the first point at least ``c`` deep). ``budget``:
    checked before the exact inside test and every :data:`BUDGET_EVERY` exact distances."""
    T_a, T_b = np.asarray(T_a, dtype=np.float64), np.asarray(T_b, dtype=np.float64)
    wa = a.hull @ T_a[:3, :3].T + T_a[:3, 3]
    wb = b.hull @ T_b[:3, :3].T + T_b[:3, 3]
    lo, hi = np.maximum(wa.min(axis=0), wb.min(axis=0)), np.minimum(wa.max(axis=0), wb.max(axis=0))
    if np.any(lo > hi):
        return 0.0
    d = _into(a, T_a, b, T_b, lo, hi, stop, step, cap, budget)
    if d > stop or d >= cap:
        return d
    return max(d, _into(b, T_b, a, T_a, lo, hi, stop, step, cap, budget))
