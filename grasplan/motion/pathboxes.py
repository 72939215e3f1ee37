"""Oriented boxes in front of coal: which pairs of a collision scene can collide at a
configuration, decided for many configurations in one compiled pass (:func:`scene_open`, for
:meth:`grasplan.motion.collision_scene.CollisionScene.configs_free`, and through it ``is_free`` and
``path_free``; the pick's lift, :func:`grasplan.motion.lift_check.lift_collision`).

coal reports a collision of two geometries only where they overlap or come within the security
margin, and every geometry lies inside its local bounding box (coal's ``aabb_local``) placed by its
joint: a pair whose two oriented boxes lie more than the margin apart cannot collide. A box that
overlaps the part's box is tested against the part's triangles (their box hierarchy,
:class:`grasplan.grasps.collision_boxes.PartBoxes`): apart from every triangle by more than the
margin and :data:`~grasplan.grasps.collision_boxes.PREPASS_TOL`, it cannot touch the mesh. Along a
path, ranges of consecutive configurations are decided at once, each box grown by the farthest its
points can move within the range (:func:`_open_pairs`, :func:`_growth`): a transit from home
(200-300 configurations at 0.01 rad) places the boxes about 30 times instead of once per configuration.
"""
from __future__ import annotations

import functools
import math
import weakref
from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from ..cell.shapes import local_box
from ..compiled.jit import kernel
from ..grasps.collision_boxes import APART, PREPASS_TOL, PartBoxes, box_vs_tree


#: the boxes must lie this much (m) beyond the security margin apart: float rounding of the box
#: arithmetic (~1e-15 m) and coal's own tolerances are far below it
SLACK = 1e-7

_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


