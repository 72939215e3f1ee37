"""Stage 6: global collision filter of gripper poses against the part and the table.

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
  wholly inside a watertight part (one of its points, ``part_mesh.contains``).
* the table, the half-space ``z < table_z`` of the world: exactly, in NumPy: a box collides iff
  its lowest corner is below ``table_z - TABLE_CONTACT_TOL`` (so touching the table top within
  1 micrometre is not a collision); a mesh iff its lowest vertex is.

Status per pose: ``collision_part`` when any shape hits the part (checked first, whatever the
table), else ``collision_table`` when any shape is below the table top, else ``ok``. So
``collision_part`` is a property of the grasp alone, independent of the cell.
"""
from __future__ import annotations

import coal
import numpy as np
import trimesh

from .cell import Cell
from .geometry import bvh
from .gripper import Box, Gripper
from .transforms import check_transform

#: a shape reaching below the table top by less than this (m) only touches it
TABLE_CONTACT_TOL = 1e-6


def obb_aabb_separated(c: np.ndarray, R: np.ndarray, h: np.ndarray, a: np.ndarray, e: np.ndarray) -> np.ndarray:
    """(M,) bool: oriented boxes (centre ``c`` (M,3), rotation ``R`` (M,3,3) whose columns are the
    box axes, half extents ``h`` (M,3)) strictly separated from the axis-aligned box with centre
    ``a`` (3,) and half extents ``e`` (3,). Exact separating-axis test (15 axes)."""
    d = c - a  # (M,3)
    absR = np.abs(R) + 1e-12  # robust for near-parallel edge axes
    sep = np.zeros(len(c), dtype=bool)
    # AABB face axes: world x, y, z
    rb = np.einsum("mij,mj->mi", absR, h)  # projection radius of the OBB on each world axis
    sep |= np.any(np.abs(d) > e + rb, axis=1)
    # OBB face axes (columns of R)
    ra = np.einsum("i,mij->mj", e, absR)
    sep |= np.any(np.abs(np.einsum("mi,mij->mj", d, R)) > ra + h, axis=1)
    # cross products world_i x box_j
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            # axis = e_i x R[:, j]; projections follow the standard OBB-OBB table with A = I
            dist = np.abs(d[:, i2] * R[:, i1, j] - d[:, i1] * R[:, i2, j])
            r_a = e[i1] * absR[:, i2, j] + e[i2] * absR[:, i1, j]
            r_b = h[:, j1] * absR[:, i, j2] + h[:, j2] * absR[:, i, j1]
            sep |= dist > r_a + r_b
    return sep


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
    def _table_hits(self, T_part_tcp: np.ndarray, sets: list[_ShapeSet]) -> np.ndarray:
        M = len(T_part_tcp)
        hit = np.zeros(M, dtype=bool)
        zrow = self.zrow
        zr_tcp = np.einsum("j,mjk->mk", zrow, T_part_tcp)  # world-z row of T_world_tcp, (M,4)
        limit = self.cell.table_z - TABLE_CONTACT_TOL
        for s in sets:
            if s.is_box:
                Tg = s.T_tcp_geom[s.index]  # (M,4,4)
                zr = np.einsum("mj,mjk->mk", zr_tcp, Tg)  # world-z row of T_world_box
                h = 0.5 * np.array([np.asarray(v.extents) for v in s.variants])[s.index]
                zmin = zr[:, 3] - np.sum(np.abs(zr[:, :3]) * h, axis=1)
                hit |= zmin < limit
            else:
                for k, v in enumerate(s.variants):
                    sel = np.flatnonzero(s.index == k)
                    if len(sel) == 0:
                        continue
                    hv = trimesh.convex.convex_hull(v.vertices).vertices if len(v.vertices) > 64 else v.vertices
                    z = zr_tcp[sel, :3] @ hv.T + zr_tcp[sel, 3:4]
                    hit[sel] |= z.min(axis=1) < limit
        return hit

    # -- part ------------------------------------------------------------------------------
    def _part_hits(self, T_part_tcp: np.ndarray, sets: list[_ShapeSet]) -> np.ndarray:
        M = len(T_part_tcp)
        need = np.zeros((len(sets), M), dtype=bool)
        Tgs = []
        inside_cand = np.zeros((len(sets), M), dtype=bool)
        for si, s in enumerate(sets):
            Tbb = T_part_tcp @ s.T_tcp_bb[s.index]
            h = s.half_bb[s.index]
            sep = obb_aabb_separated(Tbb[:, :3, 3], Tbb[:, :3, :3], h, self.aabb_center, self.aabb_half)
            need[si] = ~sep
            if self.watertight:
                # bounding box of the shape's box wholly within the part's box: might be inside the part
                ext = np.einsum("mij,mj->mi", np.abs(Tbb[:, :3, :3]), h)
                inside_cand[si] = np.all(np.abs(Tbb[:, :3, 3] - self.aabb_center) + ext <= self.aabb_half, axis=1)
            Tgs.append(T_part_tcp @ s.T_tcp_geom[s.index] if s.is_box else T_part_tcp)
        hit = np.zeros(M, dtype=bool)
        poses = np.flatnonzero(need.any(axis=0))
        collide = coal.collide
        req, res, tf, I, bvh = self.request, self.result, self._tf, self._identity, self.part_bvh
        calls = 0
        # shapes that hit most often are tried first (jaws first to begin with; the order adapts
        # every 512 poses to the hit counts so far); the first hit decides the pose
        order = list(range(len(sets)))[::-1]
        first_hits = [0] * len(sets)
        for k, m in enumerate(poses):
            if k and k % 512 == 0:
                order = sorted(order, key=lambda i: -first_hits[i])
            for si in order:
                if not need[si, m]:
                    continue
                T = Tgs[si][m]
                tf.setRotation(T[:3, :3])
                tf.setTranslation(T[:3, 3])
                res.clear()
                calls += 1
                if collide(sets[si].geoms[sets[si].index[m]], tf, bvh, I, req, res):
                    hit[m] = True
                    first_hits[si] += 1
                    break
        self.coal_calls += calls
        # a shape crossing no triangle may still lie wholly inside a closed part
        pts_idx = [(si, m) for si in range(len(sets)) for m in np.flatnonzero(inside_cand[si] & ~hit)]
        if pts_idx:
            pts = np.array([Tgs[si][m][:3, 3] if sets[si].is_box else
                            (sets[si].variants[sets[si].index[m]].vertices[0] @ Tgs[si][m][:3, :3].T + Tgs[si][m][:3, 3])
                            for si, m in pts_idx])
            inside = points_inside(self.part_mesh, pts)
            for (si, m), ins in zip(pts_idx, inside):
                if ins:
                    hit[m] = True
        return hit

    def check(self, T_part_tcp: np.ndarray, width: np.ndarray) -> np.ndarray:
        """Status per pose: (M,) array of str in ``STATUSES``.

        T_part_tcp : (M, 4, 4) TCP poses in the part frame; width : (M,) contact distance (m)."""
        T_part_tcp = check_transform(T_part_tcp, "T_part_tcp", batch=True, error=ValueError)
        width = np.asarray(width, dtype=np.float64).reshape(-1)
        if width.shape != (len(T_part_tcp),):
            raise ValueError(f"width must have shape ({len(T_part_tcp)},), got {width.shape}")
        status = np.full(len(width), "ok", dtype="<U15")
        if len(width) == 0:
            return status
        sets = self.shape_sets(width)
        part = self._part_hits(T_part_tcp, sets)
        table = self._table_hits(T_part_tcp, sets)
        status[table] = "collision_table"
        status[part] = "collision_part"
        return status

    def part_collision(self, T_part_tcp: np.ndarray, width: np.ndarray) -> np.ndarray:
        """(M,) bool: any shape hits the part (no table check)."""
        T_part_tcp = check_transform(T_part_tcp, "T_part_tcp", batch=True, error=ValueError)
        width = np.asarray(width, dtype=np.float64).reshape(-1)
        return self._part_hits(T_part_tcp, self.shape_sets(width))


def check_grasps(
    part_mesh: trimesh.Trimesh,
    gripper: Gripper,
    cell: Cell,
    T_world_part: np.ndarray,
    T_part_tcp: np.ndarray,
    width: np.ndarray,
) -> np.ndarray:
    """Status per pose ``(M,)`` str in {"ok", "collision_part", "collision_table"}.

    Builds a :class:`GripperCollider` (the part BVH) and checks the ``(M, 4, 4)`` poses; keep a
    collider yourself to check several batches against the same part."""
    return GripperCollider(part_mesh, gripper, cell, T_world_part).check(T_part_tcp, width)
