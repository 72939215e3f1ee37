"""Which (pose, body) pairs of one gripper shape need coal, decided on boxes in one compiled pass
(:meth:`grasplan.pick.world.PickWorld.gripper_at_hits`, the closed gripper along a lift).

Per pose, the shape's local box placed in the world and the world-axis box around it; a pair
whose world-axis boxes overlap (touching counts) goes to coal, as before this module. Poses that
share one orientation (a straight lift) are first taken together: the oriented box with the
shape's axes holding the shape's box at every pose (:func:`sweep`); a body whose world box the
separating-axis test (:func:`grasplan.motion.pathboxes.obb_apart`) puts apart from it is apart from the
shape at every pose, so none of its pairs needs coal. A box body (exactly its world box) that
overlaps the swept box is checked per pose; any other body is the caller's to test against the
swept box with coal (``status`` 1) before its per-pose pairs.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..compiled.jit import kernel
from ..motion.pathboxes import obb_apart


#: the swept box is this much (m) larger than the boxes it holds along each of its axes
SWEPT_PAD = 1e-9
#: a box lies inside a swept box when it does with this much (m) to spare (the robot scene places
#: the shapes by Pinocchio's FK, the coverage test by the closed form's: they agree within 1e-11 m)
INSIDE_SLACK = 1e-9


def sweep(T_world_tcp: np.ndarray, T_tcp_geom: np.ndarray, c_loc: np.ndarray, h_loc: np.ndarray,
          centres: np.ndarray, halves: np.ndarray, box: np.ndarray, pad: float = SWEPT_PAD) -> tuple[np.ndarray, ...]:
    """For one shape (local box centre ``c_loc``, half extents ``h_loc``, placed by ``T_tcp_geom``)
    at the TCP poses ``T_world_tcp`` (k, 4, 4) against bodies with world boxes (``centres``,
    ``halves`` (B, 3); ``box`` (B,): the body is exactly its box): ``(T_world_geom (k, 4, 4), ks,
    bis, status (B,), R, centre, half)``. ``(ks, bis)``: the pairs (pose order, then body order)
    whose world-axis boxes overlap, left out those of bodies with ``status`` 0 (apart from the
    swept box at every pose); ``status`` 1: a body that overlaps the swept box ``(R, centre,
    half)`` and is no box (test it with coal), 2: checked per pose. Without one shared
    orientation no sweep is made (every ``status`` 2). The swept box is ``pad`` (m) larger than the
    boxes it holds along each of its axes."""
    return _sweep(np.ascontiguousarray(T_world_tcp, dtype=np.float64).reshape(-1, 4, 4),
                  np.ascontiguousarray(T_tcp_geom, dtype=np.float64), np.ascontiguousarray(c_loc, dtype=np.float64),
                  np.ascontiguousarray(h_loc, dtype=np.float64), np.ascontiguousarray(centres, dtype=np.float64),
                  np.ascontiguousarray(halves, dtype=np.float64), np.ascontiguousarray(box, dtype=np.bool_),
                  float(pad))


@dataclass(frozen=True)
class SweptGripper:
    """The gripper's shapes (their local boxes, placed by ``T_tcp_geom`` (S, 4, 4): centres
    ``c_loc``, half extents ``h_loc`` (S, 3)) and, per shape, an oriented box (``R`` (S, 3, 3),
    ``centre``, ``half`` (S, 3)) known to touch nothing: :meth:`holds` tells the TCP poses at which
    every shape's box lies inside its swept box, so that the gripper touches nothing there."""

    T_tcp_geom: np.ndarray
    c_loc: np.ndarray
    h_loc: np.ndarray
    R: np.ndarray
    centre: np.ndarray
    half: np.ndarray

    def holds(self, T_world_tcp: np.ndarray) -> np.ndarray:
        """Per TCP pose of ``T_world_tcp`` (k, 4, 4): every shape's box inside its swept box, with
        :data:`INSIDE_SLACK` to spare."""
        return _inside(np.ascontiguousarray(T_world_tcp, dtype=np.float64).reshape(-1, 4, 4), self.T_tcp_geom,
                       self.c_loc, self.h_loc, self.R, self.centre, self.half, INSIDE_SLACK)