class PathBoxes:
    """The chain and the boxes of one collision model (a ``pin.Model`` and its
    ``pin.GeometryModel``), built once: per joint its parent, placement, kind and axis; per
    geometry its joint and local box. ``ok`` is False for a model with a joint other than
    revolute or prismatic (then nothing is ever cleared)."""

    def __init__(self, model: pin.Model, gm: pin.GeometryModel, pairs: Any = (),
                 part: tuple[Sequence[int], PartBoxes] | None = None):
        J = int(model.njoints)
        self.parent = np.array([max(int(p), 0) for p in model.parents], dtype=np.int64)
        self.R0 = np.zeros((J, 3, 3))
        self.t0 = np.zeros((J, 3))
        self.kind = np.zeros(J, dtype=np.int64)  # 0 universe, 1 revolute, 2 prismatic
        self.axis = np.zeros((J, 3))
        self.iq = np.zeros(J, dtype=np.int64)
        self.ok = True
        for j in range(J):
            M = model.jointPlacements[j]
            self.R0[j], self.t0[j] = M.rotation, M.translation
            if j == 0:
                continue
            jm = model.joints[j]
            name = jm.shortname()
            self.iq[j] = int(model.idx_qs[j])
            if name in ("JointModelRX", "JointModelRY", "JointModelRZ"):
                self.kind[j], self.axis[j] = 1, _AXES[name[-1]]
            elif name in ("JointModelPX", "JointModelPY", "JointModelPZ"):
                self.kind[j], self.axis[j] = 2, _AXES[name[-1]]
            elif name in ("JointModelRevoluteUnaligned", "JointModelPrismaticUnaligned"):
                a = np.asarray(jm.extract().axis, dtype=np.float64)
                self.kind[j], self.axis[j] = (1 if "Revolute" in name else 2), a / np.linalg.norm(a)
            else:
                self.ok = False
        n = len(gm.geometryObjects)
        #: the collision pairs ``pairs`` ((P, 2) geometry ids) of the scene it serves, in its order
        self.pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        #: the geometries' placements now (a variant moves its parts, extras and jaws: it updates those)
        self.placements = np.array([g.placement.homogeneous for g in gm.geometryObjects],
                                   dtype=np.float64).reshape(-1, 4, 4)
        self.joint = np.zeros(n, dtype=np.int64)
        self.center = np.zeros((n, 3))
        self.half = np.zeros((n, 3))
        self.finite = np.ones(n, dtype=bool)
        for k, g in enumerate(gm.geometryObjects):
            c, h = local_box(g.geometry)
            self.joint[k] = int(g.parentJoint)
            fin = bool(np.all(np.isfinite(c)) and np.all(np.isfinite(h)) and np.all(h >= 0.0))
            self.finite[k] = fin
            if fin:
                self.center[k], self.half[k] = c, h
        #: ``part = (geometry ids, tree)``: the geometries of the part's mesh (static, attached) and
        #: its triangles' box hierarchy (:class:`~grasplan.grasps.collision_boxes.PartBoxes`), which
        #: tests the other box of a pair their own boxes leave open; per geometry 0 when it is one of
        #: them, else -1
        self.tree = part[1] if part is not None and len(part[1].tri) else None
        self.tree_of = np.full(n, -1, dtype=np.int64)
        if part is not None and self.tree is not None:
            self.tree_of[list(part[0])] = 0

    @functools.cached_property
    def selected(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """``(used geometry ids, every pair as indices into them, per pair: both boxes finite)`` for
        all the model's pairs, or None when nothing can be cleared (a joint the kernel cannot take).
        A scene's active pairs are a subset: the kernel gets their rows (:func:`scene_open`)."""
        if not self.ok:
            return None
        mask = np.zeros(len(self.joint), dtype=bool)
        fin: np.ndarray = np.all(self.finite[self.pairs], axis=1)
        mask[self.pairs[fin]] = True
        slot = np.cumsum(mask) - 1  # each used geometry's index among the used ones
        return np.flatnonzero(mask), np.ascontiguousarray(np.where(fin[:, None], slot[self.pairs], -1)), fin

    def prepare(self, used: np.ndarray, placements: np.ndarray, margin: float) -> tuple[tuple, float, tuple]:
        """The kernel's arguments, the used geometries (:attr:`selected`) at ``placements``
        ((len(used), 4, 4), each in its joint's frame): ``(those before the pairs, the tolerance,
        those after it)``."""
        P = np.asarray(placements, dtype=np.float64).reshape(-1, 4, 4)
        R_loc = np.array(P[:, :3, :3], order="C")  # a copy: the caller reuses its placements array
        centre = np.ascontiguousarray(self.center[used])
        c_loc = np.ascontiguousarray(P[:, :3, 3] + (R_loc @ centre[:, :, None])[:, :, 0])
        half = np.ascontiguousarray(self.half[used])
        t = self.tree
        tree = _NO_TREE if t is None else (t.tri, t.tri_center, t.tri_half, t.center, t.half, t.child, t.start,
                                           t.count, t.stack_size)
        gjoint = np.ascontiguousarray(self.joint[used])
        return ((self.parent, self.R0, self.t0, self.kind, self.axis, self.iq, gjoint, R_loc, c_loc, half,
                 self.reach(gjoint, c_loc, half)), float(margin) + SLACK,
                (np.ascontiguousarray(self.tree_of[used]), centre, *tree))

    def reach(self, gjoint: np.ndarray, c_loc: np.ndarray, half: np.ndarray) -> np.ndarray:
        """``(G, J)``: per box (on joint ``gjoint[g]``, centre ``c_loc[g]`` in its joint's frame,
        half extents ``half[g]``) and joint, a bound on the distance of any point of the box from
        the joint's axis in every configuration (m; 0 for a joint not on the box's chain, infinite
        when a prismatic joint lies between the two, both included): the box's radius about its
        joint's origin plus the lengths of the joint placements up to that joint
        (:attr:`chain`). A point moves at most ``reach * |dq|`` when that joint turns by ``dq``."""
        radius = np.linalg.norm(c_loc, axis=1) + np.linalg.norm(half, axis=1)
        length, slides = self.chain
        L, S = length[gjoint], slides[gjoint]
        return np.where(S, np.inf, np.where(L >= 0.0, radius[:, None] + L, 0.0))

    @functools.cached_property
    def chain(self) -> tuple[np.ndarray, np.ndarray]:
        """``(length, slides)``, each ``(J, J)``: for joint i = j or an ancestor of j (i >= 1),
        ``length[j, i]`` the summed lengths of the joint placements from i (not counted) down to j
        (counted) and ``slides[j, i]`` whether a prismatic joint lies from i down to j (both
        counted); else -1 and False."""
        J = len(self.parent)
        step = np.linalg.norm(self.t0, axis=1)
        length, slides = np.full((J, J), -1.0), np.zeros((J, J), dtype=bool)
        for j in range(1, J):
            i, acc, prismatic = j, 0.0, False
            while i > 0:
                prismatic = prismatic or self.kind[i] == 2
                length[j, i], slides[j, i] = acc, prismatic
                acc += float(step[i])
                i = int(self.parent[i])
        return length, slides


#: the kernel's tree arguments of a model without a part mesh
_NO_TREE = (np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)),
            np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), 2)


