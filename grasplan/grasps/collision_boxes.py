"""Oriented boxes against the part's triangles before coal: which gripper shapes at which poses
are surely apart from the part, which surely hit it, and which only coal can decide, for many
poses in one compiled pass (:class:`PartBoxes`, for :class:`grasplan.grasps.collision.GripperCollider`),
and the collider's box-against-the-part's-box prefilter compiled (:func:`prefilter`).

The part's triangles sit in a bounding-volume hierarchy of axis-aligned boxes, built once per part;
:meth:`PartBoxes.classify` says how each answer is proven. Both answers are exact up to float
rounding (~1e-17 m here) against a tolerance of micrometres.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..compiled.jit import kernel
from ..geometry.containment import RayGrid, points_inside

if TYPE_CHECKING:
    from ..geometry.meshdata import TriangleMesh


#: the gap (m) a box and the part must have along an axis to be apart, and the depth (m) a
#: triangle point must have inside a box to prove a hit, without coal
PREPASS_TOL = 1e-5
#: triangles per leaf of the hierarchy
LEAF = 4
#: query codes of :meth:`PartBoxes.classify`
APART, HIT, UNSURE = 0, 1, 2


class PartBoxes:
    """The part's triangles (part frame, metres) in a compiled bounding-volume hierarchy, built once."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        tri = np.ascontiguousarray(np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)])
        order, lo, hi, child, start, count = _build(tri.reshape(-1, 3, 3), LEAF)
        self.tri = np.ascontiguousarray(tri.reshape(-1, 3, 3)[order])  # leaves' triangles contiguous
        lo_t, hi_t = self.tri.min(axis=1), self.tri.max(axis=1)
        self.tri_center = np.ascontiguousarray(0.5 * (lo_t + hi_t))  # each triangle's axis-aligned box
        self.tri_half = np.ascontiguousarray(0.5 * (hi_t - lo_t))
        self.center = np.ascontiguousarray(0.5 * (lo + hi))
        self.half = np.ascontiguousarray(0.5 * (hi - lo))
        self.child, self.start, self.count = child, start, count
        #: the traversal stack :func:`box_vs_tree` needs on this hierarchy
        self.stack_size = int(tree_stack(child))

    def classify(self, T_part_box: np.ndarray, half: np.ndarray, *, prove_hit: bool,
                 tol: float = PREPASS_TOL) -> np.ndarray:
        """(K,) int8 codes :data:`APART`, :data:`HIT` (only with ``prove_hit``) or :data:`UNSURE` of
        the boxes centred at ``T_part_box[:, :3, 3]`` with axes ``T_part_box[:, :3, :3]`` (K, 4, 4)
        and half extents ``half`` (K, 3), against the part.

        * **apart** when every node of the hierarchy the box reaches, and every triangle in the
          leaves it reaches, lies more than ``tol`` from it along one axis: the node's axes or the
          box's axes for nodes; the 13 separating axes of a box and a triangle (the box's 3 face
          normals, the triangle's normal, the 9 crosses of a box axis and a triangle edge) for
          triangles. The gap along any unit axis bounds the distance from below, so coal (which
          reports contact within its GJK tolerance, ~1e-6 m) reports no collision;
        * **hit** when a point of some triangle lies inside the box shrunk by ``tol`` on every side
          (a corner of the triangle, else the centroid of the triangle clipped to the shrunk box):
          moving the box by less than ``tol`` cannot part them, so coal reports the collision. Only
          for exact boxes: a mesh shape's bounding box proves apart, never hit;
        * else **unsure**: coal decides.

        A box wholly inside a closed part crosses no triangle: it is apart here as for coal (the
        collider's inside tests decide it)."""
        T = np.asarray(T_part_box, dtype=np.float64).reshape(-1, 4, 4)
        if not len(self.tri):
            return np.zeros(len(T), dtype=np.int8)
        return _classify(np.ascontiguousarray(T[:, :3, :3]), np.ascontiguousarray(T[:, :3, 3]),
                         np.ascontiguousarray(half, dtype=np.float64).reshape(-1, 3), bool(prove_hit), float(tol),
                         self.tri, self.tri_center, self.tri_half, self.center, self.half, self.child, self.start,
                         self.count, self.stack_size)


