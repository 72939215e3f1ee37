"""What :class:`grasplan.robot.ik.IKSolver` does with a closed form's raw solutions, compiled
(:mod:`grasplan.compiled`): each joint wrapped by multiples of 2 pi into its limits, nearest the
reference configuration (:func:`wrap_rows`); then the solutions whose FK pose reaches the target,
nearest the reference first, one of each group closer than the dedup tolerance
(:func:`select_solutions`). The FK poses come from the caller (Pinocchio's), so the check stays
independent of the closed form.

Compiled because the same steps in NumPy cost about 0.3 ms per IK call (their per-call overhead on
(8, 6) arrays), more than the closed form and Pinocchio's eight FK calls together.
"""
from __future__ import annotations

import math

import numpy as np

from ...compiled.jit import kernel

TWO_PI = 2.0 * math.pi
#: the 2 pi shifts tried for a joint whose nearest equivalent lies outside its limits, in order
SHIFTS = (-2.0, -1.0, 1.0, 2.0)
#: slack (rad) of the limit test before clipping
LIMIT_SLACK = 1e-12


def wrap_rows(Q: np.ndarray, lower: np.ndarray, upper: np.ndarray, q_ref: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """Every row of ``Q`` (k, n) wrapped into ``[lower, upper]``: each joint shifted by the
    multiple of 2 pi nearest ``q_ref``; where that lies outside its limits, by the shift of
    :data:`SHIFTS` that lies inside and nearest ``q_ref``; then clipped to the limits.
    ``(wrapped (k, n), ok (k,))``: a row is not ok when some joint has no equivalent within its
    limits."""
    c = np.ascontiguousarray
    lo = c(lower, dtype=np.float64)
    return _wrap(c(Q, dtype=np.float64).reshape(-1, len(lo)), lo, c(upper, dtype=np.float64), c(q_ref, dtype=np.float64))


def select_solutions(W: np.ndarray, T_reached: np.ndarray, T_target: np.ndarray, q_ref: np.ndarray, pos_tol: float,
                     rot_tol: float, dedup_tol: float, max_keep: int) -> np.ndarray:
    """Indices into ``W`` (k, n) of the solutions to return, nearest ``q_ref`` (Euclidean) first,
    at most ``max_keep``: those whose pose ``T_reached[i]`` (k, 4, 4) lies within ``pos_tol`` (m)
    and ``rot_tol`` (rad) of ``T_target`` (4, 4); a solution within ``dedup_tol`` (rad, every
    joint) of one kept before it is dropped."""
    c = np.ascontiguousarray
    return _select(c(W, dtype=np.float64), c(T_reached, dtype=np.float64), c(T_target, dtype=np.float64),
                   c(q_ref, dtype=np.float64), float(pos_tol), float(rot_tol), float(dedup_tol), int(max_keep))


@kernel(cache=True, nogil=True)
def _wrap(Q: np.ndarray, lower: np.ndarray, upper: np.ndarray, q_ref: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
    k, n = Q.shape
    out = np.empty((k, n))
    ok = np.ones(k, dtype=np.bool_)
    for i in range(k):
        for j in range(n):
            v = Q[i, j] + np.rint((q_ref[j] - Q[i, j]) / TWO_PI) * TWO_PI
            lo, hi = lower[j] - LIMIT_SLACK, upper[j] + LIMIT_SLACK
            if v < lo or v > hi:
                best, pick = np.inf, v + TWO_PI * SHIFTS[0]
                for s in SHIFTS:
                    cand = v + TWO_PI * s
                    if lo <= cand <= hi and abs(cand - q_ref[j]) < best:
                        best, pick = abs(cand - q_ref[j]), cand
                if best == np.inf:
                    ok[i] = False
                v = pick
            out[i, j] = min(max(v, lower[j]), upper[j])
    return out, ok


@kernel(cache=True, nogil=True)
def _select(W: np.ndarray, T: np.ndarray, T_want: np.ndarray, q_ref: np.ndarray, pos_tol: float, rot_tol: float,
            dedup_tol: float, max_keep: int) -> np.ndarray:  # pragma: no cover
    k, n = W.shape
    dist = np.empty(k)
    verified = np.zeros(k, dtype=np.bool_)
    for i in range(k):
        s = 0.0
        for j in range(n):
            s += (W[i, j] - q_ref[j]) ** 2
        dist[i] = math.sqrt(s)
        d0, d1, d2 = T[i, 0, 3] - T_want[0, 3], T[i, 1, 3] - T_want[1, 3], T[i, 2, 3] - T_want[2, 3]
        dp = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        # the angle of R_reached^T R_want: atan2(|skew part|, (trace - 1) / 2)
        R = np.zeros((3, 3))
        for a in range(3):
            for b in range(3):
                R[a, b] = T[i, 0, a] * T_want[0, b] + T[i, 1, a] * T_want[1, b] + T[i, 2, a] * T_want[2, b]
        cth = min(1.0, max(-1.0, (R[0, 0] + R[1, 1] + R[2, 2] - 1.0) / 2.0))
        v0, v1, v2 = R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]
        dr = math.atan2(0.5 * math.sqrt(v0 * v0 + v1 * v1 + v2 * v2), cth)
        verified[i] = dp <= pos_tol and dr <= rot_tol
    order = np.argsort(dist, kind="mergesort")
    kept = np.empty(k, dtype=np.int64)
    n_kept = 0
    for i in order:
        if not verified[i]:
            continue
        dup = False
        for t in range(n_kept):
            gap = 0.0
            for j in range(n):
                gap = max(gap, abs(W[i, j] - W[kept[t], j]))
            dup = dup or gap <= dedup_tol
        if not dup:
            kept[n_kept] = i
            n_kept += 1
            if n_kept >= max_keep:
                break
    return kept[:n_kept]