#: a range of at most this many configurations whose grown boxes put no further pair apart is
#: tested configuration by configuration (not split further)
LEAF = 8
#: the deepest range split of :func:`_open_pairs` (2 ** 62 configurations)
MAX_DEPTH = 64


@kernel(cache=True, nogil=True)
def _chain(qs: np.ndarray, k: int, parent: np.ndarray, R0: np.ndarray, t0: np.ndarray, kind: np.ndarray,
           axis: np.ndarray, iq: np.ndarray, oR: np.ndarray, ot: np.ndarray) -> None:  # pragma: no cover
    """Forward kinematics of the chain at ``qs[k]``: each joint's world rotation ``oR`` and origin ``ot``."""
    J = parent.shape[0]
    for i in range(3):
        for j in range(3):
            oR[0, i, j] = 1.0 if i == j else 0.0
        ot[0, i] = 0.0
    for jj in range(1, J):
        p = parent[jj]
        x = qs[k, iq[jj]]
        for i in range(3):  # parent pose times the joint placement
            o = ot[p, i]
            for j in range(3):
                o += oR[p, i, j] * t0[jj, j]
            ot[jj, i] = o
        if kind[jj] == 1:  # Rodrigues: rot = I + sin K + (1 - cos) K^2
            a0, a1, a2 = axis[jj, 0], axis[jj, 1], axis[jj, 2]
            sn, cs = np.sin(x), 1.0 - np.cos(x)
            r00 = 1.0 - cs * (a1 * a1 + a2 * a2)
            r11 = 1.0 - cs * (a0 * a0 + a2 * a2)
            r22 = 1.0 - cs * (a0 * a0 + a1 * a1)
            r01 = -sn * a2 + cs * a0 * a1
            r10 = sn * a2 + cs * a0 * a1
            r02 = sn * a1 + cs * a0 * a2
            r20 = -sn * a1 + cs * a0 * a2
            r12 = -sn * a0 + cs * a1 * a2
            r21 = sn * a0 + cs * a1 * a2
        else:
            r00, r01, r02, r10, r11, r12, r20, r21, r22 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
        for i in range(3):
            m0 = oR[p, i, 0] * R0[jj, 0, 0] + oR[p, i, 1] * R0[jj, 1, 0] + oR[p, i, 2] * R0[jj, 2, 0]
            m1 = oR[p, i, 0] * R0[jj, 0, 1] + oR[p, i, 1] * R0[jj, 1, 1] + oR[p, i, 2] * R0[jj, 2, 1]
            m2 = oR[p, i, 0] * R0[jj, 0, 2] + oR[p, i, 1] * R0[jj, 1, 2] + oR[p, i, 2] * R0[jj, 2, 2]
            oR[jj, i, 0] = m0 * r00 + m1 * r10 + m2 * r20
            oR[jj, i, 1] = m0 * r01 + m1 * r11 + m2 * r21
            oR[jj, i, 2] = m0 * r02 + m1 * r12 + m2 * r22
            if kind[jj] == 2:
                ot[jj, i] += x * (m0 * axis[jj, 0] + m1 * axis[jj, 1] + m2 * axis[jj, 2])


