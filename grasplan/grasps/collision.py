"""Stage 6: global collision filter of gripper poses against the part, the table and the obstacles.

:class:`GripperCollider` checks each pose's gripper body shapes and its two jaws swept while
closing (:meth:`GripperCollider.shape_sets`, :mod:`grasplan.grasps.collision_shapes`) against the
part (coal, after exact shortcuts: NumPy, and the compiled box pre-pass of
:mod:`grasplan.grasps.collision_boxes`), the table (exactly, in NumPy) and the cell's obstacles
(coal), and gives every pose a status (:meth:`GripperCollider.check_detail`); :func:`hit_reasons`
words the grasp-stage reasons
("grasp stage: gripper:finger_left hits obstacle:wall at the grasp or while closing").
"""
from __future__ import annotations

import time
from typing import Any, Protocol

import coal
import numpy as np

from ..cell.model import Cell
from ..geometry.containment import RayGrid, inside_box, obb_aabb_separated, points_inside_tree, surface_samples
from ..cell.shapes import obstacle_geometry, shared_bvh, shared_mesh_structure
from ..gripper.model import Gripper
from ..geometry.meshdata import TriangleMesh, convex_hull
from ..status import Status
from ..geometry.transforms import check_transform
from .collision_boxes import HIT, UNSURE, PartBoxes, boxes_below, points_inside_compiled, prefilter
from .collision_shapes import ShapeSet, shared_sweeps

#: a shape reaching below the table top by less than this (m) only touches it
TABLE_CONTACT_TOL = 1e-6
#: a part surface sample deeper than this (m) inside a box proves a collision without coal
SAMPLE_DEPTH = 1e-5


class PartMesh(TriangleMesh, Protocol):
    """What the collider reads of the part: a :class:`~grasplan.geometry.meshdata.TriangleMesh` that knows
    whether it is closed (:class:`~grasplan.geometry.meshdata.MeshData` and ``trimesh.Trimesh`` both do)."""

    @property
    def is_watertight(self) -> bool: ...