@kernel(cache=True, nogil=True)
def _build(tri: np.ndarray, leaf: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                np.ndarray]:  # pragma: no cover
    """Median split along the longest axis of the triangles' centroids: ``(triangle order, node lo,
    node hi, first child (-1 for a leaf; the second is the next), leaf start, leaf count)``."""
    F = tri.shape[0]
    cen = np.empty((F, 3))
    tlo = np.empty((F, 3))
    thi = np.empty((F, 3))
    for f in range(F):
        for i in range(3):
            a, b, c = tri[f, 0, i], tri[f, 1, i], tri[f, 2, i]
            cen[f, i] = (a + b + c) / 3.0
            tlo[f, i] = min(a, min(b, c))
            thi[f, i] = max(a, max(b, c))
    order = np.arange(F)
    N = max(1, 2 * F)
    lo = np.empty((N, 3))
    hi = np.empty((N, 3))
    child = np.full(N, -1, dtype=np.int64)
    start = np.zeros(N, dtype=np.int64)
    count = np.zeros(N, dtype=np.int64)
    stack = np.empty((N, 3), dtype=np.int64)  # node, first, end
    stack[0, 0], stack[0, 1], stack[0, 2] = 0, 0, F
    top, n = 1, 1
    while top > 0:
        top -= 1
        node, s, e = stack[top, 0], stack[top, 1], stack[top, 2]
        clo = np.full(3, np.inf)
        chi = np.full(3, -np.inf)
        for i in range(3):
            lo[node, i], hi[node, i] = np.inf, -np.inf
        for k in range(s, e):
            f = order[k]
            for i in range(3):
                lo[node, i] = min(lo[node, i], tlo[f, i])
                hi[node, i] = max(hi[node, i], thi[f, i])
                clo[i] = min(clo[i], cen[f, i])
                chi[i] = max(chi[i], cen[f, i])
        if e - s <= leaf:
            start[node], count[node] = s, e - s
            continue
        ax = 0
        for i in range(1, 3):
            if chi[i] - clo[i] > chi[ax] - clo[ax]:
                ax = i
        idx = order[s:e].copy()
        keys = np.empty(e - s)
        for k in range(e - s):
            keys[k] = cen[idx[k], ax]
        p = np.argsort(keys, kind="mergesort")
        for k in range(e - s):
            order[s + k] = idx[p[k]]
        mid = (s + e) // 2
        child[node] = n
        stack[top, 0], stack[top, 1], stack[top, 2] = n, s, mid
        stack[top + 1, 0], stack[top + 1, 1], stack[top + 1, 2] = n + 1, mid, e
        top += 2
        n += 2
    return order, lo[:n].copy(), hi[:n].copy(), child[:n].copy(), start[:n].copy(), count[:n].copy()


@kernel(cache=True, nogil=True, inline="always")
def _sep_axis(p: np.ndarray, a0: float, a1: float, a2: float, h: np.ndarray, tol: float) -> bool:  # pragma: no cover
    """The triangle ``p`` (3, 3) (box frame) and the box of half extents ``h`` at the origin are
    more than ``tol`` apart along the axis ``a`` (not normalised; a zero-ish axis never separates)."""
    la = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    if la < 1e-12:
        return False
    x0 = a0 * p[0, 0] + a1 * p[0, 1] + a2 * p[0, 2]
    x1 = a0 * p[1, 0] + a1 * p[1, 1] + a2 * p[1, 2]
    x2 = a0 * p[2, 0] + a1 * p[2, 1] + a2 * p[2, 2]
    mn = min(x0, min(x1, x2))
    mx = max(x0, max(x1, x2))
    r = abs(a0) * h[0] + abs(a1) * h[1] + abs(a2) * h[2] + tol * la
    return mn > r or mx < -r