@kernel(cache=True, nogil=True)
def _place(g: int, jg: int, s: int, oR: np.ndarray, ot: np.ndarray, R_loc: np.ndarray, c_loc: np.ndarray,
           half: np.ndarray, R: np.ndarray, c: np.ndarray, hw: np.ndarray) -> None:  # pragma: no cover
    """Box ``g`` on joint ``jg`` in the world, in slot ``s``: its axes ``R[s, g]``, centre
    ``c[s, g]`` and the half-widths ``hw[s, g]`` of the world-axis box around it."""
    for i in range(3):
        cc = ot[jg, i]
        for j in range(3):
            cc += oR[jg, i, j] * c_loc[g, j]
            R[s, g, i, j] = oR[jg, i, 0] * R_loc[g, 0, j] + oR[jg, i, 1] * R_loc[g, 1, j] + oR[jg, i, 2] * R_loc[g, 2, j]
        c[s, g, i] = cc
        hw[s, g, i] = abs(R[s, g, i, 0]) * half[g, 0] + abs(R[s, g, i, 1]) * half[g, 1] + abs(R[s, g, i, 2]) * half[g, 2]


@kernel(cache=True, nogil=True)
def _open_pairs(qs: np.ndarray, parent: np.ndarray, R0: np.ndarray, t0: np.ndarray, kind: np.ndarray, axis: np.ndarray,
                iq: np.ndarray, gjoint: np.ndarray, R_loc: np.ndarray, c_loc: np.ndarray, half: np.ndarray,
                reach: np.ndarray, pairs: np.ndarray, tol: float, gtree: np.ndarray, centre: np.ndarray,
                tri: np.ndarray, tc: np.ndarray, th: np.ndarray, nc: np.ndarray, nh: np.ndarray, child: np.ndarray,
                start: np.ndarray, count: np.ndarray, stack_size: int
                ) -> tuple[np.ndarray, np.ndarray, int]:  # pragma: no cover
    """Per configuration, the pairs (indices into ``pairs``) whose boxes the tests cannot put
    apart: ``(starts (n + 1,), flat, placed)``, configuration k's in ``flat[starts[k]:starts[k +
    1]]``; ``placed``: how many times the chain's boxes were placed (a configuration or a range).

    Ranges of consecutive configurations first: about the range's middle configuration, each box
    grown by how far its points can move while every joint j stays within ``max |q_j -
    q_j(middle)|`` over the range (:func:`_growth`, bounded by :meth:`PathBoxes.reach`) holds the
    box at every configuration of the range; a pair whose grown boxes lie apart (each grown only
    by the joints below the pair's common joint, :func:`_filter_pairs`) is apart at all of them.
    The others go to the range's halves, down to single configurations (a range of at most
    :data:`LEAF` that put no further pair apart: each of its configurations at once), tested with
    the boxes as they are. A configuration with a NaN joint is never cleared with its range."""
    n, J, G, P, nq = qs.shape[0], parent.shape[0], gjoint.shape[0], pairs.shape[0], qs.shape[1]
    starts = np.zeros(n + 1, dtype=np.int64)
    flat = np.empty(max(16, 2 * n), dtype=np.int64)
    if n == 0:
        return starts, flat[:0], 0
    oR, ot = np.empty((J, 3, 3)), np.empty((J, 3))
    R, c, hw = np.empty((1, G, 3, 3)), np.empty((1, G, 3)), np.empty((1, G, 3))
    cum, loose, delta, scratch = np.zeros((G, J)), np.zeros(J), np.empty(nq), np.empty((2, 3))
    common = np.zeros(P, dtype=np.int64)  # per pair, the deepest joint on both boxes' chains
    for pp in range(P):
        ja, jb = gjoint[pairs[pp, 0]], gjoint[pairs[pp, 1]]
        while ja != jb:  # a parent's index is below its children's
            if ja > jb:
                ja = parent[ja]
            else:
                jb = parent[jb]
        common[pp] = ja
    pool, pool_n = np.empty((MAX_DEPTH + 1, P), dtype=np.int64), np.zeros(MAX_DEPTH + 1, dtype=np.int64)
    lo, hi = np.empty(2 * MAX_DEPTH + 2, dtype=np.int64), np.empty(2 * MAX_DEPTH + 2, dtype=np.int64)
    lv_of = np.empty(2 * MAX_DEPTH + 2, dtype=np.int64)
    for i in range(3):  # the universe joint: the world frame
        for j in range(3):
            oR[0, i, j] = 1.0 if i == j else 0.0
        ot[0, i] = 0.0
    for g in range(G):  # fixed in the world: placed once
        if gjoint[g] == 0:
            _place(g, 0, 0, oR, ot, R_loc, c_loc, half, R, c, hw)
    for pp in range(P):
        pool[0, pp] = pp
    pool_n[0], lo[0], hi[0], lv_of[0] = P, 0, n, 0
    top, nf, placed = 1, 0, 0
    while top > 0:  # depth first, left half first: the configurations are finished in order
        top -= 1
        i0, i1, lv = lo[top], hi[top], lv_of[top]
        mid = i0 + (i1 - i0) // 2
        for j in range(nq):
            delta[j] = 0.0
            for k in range(i0, i1):
                d = abs(qs[k, j] - qs[mid, j])
                if d != d or d > delta[j]:  # a NaN stays: no range holds it, its configuration goes to coal
                    delta[j] = d
        _chain(qs, mid, parent, R0, t0, kind, axis, iq, oR, ot)
        placed += 1
        for g in range(G):
            if gjoint[g] != 0:
                _place(g, gjoint[g], 0, oR, ot, R_loc, c_loc, half, R, c, hw)
                _growth(g, gjoint[g], parent, axis, iq, reach, delta, oR, ot, c[0, g], half[g], loose, cum)
        kept = _filter_pairs(pool[lv], pool_n[lv], pool[lv + 1], pairs, R, c, hw, half, gjoint, cum, common,
                             i1 - i0 == 1, tol, gtree, centre, tri, tc, th, nc, nh, child, start, count, stack_size,
                             scratch)
        if i1 - i0 > 1 and kept > 0 and (kept < pool_n[lv] or i1 - i0 > LEAF) and lv < MAX_DEPTH - 1:
            pool_n[lv + 1] = kept
            lo[top], hi[top], lv_of[top] = mid, i1, lv + 1
            lo[top + 1], hi[top + 1], lv_of[top + 1] = i0, mid, lv + 1
            top += 2
            continue
        for k in range(i0, i1):  # certified (no pair kept), or each configuration as it is
            if kept > 0 and i1 - i0 > 1:
                _chain(qs, k, parent, R0, t0, kind, axis, iq, oR, ot)
                placed += 1
                for g in range(G):
                    if gjoint[g] != 0:
                        _place(g, gjoint[g], 0, oR, ot, R_loc, c_loc, half, R, c, hw)
                kept_k = _filter_pairs(pool[lv + 1], kept, pool[MAX_DEPTH], pairs, R, c, hw, half, gjoint, cum, common,
                                       True, tol, gtree, centre, tri, tc, th, nc, nh, child, start, count, stack_size,
                                       scratch)
                src = MAX_DEPTH
            else:
                kept_k, src = kept, lv + 1
            if nf + kept_k > flat.shape[0]:
                grown = np.empty(2 * (nf + kept_k), dtype=np.int64)
                grown[:nf] = flat[:nf]
                flat = grown
            for li in range(kept_k):
                flat[nf + li] = pool[src, li]
            nf += kept_k
            starts[k + 1] = nf
    return starts, flat[:nf], placed


