"""The pile as collision geometry for the gripper: every instance's mesh, the cell (table, bin,
obstacles) and the cloud's octree, and the vectorised gripper check of many world TCP poses.

:class:`PickWorld` is built once per (gripper, cell) and keeps each part's coal BVH; a new scene
only moves instances (their world boxes and coal transforms), so planning the next cycle reloads
nothing. :meth:`PickWorld.gripper_hits` checks the gripper of each pose (its body shapes and each
jaw swept from the pre-grasp opening to the contacts, as in ``grasplan plan``:
:meth:`grasplan.grasps.collision.GripperCollider.shape_sets`) against every body but the instance being
grasped (the part-alone grasp set already checked that one): first an exact NumPy
separating-axis test of each shape's oriented box against each body's world box, then coal for
the overlapping pairs (a neighbour's pairs first through the compiled box pre-pass of its
triangles, :meth:`grasplan.grasps.collision_boxes.PartBoxes.classify`: only the pairs it cannot
decide reach coal), the bodies in the order neighbours, cloud, obstacles, table, so that the first
body a pose hits names what blocks it.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import coal
import numpy as np

from ..cell.model import Cell
from ..grasps.collision import SAMPLE_DEPTH, GripperCollider
from ..grasps.collision_boxes import APART, HIT, PartBoxes
from ..grasps.collision_shapes import ShapeSet
from ..geometry.containment import obb_aabb_separated
from ..cell.shapes import TABLE_SIZE, bvh, convex_geometry, local_box, obstacle_geometry, shape_geometry, table_pose
from ..gripper.model import Box, Gripper
from ..part.mesh import Part
from ..motion.collision_scene import ATTACHED_CONTACT_TOL, TABLE
from ..piles.scene_file import Instance
from .gripboxes import SweptGripper, sweep

#: body name prefixes in reports
INSTANCE_PREFIX = "instance:"
CLOUD = "cloud"
#: a gripper box overlapping a box body by this much (m) along every separating axis hits it
CERTAIN_OVERLAP = 1e-6


@dataclass(frozen=True, eq=False)
class Body:
    """One collision body of the world: ``name`` (``instance:<id>``, ``cloud``, ``obstacle:<name>``,
    ``table``), coal geometry and transform, world axis-aligned box (centre, half extents)."""

    name: str
    geometry: coal.CollisionGeometry
    tf: coal.Transform3s
    center: np.ndarray
    half: np.ndarray
    convex: coal.CollisionGeometry | None = None  #: a convex shape holding the body (an instance's hull), or None
    box: bool = False  #: the geometry is a coal Box that is exactly the world box (axis-aligned)
    #: an instance's triangles in the compiled box hierarchy (:class:`grasplan.grasps.collision_boxes.PartBoxes`,
    #: part frame) and ``T_part_world``: the gripper's pairs are decided on boxes before coal; None: coal only
    part_boxes: PartBoxes | None = None
    T_body_world: np.ndarray | None = None


def _tf(T: np.ndarray) -> coal.Transform3s:
    T = np.asarray(T, dtype=np.float64)
    return coal.Transform3s(T[:3, :3].copy(), T[:3, 3].copy())


def world_box(vertices: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(centre (3,), half extents (3,))`` of the world axis-aligned box of ``vertices`` (V, 3) at ``T``."""
    w = vertices @ T[:3, :3].T + T[:3, 3]
    lo, hi = w.min(axis=0), w.max(axis=0)
    return 0.5 * (lo + hi), 0.5 * (hi - lo)


@dataclass(frozen=True, eq=False)
class PartGeometry:
    """A part's collision geometry, built once: coal BVH, hull vertices for world boxes, and the
    gripper collider whose shape sets the checks use."""

    part: Part
    bvh: coal.BVHModelOBBRSS
    hull: np.ndarray
    collider: GripperCollider
    convex: coal.CollisionGeometry  #: the hull as a coal convex shape: apart from it is apart from the mesh


