"""Stage 4, ``method="regions"``: antipodal contact *regions*, sampled at a fixed spacing.

A candidate of the paper (:mod:`grasplan.antipodal`) is one contact pair per pair of faces, so
the count grows with the square of the tessellation. Here a candidate is a sample of a *region*:

1. **Convex areas.** Convex faces are grouped into areas: edge-connected faces whose normals
   differ by less than ``tol.planar_deg`` (coplanar facets; a face of a curved surface is an area
   of its own). Area normal = area-weighted mean normal; ids are numbered by lowest face index, so
   they do not depend on the part's pose.
2. **Face pairs, streamed.** Pairs of convex faces whose normals are anti-parallel within beta and
   whose projections along the pair's closing axis overlap, found with the 6D line KD-tree of
   :mod:`grasplan.antipodal` (:func:`~grasplan.antipodal.stream_pairs`) in bounded chunks. Faces
   are split into size classes (circumradius, factor 4 apart) so that one large triangle does not
   widen the search radius of all the small ones.
3. **Regions.** The face pairs of one pair of areas ``(P, Q)`` (``P < Q``, contact 0 on P) form
   one region: the overlap of the two areas projected along ``a = (n_P - n_Q)/|n_P - n_Q|``.
   Its exact area, centroid and second moments are summed over the overlaps of its triangle pairs
   (Green's theorem over the clipped edges, as for the paper's contact placement), so they do not
   depend on the tessellation.
4. **Samples.** Each region is sampled on a square lattice of pitch ``spacing`` centred on its
   centroid and aligned with its principal axes (second moments; a region whose second moments are
   isotropic within 1e-6 keeps a fixed frame of ``a``). Lattice points inside the overlap of a
   triangle pair are lifted along ``a`` onto both triangles; a region whose lattice misses it
   entirely (thinner than the pitch, or non-convex with the centroid outside) gets the centroid of
   its largest triangle-pair overlap. The paper's rules then apply per sample: contacts facing
   away, closing axis inside both friction cones (``a`` is within beta/2 of both normals), width
   ``<= max_opening``.
5. **Curved surfaces.** Regions smaller than one lattice cell (``area < spacing^2``: single faces of
   curved surfaces, whose partner is not coplanar) give one sample each; those samples are
   deduplicated on the spacing grid (grasp-centre cell x closing-axis direction, by
   :func:`grasplan.thinning.thin_candidates` with ``axis_step_deg`` :data:`CURVED_AXIS_STEP_DEG`).

The result's ``region`` is the region id (index of the area pair in sorted ``(P, Q)`` order).
Memory is bounded by the face pairs whose projections overlap (a few per face) and the samples;
nothing grows with faces^2 or samples x faces.

Unlike the paper's rule, regions need the projections to overlap (contacts exactly opposite along
``a``); the paper's epsilon offset (closest points of disjoint triangles) is not used.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .antipodal import Candidates, _clip_edges, stream_pairs
from .thinning import thin_candidates
from .tolerance import Tolerance

#: closing-axis quantisation of the curved-surface deduplication, degrees
CURVED_AXIS_STEP_DEG = 10.0
#: face pairs per processing batch
_CHUNK = 65_536
#: size classes of faces: circumradii differ by at most this factor within a class
_CLASS_RATIO = 4.0


@dataclass(frozen=True)
class Areas:
    """Convex areas of a mesh.

    label : (m,) int64, area id per face (-1: not convex / degenerate)
    normal : (k, 3) float64, unit area normals
    centroid : (k, 3) float64, area centroids, m
    area : (k,) float64, m^2
    """

    label: np.ndarray
    normal: np.ndarray
    centroid: np.ndarray
    area: np.ndarray


def convex_areas(mesh: trimesh.Trimesh, convex: np.ndarray, tol: Tolerance) -> Areas:
    """Group convex faces into coplanar, edge-connected areas (no loop over faces)."""
    V = np.asarray(mesh.vertices, dtype=np.float64)
    F = np.asarray(mesh.faces, dtype=np.int64)
    m = len(F)
    tri = V[F]
    cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    dbl = np.linalg.norm(cr, axis=1)
    use = np.asarray(convex, dtype=bool) & (dbl > 0)
    n = np.zeros_like(cr)
    n[dbl > 0] = cr[dbl > 0] / dbl[dbl > 0, None]
    adj = np.asarray(mesh.face_adjacency, dtype=np.int64).reshape(-1, 2)
    ok = use[adj[:, 0]] & use[adj[:, 1]]
    adj = adj[ok]
    cosang = np.einsum("ij,ij->i", n[adj[:, 0]], n[adj[:, 1]])
    adj = adj[cosang >= np.cos(np.radians(tol.planar_deg))]
    g = coo_matrix((np.ones(len(adj)), (adj[:, 0], adj[:, 1])), shape=(m, m))
    _, comp = connected_components(g, directed=False)
    label = np.full(m, -1, dtype=np.int64)
    ids = np.flatnonzero(use)
    if len(ids) == 0:
        return Areas(label, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    # renumber by lowest face index (faces are visited in index order): pose-independent ids
    _, first, inv = np.unique(comp[ids], return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    label[ids] = rank[inv.ravel()]
    k = len(first)
    lab = label[ids]
    vec = np.column_stack([np.bincount(lab, weights=cr[ids, d], minlength=k) for d in range(3)])
    normal = vec / np.linalg.norm(vec, axis=1, keepdims=True)
    area = 0.5 * np.bincount(lab, weights=dbl[ids], minlength=k)
    c = tri[ids].mean(axis=1)
    centroid = np.column_stack([np.bincount(lab, weights=0.5 * dbl[ids] * c[:, d], minlength=k)
                                for d in range(3)]) / area[:, None]
    return Areas(label, normal, centroid, area)


def _frame(a: np.ndarray):
    """Orthonormal ``e1, e2`` (b, 3) perpendicular to unit ``a`` (b, 3) (a fixed function of a)."""
    helper = np.where(np.abs(a[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    e1 = np.cross(a, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(a, e1)


def _project(T: np.ndarray, origin: np.ndarray, e1: np.ndarray, e2: np.ndarray) -> np.ndarray:
    """Triangles (b, 3, 3) -> 2D (b, 3, 2) in the plane (origin, e1, e2)."""
    d = T - origin[:, None]
    return np.stack([np.einsum("bkj,bj->bk", d, e1), np.einsum("bkj,bj->bk", d, e2)], axis=-1)


def boundary_moments(S: np.ndarray, s_edge: np.ndarray, T: np.ndarray, t_edge: np.ndarray, *, closed: bool,
                     eps: float) -> np.ndarray:
    """Green's-theorem moments of the parts of the area-boundary edges of 2D triangles ``S`` that lie
    inside triangles ``T`` (both (b, 3, 2), counter-clockwise).

    ``s_edge``/``t_edge`` (b, 3) bool mark edges ``k -> k+1`` on their area's boundary. Summed over
    every overlapping triangle pair of two areas, with ``closed=True`` for P's edges in Q and
    ``closed=False`` for Q's edges in P, this is the exact overlap ``proj(P) & proj(Q)``: a boundary
    segment on T's area boundary counts when ``closed``, one on an edge shared inside T's area counts
    for exactly one of its two triangles (half-open by direction). Returns (b, 6): area, int x,
    int y, int x^2, int y^2, int xy."""
    xs, ys, xt, yt = S[..., 0], S[..., 1], T[..., 0], T[..., 1]
    ext, eyt = np.roll(xt, -1, axis=1) - xt, np.roll(yt, -1, axis=1) - yt
    lt = np.hypot(ext, eyt)
    half_open = (eyt > 0) | ((eyt == 0) & (ext > 0))
    shut = np.where(t_edge, closed, half_open)
    rx, ry, t0, t1 = _clip_edges(xs, ys, xt, yt, ext, eyt, np.where(shut, -eps, eps) * lt)
    t1 = np.where(s_edge, t1, t0)
    x0, y0 = xs + t0 * rx, ys + t0 * ry
    x1, y1 = xs + t1 * rx, ys + t1 * ry
    cr = x0 * y1 - x1 * y0
    out = np.empty((len(S), 6))
    out[:, 0] = 0.5 * cr.sum(axis=1)
    out[:, 1] = ((x0 + x1) * cr).sum(axis=1) / 6.0
    out[:, 2] = ((y0 + y1) * cr).sum(axis=1) / 6.0
    out[:, 3] = ((x0 * x0 + x0 * x1 + x1 * x1) * cr).sum(axis=1) / 12.0
    out[:, 4] = ((y0 * y0 + y0 * y1 + y1 * y1) * cr).sum(axis=1) / 12.0
    out[:, 5] = ((x0 * y1 + 2 * x0 * y0 + 2 * x1 * y1 + x1 * y0) * cr).sum(axis=1) / 24.0
    return out


def _ccw_edges(P: np.ndarray, edge: np.ndarray):
    """Counter-clockwise 2D triangles (b, 3, 2) and their edge flags (b, 3) (edge k: corner k -> k+1)."""
    flip = ((P[:, 1, 0] - P[:, 0, 0]) * (P[:, 2, 1] - P[:, 0, 1])
            - (P[:, 1, 1] - P[:, 0, 1]) * (P[:, 2, 0] - P[:, 0, 0])) < 0
    P = np.where(flip[:, None, None], P[:, [0, 2, 1]], P)
    edge = np.where(flip[:, None], edge[:, [2, 1, 0]], edge)
    return P, edge


def area_boundary_edges(F: np.ndarray, label: np.ndarray) -> np.ndarray:
    """(m, 3) bool: edge k (corner k -> k+1) of face i is on the boundary of its area (no other face
    of the same area shares it)."""
    e = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)
    e.sort(axis=1)
    lab = np.repeat(label, 3)
    key = np.column_stack([e, lab])
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return (cnt[inv.ravel()] < 2).reshape(-1, 3) | (lab < 0).reshape(-1, 3)


def _inside(P: np.ndarray, q: np.ndarray, eps: float, edge: np.ndarray) -> np.ndarray:
    """(b,) bool: points ``q`` (b, 2) inside CCW triangles ``P`` (b, 3, 2), at least ``eps`` from an edge
    of the region's boundary (points on a region's boundary are never sampled, whatever the
    tessellation; on an inner edge the point is found in both triangles and deduplicated)."""
    x, y = P[..., 0], P[..., 1]
    ex, ey = np.roll(x, -1, axis=1) - x, np.roll(y, -1, axis=1) - y
    L = np.maximum(np.hypot(ex, ey), 1e-300)
    side = (ex * (q[:, 1:] - y) - ey * (q[:, :1] - x)) / L
    return (side >= np.where(edge, eps, -eps)).all(axis=1)


def _size_classes(r: np.ndarray) -> np.ndarray:
    """(k,) int64 class of each radius ``r`` (k,): radii within a class differ by <= _CLASS_RATIO."""
    base = max(float(r.min()), 1e-300)
    return np.floor(np.log(np.maximum(r, base) / base) / np.log(_CLASS_RATIO)).astype(np.int64)


def _face_pairs_of_regions(P, Q, a, areas, start, count, members, geo, rad):
    """Face pairs ``(i, j)`` of areas ``P[k]``, ``Q[k]`` whose projections along ``a[k]`` may overlap.

    Small area pairs (``count[P] * count[Q] <= 256``) give every combination (vectorised); larger
    ones a 2D KD-tree search per area pair, per size class of the faces (one loop step per region,
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
        e1, e2 = _frame(a[k:k + 1])
        E = np.vstack([e1, e2]).T                      # (3, 2)
        xi, xj = geo.c[fi] @ E, geo.c[fj] @ E
        ci, cj = _size_classes(rad[fi]), _size_classes(rad[fj])
        for qa in np.unique(ci):
            sa = np.flatnonzero(ci == qa)
            ta = cKDTree(xi[sa])
            for qb in np.unique(cj):
                sb = np.flatnonzero(cj == qb)
                r = (rad[fi[sa]].max() + rad[fj[sb]].max()) * (1 + 1e-9)
                res = ta.sparse_distance_matrix(cKDTree(xj[sb]), r, output_type="ndarray")
                out_i.append(fi[sa[res["i"]]])
                out_j.append(fj[sb[res["j"]]])
                out_k.append(np.full(len(res), k, dtype=np.int64))
    if not out_i:
        z = np.zeros(0, dtype=np.int64)
        return z, z, z
    return np.concatenate(out_i), np.concatenate(out_j), np.concatenate(out_k)


def find_regions(mesh, convex, geo, *, max_opening, beta_deg, mu, spacing, tol):
    """Region samples (see the module docstring): ``contacts (n, 2, 3)``, ``normals (n, 2, 3)``,
    ``width (n,)``, ``faces (n, 2)``, ``region (n,)`` for :class:`grasplan.antipodal.Candidates`.

    ``geo``: the mesh's :class:`grasplan.antipodal._FaceGeometry`; lengths in metres."""
    areas = convex_areas(mesh, convex, tol)
    lab = areas.label
    ids = np.flatnonzero(lab >= 0)
    empty = (np.zeros((0, 2, 3)), np.zeros((0, 2, 3)), np.zeros(0), np.zeros((0, 2), np.int64), np.zeros(0, np.int64))
    if len(ids) < 2:
        return empty
    nA = len(areas.area)
    cosb = np.cos(np.radians(beta_deg))
    sin_half = np.sin(np.radians(beta_deg) / 2.0)
    eps = tol.distance
    rad = np.linalg.norm(geo.tri - geo.c[:, None], axis=2).max(axis=1)        # face circumradius about its centroid
    members = ids[np.argsort(lab[ids], kind="stable")]                          # faces grouped by area
    count = np.bincount(lab[ids], minlength=nA)
    start = np.cumsum(count) - count
    # area radius: largest distance of its faces' corners from the area centroid
    far = np.linalg.norm(geo.tri[ids] - areas.centroid[lab[ids]][:, None], axis=2).max(axis=1)
    arad = np.zeros(nA)
    np.maximum.at(arad, lab[ids], far)

    def face_pairs():
        for P, Q in stream_pairs(areas.centroid, areas.normal, arad, reach=max_opening, beta_deg=beta_deg, tol=tol):
            ok = np.einsum("ij,ij->i", areas.normal[P], areas.normal[Q]) <= -cosb + 1e-12
            P, Q = P[ok], Q[ok]
            a = areas.normal[P] - areas.normal[Q]
            a /= np.linalg.norm(a, axis=1, keepdims=True)
            d = areas.centroid[Q] - areas.centroid[P]
            ax = -np.einsum("ij,ij->i", d, a)                   # closing distance of the centroids
            rr = arad[P] + arad[Q]
            lateral = np.linalg.norm(d + ax[:, None] * a, axis=1)
            ok = (lateral <= rr + 4 * eps) & (ax >= -rr * sin_half - 4 * eps) & (ax <= max_opening + rr * sin_half + 4 * eps)
            P, Q, a = P[ok], Q[ok], a[ok]
            if len(P):
                i, j, k = _face_pairs_of_regions(P, Q, a, areas, start, count, members, geo, rad)
                for s in range(0, len(i), _CHUNK):
                    kk = k[s:s + _CHUNK]
                    yield i[s:s + _CHUNK], j[s:s + _CHUNK], P[kk], Q[kk]

    bedge = area_boundary_edges(np.asarray(mesh.faces, dtype=np.int64), lab)
    # ---- pass 1: face pairs whose projections overlap, and the moments of each region ----
    kept_i, kept_j, keys, mom = [], [], [], []
    for i, j, P, Q in face_pairs():
        a = areas.normal[P] - areas.normal[Q]
        a /= np.linalg.norm(a, axis=1, keepdims=True)
        e1, e2 = _frame(a)
        org = areas.centroid[P]
        Pi, Pj = _project(geo.tri[i], org, e1, e2), _project(geo.tri[j], org, e1, e2)
        box = (np.maximum(Pi.min(axis=1), Pj.min(axis=1)) <= np.minimum(Pi.max(axis=1), Pj.max(axis=1)) + eps).all(axis=1)
        i, j, P, Q, Pi, Pj = i[box], j[box], P[box], Q[box], Pi[box], Pj[box]
        kept_i.append(i)
        kept_j.append(j)
        keys.append(P * nA + Q)
        M = np.zeros((len(i), 6))
        bnd = (bedge[i].any(axis=1) | bedge[j].any(axis=1))
        if bnd.any():
            Si, Ei = _ccw_edges(Pi[bnd], bedge[i[bnd]])
            Sj, Ej = _ccw_edges(Pj[bnd], bedge[j[bnd]])
            M[bnd] = (boundary_moments(Si, Ei, Sj, Ej, closed=True, eps=eps)
                      + boundary_moments(Sj, Ej, Si, Ei, closed=False, eps=eps))
        mom.append(M)
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
    # region frame: a, temporary basis, centroid, principal axes
    a = areas.normal[RP] - areas.normal[RQ]
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    t1, t2 = _frame(a)
    A = S[:, 0]
    live = A > tol.area                  # regions whose projections really overlap
    A = np.where(live, A, 1.0)
    gx, gy = S[:, 1] / A, S[:, 2] / A
    cxx, cyy, cxy = S[:, 3] / A - gx * gx, S[:, 4] / A - gy * gy, S[:, 5] / A - gx * gy
    aniso = np.hypot(cxx - cyy, 2 * cxy) > 1e-6 * (cxx + cyy)
    theta = np.where(aniso, 0.5 * np.arctan2(2 * cxy, cxx - cyy), 0.0)
    ct, st = np.cos(theta)[:, None], np.sin(theta)[:, None]
    e1, e2 = ct * t1 + st * t2, -st * t1 + ct * t2
    g3 = areas.centroid[RP] + gx[:, None] * t1 + gy[:, None] * t2      # centroid, in the plane through P's centroid
    small = A < spacing * spacing
    # ---- pass 2: lattice points inside each triangle pair's overlap ----
    s_reg, s_q, s_i, s_j, s_lat = [], [], [], [], []
    for s in range(0, len(fi), _CHUNK):
        i, j, r = fi[s:s + _CHUNK], fj[s:s + _CHUNK], region[s:s + _CHUNK]
        Pi = _project(geo.tri[i], g3[r], e1[r], e2[r])
        Pj = _project(geo.tri[j], g3[r], e1[r], e2[r])
        lo = np.maximum(Pi.min(axis=1), Pj.min(axis=1)) / spacing      # bounding box of the overlap, pitches
        hi = np.minimum(Pi.max(axis=1), Pj.max(axis=1)) / spacing
        lo_i, lo_j = np.ceil(lo[:, 0] - 1e-9), np.ceil(lo[:, 1] - 1e-9)
        hi_i, hi_j = np.floor(hi[:, 0] + 1e-9), np.floor(hi[:, 1] + 1e-9)
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
            Ci, Ei = _ccw_edges(Pi[owner], bedge[i[owner]])
            Cj, Ej = _ccw_edges(Pj[owner], bedge[j[owner]])
            inside = _inside(Ci, q, eps, Ei) & _inside(Cj, q, eps, Ej)
            o = owner[inside]
            s_reg.append(r[o])
            s_q.append(q[inside])
            s_i.append(i[o])
            s_j.append(j[o])
            s_lat.append(np.column_stack([li[inside], lj[inside]]).astype(np.int64))
    if not s_reg:
        return empty
    reg, q, si, sj, latk = (np.concatenate(x) for x in (s_reg, s_q, s_i, s_j, s_lat))
    # one sample per (region, lattice index); the first face pair wins (points on shared edges)
    o = np.lexsort((np.arange(len(reg)), latk[:, 1], latk[:, 0], reg))
    reg, q, si, sj, latk = reg[o], q[o], si[o], sj[o], latk[o]
    keep = np.ones(len(reg), dtype=bool)
    keep[1:] = (reg[1:] != reg[:-1]) | (latk[1:] != latk[:-1]).any(axis=1)
    reg, q, si, sj = reg[keep], q[keep], si[keep], sj[keep]
    # lift onto both faces along a
    x = g3[reg] + q[:, :1] * e1[reg] + q[:, 1:] * e2[reg]
    ax = a[reg]
    p0 = x + (np.einsum("ij,ij->i", geo.n[si], geo.tri[si, 0] - x) / np.einsum("ij,ij->i", geo.n[si], ax))[:, None] * ax
    p1 = x + (np.einsum("ij,ij->i", geo.n[sj], geo.tri[sj, 0] - x) / np.einsum("ij,ij->i", geo.n[sj], ax))[:, None] * ax
    d = p1 - p0
    w = np.linalg.norm(d, axis=1)
    dn = d / np.maximum(w, 1e-300)[:, None]
    cosf = np.cos(np.arctan(mu)) - 1e-12
    ok = ((np.einsum("ij,ij->i", geo.n[si], -d) > 0) & (np.einsum("ij,ij->i", geo.n[sj], d) > 0) & (w > eps)
          & (np.einsum("ij,ij->i", -geo.n[si], dn) >= cosf) & (np.einsum("ij,ij->i", geo.n[sj], dn) >= cosf)
          & (w <= max_opening))
    reg, si, sj, p0, p1, w = reg[ok], si[ok], sj[ok], p0[ok], p1[ok], w[ok]
    contacts = np.stack([p0, p1], axis=1)
    normals = np.stack([geo.n[si], geo.n[sj]], axis=1)
    faces = np.stack([si, sj], axis=1).astype(np.int64)
    # curved surfaces: deduplicate the single samples of sub-cell regions on the spacing grid
    sm = small[reg]
    if sm.any():
        idx = np.flatnonzero(sm)
        sub = Candidates(contacts[idx], normals[idx], w[idx], faces[idx])
        drop = np.ones(len(idx), dtype=bool)
        drop[thin_candidates(sub, spacing=spacing, axis_step_deg=CURVED_AXIS_STEP_DEG)] = False
        keep = np.ones(len(reg), dtype=bool)
        keep[idx[drop]] = False
        contacts, normals, w, faces, reg = contacts[keep], normals[keep], w[keep], faces[keep], reg[keep]
    return contacts, normals, w, faces, reg.astype(np.int64)