@kernel(cache=True, nogil=True)
def _growth(g: int, jg: int, parent: np.ndarray, axis: np.ndarray, iq: np.ndarray, reach: np.ndarray,
            delta: np.ndarray, oR: np.ndarray, ot: np.ndarray, centre: np.ndarray, half: np.ndarray,
            loose: np.ndarray, cum: np.ndarray) -> None:  # pragma: no cover
    """``cum[g, j]`` for box g (on joint ``jg``, centre ``centre`` in the world now, half extents
    ``half``): how far its points can move while each joint j' from the root to j moves by up to
    ``delta`` about where it is now (and the joints below by up to theirs). Per joint: ``delta``
    times the box's distance from the joint's axis now plus the box's radius plus how far the
    joints below can take it away (``loose``: the same with :meth:`PathBoxes.reach`), at most
    ``reach`` itself; infinite on a chain with a prismatic joint."""
    J = parent.shape[0]
    for jj in range(1, J):
        d = delta[iq[jj]]
        finite = 0.0 < reach[g, jj] < np.inf and d > 0.0  # (a prismatic joint's own term: grow below)
        loose[jj] = loose[parent[jj]] + (reach[g, jj] * d if finite else 0.0)
    radius = math.sqrt(half[0] * half[0] + half[1] * half[1] + half[2] * half[2])
    for jj in range(1, J):
        d, grow = delta[iq[jj]], 0.0
        if reach[g, jj] == np.inf:
            grow = np.inf
        elif reach[g, jj] > 0.0 and not d <= 0.0:  # (a NaN motion grows it to NaN: never apart)
            a0 = oR[jj, 0, 0] * axis[jj, 0] + oR[jj, 0, 1] * axis[jj, 1] + oR[jj, 0, 2] * axis[jj, 2]
            a1 = oR[jj, 1, 0] * axis[jj, 0] + oR[jj, 1, 1] * axis[jj, 1] + oR[jj, 1, 2] * axis[jj, 2]
            a2 = oR[jj, 2, 0] * axis[jj, 0] + oR[jj, 2, 1] * axis[jj, 1] + oR[jj, 2, 2] * axis[jj, 2]
            v0, v1, v2 = centre[0] - ot[jj, 0], centre[1] - ot[jj, 1], centre[2] - ot[jj, 2]
            along = v0 * a0 + v1 * a1 + v2 * a2
            off = math.sqrt(max(0.0, v0 * v0 + v1 * v1 + v2 * v2 - along * along))
            grow = d * min(off + radius + loose[jg] - loose[jj], reach[g, jj])
        cum[g, jj] = cum[g, parent[jj]] + grow


