"""Regions method, steps 3-4: the overlap of two projected outlines, its lattice and its faces.

A region is ``proj(P) & proj(Q)`` along the closing axis. Only the areas' boundary segments are
used (:func:`region_edges`): the parts of P's outline inside Q and of Q's outline inside P
(:func:`inside_parts`: crossings found on a grid, inside/outside by the parity of a vertical ray)
give the overlap's area, centroid and second moments by Green's theorem (:func:`green_moments`),
exact whatever the triangulation of the areas' insides. Lattice rows are scanlines through both
outlines (:func:`row_intervals`); :func:`locate` finds the face of an area under a sample.
"""
from __future__ import annotations

import numpy as np

from ..geometry.grouping import expand, group_pairs, max3, min3, row_keys, unique_values


def region_edges(RP: np.ndarray, RQ: np.ndarray, eu: np.ndarray, ev: np.ndarray, estart: np.ndarray, ecount: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rows of the boundary segments of regions ``RP``/``RQ`` (local region index, polygon, from, to):
    P's edges as they are, Q's reversed (Q faces away from the closing axis)."""
    rP, kP = expand(ecount[RP])
    rQ, kQ = expand(ecount[RQ])
    eP, eQ = estart[RP][rP] + kP, estart[RQ][rQ] + kQ
    reg = np.concatenate([rP, rQ])
    poly = np.concatenate([np.zeros(len(rP), np.int64), np.ones(len(rQ), np.int64)])
    a = np.concatenate([eu[eP], ev[eQ]])
    b = np.concatenate([ev[eP], eu[eQ]])
    return reg, poly, a, b


def _cells(x0: np.ndarray, y0: np.ndarray, x1: np.ndarray, y1: np.ndarray, h: np.ndarray, pad: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Grid cells (pitch ``h`` per row) every segment touches: ``(row, cx, cy)`` (a cell is listed when
    the segment comes within ``pad`` x h of it). Dominant-axis walk: at most 2 cells per column."""
    swap = np.abs(y1 - y0) > np.abs(x1 - x0)
    ax0, ay0, ax1, ay1 = (np.where(swap, y0, x0), np.where(swap, x0, y0), np.where(swap, y1, x1), np.where(swap, x1, y1))
    lo, hi = np.minimum(ax0, ax1), np.maximum(ax0, ax1)
    c0 = np.floor(lo / h - pad).astype(np.int64)
    c1 = np.floor(hi / h + pad).astype(np.int64)
    row, k = expand(c1 - c0 + 1)
    col = c0[row] + k
    d = ax1 - ax0
    slope = np.where(d != 0, (ay1 - ay0) / np.where(d != 0, d, 1.0), 0.0)
    xa = np.maximum(lo[row], col * h[row])
    xb = np.minimum(hi[row], (col + 1) * h[row])
    ya = ay0[row] + (xa - ax0[row]) * slope[row]
    yb = ay0[row] + (xb - ax0[row]) * slope[row]
    r0 = np.floor(np.minimum(ya, yb) / h[row] - pad).astype(np.int64)
    r1 = np.floor(np.maximum(ya, yb) / h[row] + pad).astype(np.int64)
    row2, k2 = expand(r1 - r0 + 1)
    cx, cy = col[row2], r0[row2] + k2
    sw = swap[row[row2]]
    return row[row2], np.where(sw, cy, cx), np.where(sw, cx, cy)


def _cell_key(reg: np.ndarray, cx: np.ndarray, cy: np.ndarray) -> np.ndarray:
    """One int64 per (region, cell) (cells of one region are within a few million of each other)."""
    return row_keys(reg, cx, cy)


def green_moments(x0: np.ndarray, y0: np.ndarray, x1: np.ndarray, y1: np.ndarray) -> np.ndarray:
    """(k, 6) Green's-theorem moments of directed segments: area, x, y, x^2, y^2, xy."""
    cr = x0 * y1 - x1 * y0
    return np.column_stack([0.5 * cr, (x0 + x1) * cr / 6.0, (y0 + y1) * cr / 6.0,
                            (x0 * x0 + x0 * x1 + x1 * x1) * cr / 12.0, (y0 * y0 + y0 * y1 + y1 * y1) * cr / 12.0,
                            (x0 * y1 + 2 * x0 * y0 + 2 * x1 * y1 + x1 * y0) * cr / 24.0])


def inside_parts(reg: np.ndarray, poly: np.ndarray, x0: np.ndarray, y0: np.ndarray, x1: np.ndarray, y1: np.ndarray,
                 h: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For every directed boundary segment (rows; ``poly`` 0 = P, 1 = Q; counter-clockwise polygons),
    its parts inside the *other* polygon of its region: ``(row, xa, ya, xb, yb)`` sub-segments.

    Crossings with the other polygon's segments are found on a grid (pitch ``h`` per row's region);
    whether a segment starts inside is the parity of the other polygon's segments above its start
    (vertical ray, half-open in x), found per grid column."""
    n = len(reg)
    if n == 0:
        z = np.zeros(0)
        return np.zeros(0, dtype=np.int64), z, z, z, z
    pad = 1e-9
    # --- crossings: pairs of segments of the two polygons sharing a grid cell ---
    row, cx, cy = _cells(x0, y0, x1, y1, h, pad)
    key = _cell_key(reg[row], cx, cy)
    isP = poly[row] == 0
    ia, ib = group_pairs(key[isP], key[~isP])
    s, e = row[isP][ia], row[~isP][ib]
    if len(s):
        u = unique_values(s * n + e)
        s, e = u // n, u % n
    dsx, dsy = x1[s] - x0[s], y1[s] - y0[s]
    dex, dey = x1[e] - x0[e], y1[e] - y0[e]
    den = dsx * dey - dsy * dex
    wx, wy = x0[e] - x0[s], y0[e] - y0[s]
    with np.errstate(divide="ignore", invalid="ignore"):
        ts = (wx * dey - wy * dex) / den
        te = (wx * dsy - wy * dsx) / den
    hit = (den != 0) & (ts >= 0) & (ts < 1) & (te >= 0) & (te < 1)
    cr_row = np.concatenate([s[hit], e[hit]])
    cr_t = np.concatenate([ts[hit], te[hit]])
    # --- start status: parity of the other polygon's segments crossing the upward ray from the start ---
    cxs = np.floor(x0 / h).astype(np.int64)
    lo = np.floor(np.minimum(x0, x1) / h - pad).astype(np.int64)
    hi = np.floor(np.maximum(x0, x1) / h + pad).astype(np.int64)
    er, k = expand(hi - lo + 1)
    col = lo[er] + k
    inv = row_keys(np.concatenate([reg, reg[er]]), np.concatenate([1 - poly, poly[er]]), np.concatenate([cxs, col]))
    qi, ej = group_pairs(inv[:n], inv[n:])
    e = er[ej]
    px, py = x0[qi], y0[qi]
    straddle = (x0[e] <= px) != (x1[e] <= px)
    with np.errstate(divide="ignore", invalid="ignore"):
        yc = y0[e] + (px - x0[e]) * (y1[e] - y0[e]) / (x1[e] - x0[e])
    above = straddle & (yc > py)
    start_in = (np.bincount(qi[above], minlength=n) & 1).astype(bool)
    # --- sub-segments between crossings, alternating from the start status ---
    rows = np.concatenate([np.arange(n), cr_row, np.arange(n)])
    ts = np.concatenate([np.zeros(n), cr_t, np.ones(n)])
    o = np.lexsort((ts, rows))
    rows, ts = rows[o], ts[o]
    same = rows[1:] == rows[:-1]
    idx = np.flatnonzero(same)
    # rank of each sub-segment within its row
    first = np.r_[True, ~same]
    grp_start = np.maximum.accumulate(np.where(first, np.arange(len(rows)), 0))
    rank = idx - grp_start[idx]
    r = rows[idx]
    inside = start_in[r] ^ (rank & 1).astype(bool)
    idx, r = idx[inside], r[inside]
    ta, tb = ts[idx], ts[idx + 1]
    dx, dy = x1[r] - x0[r], y1[r] - y0[r]
    return r, x0[r] + ta * dx, y0[r] + ta * dy, x0[r] + tb * dx, y0[r] + tb * dy


def row_intervals(reg: np.ndarray, poly: np.ndarray, x0: np.ndarray, y0: np.ndarray, x1: np.ndarray, y1: np.ndarray,
                  spacing: float, offsets: tuple[float, ...], only0: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Scanlines ``y = j spacing + offsets[o]``: the intervals where all of P's and Q's polygons (for
    every offset) cover the line ``j``. Returns ``(region, j, xa, xb)``."""
    outs = []
    ymin, ymax = np.minimum(y0, y1), np.maximum(y0, y1)
    for k_off, off in enumerate(offsets):
        j0 = np.ceil((ymin - off) / spacing).astype(np.int64) - 1
        j1 = np.floor((ymax - off) / spacing).astype(np.int64) + 1
        j0 = np.where(only0, np.maximum(j0, 0), j0)
        j1 = np.where(only0, np.minimum(j1, 0), j1)
        row, k = expand(np.maximum(j1 - j0 + 1, 0))
        j = j0[row] + k
        y = j * spacing + off
        ok = (y0[row] <= y) != (y1[row] <= y)                     # half-open: each vertex counted once
        row, j, y = row[ok], j[ok], y[ok]
        x = x0[row] + (y - y0[row]) * (x1[row] - x0[row]) / (y1[row] - y0[row])
        outs.append((reg[row], j, np.full(len(row), k_off), poly[row], x))
    reg_, j, oi, pl, x = (np.concatenate(v) for v in zip(*outs))
    # group the crossings by (region, j, offset, polygon): one int64 key, mostly in order already
    group = row_keys(reg_, j, oi, pl)
    o = np.argsort(group, kind="stable")
    group, reg_, j, x = group[o], reg_[o], j[o], x[o]
    gstart = np.flatnonzero(np.r_[True, group[1:] != group[:-1]]) if len(group) else np.zeros(0, np.int64)
    size = np.diff(np.r_[gstart, len(group)])
    # only groups of more than two crossings need their x sorted (a pair is one interval: min, max)
    big = np.flatnonzero(size > 2)
    if len(big):
        own, k = expand(size[big])
        idx = gstart[big][own] + k
        x[idx] = x[idx][np.lexsort((x[idx], own))]
    # even-odd pairing within each group (a group of odd size is dropped)
    own, k = expand(np.where(size % 2 == 0, size // 2, 0))
    st = gstart[own] + 2 * k
    xa, xb = np.minimum(x[st], x[st + 1]), np.maximum(x[st], x[st + 1])
    ireg, ij = reg_[st], j[st]
    need = len(offsets) * 2
    # lines (region, j): covered where all `need` groups cover. A line of exactly one interval per
    # group: [max start, min end]; any other line: a sweep over its interval ends
    lstart = np.flatnonzero(np.r_[True, (ireg[1:] != ireg[:-1]) | (ij[1:] != ij[:-1])]) if len(st) else st
    n_int = np.diff(np.r_[lstart, len(st)])
    n_single = np.add.reduceat((size[own] == 2).astype(np.int64), lstart) if len(st) else n_int
    simple = (n_int == need) & (n_single == need)
    out_reg, out_j, out_a, out_b = [], [], [], []
    if simple.any():
        ls = lstart[simple]
        a_max = np.maximum.reduceat(xa, lstart)[simple] if len(st) else xa
        b_min = np.minimum.reduceat(xb, lstart)[simple] if len(st) else xb
        hit = a_max < b_min
        out_reg.append(ireg[ls][hit])
        out_j.append(ij[ls][hit])
        out_a.append(a_max[hit])
        out_b.append(b_min[hit])
    if (~simple).any():
        own_l, k_l = expand(n_int[~simple])
        sel = lstart[~simple][own_l] + k_l
        s_reg, s_j, s_a, s_b = ireg[sel], ij[sel], xa[sel], xb[sel]
        # coverage count: +1 at each interval start, -1 at each end; covered by all where count == need
        ev_reg = np.concatenate([s_reg, s_reg])
        ev_j = np.concatenate([s_j, s_j])
        ev_x = np.concatenate([s_a, s_b])
        ev_d = np.concatenate([np.ones(len(sel), np.int64), -np.ones(len(sel), np.int64)])
        line = row_keys(ev_reg, ev_j)                  # ordered as (region, j)
        o = np.lexsort((ev_d, ev_x, line))
        ev_reg, ev_j, ev_x, ev_d, line = ev_reg[o], ev_j[o], ev_x[o], ev_d[o], line[o]
        cnt = np.cumsum(ev_d)
        full = np.flatnonzero((cnt[:-1] == need) & (line[1:] == line[:-1]))
        out_reg.append(ev_reg[full])
        out_j.append(ev_j[full])
        out_a.append(ev_x[full])
        out_b.append(ev_x[full + 1])
    if not out_reg:
        z = np.zeros(0)
        return np.zeros(0, np.int64), np.zeros(0, np.int64), z, z
    r_, j_, a_, b_ = (np.concatenate(v) for v in (out_reg, out_j, out_a, out_b))
    o = np.lexsort((a_, j_, r_))
    return r_[o], j_[o], a_[o], b_[o]


def locate(qreg: np.ndarray, q: np.ndarray, face_rows: np.ndarray, tri2: np.ndarray) -> np.ndarray:
    """Index into ``face_rows`` of a triangle holding each point: ``q`` (k, 2) of region ``qreg``;
    ``face_rows`` = (region, face) rows with 2D triangles ``tri2`` (r, 3, 2) in the same frames. Picks
    the most interior candidate (largest smallest barycentric), so a point on a shared edge gets one."""
    fr_reg = face_rows
    lo, hi = min3(tri2), max3(tri2)
    # columns of width = the region's mean triangle width
    w = hi[:, 0] - lo[:, 0]
    nreg = int(max(fr_reg.max(initial=-1), qreg.max(initial=-1))) + 1
    cw = np.bincount(fr_reg, weights=w, minlength=nreg) / np.maximum(np.bincount(fr_reg, minlength=nreg), 1)
    cw = np.maximum(cw, 1e-12)
    c0 = np.floor(lo[:, 0] / cw[fr_reg] - 1e-9).astype(np.int64)
    c1 = np.floor(hi[:, 0] / cw[fr_reg] + 1e-9).astype(np.int64)
    row, k = expand(c1 - c0 + 1)
    inv = row_keys(np.concatenate([qreg, fr_reg[row]]),
                    np.concatenate([np.floor(q[:, 0] / cw[qreg]).astype(np.int64), c0[row] + k]))
    qi, fj = group_pairs(inv[:len(q)], inv[len(q):])
    f = row[fj]
    ok = (q[qi, 1] >= lo[f, 1] - 1e-9 * cw[qreg[qi]]) & (q[qi, 1] <= hi[f, 1] + 1e-9 * cw[qreg[qi]])
    qi, f = qi[ok], f[ok]
    T = tri2[f]
    px, py = q[qi, 0], q[qi, 1]
    x, y = T[..., 0], T[..., 1]
    ex, ey = np.roll(x, -1, axis=1) - x, np.roll(y, -1, axis=1) - y
    L = np.maximum(np.hypot(ex, ey), 1e-300)
    area2 = ex[:, 0] * ey[:, 2] * -1 + ey[:, 0] * ex[:, 2]          # cross(e0, -e2) sign = orientation
    sgn = np.where(area2 >= 0, 1.0, -1.0)
    side = sgn[:, None] * (ex * (py[:, None] - y) - ey * (px[:, None] - x)) / L
    score = min3(side)
    best = np.full(len(q), -np.inf)
    np.maximum.at(best, qi, score)
    pick = np.full(len(q), -1, dtype=np.int64)
    win = score >= best[qi]
    o = np.lexsort((f[win], qi[win]))
    qw, fw = qi[win][o], f[win][o]
    firstw = np.r_[True, qw[1:] != qw[:-1]]
    pick[qw[firstw]] = fw[firstw]
    return pick
