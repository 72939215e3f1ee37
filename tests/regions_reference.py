"""Reference implementation of the regions method (``method="regions"``, :mod:`grasplan.candidates.regions`)
over every overlapping triangle pair: clipping and point-in-triangle probes instead of outlines and
scanlines. O(overlapping triangle pairs); the tests check that :func:`grasplan.candidates.regions.find_regions`
gives the same samples (tests/test_regions.py). Not used by the pipeline."""
from __future__ import annotations

import numpy as np

from grasplan.candidates.antipodal_base import clip_edges, perpendicular_frame, project_triangles
from grasplan.geometry.gridsearch import all_pairs_within
from grasplan.candidates.region_areas import area_pairs, convex_areas
from grasplan.candidates.region_creases import admitted_faces, near_creases
from grasplan.candidates.regions import finish_samples

#: face pairs per processing batch
_CHUNK = 65_536
#: size classes of faces: circumradii differ by at most this factor within a class
_CLASS_RATIO = 4.0


def _ccw(P: np.ndarray) -> np.ndarray:
    """Counter-clockwise 2D triangles (b, 3, 2)."""
    flip = ((P[:, 1, 0] - P[:, 0, 0]) * (P[:, 2, 1] - P[:, 0, 1])
            - (P[:, 1, 1] - P[:, 0, 1]) * (P[:, 2, 0] - P[:, 0, 0])) < 0
    return np.where(flip[:, None, None], P[:, [0, 2, 1]], P)


def pair_moments(Pi: np.ndarray, Pj: np.ndarray, tiny: float, *, vertices: bool = False):
    """Exact moments of the overlap of CCW 2D triangles ``Pi``, ``Pj`` (b, 3, 2) (Green's theorem over
    the parts of each triangle's edges inside the other; no vertex ordering).

    ``tiny`` (m) decides only which of two coinciding edges counts (``Pi``'s, closed; ``Pj``'s only
    strictly inside): far below any length that matters, far above float noise, so the moments are
    exact to ~tiny x perimeter. Triangles of one area have disjoint interiors, so summing these over
    every overlapping triangle pair of two areas gives the moments of ``proj(P) & proj(Q)`` whatever
    the tessellation. Returns (b, 6): area, int x, int y, int x^2, int y^2, int xy (zero for a
    zero-area overlap, e.g. triangles touching along an edge); with ``vertices=True`` also (b, 12, 2)
    clipped edge end points (overlap polygon corners, repeated; NaN where an edge is clipped away)."""
    out = np.zeros((len(Pi), 6))
    ends = []
    for S, T, sgn in ((Pi, Pj, -1.0), (Pj, Pi, 1.0)):
        xs, ys, xt, yt = S[..., 0], S[..., 1], T[..., 0], T[..., 1]
        ext, eyt = np.roll(xt, -1, axis=1) - xt, np.roll(yt, -1, axis=1) - yt
        rx, ry, t0, t1 = clip_edges(xs, ys, xt, yt, ext, eyt, sgn * tiny * np.hypot(ext, eyt))
        x0, y0 = xs + t0 * rx, ys + t0 * ry
        x1, y1 = xs + t1 * rx, ys + t1 * ry
        cr = x0 * y1 - x1 * y0
        out[:, 0] += 0.5 * cr.sum(axis=1)
        out[:, 1] += ((x0 + x1) * cr).sum(axis=1) / 6.0
        out[:, 2] += ((y0 + y1) * cr).sum(axis=1) / 6.0
        out[:, 3] += ((x0 * x0 + x0 * x1 + x1 * x1) * cr).sum(axis=1) / 12.0
        out[:, 4] += ((y0 * y0 + y0 * y1 + y1 * y1) * cr).sum(axis=1) / 12.0
        out[:, 5] += ((x0 * y1 + 2 * x0 * y0 + 2 * x1 * y1 + x1 * y0) * cr).sum(axis=1) / 24.0
        if vertices:
            gone = (t1 <= t0)[..., None]
            ends += [np.where(gone, np.nan, np.stack([x0, y0], -1)), np.where(gone, np.nan, np.stack([x1, y1], -1))]
    # a zero-area overlap (touching along an edge) leaves an open segment whose moments are meaningless
    span = np.maximum(np.ptp(Pi.reshape(len(Pi), 6), axis=1), np.ptp(Pj.reshape(len(Pj), 6), axis=1))
    out[np.abs(out[:, 0]) <= 4.0 * tiny * np.maximum(span, tiny)] = 0.0
    if vertices:
        return out, np.concatenate(ends, axis=1)
    return out