@kernel(cache=True, nogil=True)
def _filter_pairs(src: np.ndarray, n_src: int, dst: np.ndarray, pairs: np.ndarray, R: np.ndarray, c: np.ndarray,
                  hw: np.ndarray, half: np.ndarray, gjoint: np.ndarray, cum: np.ndarray, common: np.ndarray,
                  exact: bool, tol: float, gtree: np.ndarray, centre: np.ndarray,
                  tri: np.ndarray, tc: np.ndarray, th: np.ndarray, nc: np.ndarray, nh: np.ndarray, child: np.ndarray,
                  start: np.ndarray, count: np.ndarray, stack_size: int, grown: np.ndarray) -> int:  # pragma: no cover
    """Of the pairs ``src[:n_src]``, those whose boxes (slot 0 of ``R``, ``c``, ``hw``) the tests
    cannot put apart, into ``dst``; their number. Unless ``exact``, each box of a pair is grown
    in every direction by how far it moves relative to the other: ``cum[g, j]`` (how far box g
    moves for the joints from the root to joint j) at its own joint less at the pair's deepest
    common joint ``common[pair]`` (the joints above that move both boxes as one).
    The tests: the world-axis boxes, the separating axes of the two oriented boxes
    (:func:`obb_apart`), and, ``exact``, for a part mesh and another geometry the other box
    against the part's triangles (:func:`_apart_from_part`; a grown box meets so many of them that
    the range's halves are cheaper). ``grown``: (2, 3) scratch."""
    n = 0
    for li in range(n_src):
        pp = src[li]
        a, b = pairs[pp, 0], pairs[pp, 1]
        ra = rb = 0.0
        if not exact:
            jc = common[pp]
            ra, rb = cum[a, gjoint[a]] - cum[a, jc], cum[b, gjoint[b]] - cum[b, jc]
        if ra == np.inf or rb == np.inf or ra != ra or rb != rb:  # a prismatic joint on the chain moved: no bound
            dst[n] = pp
            n += 1
            continue
        apart = False
        for i in range(3):
            if abs(c[0, a, i] - c[0, b, i]) - hw[0, a, i] - hw[0, b, i] - ra - rb > tol:
                apart = True
                break
        if not apart:
            for i in range(3):
                grown[0, i], grown[1, i] = half[a, i] + ra, half[b, i] + rb
            apart = obb_apart(R[0, a], c[0, a], grown[0], R[0, b], c[0, b], grown[1], tol)
        if not apart and exact and (gtree[a] >= 0) != (gtree[b] >= 0):
            t, o = (a, b) if gtree[a] >= 0 else (b, a)  # the other box against the part's triangles
            apart = _apart_from_part(R[0, t], c[0, t], centre[t], R[0, o], c[0, o], half[o], tol, tri, tc, th, nc,
                                     nh, child, start, count, stack_size)
        if not apart:
            dst[n] = pp
            n += 1
    return n


