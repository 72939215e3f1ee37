"""Exact NumPy geometry tests of the collision filter (:mod:`grasplan.grasps.collision`), run before coal
or instead of it: an oriented box against an axis-aligned box (separating axes), points in a box,
points inside a closed mesh (signed ray crossings on a binned grid, :class:`RayGrid`; near-ties and
the reference by the generalised winding number, :func:`points_inside`), and samples of a mesh's
surface (:func:`surface_samples`) whose presence inside a gripper box proves a hit.
"""
from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .meshdata import TriangleMesh


def obb_aabb_separated(c: np.ndarray, R: np.ndarray, h: np.ndarray, a: np.ndarray, e: np.ndarray) -> np.ndarray:
    """(M,) bool: oriented boxes (centre ``c`` (M,3), rotation ``R`` (M,3,3) whose columns are the
    box axes, half extents ``h`` (M,3)) strictly separated from the axis-aligned box with centre
    ``a`` (3,) and half extents ``e`` (3,) (or one box per oriented box, (M,3) each). Exact
    separating-axis test (15 axes)."""
    a = np.asarray(a, dtype=np.float64)
    e = np.broadcast_to(np.asarray(e, dtype=np.float64), np.shape(c))
    d = c - a  # (M,3)
    absR = np.abs(R) + 1e-12  # robust for near-parallel edge axes
    sep = np.zeros(len(c), dtype=bool)
    # AABB face axes: world x, y, z
    rb = np.einsum("mij,mj->mi", absR, h)  # projection radius of the OBB on each world axis
    sep |= np.any(np.abs(d) > e + rb, axis=1)
    # OBB face axes (columns of R)
    ra = np.einsum("mi,mij->mj", e, absR)
    sep |= np.any(np.abs(np.einsum("mi,mij->mj", d, R)) > ra + h, axis=1)
    # cross products world_i x box_j
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            # axis = e_i x R[:, j]; projections follow the standard OBB-OBB table with A = I
            dist = np.abs(d[:, i2] * R[:, i1, j] - d[:, i1] * R[:, i2, j])
            r_a = e[:, i1] * absR[:, i2, j] + e[:, i2] * absR[:, i1, j]
            r_b = h[:, j1] * absR[:, i, j2] + h[:, j2] * absR[:, i, j1]
            sep |= dist > r_a + r_b
    return sep