#: probes of the lattice test: a point is sampled when it and these offsets (x eps) all lie in the overlap
_PROBES = np.array([[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])


def _probe_bits(C: np.ndarray, q: np.ndarray, eps: float, tiny: float) -> np.ndarray:
    """(b,) int: bit k set when ``q + eps * _PROBES[k]`` lies in the closed CCW triangle ``C`` (b, 3, 2)
    (``tiny`` of slack, so a point on an edge shared by two triangles is found in at least one)."""
    x, y = C[..., 0], C[..., 1]
    ex, ey = np.roll(x, -1, axis=1) - x, np.roll(y, -1, axis=1) - y
    L = np.maximum(np.hypot(ex, ey), 1e-300)
    bits = np.zeros(len(q), dtype=np.int64)
    for k, (dx, dy) in enumerate(_PROBES):
        px, py = q[:, :1] + eps * dx, q[:, 1:] + eps * dy
        side = (ex * (py - y) - ey * (px - x)) / L
        bits |= (side >= -tiny).all(axis=1).astype(np.int64) << k
    return bits


def _size_classes(r: np.ndarray) -> np.ndarray:
    """(k,) int64 class of each radius ``r`` (k,): radii within a class differ by <= _CLASS_RATIO."""
    base = max(float(r.min()), 1e-300)
    return np.floor(np.log(np.maximum(r, base) / base) / np.log(_CLASS_RATIO)).astype(np.int64)


def _face_pairs_of_regions(P, Q, a, areas, start, count, members, geo, rad):
    """Face pairs ``(i, j)`` of areas ``P[k]``, ``Q[k]`` whose projections along ``a[k]`` may overlap.

    Small area pairs (``count[P] * count[Q] <= 256``) give every combination (vectorised); larger
    ones a 2D fixed-radius grid search per area pair, per size class of the faces (one loop step per region,
    not per face). Returns ``(i, j, k)`` int64 arrays."""
    nP, nQ = count[P], count[Q]
    prod = nP * nQ
    sm = np.flatnonzero(prod <= 256)
    out_i, out_j, out_k = [], [], []
    if len(sm):
        cnt = prod[sm]
        owner = np.repeat(sm, cnt)
        t = np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        out_i.append(members[start[P[owner]] + t // nQ[owner]])
        out_j.append(members[start[Q[owner]] + t % nQ[owner]])
        out_k.append(owner)
    for k in np.flatnonzero(prod > 256):
        fi = members[start[P[k]]:start[P[k]] + nP[k]]
        fj = members[start[Q[k]]:start[Q[k]] + nQ[k]]
        e1, e2 = perpendicular_frame(a[k:k + 1])
        E = np.vstack([e1, e2]).T                      # (3, 2)
        xi, xj = geo.c[fi] @ E, geo.c[fj] @ E
        ci, cj = _size_classes(rad[fi]), _size_classes(rad[fj])
        for qa in np.unique(ci):
            sa = np.flatnonzero(ci == qa)
            for qb in np.unique(cj):
                sb = np.flatnonzero(cj == qb)
                r = (rad[fi[sa]].max() + rad[fj[sb]].max()) * (1 + 1e-9)
                ii, jj = all_pairs_within(xi[sa], xj[sb], r)
                out_i.append(fi[sa[ii]])
                out_j.append(fj[sb[jj]])
                out_k.append(np.full(len(ii), k, dtype=np.int64))
    if not out_i:
        z = np.zeros(0, dtype=np.int64)
        return z, z, z
    return np.concatenate(out_i), np.concatenate(out_j), np.concatenate(out_k)


def find_regions_pairs(mesh, convex, geo, *, max_opening, beta_deg, mu, spacing, tol):
    """Reference implementation over triangle pairs (O(overlapping triangle pairs); tests compare the
    default :func:`grasplan.candidates.regions.find_regions` with it). Region samples (see the module docstring): ``contacts (n, 2, 3)``, ``normals (n, 2, 3)``,
    ``width (n,)``, ``faces (n, 2)``, ``region (n,)`` for :class:`grasplan.candidates.antipodal_base.Candidates`.

    ``geo``: the mesh's :class:`grasplan.candidates.antipodal_base.FaceGeometry`; lengths in metres."""
    admit, creases = admitted_faces(mesh, convex, geo, tol)
    areas = convex_areas(mesh, admit, tol)
    lab = areas.label
    ids = np.flatnonzero(lab >= 0)
    empty = (np.zeros((0, 2, 3)), np.zeros((0, 2, 3)), np.zeros(0), np.zeros((0, 2), np.int64), np.zeros(0, np.int64))
    if len(ids) < 2:
        return empty
    nA = len(areas.area)
    eps = tol.distance
    rad = np.linalg.norm(geo.tri - geo.c[:, None], axis=2).max(axis=1)        # face circumradius about its centroid
    members = ids[np.argsort(lab[ids], kind="stable")]                          # faces grouped by area
    count = np.bincount(lab[ids], minlength=nA)
    start = np.cumsum(count) - count
    def face_pairs():
        for P, Q, a in area_pairs(areas, geo, ids, max_opening=max_opening, beta_deg=beta_deg, tol=tol):
            if len(P):
                i, j, k = _face_pairs_of_regions(P, Q, a, areas, start, count, members, geo, rad)
                for s in range(0, len(i), _CHUNK):
                    kk = k[s:s + _CHUNK]
                    yield i[s:s + _CHUNK], j[s:s + _CHUNK], P[kk], Q[kk]

    tiny = 1e-6 * eps                    # decides coinciding edges only (see pair_moments)
    # ---- pass 1: face pairs whose projections overlap, and the exact moments of each region ----
    kept_i, kept_j, keys, mom = [], [], [], []
    for i, j, P, Q in face_pairs():
        a = areas.normal[P] - areas.normal[Q]
        a /= np.linalg.norm(a, axis=1, keepdims=True)
        e1, e2 = perpendicular_frame(a)
        org = areas.centroid[P]
        Pi, Pj = project_triangles(geo.tri[i], org, e1, e2), project_triangles(geo.tri[j], org, e1, e2)
        box = (np.maximum(Pi.min(axis=1), Pj.min(axis=1)) <= np.minimum(Pi.max(axis=1), Pj.max(axis=1)) + eps).all(axis=1)
        i, j, P, Q, Pi, Pj = i[box], j[box], P[box], Q[box], Pi[box], Pj[box]
        kept_i.append(i)
        kept_j.append(j)
        keys.append(P * nA + Q)
        mom.append(pair_moments(_ccw(Pi), _ccw(Pj), tiny))
    if not keys:
        return empty
    fi, fj = np.concatenate(kept_i), np.concatenate(kept_j)
    key = np.concatenate(keys)
    mom = np.concatenate(mom)
    order = np.lexsort((fj, fi, key))                 # deterministic: by region, then face pair
    fi, fj, key, mom = fi[order], fj[order], key[order], mom[order]
    rkey, region = np.unique(key, return_inverse=True)
    region = region.ravel()
    R = len(rkey)
    RP, RQ = rkey // nA, rkey % nA
    S = np.column_stack([np.bincount(region, weights=mom[:, c], minlength=R) for c in range(6)])
    # region frame: a, temporary basis (origin P's centroid), centroid, principal axes
    a = areas.normal[RP] - areas.normal[RQ]
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    t1, t2 = perpendicular_frame(a)
    A = S[:, 0]
    live = A > tol.area                  # regions whose projections really overlap
    A = np.where(live, A, 1.0)
    gx, gy = S[:, 1] / A, S[:, 2] / A
    cxx, cyy, cxy = S[:, 3] / A - gx * gx, S[:, 4] / A - gy * gy, S[:, 5] / A - gx * gy
    aniso = np.hypot(cxx - cyy, 2 * cxy) > 1e-6 * (cxx + cyy)
    theta = 0.5 * np.arctan2(2 * cxy, cxx - cyy)
    iso = np.flatnonzero(live & ~aniso)
    if len(iso):
        # isotropic second moments (squares, disks): the axis is the direction to the overlap's farthest
        # corner turned by 45 deg (a square gets an edge-aligned lattice), a pose-independent choice
        rows = np.flatnonzero(np.isin(region, iso))
        c_r, c_d, c_t = [], [], []
        for s in range(0, len(rows), _CHUNK):
            rr = rows[s:s + _CHUNK]
            r = region[rr]
            org = areas.centroid[RP[r]]
            Pi = _ccw(project_triangles(geo.tri[fi[rr]], org, t1[r], t2[r]))
            Pj = _ccw(project_triangles(geo.tri[fj[rr]], org, t1[r], t2[r]))
            m, V = pair_moments(Pi, Pj, tiny, vertices=True)
            V = V - np.stack([gx[r], gy[r]], axis=1)[:, None]
            d2 = np.where(np.isnan(V[..., 0]) | (m[:, :1] == 0), -1.0, (V ** 2).sum(axis=2))
            k = d2.argmax(axis=1)
            c_r.append(r)
            c_d.append(d2[np.arange(len(rr)), k])
            c_t.append(np.arctan2(V[np.arange(len(rr)), k, 1], V[np.arange(len(rr)), k, 0]))
        c_r, c_d, c_t = np.concatenate(c_r), np.concatenate(c_d), np.concatenate(c_t)
        far_d = np.full(R, -np.inf)
        np.maximum.at(far_d, c_r, c_d)
        # ties (a square's 4 corners): the smallest angle modulo 90 deg, whatever the chunking
        tied = c_d >= far_d[c_r] * (1 - 1e-9)
        far_t = np.full(R, np.inf)
        np.minimum.at(far_t, c_r[tied], np.mod(c_t[tied], np.pi / 2))
        theta[iso] = far_t[iso] + np.pi / 4
    ct, st = np.cos(theta)[:, None], np.sin(theta)[:, None]
    e1, e2 = ct * t1 + st * t2, -st * t1 + ct * t2
    g3 = areas.centroid[RP] + gx[:, None] * t1 + gy[:, None] * t2      # centroid, in the plane through P's centroid
    small = A < spacing * spacing
    # ---- pass 2: lattice points whose probes lie in the overlap (any triangle pair may hold each probe) ----
    s_reg, s_lat, s_bits, s_i, s_j = [], [], [], [], []
    for s in range(0, len(fi), _CHUNK):
        i, j, r = fi[s:s + _CHUNK], fj[s:s + _CHUNK], region[s:s + _CHUNK]
        Pi = project_triangles(geo.tri[i], g3[r], e1[r], e2[r])
        Pj = project_triangles(geo.tri[j], g3[r], e1[r], e2[r])
        lo = (np.maximum(Pi.min(axis=1), Pj.min(axis=1)) - 2 * eps) / spacing   # bounding box of the overlap, pitches
        hi = (np.minimum(Pi.max(axis=1), Pj.max(axis=1)) + 2 * eps) / spacing
        lo_i, lo_j = np.ceil(lo[:, 0]), np.ceil(lo[:, 1])
        hi_i, hi_j = np.floor(hi[:, 0]), np.floor(hi[:, 1])
        sm = small[r]        # sub-cell regions: only their centroid, lattice point (0, 0)
        lo_i, lo_j = np.where(sm, np.maximum(lo_i, 0), lo_i), np.where(sm, np.maximum(lo_j, 0), lo_j)
        hi_i, hi_j = np.where(sm, np.minimum(hi_i, 0), hi_i), np.where(sm, np.minimum(hi_j, 0), hi_j)
        ok = live[r]
        ni = np.where(ok, np.maximum(hi_i - lo_i + 1, 0), 0).astype(np.int64)
        nj = np.where(ok, np.maximum(hi_j - lo_j + 1, 0), 0).astype(np.int64)
        cnt = ni * nj
        tot = int(cnt.sum())
        if tot:
            owner = np.repeat(np.arange(len(i)), cnt)
            k = np.arange(tot) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            li = lo_i[owner] + k // nj[owner]
            lj = lo_j[owner] + k % nj[owner]
            q = np.column_stack([li * spacing, lj * spacing])
            bits = _probe_bits(_ccw(Pi[owner]), q, eps, tiny) & _probe_bits(_ccw(Pj[owner]), q, eps, tiny)
            hit = bits > 0
            o = owner[hit]
            s_reg.append(r[o])
            s_lat.append(np.column_stack([li[hit], lj[hit]]).astype(np.int64))
            s_bits.append(bits[hit])
            s_i.append(i[o])
            s_j.append(j[o])
    z = np.zeros(0, dtype=np.int64)
    reg, latk, bits, si, sj = (np.concatenate(x) if x else z for x in (s_reg, s_lat, s_bits, s_i, s_j))
    latk = latk.reshape(-1, 2)
    # one sample per (region, lattice index) whose probes are all covered; lifted with a face pair that
    # holds the point itself (the first such, in face order)
    o = np.lexsort((np.arange(len(reg)), 1 - (bits & 1), latk[:, 1], latk[:, 0], reg))
    reg, latk, bits, si, sj = reg[o], latk[o], bits[o], si[o], sj[o]
    first = np.ones(len(reg), dtype=bool)
    first[1:] = (reg[1:] != reg[:-1]) | (latk[1:] != latk[:-1]).any(axis=1)
    gid = np.cumsum(first) - 1
    cover = np.zeros(int(first.sum()), dtype=np.int64)
    np.bitwise_or.at(cover, gid, bits)
    keep = first & (cover[gid] == (1 << len(_PROBES)) - 1)
    reg, q, si, sj = reg[keep], latk[keep] * spacing, si[keep], sj[keep]
    # regions the lattice misses (thinner than the probes, or non-convex with the centroid outside): the
    # centroid of their largest triangle-pair overlap
    miss = np.setdiff1d(np.flatnonzero(live), reg)
    if len(miss):
        rows = np.flatnonzero(np.isin(region, miss) & (mom[:, 0] > tol.area))
        if len(rows):
            o = rows[np.lexsort((-mom[rows, 0], region[rows]))]
            o = o[np.r_[True, region[o][1:] != region[o][:-1]]]
            r = region[o]
            org = areas.centroid[RP[r]]
            c2 = np.column_stack([mom[o, 1], mom[o, 2]]) / mom[o, :1]          # temporary-frame coordinates
            x3 = org + c2[:, :1] * t1[r] + c2[:, 1:] * t2[r] - g3[r]
            qm = np.column_stack([np.einsum("ij,ij->i", x3, e1[r]), np.einsum("ij,ij->i", x3, e2[r])])
            reg, q = np.concatenate([reg, r]), np.vstack([q, qm])
            si, sj = np.concatenate([si, fi[o]]), np.concatenate([sj, fj[o]])
            o = np.argsort(reg, kind="stable")
            reg, q, si, sj = reg[o], q[o], si[o], sj[o]
    if len(reg) == 0:
        return empty
    # lift onto both faces along a
    x = g3[reg] + q[:, :1] * e1[reg] + q[:, 1:] * e2[reg]
    ax = a[reg]
    p0 = x + (np.einsum("ij,ij->i", geo.n[si], geo.tri[si, 0] - x) / np.einsum("ij,ij->i", geo.n[si], ax))[:, None] * ax
    p1 = x + (np.einsum("ij,ij->i", geo.n[sj], geo.tri[sj, 0] - x) / np.einsum("ij,ij->i", geo.n[sj], ax))[:, None] * ax
    ok = ~near_creases(p0, p1, creases)
    reg, si, sj, p0, p1 = reg[ok], si[ok], sj[ok], p0[ok], p1[ok]
    return finish_samples(reg, reg, si, sj, p0, p1, small, geo, mu, eps, max_opening, spacing, beta_deg)