@kernel(cache=True, nogil=True)
def _apart_from_part(Rt: np.ndarray, ct: np.ndarray, centre_t: np.ndarray, Ro: np.ndarray, co: np.ndarray,
                     ho: np.ndarray, tol: float, tri: np.ndarray, tc: np.ndarray, th: np.ndarray, nc: np.ndarray,
                     nh: np.ndarray, child: np.ndarray, start: np.ndarray, count: np.ndarray,
                     stack_size: int) -> bool:  # pragma: no cover
    """The box (axes ``Ro``, centre ``co``, half extents ``ho``, world) lies more than ``tol`` +
    :data:`~grasplan.grasps.collision_boxes.PREPASS_TOL` from every triangle of the part whose
    local box has axes ``Rt``, centre ``ct`` (world) and centre ``centre_t`` in the part's frame."""
    op = np.empty(3)
    Rq = np.empty((3, 3))
    cq = np.empty(3)
    for i in range(3):  # the part's origin in the world, the other box's axes in the part's frame
        op[i] = ct[i] - (Rt[i, 0] * centre_t[0] + Rt[i, 1] * centre_t[1] + Rt[i, 2] * centre_t[2])
        for j in range(3):
            Rq[i, j] = Rt[0, i] * Ro[0, j] + Rt[1, i] * Ro[1, j] + Rt[2, i] * Ro[2, j]
    for i in range(3):
        cq[i] = Rt[0, i] * (co[0] - op[0]) + Rt[1, i] * (co[1] - op[1]) + Rt[2, i] * (co[2] - op[2])
    return box_vs_tree(Rq, cq, ho, False, tol + PREPASS_TOL, tri, tc, th, nc, nh, child, start, count,
                       np.empty(stack_size, dtype=np.int64), np.empty((3, 3)), np.empty((12, 3)), np.empty((12, 3)),
                       np.empty(3), np.empty(3)) == APART


@kernel(cache=True, nogil=True)
def obb_apart(Ra: np.ndarray, ca: np.ndarray, ha: np.ndarray, Rb: np.ndarray, cb: np.ndarray, hb: np.ndarray,
              tol: float) -> bool:  # pragma: no cover
    """Separating-axis test of two oriented boxes in box A's frame (Gottschalk et al.'s OBBTree):
    one of the 15 axes separates them by more than ``tol``. ``|C|`` is padded by 1e-12 and edge
    axes of nearly parallel edges (length < 1e-6) are skipped, so rounding never separates
    touching boxes."""
    C = np.zeros((3, 3))
    AC = np.zeros((3, 3))
    t = np.zeros(3)
    for i in range(3):
        t[i] = Ra[0, i] * (cb[0] - ca[0]) + Ra[1, i] * (cb[1] - ca[1]) + Ra[2, i] * (cb[2] - ca[2])
        for j in range(3):
            C[i, j] = Ra[0, i] * Rb[0, j] + Ra[1, i] * Rb[1, j] + Ra[2, i] * Rb[2, j]
            AC[i, j] = abs(C[i, j]) + 1e-12
    for i in range(3):  # A's faces
        if abs(t[i]) - ha[i] - (AC[i, 0] * hb[0] + AC[i, 1] * hb[1] + AC[i, 2] * hb[2]) > tol:
            return True
    for j in range(3):  # B's faces
        tb = t[0] * C[0, j] + t[1] * C[1, j] + t[2] * C[2, j]
        if abs(tb) - (AC[0, j] * ha[0] + AC[1, j] * ha[1] + AC[2, j] * ha[2]) - hb[j] > tol:
            return True
    for i in range(3):  # edges: axis e_i x C[:, j]
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            nL = np.sqrt(C[i1, j] * C[i1, j] + C[i2, j] * C[i2, j])
            if nL < 1e-6:
                continue
            tl = t[i2] * C[i1, j] - t[i1] * C[i2, j]
            ra = ha[i1] * AC[i2, j] + ha[i2] * AC[i1, j]
            rb = hb[j1] * AC[i, j2] + hb[j2] * AC[i, j1]
            if abs(tl) - ra - rb > tol * nL:
                return True
    return False