@kernel(cache=True, nogil=True)
def _tri_apart(p: np.ndarray, h: np.ndarray, tol: float) -> bool:  # pragma: no cover
    """Separating-axis test of the triangle ``p`` (3, 3) in the box's frame and the box (13 axes)."""
    for i in range(3):  # the box's faces
        mn = min(p[0, i], min(p[1, i], p[2, i]))
        mx = max(p[0, i], max(p[1, i], p[2, i]))
        if mn > h[i] + tol or mx < -h[i] - tol:
            return True
    e0 = p[1, 0] - p[0, 0]
    e1 = p[1, 1] - p[0, 1]
    e2 = p[1, 2] - p[0, 2]
    f0 = p[2, 0] - p[0, 0]
    f1 = p[2, 1] - p[0, 1]
    f2 = p[2, 2] - p[0, 2]
    if _sep_axis(p, e1 * f2 - e2 * f1, e2 * f0 - e0 * f2, e0 * f1 - e1 * f0, h, tol):  # the triangle's normal
        return True
    for k in range(3):  # box axis u_i x edge
        d0 = p[(k + 1) % 3, 0] - p[k, 0]
        d1 = p[(k + 1) % 3, 1] - p[k, 1]
        d2 = p[(k + 1) % 3, 2] - p[k, 2]
        if _sep_axis(p, 0.0, -d2, d1, h, tol):
            return True
        if _sep_axis(p, d2, 0.0, -d0, h, tol):
            return True
        if _sep_axis(p, -d1, d0, 0.0, h, tol):
            return True
    return False


@kernel(cache=True, nogil=True)
def _tri_deep(p: np.ndarray, h: np.ndarray, tol: float, poly: np.ndarray, tmp: np.ndarray,
              s: np.ndarray) -> bool:  # pragma: no cover
    """A point of the triangle ``p`` (3, 3) (box frame) inside the box shrunk by ``tol``: a corner,
    else the centroid of the triangle clipped by the six planes of the shrunk box (``s``: scratch)."""
    for i in range(3):
        s[i] = h[i] - tol
        if s[i] <= 0.0:
            return False
    for k in range(3):
        if abs(p[k, 0]) < s[0] and abs(p[k, 1]) < s[1] and abs(p[k, 2]) < s[2]:
            return True
    n = 3
    for k in range(3):
        for i in range(3):
            poly[k, i] = p[k, i]
    for ax in range(3):
        for sg in (1.0, -1.0):  # keep sg * x[ax] <= s[ax]
            m = 0
            for k in range(n):
                k2 = (k + 1) % n
                da = sg * poly[k, ax] - s[ax]
                db = sg * poly[k2, ax] - s[ax]
                if da <= 0.0:
                    for i in range(3):
                        tmp[m, i] = poly[k, i]
                    m += 1
                if (da < 0.0 < db) or (db < 0.0 < da):
                    t = da / (da - db)
                    for i in range(3):
                        tmp[m, i] = poly[k, i] + t * (poly[k2, i] - poly[k, i])
                    m += 1
            n = m
            if n == 0:
                return False
            for k in range(n):
                for i in range(3):
                    poly[k, i] = tmp[k, i]
    # the clipped polygon's vertices lie on the triangle and in the shrunk box within rounding; its
    # centroid too: demand it inside with a margin far above rounding and far below tol
    for i in range(3):
        x = 0.0
        for k in range(n):
            x += poly[k, i]
        if abs(x / n) > s[i] * (1.0 - 1e-9):
            return False
    return True