def inside_box(p: np.ndarray, center: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(M,) bool: points ``p`` (M,3) within the axis-aligned box (centre, half extents)."""
    return np.all(np.abs(p - center) <= half, axis=1)


def points_inside(mesh: TriangleMesh, points: np.ndarray, *, chunk: int = 2_000_000) -> np.ndarray:
    """(k,) bool: generalised winding number > 1/2 for a closed mesh (exact, no ray casting).

    Sums the signed solid angles of all triangles seen from each point (O(k x faces))."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    tri = mesh.triangles
    out = np.zeros(len(pts), dtype=bool)
    step = max(1, chunk // max(len(tri), 1))
    for s0 in range(0, len(pts), step):
        p = pts[s0:s0 + step]
        a, b, c = (tri[None, :, i, :] - p[:, None, :] for i in range(3))
        la, lb, lc = (np.linalg.norm(v, axis=2) for v in (a, b, c))
        num = np.einsum("pfi,pfi->pf", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("pfi,pfi->pf", a, b) * lc + np.einsum("pfi,pfi->pf", a, c) * lb
               + np.einsum("pfi,pfi->pf", b, c) * la)
        w = np.sum(2.0 * np.arctan2(num, den), axis=1) / (4.0 * np.pi)
        out[s0:s0 + step] = np.abs(w) > 0.5
    return out


# -- inside a closed mesh: signed ray crossings, binned -----------------------------------------------
class RayGrid:
    """The triangles of a mesh binned by their (y, z) bounding box into a uniform 2D grid: the
    triangles a ray along +x from a point can cross are those of the point's cell. Each triangle is
    listed in every cell its box overlaps (cells per triangle bounded by ``max_cells``)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, *, per_cell: float = 1.0, max_cells: int = 1 << 21):
        # rays along a generic direction (a fixed rotation of the mesh), so that CAD edges and
        # vertices on round coordinates are not met exactly by rays from points on round coordinates
        self.Q = _rotation_generic()
        tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)] @ self.Q.T
        self.tri = tri
        self.xmax = tri[:, :, 0].max(axis=1)
        F = len(tri)
        lo, hi = tri[:, :, 1:].min(axis=1), tri[:, :, 1:].max(axis=1)  # (F,2) y, z
        self.lo = lo.min(axis=0) if F else np.zeros(2)
        span = np.maximum((hi.max(axis=0) - self.lo) if F else np.ones(2), 1e-12)
        G = int(np.clip(np.sqrt(max(F, 1) / per_cell), 1, 1024))
        self.G = G
        self.cell = span / G * (1 + 1e-9)
        i0 = np.clip(((lo - self.lo) / self.cell).astype(np.int64), 0, G - 1)
        i1 = np.clip(((hi - self.lo) / self.cell).astype(np.int64), 0, G - 1)
        n = (i1 - i0 + 1).prod(axis=1)
        while n.sum() > max_cells and self.G > 1:  # coarser grid until the listing is bounded
            G = self.G = max(1, self.G // 2)
            self.cell = span / G * (1 + 1e-9)
            i0 = np.clip(((lo - self.lo) / self.cell).astype(np.int64), 0, G - 1)
            i1 = np.clip(((hi - self.lo) / self.cell).astype(np.int64), 0, G - 1)
            n = (i1 - i0 + 1).prod(axis=1)
        t = np.repeat(np.arange(F), n)
        off = np.arange(len(t)) - np.repeat(np.cumsum(n) - n, n)
        ny = (i1 - i0 + 1)[:, 0]
        cy = i0[t, 0] + off % ny[t]
        cz = i0[t, 1] + off // ny[t]
        key = cy * G + cz
        o = np.argsort(key, kind="stable")
        self.tris = t[o]
        self.start = np.searchsorted(key[o], np.arange(G * G + 1))

    def pairs(self, pts: np.ndarray, *, max_pairs: int = 1 << 20) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Yield ``(point, triangle)`` index arrays: the triangles listed in each point's cell
        (``pts`` already rotated by ``self.Q``)."""
        yz = (pts[:, 1:] - self.lo) / self.cell
        inside = np.all((yz >= 0) & (yz < self.G), axis=1)
        idx = np.flatnonzero(inside)
        c = yz[idx].astype(np.int64)
        key = c[:, 0] * self.G + c[:, 1]
        s0, cnt = self.start[key], self.start[key + 1] - self.start[key]
        csum = np.cumsum(cnt)
        b = 0
        while b < len(idx):
            e = int(np.searchsorted(csum, (csum[b - 1] if b else 0) + max_pairs, side="right"))
            e = max(e, b + 1)
            q = np.repeat(idx[b:e], cnt[b:e])
            off = np.arange(len(q)) - np.repeat(np.cumsum(cnt[b:e]) - cnt[b:e], cnt[b:e])
            t = self.tris[np.repeat(s0[b:e], cnt[b:e]) + off]
            if len(q):
                yield q, t
            b = e


def ray_crossings(grid: RayGrid, pts: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """The crossings of the rays along +x from ``pts`` (already rotated by ``grid.Q``) with the
    mesh's triangles, in chunks: ``(point index, x of the crossing, +1/-1 by the triangle's
    orientation, tie)``, where tie marks a ray passing within rounding of an edge or a vertex, or a
    triangle seen edge-on (its sign and x then mean nothing). Triangles wholly behind a point are
    left out; the caller decides about crossings behind it or at it."""
    if not len(pts):
        return
    scale = float(np.abs(grid.tri).max()) if len(grid.tri) else 1.0
    eps = 1e-12 * scale * scale
    for q, t in grid.pairs(pts):
        ahead = grid.xmax[t] >= pts[q, 0]  # triangles wholly behind the point are not crossed
        q, t = q[ahead], t[ahead]
        tri = grid.tri[t]  # (P,3,3)
        y, z = pts[q, 1:2], pts[q, 2:3]
        # 2D edge functions in the (y, z) plane of the point against each edge
        ay, az = tri[:, :, 1] - y, tri[:, :, 2] - z
        by, bz = np.roll(ay, -1, axis=1), np.roll(az, -1, axis=1)
        ef = ay * bz - az * by  # (P,3): twice the signed area of (point, v_k, v_k+1)
        near = np.any(np.abs(ef) <= eps, axis=1)
        clear_out = np.any(ef > eps, axis=1) & np.any(ef < -eps, axis=1)
        cand = ~clear_out
        if not cand.any():
            continue
        q, tri, ef, near = q[cand], tri[cand], ef[cand], near[cand]
        area = ef.sum(axis=1)  # twice the projected signed area
        flat = np.abs(area) <= eps
        w = ef / np.where(flat, 1.0, area)[:, None]  # barycentric weight of vertex k+2
        xh = np.einsum("pk,pk->p", np.roll(w, -1, axis=1), tri[:, :, 0])
        yield q, xh, np.where(area > 0, 1, -1), near | flat


def crossing_counts(grid: RayGrid, pts: np.ndarray, *, check: Callable[[], None] | None = None,
                    chunk: int = 2048) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(wind, tie, on)`` for points already rotated by ``grid.Q``: the signed count of the
    crossings of each point's ray along +x (the winding number of a closed mesh), whether a
    crossing passed within rounding of an edge, a vertex or a triangle seen edge-on or lay at the
    point itself (the count cannot decide: ``tie``), and whether the ray met a triangle at the point
    itself, well inside its edges (``on``: the point lies on the surface). ``check`` is called
    before every ``chunk`` points (a budget's check, which raises when spent)."""
    k = len(pts)
    wind = np.zeros(k, dtype=np.int64)
    tie = np.zeros(k, dtype=bool)
    on_surface = np.zeros(k, dtype=bool)
    scale = float(np.abs(grid.tri).max()) if len(grid.tri) else 1.0
    for c0 in range(0, k, chunk):
        if check is not None:
            check()
        for q, xh, sign, bad in ray_crossings(grid, pts[c0:c0 + chunk]):
            q = q + c0
            ahead = xh - pts[q, 0]
            on = np.abs(ahead) <= 1e-12 * scale
            cross = ~bad & ~on & (ahead > 0)
            np.add.at(wind, q[cross], sign[cross])
            tie[q[bad | on]] = True
            on_surface[q[on & ~bad]] = True
    return wind, tie, on_surface


def points_inside_tree(grid: RayGrid, mesh: TriangleMesh, points: np.ndarray) -> np.ndarray:
    """(k,) bool: inside a closed mesh, by the signed count of crossings of the ray from each point
    along +x (= the winding number of a closed mesh). Points whose ray passes within rounding of an
    edge, a vertex or a triangle seen edge-on, or that lie on the surface, are decided by the
    generalised winding number (:func:`points_inside`) instead."""
    pts0 = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts0) == 0:
        return np.zeros(0, dtype=bool)
    wind, tie, _ = crossing_counts(grid, pts0 @ grid.Q.T, chunk=max(len(pts0), 1))
    out = wind != 0
    if tie.any():
        out[tie] = points_inside(mesh, pts0[tie])
    return out


def placed_in_box(points: np.ndarray, T: np.ndarray, lo: np.ndarray, hi: np.ndarray, *,
                  columns: np.ndarray | None = None) -> np.ndarray:
    """The points (k, 3) moved by ``T`` (4, 4), ``points @ R.T + t``, of those that land in the box
    ``lo``..``hi`` (m, 3): one axis at a time (the points left after one axis are few), with a
    rounding margin, then exactly as a whole. ``columns``: the same points as (3, k) rows (x, y, z;
    a contiguous copy the caller keeps: the axis passes run on them)."""
    T = np.asarray(T, dtype=np.float64)
    R, t = T[:3, :3], T[:3, 3]
    P = np.ascontiguousarray(np.asarray(points).T) if columns is None else columns
    pad = 1e-9 * (1.0 + float(np.max(np.abs(hi - lo))))
    idx: np.ndarray | None = None
    for ax in (2, 0, 1):
        r = R[ax]
        if idx is None:
            v = r[0] * P[0] + r[1] * P[1] + r[2] * P[2] + t[ax]
        else:
            v = r[0] * P[0, idx] + r[1] * P[1, idx] + r[2] * P[2, idx] + t[ax]
        keep = (v >= lo[ax] - pad) & (v <= hi[ax] + pad)
        idx = np.flatnonzero(keep) if idx is None else idx[keep]
        if not len(idx):
            return np.zeros((0, 3))
    w = points[idx] @ R.T + t
    return w[np.all((w >= lo) & (w <= hi), axis=1)]


def _rotation_generic() -> np.ndarray:
    """A fixed rotation about an axis and by an angle of no special value (Rodrigues)."""
    k = np.array([0.2718281828, 0.5772156649, 0.7071067812])
    k = k / np.linalg.norm(k)
    a = 0.6180339887
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * (K @ K)


def surface_samples(mesh: TriangleMesh, *, spacing: float = 0.006, max_samples: int = 50_000) -> np.ndarray:
    """(k, 3) points on the surface of ``mesh``: its vertices, and on each triangle longer than
    ``spacing`` a barycentric grid of about ``spacing`` (coarser when there would be more than
    ``max_samples`` grid points). Each point is a convex combination of one triangle's corners."""
    V = np.asarray(mesh.vertices, dtype=np.float64)
    tri = V[np.asarray(mesh.faces, dtype=np.int64)]
    area = float(np.asarray(mesh.area_faces).sum())
    spacing = max(spacing, np.sqrt(2.0 * area / max(max_samples, 1)))
    edge = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    while True:
        n = np.minimum(np.ceil(edge / spacing).astype(np.int64), 64)  # subdivisions per edge
        total = int(np.sum(np.where(n > 1, (n + 1) * (n + 2) // 2, 0)))
        if total <= max_samples:
            break
        spacing *= 1.05 * np.sqrt(total / max_samples)
    out = [V]
    for k in np.unique(n[n > 1]):
        ii, jj = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
        m = ii + jj <= k
        w = np.stack([ii[m], jj[m], k - ii[m] - jj[m]], axis=1).astype(np.float64) / k  # (g, 3)
        w = w[(w < 1.0).all(axis=1)]  # corners are vertices already
        sel = np.flatnonzero(n == k)
        for s0 in range(0, len(sel), max(1, 1_000_000 // max(len(w), 1))):
            t = tri[sel[s0:s0 + 1_000_000 // max(len(w), 1)]]
            out.append(np.einsum("gk,tkx->tgx", w, t).reshape(-1, 3))
    return np.concatenate(out)