_BOXES: "weakref.WeakKeyDictionary[Any, PathBoxes]" = weakref.WeakKeyDictionary()
#: kernel arguments kept per scene variant (one per jaw opening and carried part's pose; a grasp
#: reuses its own through its approach, lift and transit, the next grasp has others)
MAX_PREPARED = 8


def _prepared(scene: Any) -> tuple[tuple[tuple, float, tuple], np.ndarray, np.ndarray] | None:
    """``(the kernel's arguments but the pairs and the tolerance, every pair's rows into the used
    geometries, per pair: the kernel can take it)`` for ``scene`` with its jaws and carried part as
    they are; cached per variant, jaw opening and attached part's pose (the last :data:`MAX_PREPARED`
    of a variant). None when the boxes cannot
    serve the model."""
    scene._apply()
    sh = scene._shared
    boxes = _BOXES.get(sh)
    if boxes is None:
        boxes = _BOXES[sh] = PathBoxes(sh.model, sh.gm, sh.pairs, sh.part_tree())
    sel = boxes.selected
    if sel is None:
        return None
    objs = sh.gm.geometryObjects
    found = scene.__dict__.get("_boxes_sel")
    if found is None:
        used = sel[0].tolist()
        # the used geometries' placements: the robot's and the cell's as the model was built, the
        # part's and the extras' this variant's; the jaws and the carried part move (per opening
        # and grasp)
        placements = boxes.placements[used]
        for i, k in enumerate(used):
            if k in scene._placements:
                placements[i] = objs[k].placement.homogeneous
        moving = [i for i, k in enumerate(used) if k in sh.moving_ids]
        found = scene.__dict__["_boxes_sel"] = (used, moving, placements)
        scene.__dict__["_boxes_prep"] = {}
    used, moving, placements = found
    preps = scene.__dict__["_boxes_prep"]
    key = (sh.opening, None if scene.T_tcp_part is None else scene.T_tcp_part.tobytes())
    prep = preps.get(key)
    if prep is None:
        if len(preps) >= MAX_PREPARED:
            del preps[next(iter(preps))]
        for i in moving:
            placements[i] = objs[used[i]].placement.homogeneous
        prep = preps[key] = boxes.prepare(sel[0], placements, sh.margin)
    return prep, sel[1], sel[2]


def scene_open(scene: Any, qs: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Per configuration of ``qs`` (N, n) of ``scene`` (jaws as they are), the active pairs whose
    oriented boxes do not lie apart, the only ones coal can find colliding there: ``(starts (N +
    1,), pair ids)`` (indices into the scene's pairs, configuration k's in ``pair_ids[starts[k]:
    starts[k + 1]]``), or None when the boxes cannot serve this scene (a joint or a box the
    kernel cannot take).

    One numba-compiled loop (:func:`_open_pairs`) over ranges of ``qs`` (in path order, so that a
    range's configurations lie close; the module docstring): forward kinematics of the chain
    (revolute and prismatic joints), each box's world pose (the world's fixed boxes once), then per
    pair the world-axis boxes and, where those overlap, the separating-axis test of the two oriented
    boxes (15 axes, :func:`obb_apart`). coal's narrow phase then runs on the listed pairs alone: a
    configuration is free exactly when coal finds none of them colliding, and one with none listed
    needs no coal call (tests/test_pathboxes.py checks both against coal on every pair). On the
    bench piles (docs/pick.md) the boxes leave no pair at 92-94 % of a path's configurations, at
    about 2 us per configuration against ~13 us for coal's check through Pinocchio's broad phase
    (~26 us on the lift), which they replace; the same test in plain NumPy cost 5-10 us per
    configuration and saved nothing. A model with another joint kind, or a geometry whose box is
    not finite, is left to that broad phase."""
    found = _prepared(scene)
    if found is None:
        return None
    prep, rows, finite = found
    active = np.flatnonzero(scene._active)
    if not finite[active].all():
        return None
    head, tol, tail = prep
    starts, flat, _ = _open_pairs(np.ascontiguousarray(qs, dtype=np.float64).reshape(-1, scene.model.nq), *head,
                                  rows[active], tol, *tail)
    return starts, active[flat]