@kernel(cache=True, nogil=True)
def _inside(T: np.ndarray, T_tcp_geom: np.ndarray, c_loc: np.ndarray, h_loc: np.ndarray, Rs: np.ndarray,
            cs: np.ndarray, hs: np.ndarray, slack: float) -> np.ndarray:  # pragma: no cover
    K, S = T.shape[0], T_tcp_geom.shape[0]
    out = np.ones(K, dtype=np.bool_)
    Tg = np.empty((4, 4))
    for k in range(K):
        for s in range(S):
            for i in range(4):
                for j in range(4):
                    Tg[i, j] = (T[k, i, 0] * T_tcp_geom[s, 0, j] + T[k, i, 1] * T_tcp_geom[s, 1, j]
                                + T[k, i, 2] * T_tcp_geom[s, 2, j] + T[k, i, 3] * T_tcp_geom[s, 3, j])
            inside = True
            for i in range(3):  # along each axis of the swept box: the shape's box centre and reach
                d = 0.0
                r = 0.0
                for m in range(3):
                    c = Tg[m, 0] * c_loc[s, 0] + Tg[m, 1] * c_loc[s, 1] + Tg[m, 2] * c_loc[s, 2] + Tg[m, 3]
                    d += Rs[s, m, i] * (c - cs[s, m])
                for j in range(3):
                    r += abs(Rs[s, 0, i] * Tg[0, j] + Rs[s, 1, i] * Tg[1, j] + Rs[s, 2, i] * Tg[2, j]) * h_loc[s, j]
                if abs(d) + r > hs[s, i] - slack:
                    inside = False
                    break
            if not inside:
                out[k] = False
                break
    return out


@kernel(cache=True, nogil=True)
def _sweep(T: np.ndarray, T_tcp_geom: np.ndarray, c_loc: np.ndarray, h_loc: np.ndarray, bc: np.ndarray,
           bh: np.ndarray, box: np.ndarray, pad: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover
    K, B = T.shape[0], bc.shape[0]
    Tg = np.empty((K, 4, 4))
    c = np.empty((K, 3))
    hw = np.empty((K, 3))
    same = K > 1
    for k in range(K):
        for i in range(4):
            for j in range(4):
                Tg[k, i, j] = (T[k, i, 0] * T_tcp_geom[0, j] + T[k, i, 1] * T_tcp_geom[1, j]
                               + T[k, i, 2] * T_tcp_geom[2, j] + T[k, i, 3] * T_tcp_geom[3, j])
        for i in range(3):
            c[k, i] = Tg[k, i, 0] * c_loc[0] + Tg[k, i, 1] * c_loc[1] + Tg[k, i, 2] * c_loc[2] + Tg[k, i, 3]
            hw[k, i] = abs(Tg[k, i, 0]) * h_loc[0] + abs(Tg[k, i, 1]) * h_loc[1] + abs(Tg[k, i, 2]) * h_loc[2]
            if same and k > 0:
                for j in range(3):
                    if T[k, i, j] != T[0, i, j]:
                        same = False
    status = np.full(B, 2, dtype=np.int64)
    R = np.zeros((3, 3))
    cs = np.zeros(3)
    hs = np.zeros(3)
    if same:
        for i in range(3):
            for j in range(3):
                R[i, j] = Tg[0, i, j]
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for k in range(K):  # the centres in the shape's axes
            for j in range(3):
                x = R[0, j] * c[k, 0] + R[1, j] * c[k, 1] + R[2, j] * c[k, 2]
                lo[j] = min(lo[j], x)
                hi[j] = max(hi[j], x)
        mid = 0.5 * (lo + hi)
        for j in range(3):
            hs[j] = h_loc[j] + 0.5 * (hi[j] - lo[j]) + pad
        for i in range(3):
            cs[i] = R[i, 0] * mid[0] + R[i, 1] * mid[1] + R[i, 2] * mid[2]
        eye = np.eye(3)
        for b in range(B):
            apart = False
            for i in range(3):  # world-axis boxes first
                r = abs(R[i, 0]) * hs[0] + abs(R[i, 1]) * hs[1] + abs(R[i, 2]) * hs[2]
                if abs(cs[i] - bc[b, i]) > r + bh[b, i]:
                    apart = True
                    break
            if not apart:
                apart = obb_apart(R, cs, hs, eye, bc[b], bh[b], 0.0)
            status[b] = 0 if apart else (2 if box[b] else 1)
    n = 0
    ks = np.empty(K * B, dtype=np.int64)
    bis = np.empty(K * B, dtype=np.int64)
    for k in range(K):
        for b in range(B):
            if status[b] == 0:
                continue
            near = True
            for i in range(3):
                if abs(c[k, i] - bc[b, i]) > hw[k, i] + bh[b, i]:
                    near = False
                    break
            if near:
                ks[n], bis[n] = k, b
                n += 1
    return Tg, ks[:n], bis[:n], status, R, cs, hs