@kernel(cache=True, nogil=True)
def box_vs_tree(Rq: np.ndarray, cq: np.ndarray, hq: np.ndarray, prove_hit: bool, tol: float, tri: np.ndarray,
                tc: np.ndarray, th: np.ndarray, nc: np.ndarray, nh: np.ndarray, child: np.ndarray, start: np.ndarray,
                count: np.ndarray, stack: np.ndarray, p: np.ndarray, poly: np.ndarray, tmp: np.ndarray, w: np.ndarray,
                scratch: np.ndarray) -> int:  # pragma: no cover
    """:data:`APART`, :data:`HIT` or :data:`UNSURE` (:meth:`PartBoxes.classify`) of the box with axes
    ``Rq`` (3, 3), centre ``cq`` and half extents ``hq`` (part frame) against the part's hierarchy;
    ``stack`` (:attr:`PartBoxes.stack_size` long, :func:`tree_stack`), ``p``, ``poly``, ``tmp``, ``w``,
    ``scratch``: scratch."""
    for i in range(3):  # half widths of the part-axis box around the query box
        w[i] = abs(Rq[i, 0]) * hq[0] + abs(Rq[i, 1]) * hq[1] + abs(Rq[i, 2]) * hq[2]
    unsure = False
    top = 1
    stack[0] = 0
    while top > 0:
        top -= 1
        node = stack[top]
        apart = False
        for i in range(3):  # the node's (part) axes
            if abs(cq[i] - nc[node, i]) > w[i] + nh[node, i] + tol:
                apart = True
                break
        if not apart:
            for j in range(3):  # the query box's axes
                d = 0.0
                r = 0.0
                for i in range(3):
                    d += Rq[i, j] * (nc[node, i] - cq[i])
                    r += abs(Rq[i, j]) * nh[node, i]
                if abs(d) > hq[j] + r + tol:
                    apart = True
                    break
        if apart:
            continue
        if child[node] >= 0:
            stack[top] = child[node]
            stack[top + 1] = child[node] + 1
            top += 2
            continue
        for f in range(start[node], start[node] + count[node]):
            far = False
            for i in range(3):  # the triangle's axis-aligned box against the query box's
                if abs(cq[i] - tc[f, i]) > w[i] + th[f, i] + tol:
                    far = True
                    break
            if far:
                continue
            for k in range(3):  # the triangle in the box's frame
                for j in range(3):
                    p[k, j] = (Rq[0, j] * (tri[f, k, 0] - cq[0]) + Rq[1, j] * (tri[f, k, 1] - cq[1])
                               + Rq[2, j] * (tri[f, k, 2] - cq[2]))
            if _tri_apart(p, hq, tol):
                continue
            if prove_hit and _tri_deep(p, hq, tol, poly, tmp, scratch):
                return HIT
            unsure = True
    return UNSURE if unsure else APART


@kernel(cache=True, nogil=True)
def _classify(R: np.ndarray, c: np.ndarray, h: np.ndarray, prove_hit: bool, tol: float, tri: np.ndarray,
              tc: np.ndarray, th: np.ndarray, nc: np.ndarray, nh: np.ndarray, child: np.ndarray, start: np.ndarray,
              count: np.ndarray, stack_size: int) -> np.ndarray:  # pragma: no cover
    K = R.shape[0]
    out = np.zeros(K, dtype=np.int8)
    stack = np.empty(stack_size, dtype=np.int64)
    p = np.empty((3, 3))
    poly = np.empty((12, 3))
    tmp = np.empty((12, 3))
    w = np.empty(3)
    scratch = np.empty(3)
    for q in range(K):
        out[q] = box_vs_tree(R[q], c[q], h[q], prove_hit, tol, tri, tc, th, nc, nh, child, start, count, stack, p,
                             poly, tmp, w, scratch)
    return out


@kernel(cache=True, nogil=True)
def tree_stack(child: np.ndarray) -> int:  # pragma: no cover
    """A stack size enough for :func:`box_vs_tree` on the hierarchy ``child``: 2 x its depth + 2
    (node 0 is the root; a node's children are ``child[node]`` and ``child[node] + 1``)."""
    n = child.shape[0]
    if n == 0:
        return 2
    depth = np.zeros(n, dtype=np.int64)
    deepest = 0
    for node in range(n):  # children come after their parent
        if child[node] >= 0:
            depth[child[node]] = depth[node] + 1
            depth[child[node] + 1] = depth[node] + 1
            deepest = max(deepest, depth[node] + 1)
    return 2 * deepest + 2