class GripperCollider:
    #: poses per block of the coal loop (the shape order adapts to the hit counts between blocks)
    block = 1024
    """Collision checks of one gripper against one part in one cell.

    The part's BVH, the body geometry and the coal request/result objects are built once; call
    :meth:`check` for any number of pose batches.

    Parameters
    ----------
    part_mesh : PartMesh (a MeshData or a trimesh) in the part frame, metres
    gripper : Gripper
    cell : Cell (table height)
    T_world_part : (4, 4)
    """

    def __init__(self, part_mesh: PartMesh, gripper: Gripper, cell: Cell, T_world_part: np.ndarray, *,
                 prepass: bool = True):
        T_world_part = check_transform(T_world_part, "T_world_part", error=ValueError)
        #: decide (shape, pose) pairs on boxes against the part's triangles before coal
        #: (:mod:`grasplan.grasps.collision_boxes`); False: coal for every pair the prefilter leaves
        self.prepass = bool(prepass)
        self._boxes: PartBoxes | None = None
        #: seconds spent so far, summed over :meth:`check_detail` calls: ``shapes`` (the shapes per
        #: pose, :meth:`shape_sets`), ``part`` (the whole part check: prefilter, inside tests,
        #: pre-pass and coal), of it ``part_boxes`` (the compiled pre-pass) and ``part_coal`` (coal's
        #: calls on the part), ``table``, ``obstacle``
        self.timing = {"shapes": 0.0, "part": 0.0, "part_boxes": 0.0, "part_coal": 0.0, "table": 0.0,
                       "obstacle": 0.0}
        #: pairs the pre-pass decided: ``apart``, ``hit``; ``unsure`` went to coal
        self.prepass_counts = {"apart": 0, "hit": 0, "unsure": 0}
        self.part_mesh = part_mesh
        self.gripper = gripper
        self.cell = cell
        self.T_world_part = T_world_part
        self._bvh: coal.BVHModelOBBRSS | None = None   # built on first use (a part without poses needs none)
        self._grid: RayGrid | None = None
        self._samples: Any = None             # scipy.spatial.cKDTree of the surface samples, on first use
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
        self._body = [ShapeSet([b], np.zeros(0, dtype=np.int64)) for b in gripper.body]  # index set per batch
        self._sweeps = shared_sweeps(gripper)
        self.coal_calls = 0
        #: poses decided as hits without coal: "centre" (box centre inside the closed part),
        #: "sample" (a point of the part's surface deeper than SAMPLE_DEPTH inside the box: a stored
        #: surface sample, or a triangle's point found by the compiled pre-pass)
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
    def part_bvh(self) -> coal.BVHModelOBBRSS:
        """coal OBBRSS hierarchy of the part's triangles (:func:`~grasplan.cell.shapes.shared_bvh`, on first use)."""
        if self._bvh is None:
            self._bvh = shared_bvh(self.part_mesh.vertices, self.part_mesh.faces)
        return self._bvh

    @property
    def part_boxes(self) -> PartBoxes:
        """The part's triangles in the compiled box hierarchy of the pre-pass (built on first use,
        shared per mesh content: :func:`~grasplan.cell.shapes.shared_mesh_structure`)."""
        if self._boxes is None:
            self._boxes = shared_mesh_structure("part_boxes", self.part_mesh.vertices, self.part_mesh.faces, PartBoxes)
        return self._boxes

    @property
    def sample_tree(self) -> Any:
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
    def shape_sets(self, width: np.ndarray) -> list[ShapeSet]:
        """Body shapes (one variant each) then the two swept jaws (one variant per distinct width),
        all in the TCP frame of the pose: every body shape (boxes, meshes) of the gripper, and each jaw
        swept from the pre-grasp opening ``o_pre = min(max_opening, width + 10 mm)`` inwards to
        ``o_close = min(width + 2 mm, o_pre)`` (:meth:`Gripper.swept_fingers`: one exact box for a box
        jaw, the convex hull of the two end placements for a mesh jaw)."""
        index = self._sweeps.rows_for(width)
        M = len(width)
        body = []
        for s in self._body:
            s2 = ShapeSet.__new__(ShapeSet)
            s2.__dict__.update(s.__dict__)
            s2.index = np.zeros(M, dtype=np.int64)
            body.append(s2)
        return body + [self._sweeps.shape_set(0, index), self._sweeps.shape_set(1, index)]

    # -- table ------------------------------------------------------------------------------
    def _table_hits(self, T_part_tcp: np.ndarray, sets: list[ShapeSet], todo: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
        """``(hit (M,) bool, first hitting element (M,) int, -1 when free)`` against the table, the
        half-space ``z < table_z`` of the world, exactly: a box collides iff its lowest corner is below
        ``table_z - TABLE_CONTACT_TOL`` (so touching the table top within 1 micrometre is not a
        collision); a mesh iff its lowest vertex is. ``todo`` (M,) bool: check only those poses
        (the others are free here)."""
        M = len(T_part_tcp)
        if todo is not None:
            idx = np.flatnonzero(todo)
            hit = np.zeros(M, dtype=bool)
            elem = np.full(M, -1, dtype=np.int64)
            sub = [ShapeSet.__new__(ShapeSet) for _ in sets]
            for s2, s in zip(sub, sets):
                s2.__dict__.update(s.__dict__)
                s2.index = s.index[idx]
            hit[idx], elem[idx] = self._table_hits(T_part_tcp[idx], sub)
            return hit, elem
        hit = np.zeros(M, dtype=bool)
        elem = np.full(M, -1, dtype=np.int64)
        zrow = np.ascontiguousarray(self.zrow, dtype=np.float64)
        zr_tcp: np.ndarray | None = None
        limit = self.cell.table_z - TABLE_CONTACT_TOL
        T = np.ascontiguousarray(T_part_tcp, dtype=np.float64)
        for si, s in enumerate(sets):
            h_s = np.zeros(M, dtype=bool)
            if s.is_box:  # compiled: the world z of the box's lowest corner per pose
                index = np.zeros(0, dtype=np.int64) if len(s.T_tcp_geom) == 1 else np.ascontiguousarray(s.index,
                                                                                                         dtype=np.int64)
                h_s |= boxes_below(zrow, T, np.ascontiguousarray(s.T_tcp_geom, dtype=np.float64),
                                   np.ascontiguousarray(s.half_bb, dtype=np.float64), index, float(limit))
            else:
                if zr_tcp is None:
                    zr_tcp = np.einsum("j,mjk->mk", zrow, T)  # world-z row of T_world_tcp, (M,4)
                for k in np.unique(s.index).tolist():
                    v = s.variants[k]
                    sel = np.flatnonzero(s.index == k)
                    hv = convex_hull(v.vertices).vertices if len(v.vertices) > 64 else v.vertices
                    z = zr_tcp[sel, :3] @ hv.T + zr_tcp[sel, 3:4]
                    h_s[sel] |= z.min(axis=1) < limit
            elem[h_s & ~hit] = si
            hit |= h_s
        return hit, elem

    # -- obstacles --------------------------------------------------------------------------
    def _obstacle_hits(self, T_part_tcp: np.ndarray, sets: list[ShapeSet], todo: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(hit (M,), first element (M,), obstacle index (M,))`` for the poses ``todo`` (M,) bool
        (-1 where free or not checked). The obstacles (``cell.obstacles``, the bin's floor and walls
        among them) are coal geometry from :func:`grasplan.cell.shapes.obstacle_geometry`, built once
        per collider. Prefilter: each shape's world oriented bounding box against each obstacle's
        world axis-aligned box (the NumPy separating-axis test); coal for the overlapping ones (first
        hit decides). Touching counts as a collision."""
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
            for o in range(len(self.obstacles)):
                need[si, o] = ~obb_aabb_separated(Tbb[:, :3, 3], Tbb[:, :3, :3], h, self._obs_center[o],
                                                  self._obs_half[o])
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
    def _part_prefilter(self, T_part_tcp: np.ndarray, sets: list[ShapeSet]
                        ) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
        """``(T_part_geom per set (M, 4, 4), need (S, M), inside_cand (S, M))``: where each shape's
        geometry is, whether its box is not separated from the part's box, and whether its box's
        world-axis box lies within the part's box (a closed part only: it might lie inside)."""
        M = len(T_part_tcp)
        Tgs = []
        need = np.zeros((len(sets), M), dtype=bool)
        inside_cand = np.zeros((len(sets), M), dtype=bool)
        for si, s in enumerate(sets):
            Tbb = T_part_tcp @ s.T_tcp_bb[s.index]
            h = s.half_bb[s.index]
            if self.prepass:  # the same two tests compiled, in one pass
                need[si], within = prefilter(Tbb, h, self.aabb_center, self.aabb_half)
                if self.watertight:
                    inside_cand[si] = within
            else:
                need[si] = ~obb_aabb_separated(Tbb[:, :3, 3], Tbb[:, :3, :3], h, self.aabb_center, self.aabb_half)
                if self.watertight:
                    # bounding box of the shape's box wholly within the part's box: might be inside the part
                    ext = np.einsum("mij,mj->mi", np.abs(Tbb[:, :3, :3]), h)
                    inside_cand[si] = np.all(np.abs(Tbb[:, :3, 3] - self.aabb_center) + ext <= self.aabb_half, axis=1)
            Tgs.append(Tbb if s.is_box else T_part_tcp)  # a box's bounding box is the box
        return Tgs, need, inside_cand

    def _inside(self, pts: np.ndarray) -> np.ndarray:
        """(k,) bool: the points (k, 3) inside the closed part (ray crossings, compiled with ``prepass``)."""
        if self.prepass:
            return points_inside_compiled(self.ray_grid, self.part_mesh, pts)
        return points_inside_tree(self.ray_grid, self.part_mesh, pts)

    def _prepass(self, s: ShapeSet, T_geom: np.ndarray, T_part_tcp: np.ndarray, todo: np.ndarray,
                 half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(hit poses, poses for coal)`` of ``todo`` for the shape set ``s`` (geometry at ``T_geom``,
        per-variant half extents ``half`` of a box set), by :meth:`PartBoxes.classify`."""
        t0 = time.perf_counter()
        if s.is_box:
            code = self.part_boxes.classify(T_geom[todo], half[s.index[todo]], prove_hit=True, tol=SAMPLE_DEPTH)
        else:  # the shape's local bounding box holds it: apart proofs only
            code = self.part_boxes.classify(T_part_tcp[todo] @ s.T_tcp_bb[s.index[todo]], s.half_bb[s.index[todo]],
                                            prove_hit=False, tol=SAMPLE_DEPTH)
        sure, unsure = todo[code == HIT], todo[code == UNSURE]
        self.prepass_counts["hit"] += len(sure)
        self.certified["sample"] += len(sure)
        self.prepass_counts["unsure"] += len(unsure)
        self.prepass_counts["apart"] += len(todo) - len(sure) - len(unsure)
        self.timing["part_boxes"] += time.perf_counter() - t0
        return sure, unsure

    def _coal_part(self, s: ShapeSet, T_geom: np.ndarray, todo: np.ndarray) -> np.ndarray:
        """The poses of ``todo`` at which coal finds the shape set ``s`` (geometry at ``T_geom``)
        colliding with the part."""
        t0 = time.perf_counter()
        collide, req, res, tf, I = coal.collide, self.request, self.result, self._tf, self._identity
        hl = []
        for m in todo:
            T = T_geom[m]
            tf.setRotation(T[:3, :3])
            tf.setTranslation(T[:3, 3])
            res.clear()
            if collide(s.geoms[s.index[m]], tf, self.part_bvh, I, req, res):
                hl.append(m)
        self.coal_calls += len(todo)
        self.timing["part_coal"] += time.perf_counter() - t0
        return np.asarray(hl, dtype=np.int64)

    def _part_hits(self, T_part_tcp: np.ndarray, sets: list[ShapeSet]) -> tuple[np.ndarray, np.ndarray]:
        """``(hit (M,) bool, first hitting element (M,) int, -1 when free)``."""
        M = len(T_part_tcp)
        elem = np.full(M, -1, dtype=np.int64)
        hit = np.zeros(M, dtype=bool)
        Tgs, need, inside_cand = self._part_prefilter(T_part_tcp, sets)
        # in blocks of poses, per shape: shapes that hit most often so far are tried first (jaws
        # first to begin with); the first shape that hits decides the pose. On a closed part a box
        # whose centre is inside it hits it (it crosses the surface or lies inside): that exact
        # ray-crossing test runs before coal while it finds enough hits to pay for itself.
        order = list(range(len(sets)))[::-1]
        first_hits = np.zeros(len(sets), dtype=np.int64)
        centre_rate = np.ones(len(sets))
        sample_rate = np.ones(len(sets))
        # half extents per variant of the box shapes (no box certificate for mesh shapes)
        half = [s.half_bb if s.is_box else np.zeros((0, 3)) for s in sets]
        for b0 in range(0, M, self.block):
            blk = np.arange(b0, min(M, b0 + self.block))
            for si in order:
                s = sets[si]
                todo = blk[need[si, blk] & ~hit[blk]]
                if len(todo) == 0:
                    continue
                if self.watertight and s.is_box and centre_rate[si] >= 0.2:
                    cand = todo[inside_box(Tgs[si][todo, :3, 3], self.aabb_center, self.aabb_half)]
                    ins = cand[self._inside(Tgs[si][cand, :3, 3])]
                    centre_rate[si] = 0.5 * centre_rate[si] + 0.5 * len(ins) / max(len(todo), 1)
                    self.certified["centre"] += len(ins)
                    hit[ins] = True
                    elem[ins] = si
                    first_hits[si] += len(ins)
                    todo = todo[~hit[todo]]
                if s.is_box and sample_rate[si] >= 0.1 and len(todo) and not self.prepass:
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
                sure = np.zeros(0, dtype=np.int64)
                if self.prepass and len(todo):
                    sure, todo = self._prepass(s, Tgs[si], T_part_tcp, todo, half[si])
                hits = np.concatenate([sure, self._coal_part(s, Tgs[si], todo)])
                hit[hits] = True
                elem[hits] = si
                first_hits[si] += len(hits)
            order = sorted(order, key=lambda i: -first_hits[i])
        self._inside_hits(sets, Tgs, inside_cand, hit, elem)
        return hit, elem

    def _inside_hits(self, sets: list[ShapeSet], Tgs: list[np.ndarray], inside_cand: np.ndarray, hit: np.ndarray,
                     elem: np.ndarray) -> None:
        """A shape crossing no triangle may still lie wholly inside a closed part: the poses not hit
        yet whose shape (a candidate by ``inside_cand``) has a point inside the part are hit (``hit``,
        ``elem`` updated in place; the first such shape in element order names the pose)."""
        cand = [np.flatnonzero(inside_cand[si] & ~hit) for si in range(len(sets))]
        if sum(len(c) for c in cand):
            # one point per shape: a box's centre, a mesh's first vertex
            pts = np.concatenate([Tgs[si][c, :3, 3] if sets[si].is_box else
                                  np.array([sets[si].variants[sets[si].index[m]].vertices[0] @ Tgs[si][m][:3, :3].T
                                            + Tgs[si][m][:3, 3] for m in c]).reshape(-1, 3)
                                  for si, c in enumerate(cand)])
            inside = self._inside(pts)
            k0 = 0
            for si, c in enumerate(cand):  # the first shape (in element order) inside names the pose
                ins = c[inside[k0:k0 + len(c)]]
                k0 += len(c)
                new = ins[~hit[ins]]
                hit[new] = True
                elem[new] = si

    def check(self, T_part_tcp: np.ndarray, width: np.ndarray) -> np.ndarray:
        """Status per pose: (M,) array of :class:`~grasplan.status.Status` values (str).

        T_part_tcp : (M, 4, 4) TCP poses in the part frame; width : (M,) contact distance (m)."""
        return self.check_detail(T_part_tcp, width)[0]

    def check_detail(self, T_part_tcp: np.ndarray, width: np.ndarray, *, part_free: bool = False
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(status (M,) str, element (M,) int, body (M,) int)``: the status per pose, the gripper
        element that decided it (index into :meth:`element_names`: ``body_<k>``, ``finger_left``,
        ``finger_right``) and the body it hit (index into :meth:`body_names`: ``part``, ``table``,
        ``obstacle:<name>``); -1 for ``ok``.

        Status: ``collision_part`` when any shape hits the part (checked first, whatever the table),
        else ``collision_table`` when any shape is below the table top (:meth:`_table_hits`), else
        ``collision_obstacle`` when any shape hits an obstacle (:meth:`_obstacle_hits`), else ``ok``.
        So ``collision_part`` is a property of the grasp alone, independent of the cell.

        The part (:meth:`_part_hits`): coal (``coal.BVHModelOBBRSS`` of the part mesh, built once per
        collider; ``coal.Box`` for boxes). Touching counts as a collision (coal's ``distance <= 0``
        within its GJK tolerance, ~1e-6 m). A shape whose oriented box is separated from the part's
        axis-aligned box (exact 15-axis separating-axis test in NumPy) is free without calling coal.
        coal tests surfaces: a shape that crosses no triangle is also tested for lying wholly inside a
        watertight part (one of its points, :func:`grasplan.geometry.containment.points_inside_tree`:
        signed ray crossings, the winding number of a closed mesh, exact; near-ties by the generalised
        winding number). Exact certificates decide box-part hits before coal: a box whose centre is
        inside a watertight part hits it (NumPy, while it keeps finding hits); then, with ``prepass``
        (the default), the compiled pre-pass (:class:`grasplan.grasps.collision_boxes.PartBoxes`)
        decides each remaining (shape, pose) pair against the part's triangles: apart (every triangle
        more than ``SAMPLE_DEPTH`` away along a separating axis), hit (a point of a triangle deeper
        than ``SAMPLE_DEPTH`` inside a box) or unsure, and coal runs on the unsure ones alone. Without
        ``prepass``, a box containing a sample of the part's surface
        (:func:`grasplan.geometry.containment.surface_samples`: convex combinations of a triangle's
        corners) deeper than ``SAMPLE_DEPTH`` hits it (while it keeps finding hits) and coal decides
        the rest. Both give the same statuses. Shapes are tried in blocks of poses, those that hit
        most often first; the first hit names the pose's element.

        ``part_free``: the poses are known to be free of the part (a grasp database's, checked in
        the part frame once, :mod:`grasplan.grasps.graspdb`): only the table and the obstacles are
        checked."""
        T_part_tcp = check_transform(T_part_tcp, "T_part_tcp", batch=True, error=ValueError)
        width = np.asarray(width, dtype=np.float64).reshape(-1)
        if width.shape != (len(T_part_tcp),):
            raise ValueError(f"width must have shape ({len(T_part_tcp)},), got {width.shape}")
        M = len(width)
        status = np.full(M, Status.OK.value, dtype="<U18")
        elem = np.full(M, -1, dtype=np.int64)
        body = np.full(M, -1, dtype=np.int64)
        if M == 0:
            return status, elem, body
        if self.gripper.moving_tcp:  # the shapes are given at max_opening: place them for each width
            T_part_tcp = T_part_tcp @ self.gripper.T_tcp_gripper(width)
        t0 = time.perf_counter()
        sets = self.shape_sets(width)
        self.timing["shapes"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        if part_free:
            part, e_part = np.zeros(M, dtype=bool), np.full(M, -1, dtype=np.int64)
        else:
            part, e_part = self._part_hits(T_part_tcp, sets)
        t1 = time.perf_counter()
        table, e_table = self._table_hits(T_part_tcp, sets, ~part)  # a part hit decides the pose
        t2 = time.perf_counter()
        obst, e_obst, which = self._obstacle_hits(T_part_tcp, sets, ~(part | table))
        self.timing["part"] += t1 - t0
        self.timing["table"] += t2 - t1
        self.timing["obstacle"] += time.perf_counter() - t2
        status[obst], elem[obst], body[obst] = Status.COLLISION_OBSTACLE.value, e_obst[obst], 2 + which[obst]
        status[table], elem[table], body[table] = Status.COLLISION_TABLE.value, e_table[table], 1
        status[part], elem[part], body[part] = Status.COLLISION_PART.value, e_part[part], 0
        return status, elem, body

    def timing_s(self) -> dict[str, float]:
        """:attr:`timing` under the keys of a plan's ``timing_s``: ``collision_<key>``."""
        return {f"collision_{k}": v for k, v in self.timing.items()}

    def reasons(self, status: np.ndarray, element: np.ndarray, body: np.ndarray) -> np.ndarray:
        """(M,) object array of grasp-stage reasons from :meth:`check_detail` ("" for ``ok``)."""
        return hit_reasons(status, element, body, self.element_names(), self.body_names())

    def part_collision(self, T_part_tcp: np.ndarray, width: np.ndarray) -> np.ndarray:
        """(M,) bool: any shape hits the part (no table check)."""
        T_part_tcp = check_transform(T_part_tcp, "T_part_tcp", batch=True, error=ValueError)
        width = np.asarray(width, dtype=np.float64).reshape(-1)
        if self.gripper.moving_tcp:
            T_part_tcp = T_part_tcp @ self.gripper.T_tcp_gripper(width)
        return self._part_hits(T_part_tcp, self.shape_sets(width))[0]


def hit_reasons(status: np.ndarray, element: np.ndarray, body: np.ndarray, element_names: list[str],
                body_names: list[str]) -> np.ndarray:
    """(M,) object array: "grasp stage: gripper:<element> hits <body> at the grasp or while
    closing" for rejected poses, "" for ``ok`` ones (vectorised over the distinct codes)."""
    status = np.asarray(status).astype(str)
    element = np.asarray(element, dtype=np.int64)
    body = np.asarray(body, dtype=np.int64)
    out = np.full(len(status), "", dtype=object)
    bad = np.flatnonzero(status != Status.OK.value)
    if len(bad) == 0:
        return out
    # the distinct (element, body) pairs in lexicographic order, as one integer key each
    e, b = element[bad] + 1, body[bad] + 1
    span = int(b.max()) + 1
    keys, inv = np.unique(e * span + b, return_inverse=True)
    codes = np.stack([keys // span - 1, keys % span - 1], axis=1)
    texts = np.array([
        f"grasp stage: gripper:{element_names[e] if 0 <= e < len(element_names) else '?'} hits "
        f"{body_names[b] if 0 <= b < len(body_names) else '?'} at the grasp or while closing"
        for e, b in codes], dtype=object)
    out[bad] = texts[inv.reshape(-1)]
    return out


def check_grasps(
    part_mesh: PartMesh,
    gripper: Gripper,
    cell: Cell,
    T_world_part: np.ndarray,
    T_part_tcp: np.ndarray,
    width: np.ndarray,
) -> np.ndarray:
    """Status per pose ``(M,)`` str: the :class:`~grasplan.status.Status` values ``ok``, ``collision_part``,
    ``collision_table`` or ``collision_obstacle`` (:data:`grasplan.status.GRASP_STATUSES`).

    Builds a :class:`GripperCollider` (the part BVH) and checks the ``(M, 4, 4)`` poses; keep a
    collider yourself to check several batches against the same part."""
    return GripperCollider(part_mesh, gripper, cell, T_world_part).check(T_part_tcp, width)
