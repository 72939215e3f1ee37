"""Compiled inner loop of the contact patches: (polygon, grasp) pairs clipped to a finger pad and integrated.

:func:`slab_polygons` clips each (element, contact) pair to the contact's slab, once for every roll;
:func:`accumulate_pairs` turns each (polygon, grasp) pair into the grasp's TCP frame, culls it
against the pad's rectangle, clips it to it (Sutherland-Hodgman, one side at a time) and adds its
area and first and second moments (the formulas of :func:`grasplan.geometry.polygons.polygon_moments`)
to the grasp's. Used by :mod:`grasplan.grasps.patches` (``cache=True``: compiled once, at
install by :mod:`grasplan.cli.warmup`).
"""
from __future__ import annotations

import numpy as np

from ..compiled.jit import kernel


@kernel(cache=True)
def _clip(P: np.ndarray, m: int, col: int, bound: float, sgn: float, out: np.ndarray) -> int:
    """Clip the polygon of the first ``m`` rows of ``P`` (rows: vertices, in order) to
    ``sgn * (P[:, col] - bound) <= 0`` into ``out`` (every column interpolated, Sutherland-Hodgman);
    returns the new vertex count."""
    k = 0
    for i in range(m):
        j = i + 1 if i + 1 < m else 0
        dp = sgn * (P[i, col] - bound)
        dq = sgn * (P[j, col] - bound)
        in_p = dp <= 0.0
        if in_p:
            out[k] = P[i]
            k += 1
        if in_p != (dq <= 0.0):
            t = dp / (dp - dq)
            for c in range(P.shape[1]):
                out[k, c] = P[i, c] + t * (P[j, c] - P[i, c])
            k += 1
    return k


@kernel(cache=True)
def accumulate_pairs(poly: np.ndarray, n: np.ndarray, w: np.ndarray, flat: np.ndarray, src: np.ndarray,
                     g: np.ndarray, o: np.ndarray, R: np.ndarray, rect: np.ndarray, mom: np.ndarray, jaw: int) -> None:
    """Add the pad moments of ``K`` (polygon, grasp) pairs to ``mom`` (M, 2, 2, 6) in place.

    ``poly`` (P, V, 3) part-frame polygons (the first ``n[p]`` vertices valid) with weights ``w``
    (P,) (+-1: holes of merged areas subtract) and ``flat`` (P,) bool (the face is parallel to the
    pad); pair ``k`` is polygon ``src[k]`` with grasp ``g[k]``; TCP origins ``o`` (M, 3) and
    rotations ``R`` (M, 3, 3); ``rect`` (4,)
    ``y_lo, y_hi, z_lo, z_hi`` in the TCP frame; ``jaw`` 0 or 1. Adds ``w * [A, int y, int z,
    int y^2, int z^2, int yz]`` to ``mom[g, jaw, 0]`` and, when ``flat``, to ``mom[g, jaw, 1]``."""
    K, V = len(src), poly.shape[1]
    cap = 16 * V + 16  # each clip at most doubles a polygon's vertices
    A = np.empty((cap, 2))  # (y, z) per vertex, TCP frame
    B = np.empty((cap, 2))
    y_lo, y_hi, z_lo, z_hi = rect[0], rect[1], rect[2], rect[3]
    for k in range(K):
        gi = g[k]
        pk = src[k]
        m = n[pk]
        ymin = np.inf
        ymax = -np.inf
        zmin = np.inf
        zmax = -np.inf
        for v in range(m):
            d0 = poly[pk, v, 0] - o[gi, 0]
            d1 = poly[pk, v, 1] - o[gi, 1]
            d2 = poly[pk, v, 2] - o[gi, 2]
            y = d0 * R[gi, 0, 1] + d1 * R[gi, 1, 1] + d2 * R[gi, 2, 1]
            z = d0 * R[gi, 0, 2] + d1 * R[gi, 1, 2] + d2 * R[gi, 2, 2]
            A[v, 0] = y
            A[v, 1] = z
            ymin = min(ymin, y)
            ymax = max(ymax, y)
            zmin = min(zmin, z)
            zmax = max(zmax, z)
        if not (ymin <= y_hi and ymax >= y_lo and zmin <= z_hi and zmax >= z_lo):
            continue  # outside the pad: culled before clipping
        m = _clip(A, m, 0, y_lo, -1.0, B)
        m = _clip(B, m, 0, y_hi, 1.0, A)
        m = _clip(A, m, 1, z_lo, -1.0, B)
        m = _clip(B, m, 1, z_hi, 1.0, A)
        if m == 0:
            continue
        a = sy = sz = syy = szz = syz = 0.0
        for i in range(m):
            j = i + 1 if i + 1 < m else 0
            Y, Z, Y1, Z1 = A[i, 0], A[i, 1], A[j, 0], A[j, 1]
            c = Y * Z1 - Y1 * Z
            a += c
            sy += (Y + Y1) * c
            sz += (Z + Z1) * c
            syy += (Y * Y + Y * Y1 + Y1 * Y1) * c
            szz += (Z * Z + Z * Z1 + Z1 * Z1) * c
            syz += (Y * Z1 + 2 * Y * Z + 2 * Y1 * Z1 + Y1 * Z) * c
        area = 0.5 * a
        s = (1.0 if area > 0 else -1.0 if area < 0 else 0.0) * w[pk]
        vals = (area * s, sy / 6.0 * s, sz / 6.0 * s, syy / 12.0 * s, szz / 12.0 * s, syz / 24.0 * s)
        for c6 in range(6):
            mom[gi, jaw, 0, c6] += vals[c6]
            if flat[pk]:
                mom[gi, jaw, 1, c6] += vals[c6]