def prefilter(T_part_box: np.ndarray, half: np.ndarray, center: np.ndarray, extent: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """``(near (K,), within (K,))`` for the boxes placed by ``T_part_box`` (K, 4, 4) with half
    extents ``half`` (K, 3) against the axis-aligned box (``center``, half extents ``extent``):
    ``near``: not strictly separated from it, the same arithmetic as
    :func:`grasplan.geometry.containment.obb_aabb_separated` (15 axes) compiled; ``within``: the
    box's own world-axis box lies inside it (touching counts)."""
    T = np.ascontiguousarray(T_part_box, dtype=np.float64).reshape(-1, 4, 4)
    return _prefilter(T, np.ascontiguousarray(half, dtype=np.float64).reshape(-1, 3),
                      np.ascontiguousarray(center, dtype=np.float64), np.ascontiguousarray(extent, dtype=np.float64))


@kernel(cache=True, nogil=True)
def _prefilter(T: np.ndarray, h: np.ndarray, a: np.ndarray, e: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
    K = T.shape[0]
    near = np.zeros(K, dtype=np.bool_)
    within = np.zeros(K, dtype=np.bool_)
    absR = np.empty((3, 3))
    d = np.empty(3)
    for k in range(K):
        for i in range(3):
            d[i] = T[k, i, 3] - a[i]
            for j in range(3):
                absR[i, j] = abs(T[k, i, j]) + 1e-12
        inside = True
        for i in range(3):  # the box's world-axis box inside the fixed box
            ext = abs(T[k, i, 0]) * h[k, 0] + abs(T[k, i, 1]) * h[k, 1] + abs(T[k, i, 2]) * h[k, 2]
            if not (abs(d[i]) + ext <= e[i]):
                inside = False
        within[k] = inside
        sep = False
        for i in range(3):  # world axes
            rb = absR[i, 0] * h[k, 0] + absR[i, 1] * h[k, 1] + absR[i, 2] * h[k, 2]
            if abs(d[i]) > e[i] + rb:
                sep = True
        for j in range(3):  # the box's axes
            ra = e[0] * absR[0, j] + e[1] * absR[1, j] + e[2] * absR[2, j]
            pj = d[0] * T[k, 0, j] + d[1] * T[k, 1, j] + d[2] * T[k, 2, j]
            if abs(pj) > ra + h[k, j]:
                sep = True
        for i in range(3):  # world axis i x box axis j
            i1, i2 = (i + 1) % 3, (i + 2) % 3
            for j in range(3):
                j1, j2 = (j + 1) % 3, (j + 2) % 3
                dist = abs(d[i2] * T[k, i1, j] - d[i1] * T[k, i2, j])
                r_a = e[i1] * absR[i2, j] + e[i2] * absR[i1, j]
                r_b = h[k, j1] * absR[i, j2] + h[k, j2] * absR[i, j1]
                if dist > r_a + r_b:
                    sep = True
        near[k] = not sep
    return near, within


def points_inside_compiled(grid: RayGrid, mesh: TriangleMesh, points: np.ndarray) -> np.ndarray:
    """(k,) bool: :func:`grasplan.geometry.containment.points_inside_tree` with the ray crossings
    counted in one compiled pass (the same arithmetic, per point and triangle of its cell); the
    points it cannot decide (a ray within rounding of an edge, a vertex or a triangle seen edge-on,
    or a point on the surface) by the generalised winding number, as there."""
    pts0 = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    scale = float(np.abs(grid.tri).max()) if len(grid.tri) else 1.0
    wind, tie = _crossings(np.ascontiguousarray(pts0 @ grid.Q.T), grid.tri, grid.xmax, grid.lo, grid.cell,
                           int(grid.G), grid.tris, grid.start, scale)
    out: np.ndarray = wind != 0
    if tie.any():
        out[tie] = points_inside(mesh, pts0[tie])
    return out


@kernel(cache=True, nogil=True)
def _crossings(pts: np.ndarray, tri: np.ndarray, xmax: np.ndarray, lo: np.ndarray, cell: np.ndarray, G: int,
               tris: np.ndarray, start: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
    """``(wind, tie)`` per point (rotated by the grid's ``Q``), as
    :func:`grasplan.geometry.containment.crossing_counts` computes them."""
    k = pts.shape[0]
    wind = np.zeros(k, dtype=np.int64)
    tie = np.zeros(k, dtype=np.bool_)
    eps = 1e-12 * scale * scale
    on_tol = 1e-12 * scale
    ay = np.empty(3)
    az = np.empty(3)
    ef = np.empty(3)
    for q in range(k):
        y0 = (pts[q, 1] - lo[0]) / cell[0]
        z0 = (pts[q, 2] - lo[1]) / cell[1]
        if not (y0 >= 0 and z0 >= 0 and y0 < G and z0 < G):
            continue
        key = np.int64(y0) * G + np.int64(z0)
        px, py, pz = pts[q, 0], pts[q, 1], pts[q, 2]
        for s in range(start[key], start[key + 1]):
            t = tris[s]
            if not (xmax[t] >= px):  # wholly behind the point
                continue
            for v in range(3):
                ay[v] = tri[t, v, 1] - py
                az[v] = tri[t, v, 2] - pz
            near = False
            pos = False
            neg = False
            for v in range(3):
                v2 = (v + 1) % 3
                ef[v] = ay[v] * az[v2] - az[v] * ay[v2]
                near = near or abs(ef[v]) <= eps
                pos = pos or ef[v] > eps
                neg = neg or ef[v] < -eps
            if pos and neg:  # clearly outside the triangle's shadow
                continue
            area = ef[0] + ef[1]
            area = area + ef[2]
            flat = abs(area) <= eps
            den = 1.0 if flat else area
            xh = (ef[1] / den) * tri[t, 0, 0]
            xh = xh + (ef[2] / den) * tri[t, 1, 0]
            xh = xh + (ef[0] / den) * tri[t, 2, 0]
            ahead = xh - px
            on = abs(ahead) <= on_tol
            if near or flat or on:
                tie[q] = True
            elif ahead > 0:
                wind[q] += 1 if area > 0 else -1
    return wind, tie


@kernel(cache=True)
def boxes_below(zrow: np.ndarray, T_part_tcp: np.ndarray, T_tcp_box: np.ndarray, half: np.ndarray,
                index: np.ndarray, limit: float) -> np.ndarray:
    """(M,) bool: pose ``m``'s box (``T_tcp_box[index[m]]``, half extents ``half[index[m]]``; box 0
    for every pose when ``index`` is empty) has its lowest corner below ``limit``, the world's z
    being ``zrow (4,) . T_part_tcp[m] . T_tcp_box`` (``zrow``: the world-z row of ``T_world_part``)."""
    M = T_part_tcp.shape[0]
    out = np.zeros(M, dtype=np.bool_)
    zt = np.empty(4)
    for m in range(M):
        for k in range(4):
            zt[k] = (zrow[0] * T_part_tcp[m, 0, k] + zrow[1] * T_part_tcp[m, 1, k] + zrow[2] * T_part_tcp[m, 2, k]
                     + zrow[3] * T_part_tcp[m, 3, k])
        v = index[m] if index.shape[0] else 0
        reach = 0.0
        for k in range(3):
            zk = (zt[0] * T_tcp_box[v, 0, k] + zt[1] * T_tcp_box[v, 1, k] + zt[2] * T_tcp_box[v, 2, k]
                  + zt[3] * T_tcp_box[v, 3, k])
            reach += abs(zk) * half[v, k]
        z = (zt[0] * T_tcp_box[v, 0, 3] + zt[1] * T_tcp_box[v, 1, 3] + zt[2] * T_tcp_box[v, 2, 3]
             + zt[3] * T_tcp_box[v, 3, 3])
        out[m] = z - reach < limit
    return out
