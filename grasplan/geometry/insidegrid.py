"""Which points lie inside a closed mesh, and how deep, decided on a voxel grid before any exact test.

The depth probes of a pile (:mod:`grasplan.pick.depth`, :mod:`grasplan.piles.checks`) ask of
hundreds of points at a time whether they lie inside a neighbour's mesh and how far from its
surface. :class:`InsideGrid` answers most of them by one array lookup and leaves the rest to the
exact test; :func:`inside_grid` builds it once per mesh (kept while the mesh lives).
"""
from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np

from .containment import RayGrid, points_inside_tree, ray_crossings
from .meshdata import MeshData

#: voxel edge (m) of the grid, unless that makes more than :data:`MAX_VOXELS` voxels
VOXEL = 0.0005
MAX_VOXELS = 2_000_000
#: at most this many surface samples are placed (the sample spacing grows beyond)
MAX_SURFACE_SAMPLES = 2_000_000


def _samples(tri: np.ndarray, spacing: float) -> tuple[np.ndarray, float]:
    """Surface samples of the triangles ``tri`` (F, 3, 3) and ``e``: every point of every triangle
    lies within ``e`` of one (a barycentric grid of ``n`` steps per triangle, its sub-triangles'
    edges at most ``e``)."""
    edge = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    while True:
        n = np.maximum(np.ceil(edge / spacing).astype(np.int64), 1)
        if int(np.sum((n + 1) * (n + 2) // 2)) <= MAX_SURFACE_SAMPLES:
            break
        spacing *= 1.5
    e = float(np.max(edge / n)) if len(tri) else 0.0
    out = []
    for k in np.unique(n):
        ii, jj = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
        m = ii + jj <= k
        w = np.stack([ii[m], jj[m], k - ii[m] - jj[m]], axis=1).astype(np.float64) / k  # (g, 3)
        sel = np.flatnonzero(n == k)
        per = max(1, 500_000 // len(w))
        for s0 in range(0, len(sel), per):
            out.append(np.einsum("gk,tkx->tgx", w, tri[sel[s0:s0 + per]]).reshape(-1, 3))
    return (np.concatenate(out) if out else np.zeros((0, 3))), e


@dataclass(frozen=True, eq=False)
class InsideGrid:
    """The mesh's box (in the generic frame of :class:`~grasplan.geometry.containment.RayGrid`, a
    voxel larger on every side) cut into voxels of edge ``h``, each either

    * **surface** (state 0): it may hold a point of the surface. Every voxel holding a surface sample
      (a barycentric grid on every triangle, each surface point within ``e <= h`` of a sample:
      :func:`_samples`) and those within ``ceil(e / h)`` voxels of one along each axis; a point there
      is decided by the exact test (:func:`~grasplan.geometry.containment.points_inside_tree`);
    * **inside** (1) or **outside** (-1): it holds no surface point, so every point of it is on the
      side of its centre, found by counting the signed crossings of the mesh along each row of voxel
      centres (the winding number of :func:`~grasplan.geometry.containment.ray_crossings`; a row whose
      ray passes within rounding of an edge is left undecided, state 0).

    An inside voxel also records a lower bound of the depth of any point in it: the distance of its
    centre to the nearest surface voxel's centre (Euclidean distance transform) less twice the
    voxel's half-diagonal (the point's offset from its centre, the surface point's from its voxel's).
    Points beyond the grid are outside. Rounding of the voxel index can only misplace a point within
    about 1e-15 m of a voxel face, where a wrong side means a depth of that order. The grid has at
    most ``max_voxels`` voxels (coarser ``h`` for a large part).

    ``Q``: the rotation into the grid's frame (a point ``p`` of the mesh's frame is at ``Q @ p``
    there); ``origin``: the grid's lowest corner in that frame."""

    Q: np.ndarray
    origin: np.ndarray
    h: float
    state: np.ndarray  #: (nx, ny, nz) int8: 1 inside, -1 outside, 0 surface or undecided
    depth_lo: np.ndarray  #: (nx, ny, nz) float32: inside voxels' lower bound of a point's depth (m)

    @classmethod
    def build(cls, mesh: MeshData, *, voxel: float = VOXEL, max_voxels: int = MAX_VOXELS) -> "InsideGrid":
        from scipy import ndimage

        V = np.asarray(mesh.vertices, dtype=np.float64)
        F = np.asarray(mesh.faces, dtype=np.int64)
        ray = RayGrid(V, F)
        Vq = V @ ray.Q.T
        span = Vq.max(axis=0) - Vq.min(axis=0)
        h = max(float(voxel), float(np.prod(span + 2 * voxel) / max_voxels) ** (1.0 / 3.0))
        while np.prod(np.ceil(span / h) + 2) > max_voxels:
            h *= 1.05
        origin = Vq.min(axis=0) - h
        shape = tuple(int(v) for v in np.ceil(span / h).astype(np.int64) + 2)
        nx, ny, nz = shape
        # surface voxels: those of the samples, grown by ceil(e / h) along each axis
        pts, e = _samples(Vq[F], h)
        idx = np.clip(np.floor((pts - origin) / h).astype(np.int64), 0, np.array(shape) - 1)
        surface = np.zeros(shape, dtype=bool)
        surface[idx[:, 0], idx[:, 1], idx[:, 2]] = True
        grow = max(1, math.ceil(e * (1 + 1e-9) / h))
        surface = ndimage.binary_dilation(surface, structure=np.ones((3, 3, 3), dtype=bool), iterations=grow)
        # the side of each voxel centre: signed crossings along each row (rays along +x from before the grid)
        jj, kk = np.meshgrid(np.arange(ny), np.arange(nz), indexing="ij")
        starts = np.stack([np.full(jj.size, origin[0] - 1.0), origin[1] + (jj.ravel() + 0.5) * h,
                           origin[2] + (kk.ravel() + 0.5) * h], axis=1)
        diff = np.zeros((ny * nz, nx + 1), dtype=np.int64)
        undecided = np.zeros(ny * nz, dtype=bool)
        x0 = origin[0] + 0.5 * h
        for q, xh, sign, tie in ray_crossings(ray, starts):
            undecided[q[tie]] = True
            q, xh, sign = q[~tie], xh[~tie], sign[~tie]
            upto = np.clip(np.ceil((xh - x0) / h).astype(np.int64), 0, nx)  # centres i < upto lie before it
            np.add.at(diff, (q, np.zeros_like(q)), sign)
            np.add.at(diff, (q, upto), -sign)
        wind = np.cumsum(diff[:, :nx], axis=1).reshape(ny, nz, nx).transpose(2, 0, 1)
        state = np.where(wind != 0, 1, -1).astype(np.int8)
        state[surface] = 0
        state[:, undecided.reshape(ny, nz)] = 0
        dist = ndimage.distance_transform_edt(~surface, sampling=h) if surface.any() else np.full(shape, np.inf)
        depth_lo = np.where(state == 1, np.maximum(dist - math.sqrt(3.0) * h, 0.0), 0.0).astype(np.float32)
        return cls(Q=ray.Q, origin=origin, h=h, state=state, depth_lo=depth_lo)

    def lookup(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(state, depth_lo)`` per point (k, 3) of the mesh's frame: 1 inside, -1 outside, 0 to be
        decided exactly; a lower bound of an inside point's depth (m; 0 otherwise)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3) @ self.Q.T
        idx = np.floor((p - self.origin) / self.h).astype(np.int64)
        ok = np.all((idx >= 0) & (idx < np.array(self.state.shape)), axis=1)
        state = np.full(len(p), -1, dtype=np.int8)
        depth = np.zeros(len(p), dtype=np.float64)
        i = idx[ok]
        state[ok] = self.state[i[:, 0], i[:, 1], i[:, 2]]
        depth[ok] = self.depth_lo[i[:, 0], i[:, 1], i[:, 2]]
        return state, depth

    def inside(self, ray: RayGrid, mesh: MeshData, points: np.ndarray) -> np.ndarray:
        """(k,) bool, exactly :func:`~grasplan.geometry.containment.points_inside_tree`: the grid's verdict
        where it has one, the exact test for the rest."""
        state, _ = self.lookup(points)
        out = state == 1
        todo = np.flatnonzero(state == 0)
        if len(todo):
            out[todo] = points_inside_tree(ray, mesh, np.asarray(points, dtype=np.float64).reshape(-1, 3)[todo])
        return out


_GRIDS: "weakref.WeakKeyDictionary[MeshData, InsideGrid]" = weakref.WeakKeyDictionary()


def inside_grid(mesh: MeshData) -> InsideGrid:
    """``mesh``'s :class:`InsideGrid`, built on first use and kept while the mesh lives."""
    g = _GRIDS.get(mesh)
    if g is None:
        g = _GRIDS[mesh] = InsideGrid.build(mesh)
    return g