@kernel(cache=True)
def slab_polygons(pts: np.ndarray, first: np.ndarray, count: np.ndarray, f: np.ndarray, gu: np.ndarray,
                  cu: np.ndarray, axu: np.ndarray, depth: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The elements ``f`` (K,) clipped to the slabs of their contacts ``gu`` (K,): ``|(v - cu) . axu|
    <= depth`` (``cu``, ``axu`` (U, 3): contact points and closing axes). Elements are polygons of
    ``pts`` (``count[e]`` vertices from ``first[e]``). Returns ``(keep (K,) bool, poly (k, V, 3),
    n (k,))``: the pairs that reach the slab (some vertex within ``depth`` of the contact plane on
    each side) and their clipped polygons (part frame, the first ``n`` vertices valid)."""
    K = len(f)
    vmax = 0
    for k in range(K):
        vmax = max(vmax, count[f[k]])
    cap = 4 * vmax + 4
    keep = np.zeros(K, dtype=np.bool_)
    A = np.empty((cap, 4))  # (x - x_contact along the axis, part-frame point) per vertex
    B = np.empty((cap, 4))
    out = np.zeros((K, cap, 3))
    nout = np.zeros(K, dtype=np.int64)
    kept = 0
    for k in range(K):
        e, u = f[k], gu[k]
        m = count[e]
        lo, hi = np.inf, -np.inf
        for v in range(m):
            p = pts[first[e] + v]
            x = (p[0] - cu[u, 0]) * axu[u, 0] + (p[1] - cu[u, 1]) * axu[u, 1] + (p[2] - cu[u, 2]) * axu[u, 2]
            A[v, 0], A[v, 1], A[v, 2], A[v, 3] = x, p[0], p[1], p[2]
            lo = min(lo, x)
            hi = max(hi, x)
        if not (lo <= depth and hi >= -depth):
            continue
        keep[k] = True
        m = _clip(A, m, 0, -depth, -1.0, B)  # x >= -depth
        m = _clip(B, m, 0, depth, 1.0, A)  # x <= depth
        for i in range(m):
            out[kept, i] = A[i, 1:]
        nout[kept] = m
        kept += 1
    return keep, out[:kept], nout[:kept]


@kernel(cache=True)
def within_disc(poly: np.ndarray, npx: np.ndarray, o: np.ndarray, R: np.ndarray, ref: np.ndarray,
                disc2: float) -> np.ndarray:
    """(K,) bool: every valid vertex (the first ``npx[k]``, at least one) of polygon ``poly[k]``
    (K, V, 3) lies within ``sqrt(disc2)`` of the closing axis of pose ``ref[k]`` (the line through
    ``o[ref[k]]`` along the first column of ``R[ref[k]]``; squared distance ``|d|^2 - (d . x)^2``):
    inside the disc the pad covers at every roll about that axis."""
    K = poly.shape[0]
    out = np.zeros(K, dtype=np.bool_)
    for k in range(K):
        if npx[k] <= 0:
            continue
        r = ref[k]
        ok = True
        for v in range(npx[k]):
            d0 = poly[k, v, 0] - o[r, 0]
            d1 = poly[k, v, 1] - o[r, 1]
            d2 = poly[k, v, 2] - o[r, 2]
            along = d0 * R[r, 0, 0] + d1 * R[r, 1, 0] + d2 * R[r, 2, 0]
            if not (d0 * d0 + d1 * d1 + d2 * d2) - along * along < disc2:
                ok = False
                break
        out[k] = ok
    return out


@kernel(cache=True)
def _load_holds(s: float, d: int, fx: np.ndarray, fy: np.ndarray, fz: np.ndarray, tau_x: np.ndarray, tp: np.ndarray,
                uy: np.ndarray, uz: np.ndarray, arm0: float, arm1: float, inv_w: float, L0: float, L1: float, F: float,
                mu: float, lmin: float) -> bool:
    """Load ``d`` of a grasp held at scale ``s`` (the arithmetic of
    :func:`grasplan.grasps.wrench.gravity_margin`)."""
    n0 = F - 0.5 * s * fx[d]
    n1 = F + 0.5 * s * fx[d]
    cap = arm0 * n0 + arm1 * n1
    if cap > 0:
        used = min(max(s * tp[d] / max(cap, 1e-300), 0.0), 1.0)
    else:
        used = 0.0
    rest = max(s * tp[d] - cap, 0.0) * inv_w
    hy = rest * uz[d]
    hz = -rest * uy[d]
    t0 = (0.5 * s * fy[d] - hy) ** 2 + (0.5 * s * fz[d] - hz) ** 2
    t1 = (0.5 * s * fy[d] + hy) ** 2 + (0.5 * s * fz[d] + hz) ** 2
    c0 = (mu * n0) ** 2
    c1 = (mu * n1) ** 2
    if not (n0 > 0 and n1 > 0 and t0 <= c0 and t1 <= c1):
        return False
    shrink = np.sqrt(1.0 - used)
    twist = (max(L0 * shrink, lmin) * np.sqrt(max(c0 - t0, 0.0))
             + max(L1 * shrink, lmin) * np.sqrt(max(c1 - t1, 0.0)))
    return s * tau_x[d] <= twist


@kernel(cache=True)
def _tcp_loads(m: int, R: np.ndarray, p: np.ndarray, com: np.ndarray, f_part: np.ndarray, fx: np.ndarray,
               fy: np.ndarray, fz: np.ndarray, tau_x: np.ndarray, tp: np.ndarray, uy: np.ndarray, uz: np.ndarray) -> None:
    """Grasp ``m``'s loads in its TCP frame into ``fx .. uz`` (D,): the force, the twist about the
    closing axis and the size and direction of the moment perpendicular to it, about the TCP."""
    e0, e1, e2 = com[0] - p[m, 0], com[1] - p[m, 1], com[2] - p[m, 2]
    cx = R[m, 0, 0] * e0 + R[m, 1, 0] * e1 + R[m, 2, 0] * e2  # R^T (com - p): the TCP frame
    cy = R[m, 0, 1] * e0 + R[m, 1, 1] * e1 + R[m, 2, 1] * e2
    cz = R[m, 0, 2] * e0 + R[m, 1, 2] * e1 + R[m, 2, 2] * e2
    for d in range(f_part.shape[0]):
        x = R[m, 0, 0] * f_part[d, 0] + R[m, 1, 0] * f_part[d, 1] + R[m, 2, 0] * f_part[d, 2]
        y = R[m, 0, 1] * f_part[d, 0] + R[m, 1, 1] * f_part[d, 1] + R[m, 2, 1] * f_part[d, 2]
        z = R[m, 0, 2] * f_part[d, 0] + R[m, 1, 2] * f_part[d, 1] + R[m, 2, 2] * f_part[d, 2]
        fx[d], fy[d], fz[d] = x, y, z
        tau_x[d] = abs(cy * z - cz * y)  # com x f
        ty, tz = cz * x - cx * z, cx * y - cy * x
        tp[d] = np.hypot(ty, tz)
        uy[d] = ty / max(tp[d], 1e-300) if tp[d] > 0 else 0.0
        uz[d] = tz / max(tp[d], 1e-300) if tp[d] > 0 else 0.0


@kernel(cache=True)
def _all_hold(s: float, last: int, fx: np.ndarray, fy: np.ndarray, fz: np.ndarray, tau_x: np.ndarray,
              tp: np.ndarray, uy: np.ndarray, uz: np.ndarray, arm0: float, arm1: float, inv_w: float, L0: float,
              L1: float, F: float, mu: float, lmin: float) -> int:
    """-1 when every load holds at scale ``s``, else the first that slips (load ``last`` tried first)."""
    if not _load_holds(s, last, fx, fy, fz, tau_x, tp, uy, uz, arm0, arm1, inv_w, L0, L1, F, mu, lmin):
        return last
    for d in range(fx.shape[0]):
        if d != last and not _load_holds(s, d, fx, fy, fz, tau_x, tp, uy, uz, arm0, arm1, inv_w, L0, L1, F, mu,
                                         lmin):
            return d
    return -1


@kernel(cache=True)
def _bisect(last: int, fx: np.ndarray, fy: np.ndarray, fz: np.ndarray, tau_x: np.ndarray, tp: np.ndarray,
            uy: np.ndarray, uz: np.ndarray, arm0: float, arm1: float, inv_w: float, L0: float, L1: float, F: float,
            mu: float, lmin: float, log_lo: float, log_hi: float, iterations: int) -> tuple[float, int]:
    """``(margin, load that slipped last)`` of one grasp's loads: bisection on ``log s`` over
    ``[log_lo, log_hi]`` (``iterations`` steps) with every load tested at each step, the result
    ``exp(lo)``, 0 when even that slips.

    The same answer with fewer tests: the bisection is run on load ``last`` alone, then every load
    is tested at its result; when all hold there, every step had the outcome of the full test (a
    step that held lies below the result, where all hold; a step that failed failed for ``last``),
    each load's test being monotone in the scale. Else it is run again on the load that slipped
    (twice at most), then with every load at every step."""
    for _ in range(3):
        lo, hi = log_lo, log_hi
        for _ in range(iterations):
            mid = 0.5 * (lo + hi)
            if _load_holds(np.exp(mid), last, fx, fy, fz, tau_x, tp, uy, uz, arm0, arm1, inv_w, L0, L1, F, mu, lmin):
                lo = mid
            else:
                hi = mid
        s = np.exp(lo)
        d = _all_hold(s, last, fx, fy, fz, tau_x, tp, uy, uz, arm0, arm1, inv_w, L0, L1, F, mu, lmin)
        if d < 0:
            return s, last
        if lo == log_lo:  # no step held for ``last``, so none held for every load; exp(lo) slips
            return 0.0, d
        last = d
    lo, hi = log_lo, log_hi
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        d = _all_hold(np.exp(mid), last, fx, fy, fz, tau_x, tp, uy, uz, arm0, arm1, inv_w, L0, L1, F, mu, lmin)
        if d < 0:
            lo = mid
        else:
            hi, last = mid, d
    s = np.exp(lo)
    d = _all_hold(s, last, fx, fy, fz, tau_x, tp, uy, uz, arm0, arm1, inv_w, L0, L1, F, mu, lmin)
    return (s, last) if d < 0 else (0.0, d)


@kernel(cache=True)
def margin_of_loads(R: np.ndarray, p: np.ndarray, com: np.ndarray, f_part: np.ndarray, arm0: np.ndarray,
                    arm1: np.ndarray, inv_w: np.ndarray, L0: np.ndarray, L1: np.ndarray, F: float, mu: float,
                    lmin: float, log_lo: float, log_hi: float, iterations: int) -> np.ndarray:
    """(M,) the largest load scale each grasp holds (:func:`grasplan.grasps.wrench.gravity_margin`):
    per grasp (TCP axes ``R`` (M, 3, 3) and origin ``p`` (M, 3) in the part frame), the loads
    ``f_part`` (D, 3, part frame) and the centre of mass ``com`` in its TCP frame, then bisection on
    ``log s`` over ``[log_lo, log_hi]`` (``iterations`` steps), 0 when even the lower end slips. The
    load that slipped last is tried first (the same answer, fewer tests)."""
    M, D = R.shape[0], f_part.shape[0]
    out = np.zeros(M)
    fx, fy, fz, tau_x, tp, uy, uz = (np.empty(D), np.empty(D), np.empty(D), np.empty(D), np.empty(D), np.empty(D),
                                     np.empty(D))
    last = 0
    for m in range(M):
        _tcp_loads(m, R, p, com, f_part, fx, fy, fz, tau_x, tp, uy, uz)
        out[m], last = _bisect(last, fx, fy, fz, tau_x, tp, uy, uz, arm0[m], arm1[m], inv_w[m], L0[m], L1[m], F, mu,
                               lmin, log_lo, log_hi, iterations)
    return out


@kernel(cache=True)
def margin_summary(R: np.ndarray, p: np.ndarray, com: np.ndarray, f_part: np.ndarray, arm0: np.ndarray,
                   arm1: np.ndarray, inv_w: np.ndarray, L0: np.ndarray, L1: np.ndarray, F: float, mu: float,
                   lmin: float, log_lo: float, log_hi: float, iterations: int) -> tuple[int, float]:
    """``(grasps whose margin is >= 1, the largest margin)`` of :func:`margin_of_loads`'s margins,
    the same numbers without bisecting every grasp: a grasp is bisected only when it holds at
    ``min(1, largest so far)`` (a grasp that slips there has a smaller margin, the test being
    monotone in the scale)."""
    M, D = R.shape[0], f_part.shape[0]
    fx, fy, fz, tau_x, tp, uy, uz = (np.empty(D), np.empty(D), np.empty(D), np.empty(D), np.empty(D), np.empty(D),
                                     np.empty(D))
    count, best, last = 0, 0.0, 0
    for m in range(M):
        _tcp_loads(m, R, p, com, f_part, fx, fy, fz, tau_x, tp, uy, uz)
        if best > 0.0:
            d = _all_hold(min(1.0, best), last, fx, fy, fz, tau_x, tp, uy, uz, arm0[m], arm1[m], inv_w[m], L0[m],
                          L1[m], F, mu, lmin)
            if d >= 0:
                last = d
                continue
        s, last = _bisect(last, fx, fy, fz, tau_x, tp, uy, uz, arm0[m], arm1[m], inv_w[m], L0[m], L1[m], F, mu,
                          lmin, log_lo, log_hi, iterations)
        count += s >= 1.0
        best = max(best, s)
    return count, best
