"""Stage 6: global collision filter of gripper poses against the part, the table and the obstacles.

Checked geometry per pose (issue 3), all in the TCP frame of the pose:

* every body shape (boxes, meshes) of the gripper;
* each jaw swept from the pre-grasp opening ``o_pre = min(max_opening, width + 10 mm)`` inwards to
  ``o_close = min(width + 2 mm, o_pre)`` (:meth:`Gripper.swept_fingers`: one exact box for a box
  jaw, the convex hull of the two end placements for a mesh jaw).

Against:

* the part: coal (``coal.BVHModelOBBRSS`` of the part mesh, built once per
  :class:`GripperCollider`; ``coal.Box`` for boxes). Touching counts as a collision (coal's
  ``distance <= 0`` within its GJK tolerance, ~1e-6 m). A shape whose oriented box is separated
  from the part's axis-aligned box (exact 15-axis separating-axis test in NumPy) is free without
  calling coal. coal tests surfaces: a shape that crosses no triangle is also tested for lying
  wholly inside a watertight part (one of its points, :func:`points_inside_tree`: signed ray
  crossings, the winding number of a closed mesh, exact; near-ties by the generalised winding
  number). Two exact certificates decide box-part hits in NumPy before coal, each only while it
  keeps finding hits: a box whose centre is inside a watertight part hits it; a box containing a
  sample of the part's surface (:func:`surface_samples`: convex combinations of a triangle's
  corners) deeper than ``SAMPLE_DEPTH`` hits it. Shapes are tried in blocks of poses, those that
  hit most often first; the first hit names the pose's element.
* the table, the half-space ``z < table_z`` of the world: exactly, in NumPy: a box collides iff
  its lowest corner is below ``table_z - TABLE_CONTACT_TOL`` (so touching the table top within
  1 micrometre is not a collision); a mesh iff its lowest vertex is.

* the cell's obstacles (``cell.obstacles``, the bin's floor and walls among them): coal
  geometry from :func:`grasplan.geometry.obstacle_geometry`, built once per collider; a shape
  whose oriented bounding box is separated from the obstacle's world axis-aligned box (the same
  NumPy separating-axis test) is free without calling coal. Touching counts as a collision.

Status per pose: ``collision_part`` when any shape hits the part (checked first, whatever the
table), else ``collision_table`` when any shape is below the table top, else
``collision_obstacle`` when any shape hits an obstacle, else ``ok``. So ``collision_part`` is a
property of the grasp alone, independent of the cell.

:meth:`GripperCollider.check_detail` also returns, per pose, the first gripper element that hit
(index into :meth:`GripperCollider.element_names`: ``body_<k>``, ``finger_left``,
``finger_right``) and the body it hit (index into :meth:`GripperCollider.body_names`: ``part``,
``table``, ``obstacle:<name>``); :func:`hit_reasons` turns them into the grasp-stage reasons
("grasp stage: gripper:finger_left hits obstacle:wall at the grasp or while closing").
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import coal
import numpy as np

if TYPE_CHECKING:  # imported where a trimesh is built (obstacle primitives, mesh files)
    import trimesh

from .cell import Cell
from .geometry import bvh, obstacle_geometry
from .gripper.model import Box, Gripper
from .meshdata import convex_hull
from .transforms import check_transform

#: a shape reaching below the table top by less than this (m) only touches it
TABLE_CONTACT_TOL = 1e-6


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

def points_inside(mesh: trimesh.Trimesh, points: np.ndarray, *, chunk: int = 2_000_000) -> np.ndarray:
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

    def pairs(self, pts: np.ndarray, *, max_pairs: int = 1 << 20):
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


def points_inside_tree(grid: RayGrid, mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """(k,) bool: inside a closed mesh, by the signed count of crossings of the ray from each point
    along +x (= the winding number of a closed mesh). Points whose ray passes within rounding of an
    edge, a vertex or a triangle seen edge-on, or that lie on the surface, are decided by the
    generalised winding number (:func:`points_inside`) instead."""
    pts0 = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    pts = pts0 @ grid.Q.T
    k = len(pts)
    wind = np.zeros(k, dtype=np.int64)
    tie = np.zeros(k, dtype=bool)
    if k == 0:
        return np.zeros(0, dtype=bool)
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
        ahead = xh - pts[q, 0]
        on = np.abs(ahead) <= 1e-12 * scale
        cross = ~near & ~flat & ~on & (ahead > 0)
        np.add.at(wind, q[cross], np.where(area[cross] > 0, 1, -1))
        tie[q[near | flat | on]] = True
    out = wind != 0
    if tie.any():
        out[tie] = points_inside(mesh, pts0[tie])
    return out


def _rotation_generic() -> np.ndarray:
    """A fixed rotation about an axis and by an angle of no special value (Rodrigues)."""
    k = np.array([0.2718281828, 0.5772156649, 0.7071067812])
    k = k / np.linalg.norm(k)
    a = 0.6180339887
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * (K @ K)


#: a part surface sample deeper than this (m) inside a box proves a collision without coal
SAMPLE_DEPTH = 1e-5


def surface_samples(mesh: trimesh.Trimesh, *, spacing: float = 0.006, max_samples: int = 50_000) -> np.ndarray:
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

class _ShapeSet:
    """One gripper shape per pose: coal geometry per unique variant, ``T_tcp_shape`` per pose."""

    def __init__(self, variants: list, index: np.ndarray):
        self.variants = variants  # list of Box | MeshShape
        self.index = index  # (M,) variant per pose
        self.is_box = isinstance(variants[0], Box)
        geoms = []
        for v in variants:
            if isinstance(v, Box):
                geoms.append(coal.Box(*np.asarray(v.extents, dtype=np.float64)))
            else:
                geoms.append(bvh(v.vertices, v.faces))
        self.geoms = geoms
        # local bounding box of each variant, in the TCP frame (for the prefilter)
        Ts, hs, _low = [], [], []
        for v in variants:
            if isinstance(v, Box):
                Ts.append(v.T_tcp_box)
                hs.append(0.5 * np.asarray(v.extents, dtype=np.float64))
            else:
                lo, hi = v.vertices.min(axis=0), v.vertices.max(axis=0)
                T = np.eye(4)
                T[:3, 3] = 0.5 * (lo + hi)
                Ts.append(T)
                hs.append(0.5 * (hi - lo))
        self.T_tcp_geom = np.array([v.T_tcp_box if isinstance(v, Box) else np.eye(4) for v in variants])
        self.T_tcp_bb = np.array(Ts)
        self.half_bb = np.array(hs)


class GripperCollider:
    #: poses per block of the coal loop (the shape order adapts to the hit counts between blocks)
    block = 1024
    """Collision checks of one gripper against one part in one cell.

    The part's BVH, the body geometry and the coal request/result objects are built once; call
    :meth:`check` for any number of pose batches.

    Parameters
    ----------
    part_mesh : trimesh.Trimesh in the part frame, metres
    gripper : Gripper
    cell : Cell (table height)
    T_world_part : (4, 4)
    """

    def __init__(self, part_mesh: trimesh.Trimesh, gripper: Gripper, cell: Cell, T_world_part: np.ndarray):
        T_world_part = check_transform(T_world_part, "T_world_part", error=ValueError)
        self.part_mesh = part_mesh
        self.gripper = gripper
        self.cell = cell
        self.T_world_part = T_world_part
        self.part_bvh = bvh(part_mesh.vertices, part_mesh.faces)
        self._grid = self._samples = None
        lo, hi = part_mesh.bounds
        self.aabb_center = 0.5 * (lo + hi)
        self.aabb_half = 0.5 * (hi - lo)
        self.watertight = bool(part_mesh.is_watertight)
        # world z of a part-frame point p: zrow[:3] @ p + zrow[3]
        self.zrow = T_world_part[2].copy()
        self.request = coal.CollisionRequest()
        # enable_contact stays True (coal's default) although a yes/no answer is all we need: with
        # enable_contact = False coal 3.0 misses shallow box-into-mesh penetrations (a swept jaw
        # 51 micrometres into SileaneGear reported free; python-fcl and coal with contacts both
        # report it). test_paper_part_ok_and_rejected_independently_checked[SileaneGear] pins it.
        self.request.enable_contact = True
        self.request.num_max_contacts = 1
        self.result = coal.CollisionResult()
        self._tf = coal.Transform3s()
        self._identity = coal.Transform3s()
        self._body = [_ShapeSet([b], None) for b in gripper.body]
        self._finger_cache: dict = {}
        self.coal_calls = 0
        #: poses decided as hits without coal: "centre" (box centre inside the closed part),
        #: "sample" (a part surface sample inside the box)
        self.certified = {"centre": 0, "sample": 0}
        # obstacles: coal geometry, world pose and world axis-aligned box (centre, half extents)
        self.obstacles = tuple(getattr(cell, "obstacles", ()) or ())
        self._obs_geom = [obstacle_geometry(o) for o in self.obstacles]
        self._obs_tf = [coal.Transform3s(np.asarray(o.T_world_obstacle)[:3, :3].copy(),
                                         np.asarray(o.T_world_obstacle)[:3, 3].copy()) for o in self.obstacles]
        bounds = [o.aabb() for o in self.obstacles]
        self._obs_center = [0.5 * (lo + hi) for lo, hi in bounds]
        self._obs_half = [0.5 * (hi - lo) for lo, hi in bounds]

    @property
    def sample_tree(self):
        """k-d tree of :func:`surface_samples` of the part (built on first use)."""
        if self._samples is None:
            from scipy.spatial import cKDTree

            self._samples = cKDTree(surface_samples(self.part_mesh))
        return self._samples

    @property
    def ray_grid(self) -> RayGrid:
        """Ray-crossing grid of the part's triangles for the inside test (built on first use)."""
        if self._grid is None:
            self._grid = RayGrid(self.part_mesh.vertices, self.part_mesh.faces)
        return self._grid

    def element_names(self) -> list[str]:
        """Names of the gripper elements the element codes of :meth:`check_detail` index."""
        return [f"body_{k}" for k in range(len(self._body))] + ["finger_left", "finger_right"]

    def body_names(self) -> list[str]:
        """Names of the bodies the body codes of :meth:`check_detail` index."""
        return ["part", "table"] + [f"obstacle:{o.name}" for o in self.obstacles]

    # -- geometry per pose -------------------------------------------------------------------
    def shape_sets(self, width: np.ndarray) -> list[_ShapeSet]:
        """Body shapes (one variant each) then the two swept jaws (one variant per distinct width)."""
        g = self.gripper
        o_pre = g.pregrasp_opening(width)
        o_close = g.close_to_opening(width)
        key = np.round(np.stack([o_pre, o_close], axis=1), 12)
        uk, inv = np.unique(key, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        left, right = [], []
        for a, b in uk:
            k = (float(a), float(b))
            if k not in self._finger_cache:
                self._finger_cache[k] = g.swept_fingers(a, b)
            sl, sr = self._finger_cache[k]
            left.append(sl)
            right.append(sr)
        M = len(width)
        body = []
        for s in self._body:
            s2 = _ShapeSet.__new__(_ShapeSet)
            s2.__dict__.update(s.__dict__)
            s2.index = np.zeros(M, dtype=np.int64)
            body.append(s2)
        return body + [_ShapeSet(left, inv), _ShapeSet(right, inv)]

    # -- table ------------------------------------------------------------------------------
    def _table_hits(self, T_part_tcp: np.ndarray, sets: list[_ShapeSet]) -> tuple[np.ndarray, np.ndarray]:
        """``(hit (M,) bool, first hitting element (M,) int, -1 when free)``."""
        M = len(T_part_tcp)
        hit = np.zeros(M, dtype=bool)
        elem = np.full(M, -1, dtype=np.int64)
        zrow = self.zrow
        zr_tcp = np.einsum("j,mjk->mk", zrow, T_part_tcp)  # world-z row of T_world_tcp, (M,4)
        limit = self.cell.table_z - TABLE_CONTACT_TOL
        for si, s in enumerate(sets):
            h_s = np.zeros(M, dtype=bool)
            if s.is_box:
                Tg = s.T_tcp_geom[s.index]  # (M,4,4)
                zr = np.einsum("mj,mjk->mk", zr_tcp, Tg)  # world-z row of T_world_box
                h = 0.5 * np.array([np.asarray(v.extents) for v in s.variants])[s.index]
                zmin = zr[:, 3] - np.sum(np.abs(zr[:, :3]) * h, axis=1)
                h_s |= zmin < limit
            else:
                for k, v in enumerate(s.variants):
                    sel = np.flatnonzero(s.index == k)
                    if len(sel) == 0:
                        continue
                    hv = convex_hull(v.vertices).vertices if len(v.vertices) > 64 else v.vertices
                    z = zr_tcp[sel, :3] @ hv.T + zr_tcp[sel, 3:4]
                    h_s[sel] |= z.min(axis=1) < limit
            elem[h_s & ~hit] = si
            hit |= h_s
        return hit, elem

    # -- obstacles --------------------------------------------------------------------------
    def _obstacle_hits(self, T_part_tcp: np.ndarray, sets: list[_ShapeSet], todo: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(hit (M,), first element (M,), obstacle index (M,))`` for the poses ``todo`` (M,) bool
        (-1 where free or not checked). Prefilter: each shape's world oriented bounding box against
        each obstacle's world axis-aligned box; coal for the overlapping ones (first hit decides)."""
        M = len(T_part_tcp)
        hit = np.zeros(M, dtype=bool)
        elem = np.full(M, -1, dtype=np.int64)
        obs = np.full(M, -1, dtype=np.int64)
        if not self.obstacles or not todo.any():
            return hit, elem, obs
        idx = np.flatnonzero(todo)
        T_world_tcp = self.T_world_part @ T_part_tcp[idx]  # (m, 4, 4)
        need = np.zeros((len(sets), len(self.obstacles), len(idx)), dtype=bool)
        Tgs = []
        for si, s in enumerate(sets):
            Tbb = T_world_tcp @ s.T_tcp_bb[s.index[idx]]
            h = s.half_bb[s.index[idx]]
            for oi in range(len(self.obstacles)):
                need[si, oi] = ~obb_aabb_separated(Tbb[:, :3, 3], Tbb[:, :3, :3], h, self._obs_center[oi],
                                                   self._obs_half[oi])
            Tgs.append(T_world_tcp @ s.T_tcp_geom[s.index[idx]] if s.is_box else T_world_tcp)
        collide = coal.collide
        req, res, tf = self.request, self.result, self._tf
        calls = 0
        for k in np.flatnonzero(need.any(axis=(0, 1))):
            m = idx[k]
            for si in range(len(sets) - 1, -1, -1):  # jaws first: they reach furthest
                for oi in np.flatnonzero(need[si, :, k]):
                    T = Tgs[si][k]
                    tf.setRotation(T[:3, :3])
                    tf.setTranslation(T[:3, 3])
                    res.clear()
                    calls += 1
                    if collide(sets[si].geoms[sets[si].index[m]], tf, self._obs_geom[oi], self._obs_tf[oi], req, res):
                        hit[m], elem[m], obs[m] = True, si, oi
                        break
                if hit[m]:
                    break
        self.coal_calls += calls
        return hit, elem, obs

    # -- part ------------------------------------------------------------------------------
    def _part_hits(self, T_part_tcp: np.ndarray, sets: list[_ShapeSet]) -> tuple[np.ndarray, np.ndarray]:
        """``(hit (M,) bool, first hitting element (M,) int, -1 when free)``."""
        M = len(T_part_tcp)
        elem = np.full(M, -1, dtype=np.int64)
        hit = np.zeros(M, dtype=bool)
        Tgs = []
        need = np.zeros((len(sets), M), dtype=bool)
        inside_cand = np.zeros((len(sets), M), dtype=bool)
        for si, s in enumerate(sets):
            Tbb = T_part_tcp @ s.T_tcp_bb[s.index]
            h = s.half_bb[s.index]
            need[si] = ~obb_aabb_separated(Tbb[:, :3, 3], Tbb[:, :3, :3], h, self.aabb_center, self.aabb_half)
            if self.watertight:
                # bounding box of the shape's box wholly within the part's box: might be inside the part
                ext = np.einsum("mij,mj->mi", np.abs(Tbb[:, :3, :3]), h)
                inside_cand[si] = np.all(np.abs(Tbb[:, :3, 3] - self.aabb_center) + ext <= self.aabb_half, axis=1)
            Tgs.append(T_part_tcp @ s.T_tcp_geom[s.index] if s.is_box else T_part_tcp)
        collide = coal.collide
        req, res, tf, I, part_bvh = self.request, self.result, self._tf, self._identity, self.part_bvh
        calls = 0

        def coal_hit(si: int, m: int) -> bool:
            T = Tgs[si][m]
            tf.setRotation(T[:3, :3])
            tf.setTranslation(T[:3, 3])
            res.clear()
            return bool(collide(sets[si].geoms[sets[si].index[m]], tf, part_bvh, I, req, res))

        # in blocks of poses, per shape: shapes that hit most often so far are tried first (jaws
        # first to begin with); the first shape that hits decides the pose. On a closed part a box
        # whose centre is inside it hits it (it crosses the surface or lies inside): that exact
        # ray-crossing test runs before coal while it finds enough hits to pay for itself.
        order = list(range(len(sets)))[::-1]
        first_hits = np.zeros(len(sets), dtype=np.int64)
        centre_rate = np.ones(len(sets))
        sample_rate = np.ones(len(sets))
        half = [0.5 * np.array([np.asarray(v.extents, dtype=np.float64) for v in s.variants]) if s.is_box else None
                for s in sets]
        for b0 in range(0, M, self.block):
            blk = np.arange(b0, min(M, b0 + self.block))
            for si in order:
                s = sets[si]
                todo = blk[need[si, blk] & ~hit[blk]]
                if len(todo) == 0:
                    continue
                if self.watertight and s.is_box and centre_rate[si] >= 0.2:
                    cand = todo[inside_box(Tgs[si][todo, :3, 3], self.aabb_center, self.aabb_half)]
                    ins = cand[points_inside_tree(self.ray_grid, self.part_mesh, Tgs[si][cand, :3, 3])]
                    centre_rate[si] = 0.5 * centre_rate[si] + 0.5 * len(ins) / max(len(todo), 1)
                    self.certified["centre"] += len(ins)
                    hit[ins] = True
                    elem[ins] = si
                    first_hits[si] += len(ins)
                    todo = todo[~hit[todo]]
                if s.is_box and sample_rate[si] >= 0.1 and len(todo):
                    # the part's surface sample nearest the box centre lies inside the box: a hit
                    T = Tgs[si][todo]
                    _, j = self.sample_tree.query(T[:, :3, 3])
                    local = np.einsum("mji,mj->mi", T[:, :3, :3], self.sample_tree.data[j] - T[:, :3, 3])
                    h = half[si][s.index[todo]]
                    ins = todo[np.all(np.abs(local) < h - SAMPLE_DEPTH, axis=1)]
                    sample_rate[si] = 0.5 * sample_rate[si] + 0.5 * len(ins) / len(todo)
                    self.certified["sample"] += len(ins)
                    hit[ins] = True
                    elem[ins] = si
                    first_hits[si] += len(ins)
                    todo = todo[~hit[todo]]
                hl = []
                for m in todo:
                    calls += 1
                    if coal_hit(si, m):
                        hl.append(m)
                hits = np.asarray(hl, dtype=np.int64)
                hit[hits] = True
                elem[hits] = si
                first_hits[si] += len(hits)
            order = sorted(order, key=lambda i: -first_hits[i])
        self.coal_calls += calls
        # a shape crossing no triangle may still lie wholly inside a closed part
        pts_idx = [(si, m) for si in range(len(sets)) for m in np.flatnonzero(inside_cand[si] & ~hit)]
        if pts_idx:
            pts = np.array([Tgs[si][m][:3, 3] if sets[si].is_box else
                            (sets[si].variants[sets[si].index[m]].vertices[0] @ Tgs[si][m][:3, :3].T + Tgs[si][m][:3, 3])
                            for si, m in pts_idx])
            inside = points_inside_tree(self.ray_grid, self.part_mesh, pts)
            for (si, m), ins in zip(pts_idx, inside):
                if ins and not hit[m]:
                    hit[m] = True
                    elem[m] = si
        return hit, elem

    def check(self, T_part_tcp: np.ndarray, width: np.ndarray) -> np.ndarray:
        """Status per pose: (M,) array of str in ``STATUSES``.

        T_part_tcp : (M, 4, 4) TCP poses in the part frame; width : (M,) contact distance (m)."""
        return self.check_detail(T_part_tcp, width)[0]

    def check_detail(self, T_part_tcp: np.ndarray, width: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(status (M,) str, element (M,) int, body (M,) int)``: the status per pose (see the
        module docstring), the gripper element that decided it (index into
        :meth:`element_names`) and the body it hit (index into :meth:`body_names`); -1 for ``ok``."""
        T_part_tcp = check_transform(T_part_tcp, "T_part_tcp", batch=True, error=ValueError)
        width = np.asarray(width, dtype=np.float64).reshape(-1)
        if width.shape != (len(T_part_tcp),):
            raise ValueError(f"width must have shape ({len(T_part_tcp)},), got {width.shape}")
        M = len(width)
        status = np.full(M, "ok", dtype="<U18")
        elem = np.full(M, -1, dtype=np.int64)
        body = np.full(M, -1, dtype=np.int64)
        if M == 0:
            return status, elem, body
        sets = self.shape_sets(width)
        part, e_part = self._part_hits(T_part_tcp, sets)
        table, e_table = self._table_hits(T_part_tcp, sets)
        obst, e_obst, which = self._obstacle_hits(T_part_tcp, sets, ~(part | table))
        status[obst], elem[obst], body[obst] = "collision_obstacle", e_obst[obst], 2 + which[obst]
        status[table], elem[table], body[table] = "collision_table", e_table[table], 1
        status[part], elem[part], body[part] = "collision_part", e_part[part], 0
        return status, elem, body

    def reasons(self, status: np.ndarray, element: np.ndarray, body: np.ndarray) -> np.ndarray:
        """(M,) object array of grasp-stage reasons from :meth:`check_detail` ("" for ``ok``)."""
        return hit_reasons(status, element, body, self.element_names(), self.body_names())

    def part_collision(self, T_part_tcp: np.ndarray, width: np.ndarray) -> np.ndarray:
        """(M,) bool: any shape hits the part (no table check)."""
        T_part_tcp = check_transform(T_part_tcp, "T_part_tcp", batch=True, error=ValueError)
        width = np.asarray(width, dtype=np.float64).reshape(-1)
        return self._part_hits(T_part_tcp, self.shape_sets(width))[0]


def hit_reasons(status, element, body, element_names: list[str], body_names: list[str]) -> np.ndarray:
    """(M,) object array: "grasp stage: gripper:<element> hits <body> at the grasp or while
    closing" for rejected poses, "" for ``ok`` ones (vectorised over the distinct codes)."""
    status = np.asarray(status).astype(str)
    element = np.asarray(element, dtype=np.int64)
    body = np.asarray(body, dtype=np.int64)
    out = np.full(len(status), "", dtype=object)
    bad = np.flatnonzero(status != "ok")
    if len(bad) == 0:
        return out
    codes, inv = np.unique(np.stack([element[bad], body[bad]], axis=1), axis=0, return_inverse=True)
    texts = np.array([
        f"grasp stage: gripper:{element_names[e] if 0 <= e < len(element_names) else '?'} hits "
        f"{body_names[b] if 0 <= b < len(body_names) else '?'} at the grasp or while closing"
        for e, b in codes], dtype=object)
    out[bad] = texts[inv.reshape(-1)]
    return out


def check_grasps(
    part_mesh: trimesh.Trimesh,
    gripper: Gripper,
    cell: Cell,
    T_world_part: np.ndarray,
    T_part_tcp: np.ndarray,
    width: np.ndarray,
) -> np.ndarray:
    """Status per pose ``(M,)`` str in {"ok", "collision_part", "collision_table", "collision_obstacle"}.

    Builds a :class:`GripperCollider` (the part BVH) and checks the ``(M, 4, 4)`` poses; keep a
    collider yourself to check several batches against the same part."""
    return GripperCollider(part_mesh, gripper, cell, T_world_part).check(T_part_tcp, width)