class PickWorld:
    """Gripper checks against a pile (see the module docstring)."""

    def __init__(self, gripper: Gripper, cell: Cell):
        self.gripper, self.cell = gripper, cell
        self.parts: dict[str, PartGeometry] = {}
        self.cloud: Body | None = None
        T_table = table_pose(cell.table_z)
        half = 0.5 * np.asarray(TABLE_SIZE)
        self.cell_bodies: list[Body] = []
        #: the cell as the robot scene's carried part meets it (:meth:`grasplan.motion.collision_scene.CollisionScene.attached`):
        #: obstacles and table shrunk by ATTACHED_CONTACT_TOL (their world boxes: the unshrunk ones)
        self.cell_shrunk: list[Body] = []
        for o in cell.obstacles:
            lo, hi = o.aabb()
            geom = obstacle_geometry(o)
            exact = isinstance(geom, coal.Box) and np.allclose(  # its world box is the box itself
                np.sort(hi - lo), np.sort(2.0 * np.asarray(geom.halfSide)), rtol=0.0, atol=1e-12)
            self.cell_bodies.append(Body(o.body, geom, _tf(o.T_world_obstacle), 0.5 * (lo + hi), 0.5 * (hi - lo),
                                         box=bool(exact)))
            low = obstacle_geometry(o, shrink=ATTACHED_CONTACT_TOL)
            self.cell_shrunk.append(Body(o.body, low, _tf(o.T_world_obstacle), 0.5 * (lo + hi), 0.5 * (hi - lo),
                                         low if isinstance(low, (coal.Box, coal.Cylinder, coal.Sphere)) else None))
        self.cell_bodies.append(Body(TABLE, coal.Box(*TABLE_SIZE), _tf(T_table), T_table[:3, 3].copy(), half, box=True))
        T_low = table_pose(cell.table_z, ATTACHED_CONTACT_TOL)
        low = coal.Box(*TABLE_SIZE)
        self.cell_shrunk.append(Body(TABLE, low, _tf(T_low), T_table[:3, 3].copy(), half, low))
        self.instances: dict[str, Body] = {}
        self.request = coal.CollisionRequest()
        self.request.enable_contact = True  # see grasplan.grasps.collision: contacts on for shallow hits
        self.request.num_max_contacts = 1
        self.result = coal.CollisionResult()
        self.hull_request, self.hull_result = coal.CollisionRequest(), coal.CollisionResult()
        self.coal_calls = 0
        self._closed: dict[float, list] = {}  # gripper shapes per jaw opening (the last few asked)
        self._boxes: dict[tuple[float, ...], tuple] = {}  # a box shape's coal geometry and local box, per size

    # -- contents -----------------------------------------------------------------------------------
    def add_part(self, name: str, part: Part) -> PartGeometry:
        from ..geometry.meshdata import convex_hull

        mesh = part.mesh
        hull = np.asarray(convex_hull(np.asarray(mesh.vertices)).vertices, dtype=np.float64)
        g = PartGeometry(part=part, bvh=bvh(mesh.vertices, mesh.faces), hull=hull,
                         collider=GripperCollider(mesh, self.gripper, self.cell, np.eye(4)),
                         convex=convex_geometry(hull))
        self.parts[name] = g
        return g

    def set_cloud(self, octree: coal.OcTree | None, points: np.ndarray | None = None, resolution: float = 0.0) -> None:
        """The cloud's octree (world frame) and the points it was built from (for its box), or None."""
        if octree is None or points is None:
            self.cloud = None
            return
        lo, hi = points.min(axis=0) - resolution, points.max(axis=0) + resolution
        self.cloud = Body(CLOUD, octree, coal.Transform3s(), 0.5 * (lo + hi), 0.5 * (hi - lo))

    def set_instances(self, instances: Sequence[Instance]) -> None:
        """Place the scene's instances (their parts must have been added)."""
        out: dict[str, Body] = {}
        for inst in instances:
            g = self.parts[inst.part]
            c, h = world_box(g.hull, inst.T_world_part)
            out[inst.id] = Body(INSTANCE_PREFIX + inst.id, g.bvh, _tf(inst.T_world_part), c, h, g.convex,
                                part_boxes=g.collider.part_boxes,
                                T_body_world=np.linalg.inv(np.asarray(inst.T_world_part, dtype=np.float64)))
        self.instances = out

    def bodies(self, target: str | None) -> list[Body]:
        """Every body but instance ``target``: neighbours (scene order), cloud, obstacles, table."""
        out = [b for i, b in self.instances.items() if i != target]
        if self.cloud is not None:
            out.append(self.cloud)
        return out + self.cell_bodies

    # -- the check ----------------------------------------------------------------------------------
    def gripper_hits(self, part: str, target: str | None, T_world_tcp: np.ndarray, width: np.ndarray,
                     bodies: list[Body] | None = None) -> tuple[np.ndarray, list[Body]]:
        """``(first body hit (M,) int64 index into the returned bodies, -1 = free; bodies)`` for the
        gripper at the world TCP poses ``T_world_tcp`` (M, 4, 4) closing to contact ``width`` (M,)."""
        bodies = self.bodies(target) if bodies is None else bodies
        T_world_tcp = np.asarray(T_world_tcp, dtype=np.float64).reshape(-1, 4, 4)
        M = len(T_world_tcp)
        first = np.full(M, -1, dtype=np.int64)
        if M == 0 or not bodies:
            return first, bodies
        sets = self.parts[part].collider.shape_sets(np.asarray(width, dtype=np.float64).reshape(-1))
        need = np.zeros((len(bodies), len(sets), M), dtype=bool)
        # a box shape overlapping an axis-aligned box body even with both shrunk by CERTAIN_OVERLAP
        # hits it (the separating-axis test is exact for two boxes): no coal call; touching ones go to coal
        hit = np.zeros((len(bodies), len(sets), M), dtype=bool)
        boxes = np.array([b.box for b in bodies], dtype=bool)
        Tgs = []
        # distance of each TCP to each body's box, against each shape's reach from the TCP (a
        # bounding sphere): only the poses within reach get the exact box test
        tcp = T_world_tcp[:, :3, 3]
        centres = np.array([b.center for b in bodies], dtype=np.float64)
        halves = np.array([b.half for b in bodies], dtype=np.float64)
        gap = np.linalg.norm(np.maximum(np.abs(tcp[None] - centres[:, None]) - halves[:, None], 0.0), axis=2)  # (B, M)
        for si, s in enumerate(sets):
            reach = float(np.max(np.linalg.norm(s.T_tcp_bb[:, :3, 3], axis=1) + np.linalg.norm(s.half_bb, axis=1)))
            Tbb = T_world_tcp @ s.T_tcp_bb[s.index]
            h = s.half_bb[s.index]
            bi_, m_ = np.nonzero(gap <= reach)  # every (body, pose) within reach in one separating-axis test
            if len(m_):
                need[bi_, si, m_] = ~obb_aabb_separated(Tbb[m_, :3, 3], Tbb[m_, :3, :3], h[m_], centres[bi_],
                                                        halves[bi_])
                if s.is_box:
                    k = np.flatnonzero(boxes[bi_] & need[bi_, si, m_])
                    mk, bk = m_[k], bi_[k]
                    hit[bk, si, mk] = ~obb_aabb_separated(Tbb[mk, :3, 3], Tbb[mk, :3, :3],
                                                          np.maximum(h[mk] - CERTAIN_OVERLAP, 0.0), centres[bk],
                                                          np.maximum(halves[bk] - CERTAIN_OVERLAP, 0.0))
            Tgs.append(T_world_tcp @ s.T_tcp_geom[s.index] if s.is_box else T_world_tcp)
            self._prepass(bodies, s, si, Tgs[-1] if s.is_box else Tbb, h, need, hit)
        collide, req, res = coal.collide, self.request, self.result
        tf = coal.Transform3s()
        calls = 0
        # candidate (pose, body, shape) triples in checking order: pose, then body order, jaws first
        m_i, b_i, s_i = np.nonzero(np.transpose(need, (2, 0, 1))[:, :, ::-1])
        s_i = len(sets) - 1 - s_i
        geoms = [[s.geoms[k] for k in s.index] for s in sets]
        done = -1
        for m, bi, si in zip(m_i.tolist(), b_i.tolist(), s_i.tolist()):
            if m == done:
                continue
            if hit[bi, si, m]:
                first[m] = bi
                done = m
                continue
            T = Tgs[si][m]
            tf.setRotation(T[:3, :3])
            tf.setTranslation(T[:3, 3])
            res.clear()
            calls += 1
            b = bodies[bi]
            if collide(geoms[si][m], tf, b.geometry, b.tf, req, res):
                first[m] = bi
                done = m
        self.coal_calls += calls
        return first, bodies

    def _prepass(self, bodies: list[Body], s: ShapeSet, si: int, T_world_box: np.ndarray, half: np.ndarray,
                 need: np.ndarray, hit: np.ndarray) -> None:
        """Decide shape set ``s``'s pairs with the instance bodies on boxes before coal
        (:meth:`grasplan.grasps.collision_boxes.PartBoxes.classify`, as the grasp stage does):
        ``need`` cleared where the shape (a box at ``T_world_box`` (M, 4, 4) with ``half`` (M, 3); a
        mesh shape's bounding box) is apart from the instance's triangles by more than
        :data:`grasplan.grasps.collision.SAMPLE_DEPTH`, ``hit`` set where a point of a triangle lies
        that deep inside a box shape; coal decides the rest."""
        for bi, b in enumerate(bodies):
            if b.part_boxes is None or b.T_body_world is None:
                continue
            m = np.flatnonzero(need[bi, si] & ~hit[bi, si])
            if not len(m):
                continue
            code = b.part_boxes.classify(b.T_body_world @ T_world_box[m], half[m], prove_hit=s.is_box,
                                         tol=SAMPLE_DEPTH)
            need[bi, si, m[code == APART]] = False
            hit[bi, si, m[code == HIT]] = True

    def part_hits(self, part: str, T_world_part: np.ndarray, shifts: np.ndarray, bodies: list[Body],
                  allowed: Callable[[np.ndarray, Body], bool] | None = None, *, first_only: bool = False,
                  far_first: bool = False) -> np.ndarray:
        """First body (index into ``bodies``, -1 none) the part ``part`` hits at ``T_world_part``
        moved by each world vector of ``shifts`` (k, 3) (a straight lift): world boxes first (the
        part's box only translates), then coal; a contact for which ``allowed(T_world_part moved,
        body)`` is true (a shallow one) is no hit. ``first_only``: stop at the first shift hitting
        anything (the later shifts stay -1); with ``far_first`` the shifts are taken from the last
        one back (whether any hits is the same; a part dragged through a neighbour is usually
        deepest at the far end, so that hit is found first). A pair whose convex hulls are apart
        (coal's GJK on :attr:`PartGeometry.convex`) is apart without the mesh test."""
        g = self.parts[part]
        T = np.asarray(T_world_part, dtype=np.float64)
        shifts = np.asarray(shifts, dtype=np.float64).reshape(-1, 3)
        first = np.full(len(shifts), -1, dtype=np.int64)
        if not bodies or not len(shifts):
            return first
        c0, h = world_box(g.hull, T)
        centres = c0 + shifts
        bc = np.array([b.center for b in bodies])
        bh = np.array([b.half for b in bodies])
        near = np.all(np.abs(centres[:, None, :] - bc[None]) <= h + bh[None], axis=2)  # (k, bodies)
        req, res = self.request, self.result
        hreq, hres = self.hull_request, self.hull_result
        tf = coal.Transform3s(T[:3, :3].copy(), T[:3, 3].copy())
        ks, bis = np.nonzero(near)
        if far_first:
            ks, bis = ks[::-1], bis[::-1]
        for k, bi in zip(ks, bis):
            if first[k] >= 0:
                continue
            tf.setTranslation(T[:3, 3] + shifts[k])
            b = bodies[bi]
            if b.convex is not None:  # the two hulls apart (GJK, microseconds): the meshes are apart
                hres.clear()
                if not coal.collide(g.convex, tf, b.convex, b.tf, hreq, hres):
                    continue
            res.clear()
            self.coal_calls += 1
            if coal.collide(g.bvh, tf, b.geometry, b.tf, req, res):
                if allowed is not None:
                    Tk = T.copy()
                    Tk[:3, 3] += shifts[k]
                    if allowed(Tk, b):
                        continue
                first[k] = bi
                if first_only:
                    break
        return first

    def clear_of_cell(self, part: str, T_world_part: np.ndarray, travel: np.ndarray, direction: np.ndarray
                      ) -> np.ndarray:
        """Per lift ``travel`` (k,) m along ``direction`` (3,): the part at ``T_world_part`` moved that
        far touches none of :attr:`cell_shrunk` (the table and obstacles as the robot scene's carried
        part meets them), so the robot scene's lift need not check those pairs there."""
        shifts = np.asarray(travel, dtype=np.float64)[:, None] * np.asarray(direction, dtype=np.float64)
        return self.part_hits(part, T_world_part, shifts, self.cell_shrunk) < 0

    def _shapes(self, opening: float) -> list[tuple[coal.CollisionGeometry, np.ndarray, np.ndarray, np.ndarray]]:
        """The gripper's shapes with the jaws at ``opening``: ``(coal geometry, T_tcp_geom, local
        box centre, half extents)``, cached for the last few openings."""
        key = round(float(opening), 12)
        shapes = self._closed.get(key)
        if shapes is None:
            shapes = []
            for shape in (*self.gripper.body, *self.gripper.fingers(opening)):
                if isinstance(shape, Box):  # its coal geometry and local box depend on its size alone
                    size = tuple(np.asarray(shape.extents, dtype=np.float64).tolist())
                    made = self._boxes.get(size)
                    if made is None:
                        if len(self._boxes) >= 16:  # a gripper has a few box sizes: bounded all the same
                            self._boxes.clear()
                        geom = shape_geometry(shape)[0]
                        made = self._boxes[size] = (geom, *local_box(geom))
                    shapes.append((made[0], np.asarray(shape.T_tcp_box, dtype=np.float64), made[1], made[2]))
                else:
                    geom, T_tcp_geom = shape_geometry(shape)
                    c_loc, h_loc = local_box(geom)
                    shapes.append((geom, np.asarray(T_tcp_geom, dtype=np.float64), c_loc, h_loc))
            if len(self._closed) >= 4:
                self._closed.clear()
            self._closed[key] = shapes
        return shapes

    def _box_apart(self, R: np.ndarray, centre: np.ndarray, half: np.ndarray, bodies: list[Body],
                   which: np.ndarray, stop: bool = False) -> np.ndarray:
        """Per body index of ``which``: coal finds the oriented box (axes ``R`` (3, 3), ``centre``,
        ``half`` extents) apart from that body; with ``stop``, the check ends at the first body it
        touches (the later ones stay False)."""
        out = np.zeros(len(which), dtype=bool)
        if not len(which):
            return out
        tf = coal.Transform3s()
        tf.setRotation(R)
        tf.setTranslation(centre)
        box, req, res = coal.Box(*(2.0 * np.asarray(half))), self.hull_request, self.hull_result
        for i, bi in enumerate(which.tolist()):
            b = bodies[bi]
            res.clear()
            self.coal_calls += 1
            out[i] = not coal.collide(box, tf, b.geometry, b.tf, req, res)
            if stop and not out[i]:
                break
        return out

    def gripper_swept_free(self, T_a: np.ndarray, T_b: np.ndarray, opening: float, pad: float,
                           bodies: list[Body] | None = None) -> SweptGripper | None:
        """The gripper with its jaws at ``opening`` moved straight from the TCP pose ``T_a`` to
        ``T_b`` (same orientation): per shape, its local box swept from one to the other and
        grown by ``pad`` (m), when every such box is apart from every body of ``bodies`` (default:
        every body, the grasped part's included; world boxes, the separating-axis test, then coal
        for a body that is no box); else None (a box touches a body: nothing is known)."""
        bodies = self.bodies(None) if bodies is None else bodies
        T2 = np.stack([np.asarray(T_a, dtype=np.float64), np.asarray(T_b, dtype=np.float64)])
        bc = np.array([b.center for b in bodies]).reshape(-1, 3)
        bh = np.array([b.half for b in bodies]).reshape(-1, 3)
        box = np.array([b.box for b in bodies], dtype=bool)
        out = []
        for _, T_tcp_geom, c_loc, h_loc in self._shapes(opening):
            _, _, _, status, R, cs, hs = sweep(T2, T_tcp_geom, c_loc, h_loc, bc, bh, box, pad)
            if np.any(status == 2) or not np.any(hs):  # a box body overlaps, or no sweep (turning)
                return None
            if not self._box_apart(R, cs, hs, bodies, np.flatnonzero(status == 1), stop=True).all():
                return None
            out.append((T_tcp_geom, c_loc, h_loc, R, cs, hs))
        return SweptGripper(*(np.ascontiguousarray(np.array([o[i] for o in out], dtype=np.float64)) for i in range(6)))

    def gripper_at_hits(self, T_world_tcp: np.ndarray, opening: float, bodies: list[Body]) -> np.ndarray:
        """First body (index into ``bodies``, -1 none) the gripper hits at each world TCP pose
        (k, 4, 4) with its jaws at ``opening`` (m; not swept): body shapes and both jaws, world boxes
        first (each shape's local box), then coal. The robot scene checks the same shapes at the
        same poses, so a hit here is a hit there.

        Poses that share one orientation (a straight lift) are first checked together, per shape
        and body (:func:`grasplan.pick.gripboxes.sweep`): the oriented box holding that shape's box
        at every pose against the body (the separating-axis test on the body's world box, then
        coal for a body that is no box); where it is apart, that body is apart from the shape at
        every pose and needs no per-pose call."""
        T_all = np.asarray(T_world_tcp, dtype=np.float64).reshape(-1, 4, 4)
        first = np.full(len(T_all), -1, dtype=np.int64)
        if not bodies or not len(T_all):
            return first
        shapes = self._shapes(opening)
        bc = np.array([b.center for b in bodies])
        bh = np.array([b.half for b in bodies])
        box = np.array([b.box for b in bodies], dtype=bool)
        req, res = self.request, self.result
        tf = coal.Transform3s()
        for geom, T_tcp_geom, c_loc, h_loc in shapes:
            Tg, ks, bis, status, R, cs, hs = sweep(T_all, T_tcp_geom, c_loc, h_loc, bc, bh, box)
            check = np.flatnonzero(status == 1)
            if len(check):  # bodies overlapping the swept box that are no box: coal decides
                status[check[self._box_apart(R, cs, hs, bodies, check)]] = 0
                keep = status[bis] != 0
                ks, bis = ks[keep], bis[keep]
            for k, bi in zip(ks.tolist(), bis.tolist()):
                if first[k] >= 0:
                    continue
                tf.setRotation(Tg[k, :3, :3])
                tf.setTranslation(Tg[k, :3, 3])
                res.clear()
                self.coal_calls += 1
                b = bodies[bi]
                if coal.collide(geom, tf, b.geometry, b.tf, req, res):
                    first[k] = bi
        return first

