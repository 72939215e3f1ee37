"""Stage 4, ``method="regions"``: antipodal contact *regions*, sampled at a fixed spacing.

A candidate of the paper (:mod:`grasplan.antipodal`) is one contact pair per pair of faces, so
the count grows with the square of the tessellation. Here a candidate is a sample of a *region*:

1. **Convex areas.** Faces that hold convex points are grouped into areas: edge-connected faces
   whose normals differ by less than ``tol.planar_deg`` (coplanar facets; a face of a curved surface
   is an area of its own). Area normal = area-weighted mean normal; ids are numbered by lowest face
   index, so they do not depend on the part's pose. A face is admitted when the convexity stage
   calls it convex, or when it is concave only because neighbours rise above it across some (not
   all) of its edges -- a shallow crease the BLM does not split (within ``180 - gamma``); samples
   closer than :data:`CONCAVE_MARGIN` (the BLM's 0.1 mm strip) to such a rising edge are dropped.
2. **Candidate regions, streamed.** Pairs of areas ``(P, Q)`` (``P < Q``, contact 0 on P) whose
   normals are anti-parallel within beta and whose discs (centroid, largest corner distance) can
   overlap along the closing axis ``a = (n_P - n_Q)/|n_P - n_Q|`` within ``max_opening``: the 6D
   line search of :func:`grasplan.antipodal.stream_pairs` over *areas*, in bounded chunks.
3. **Exact overlap from the outlines.** A region is ``proj(P) & proj(Q)`` along ``a``. Only the
   areas' boundary edges are used: the parts of P's outline inside Q and of Q's outline inside P
   (crossings found on a grid, inside/outside by the parity of a vertical ray) give the overlap's
   area, centroid and second moments by Green's theorem -- exact, so they do not depend on how the
   inside of an area is triangulated. Q's projection is shifted by :data:`_SHIFT` x the part size
   along a fixed direction so that coinciding outlines (every prism) become generic.
4. **Samples.** Each region is sampled on a square lattice of pitch ``spacing`` centred on its
   centroid and aligned with its principal axes (isotropic second moments -- squares, disks -- take
   the direction to the overlap's farthest corner, turned by 45 deg). A lattice point is a sample
   when the cross of points ``+-eps`` around it (``eps = tol.distance``) lies in both projections
   (scanlines at ``y - eps, y, y + eps``, even-odd intervals), so points on an outline are never
   sampled whatever the tessellation. A region the lattice misses (thinner than a pitch and off
   it) gets the middle of its widest interval on the centroid's scanline; a strip's centroid line
   is always sampled. Each sample is located in a face of P and of Q (2D point location in each
   area's plane) and lifted along ``a`` onto both. The paper's rules then apply per sample:
   contacts facing away, closing axis inside both friction cones (``a`` is within beta/2 of both
   normals), width ``<= max_opening``.
5. **Curved surfaces.** Regions smaller than one lattice cell (``area < spacing^2``: single faces of
   curved surfaces, whose partner is not coplanar) give one sample each (their centroid); those
   samples are deduplicated on the spacing grid (grasp-centre cell x closing-axis direction, by
   :func:`grasplan.thinning.thin_candidates` with ``axis_step_deg`` :data:`CURVED_AXIS_STEP_DEG`).

The result's ``region`` is the region id (rank of the area pair among the regions with a
positive overlap, in sorted ``(P, Q)`` order). Cost and memory follow the areas' outline lengths
and the samples, processed in batches of :data:`_EDGE_CHUNK` boundary edges; nothing grows with
faces^2, samples x faces or the triangle count of an area's interior.

:func:`find_regions_pairs` is an independent reference implementation of the same definition over
every overlapping triangle pair (clipping + point-in-triangle probes); the tests check that both
give the same samples. It costs O(overlapping triangle pairs) and is not used by the pipeline.

Unlike the paper's rule, regions need the projections to overlap (contacts exactly opposite along
``a``); the paper's epsilon offset (closest points of disjoint triangles) is not used.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .antipodal import Candidates, _clip_edges, stream_pairs
from .convexity import mesh_edge_adjacency
from .gridsearch import all_pairs_within, any_within
from .meshdata import connected_components, edge_adjacency
from .thinning import thin_candidates
from .tolerance import Tolerance

if TYPE_CHECKING:  # trimesh (and scipy) load with the first mesh; importing this module stays cheap
    import trimesh

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


def convex_areas(mesh: trimesh.Trimesh, convex: np.ndarray, tol: Tolerance, adjacency=None, geo=None) -> Areas:
    """Group convex faces into coplanar, edge-connected areas (no loop over faces). ``adjacency``: the
    mesh's :func:`grasplan.convexity.edge_adjacency`, if already known; ``geo``: its
    :class:`grasplan.antipodal._FaceGeometry`, if already known (its triangles are reused)."""
    F = np.asarray(mesh.faces, dtype=np.int64)
    m = len(F)
    tri = geo.tri if geo is not None else np.asarray(mesh.vertices, dtype=np.float64)[F]
    cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    dbl = np.linalg.norm(cr, axis=1)
    use = np.asarray(convex, dtype=bool) & (dbl > 0)
    n = np.zeros_like(cr)
    n[dbl > 0] = cr[dbl > 0] / dbl[dbl > 0, None]
    adj = (edge_adjacency(F) if adjacency is None else adjacency)[0]
    ok = use[adj[:, 0]] & use[adj[:, 1]]
    adj = adj[ok]
    cosang = np.einsum("ij,ij->i", n[adj[:, 0]], n[adj[:, 1]])
    adj = adj[cosang >= np.cos(np.radians(tol.planar_deg))]
    _, comp = connected_components(m, adj)
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
    c = geo.c[ids] if geo is not None else tri[ids].mean(axis=1)
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
        rx, ry, t0, t1 = _clip_edges(xs, ys, xt, yt, ext, eyt, sgn * tiny * np.hypot(ext, eyt))
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


def _flat_keys(cols: list) -> np.ndarray | None:
    """The rows' flat index in the box of their ranges (lexicographic order; equal rows, equal
    keys), or None when that box does not fit an int64. ``cols``: non-empty int64 columns."""
    lo = [c.min() for c in cols]
    dims = [int(c.max() - m) + 1 for c, m in zip(cols, lo)]
    if np.prod(np.array(dims, dtype=np.float64)) >= 2.0**62:
        return None
    return np.ravel_multi_index([c - m for c, m in zip(cols, lo)], dims)


def _row_ids(*cols) -> np.ndarray:
    """(k,) int64 dense ids of the distinct rows of integer columns (equal rows, equal ids): one flat
    int64 key when the ranges fit (a 1D unique is ~10x faster than ``unique(axis=0)``)."""
    cols = [np.asarray(c, dtype=np.int64) for c in cols]
    if len(cols[0]) == 0:
        return np.zeros(0, dtype=np.int64)
    flat = _flat_keys(cols)
    if flat is not None:
        _, inv = np.unique(flat, return_inverse=True)
    else:
        _, inv = np.unique(np.column_stack(cols), axis=0, return_inverse=True)
    return inv.ravel().astype(np.int64)


def _row_keys(*cols) -> np.ndarray:
    """(k,) int64 keys of the rows of integer columns, ordered as the rows lexicographically (equal
    rows, equal keys): the flat index when the ranges fit, else :func:`_row_ids`. Enough for sorting
    and matching (:func:`_group_pairs`) without the dense renumbering's extra sort."""
    cols = [np.asarray(c, dtype=np.int64) for c in cols]
    if len(cols[0]) == 0:
        return np.zeros(0, dtype=np.int64)
    flat = _flat_keys(cols)
    return flat if flat is not None else _row_ids(*cols)


def area_boundary_edges(F: np.ndarray, label: np.ndarray) -> np.ndarray:
    """(m, 3) bool: edge k (corner k -> k+1) of face i is on the boundary of its area (no other face
    of the same area shares it)."""
    e = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)
    e.sort(axis=1)
    lab = np.repeat(label, 3)
    inv = _row_ids(e[:, 0], e[:, 1], lab)
    cnt = np.bincount(inv)
    return (cnt[inv] < 2).reshape(-1, 3) | (lab < 0).reshape(-1, 3)


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
        e1, e2 = _frame(a[k:k + 1])
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
    default :func:`find_regions` with it). Region samples (see the module docstring): ``contacts (n, 2, 3)``, ``normals (n, 2, 3)``,
    ``width (n,)``, ``faces (n, 2)``, ``region (n,)`` for :class:`grasplan.antipodal.Candidates`.

    ``geo``: the mesh's :class:`grasplan.antipodal._FaceGeometry`; lengths in metres."""
    admit, creases = _admitted(mesh, convex, geo, tol)
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
        for P, Q, a in _area_pairs(areas, geo, ids, max_opening=max_opening, beta_deg=beta_deg, tol=tol):
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
        e1, e2 = _frame(a)
        org = areas.centroid[P]
        Pi, Pj = _project(geo.tri[i], org, e1, e2), _project(geo.tri[j], org, e1, e2)
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
    t1, t2 = _frame(a)
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
            Pi = _ccw(_project(geo.tri[fi[rr]], org, t1[r], t2[r]))
            Pj = _ccw(_project(geo.tri[fj[rr]], org, t1[r], t2[r]))
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
        Pi = _project(geo.tri[i], g3[r], e1[r], e2[r])
        Pj = _project(geo.tri[j], g3[r], e1[r], e2[r])
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
    ok = ~_near_creases(p0, p1, creases)
    reg, si, sj, p0, p1 = reg[ok], si[ok], sj[ok], p0[ok], p1[ok]
    return _finish(reg, reg, si, sj, p0, p1, small, geo, mu, eps, max_opening, spacing)


# ============================================================ boundary-edge method (the default)
#: Q's projection is shifted by this fraction of the part scale along a fixed generic direction of the
#: region's temporary frame, so coinciding outlines (every prism) become generic; moves results by
#: about this fraction of the part size (far below the 1e-9 m the tests ask for)
_SHIFT = 1e-10
_SHIFT_DIR = (np.cos(1.0), np.sin(1.0))
#: boundary-edge rows per region batch (bounds every temporary array)
_EDGE_CHUNK = 400_000


def _area_pairs(areas: Areas, geo, ids: np.ndarray, *, max_opening: float, beta_deg: float, tol):
    """Chunks ``(P, Q, a)`` of area pairs that can form a region: normals anti-parallel within beta
    and the two areas' discs (centroid, radius = farthest face corner) able to overlap along the
    closing axis ``a = (n_P - n_Q) / |n_P - n_Q|`` within ``max_opening``. ``ids``: the faces that
    belong to an area. Streams the 6D line search (:func:`grasplan.antipodal.stream_pairs`)."""
    nA = len(areas.area)
    lab = areas.label
    cosb = np.cos(np.radians(beta_deg))
    sin_half = np.sin(np.radians(beta_deg) / 2.0)
    eps = tol.distance
    # area radius: largest distance of its faces' corners from the area centroid
    arad = _group_max(lab[ids], _max3(np.linalg.norm(geo.tri[ids] - areas.centroid[lab[ids]][:, None], axis=2)), nA)
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
        yield P[ok], Q[ok], a[ok]


def _max3(a: np.ndarray) -> np.ndarray:
    """``a.max(axis=1)`` for ``a`` (k, 3, ...) by two elementwise maxima (NumPy reduces a length-3 axis slowly)."""
    return np.maximum(np.maximum(a[:, 0], a[:, 1]), a[:, 2])


def _min3(a: np.ndarray) -> np.ndarray:
    """``a.min(axis=1)`` for ``a`` (k, 3, ...), see :func:`_max3`."""
    return np.minimum(np.minimum(a[:, 0], a[:, 1]), a[:, 2])


def _group_max(key: np.ndarray, val: np.ndarray, n: int) -> np.ndarray:
    """(n,) max of ``val`` per ``key`` (0 where a key has none), by one sort (``np.maximum.at`` is slow)."""
    out = np.zeros(n)
    if len(key) == 0:
        return out
    o = np.argsort(key, kind="stable")
    k = key[o]
    st = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    out[k[st]] = np.maximum.reduceat(val[o], st)
    return out


def _expand(cnt: np.ndarray):
    """``(owner, k)``: for every owner o, ``k = 0 .. cnt[o] - 1``."""
    cnt = np.asarray(cnt, dtype=np.int64)
    owner = np.repeat(np.arange(len(cnt)), cnt)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    return owner, k


def _cells(x0, y0, x1, y1, h, pad):
    """Grid cells (pitch ``h`` per row) every segment touches: ``(row, cx, cy)`` (a cell is listed when
    the segment comes within ``pad`` x h of it). Dominant-axis walk: at most 2 cells per column."""
    swap = np.abs(y1 - y0) > np.abs(x1 - x0)
    ax0, ay0, ax1, ay1 = (np.where(swap, y0, x0), np.where(swap, x0, y0), np.where(swap, y1, x1), np.where(swap, x1, y1))
    lo, hi = np.minimum(ax0, ax1), np.maximum(ax0, ax1)
    c0 = np.floor(lo / h - pad).astype(np.int64)
    c1 = np.floor(hi / h + pad).astype(np.int64)
    row, k = _expand(c1 - c0 + 1)
    col = c0[row] + k
    d = ax1 - ax0
    slope = np.where(d != 0, (ay1 - ay0) / np.where(d != 0, d, 1.0), 0.0)
    xa = np.maximum(lo[row], col * h[row])
    xb = np.minimum(hi[row], (col + 1) * h[row])
    ya = ay0[row] + (xa - ax0[row]) * slope[row]
    yb = ay0[row] + (xb - ax0[row]) * slope[row]
    r0 = np.floor(np.minimum(ya, yb) / h[row] - pad).astype(np.int64)
    r1 = np.floor(np.maximum(ya, yb) / h[row] + pad).astype(np.int64)
    row2, k2 = _expand(r1 - r0 + 1)
    cx, cy = col[row2], r0[row2] + k2
    sw = swap[row[row2]]
    return row[row2], np.where(sw, cy, cx), np.where(sw, cx, cy)


def _group_pairs(key_a, key_b):
    """All ``(ia, ib)`` with ``key_a[ia] == key_b[ib]`` (int64 keys), by sorting."""
    oa, ob = np.argsort(key_a, kind="stable"), np.argsort(key_b, kind="stable")
    ka, kb = key_a[oa], key_b[ob]
    lo = np.searchsorted(kb, ka, side="left")
    hi = np.searchsorted(kb, ka, side="right")
    ia, k = _expand(hi - lo)
    return oa[ia], ob[lo[ia] + k]


def _cell_key(reg, cx, cy):
    """One int64 per (region, cell) (cells of one region are within a few million of each other)."""
    return _row_keys(reg, cx, cy)


def _green(x0, y0, x1, y1):
    """(k, 6) Green's-theorem moments of directed segments: area, x, y, x^2, y^2, xy."""
    cr = x0 * y1 - x1 * y0
    return np.column_stack([0.5 * cr, (x0 + x1) * cr / 6.0, (y0 + y1) * cr / 6.0,
                            (x0 * x0 + x0 * x1 + x1 * x1) * cr / 12.0, (y0 * y0 + y0 * y1 + y1 * y1) * cr / 12.0,
                            (x0 * y1 + 2 * x0 * y0 + 2 * x1 * y1 + x1 * y0) * cr / 24.0])


def _inside_parts(reg, poly, x0, y0, x1, y1, h):
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
    ia, ib = _group_pairs(key[isP], key[~isP])
    s, e = row[isP][ia], row[~isP][ib]
    if len(s):
        u = np.unique(s * n + e)
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
    er, k = _expand(hi - lo + 1)
    col = lo[er] + k
    inv = _row_keys(np.concatenate([reg, reg[er]]), np.concatenate([1 - poly, poly[er]]), np.concatenate([cxs, col]))
    qi, ej = _group_pairs(inv[:n], inv[n:])
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


def _row_intervals(reg, poly, x0, y0, x1, y1, spacing, offsets, only0):
    """Scanlines ``y = j spacing + offsets[o]``: the intervals where all of P's and Q's polygons (for
    every offset) cover the line ``j``. Returns ``(region, j, xa, xb)``."""
    outs = []
    ymin, ymax = np.minimum(y0, y1), np.maximum(y0, y1)
    for oi, off in enumerate(offsets):
        j0 = np.ceil((ymin - off) / spacing).astype(np.int64) - 1
        j1 = np.floor((ymax - off) / spacing).astype(np.int64) + 1
        j0 = np.where(only0, np.maximum(j0, 0), j0)
        j1 = np.where(only0, np.minimum(j1, 0), j1)
        row, k = _expand(np.maximum(j1 - j0 + 1, 0))
        j = j0[row] + k
        y = j * spacing + off
        ok = (y0[row] <= y) != (y1[row] <= y)                     # half-open: each vertex counted once
        row, j, y = row[ok], j[ok], y[ok]
        x = x0[row] + (y - y0[row]) * (x1[row] - x0[row]) / (y1[row] - y0[row])
        outs.append((reg[row], j, np.full(len(row), oi), poly[row], x))
    reg_, j, oi, pl, x = (np.concatenate(v) for v in zip(*outs))
    o = np.lexsort((x, pl, oi, j, reg_))
    reg_, j, oi, pl, x = reg_[o], j[o], oi[o], pl[o], x[o]
    # even-odd pairing within each (region, j, offset, polygon) group
    g = np.r_[True, (reg_[1:] != reg_[:-1]) | (j[1:] != j[:-1]) | (oi[1:] != oi[:-1]) | (pl[1:] != pl[:-1])]
    gid = np.cumsum(g) - 1
    gstart = np.flatnonzero(g)
    rank = np.arange(len(x)) - gstart[gid]
    size = np.bincount(gid)
    even = (size[gid] % 2 == 0)
    st = np.flatnonzero(even & (rank % 2 == 0))
    need = len(offsets) * 2
    # coverage count: +1 at each interval start, -1 at each end; covered by all where count == need
    ev_reg = np.concatenate([reg_[st], reg_[st]])
    ev_j = np.concatenate([j[st], j[st]])
    ev_x = np.concatenate([x[st], x[st + 1]])
    ev_d = np.concatenate([np.ones(len(st), np.int64), -np.ones(len(st), np.int64)])
    o = np.lexsort((ev_d, ev_x, ev_j, ev_reg))
    ev_reg, ev_j, ev_x, ev_d = ev_reg[o], ev_j[o], ev_x[o], ev_d[o]
    cnt = np.cumsum(ev_d)
    full = np.flatnonzero((cnt[:-1] == need) & (ev_reg[1:] == ev_reg[:-1]) & (ev_j[1:] == ev_j[:-1]))
    return ev_reg[full], ev_j[full], ev_x[full], ev_x[full + 1]


def _locate(qreg, q, face_rows, tri2):
    """Index into ``face_rows`` of a triangle holding each point: ``q`` (k, 2) of region ``qreg``;
    ``face_rows`` = (region, face) rows with 2D triangles ``tri2`` (r, 3, 2) in the same frames. Picks
    the most interior candidate (largest smallest barycentric), so a point on a shared edge gets one."""
    fr_reg = face_rows
    lo, hi = _min3(tri2), _max3(tri2)
    # columns of width = the region's mean triangle width
    w = hi[:, 0] - lo[:, 0]
    nreg = int(max(fr_reg.max(initial=-1), qreg.max(initial=-1))) + 1
    cw = np.bincount(fr_reg, weights=w, minlength=nreg) / np.maximum(np.bincount(fr_reg, minlength=nreg), 1)
    cw = np.maximum(cw, 1e-12)
    c0 = np.floor(lo[:, 0] / cw[fr_reg] - 1e-9).astype(np.int64)
    c1 = np.floor(hi[:, 0] / cw[fr_reg] + 1e-9).astype(np.int64)
    row, k = _expand(c1 - c0 + 1)
    inv = _row_keys(np.concatenate([qreg, fr_reg[row]]),
                    np.concatenate([np.floor(q[:, 0] / cw[qreg]).astype(np.int64), c0[row] + k]))
    qi, fj = _group_pairs(inv[:len(q)], inv[len(q):])
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
    score = _min3(side)
    best = np.full(len(q), -np.inf)
    np.maximum.at(best, qi, score)
    pick = np.full(len(q), -1, dtype=np.int64)
    win = score >= best[qi]
    o = np.lexsort((f[win], qi[win]))
    qw, fw = qi[win][o], f[win][o]
    firstw = np.r_[True, qw[1:] != qw[:-1]]
    pick[qw[firstw]] = fw[firstw]
    return pick


def _region_edges(RP, RQ, eu, ev, estart, ecount):
    """Rows of the boundary segments of regions ``RP``/``RQ`` (local region index, polygon, from, to):
    P's edges as they are, Q's reversed (Q faces away from the closing axis)."""
    rP, kP = _expand(ecount[RP])
    rQ, kQ = _expand(ecount[RQ])
    eP, eQ = estart[RP][rP] + kP, estart[RQ][rQ] + kQ
    reg = np.concatenate([rP, rQ])
    poly = np.concatenate([np.zeros(len(rP), np.int64), np.ones(len(rQ), np.int64)])
    a = np.concatenate([eu[eP], ev[eQ]])
    b = np.concatenate([ev[eP], eu[eQ]])
    return reg, poly, a, b


def _batches(weight, limit):
    """Consecutive index ranges whose summed weight stays near ``limit`` (at least one item each)."""
    cs = np.cumsum(weight)
    out, s = [], 0
    while s < len(weight):
        base = cs[s - 1] if s else 0
        e = int(np.searchsorted(cs, base + limit, side="right"))
        e = max(e, s + 1)
        out.append((s, e))
        s = e
    return out


def find_regions(mesh, convex, geo, *, max_opening, beta_deg, mu, spacing, tol):
    """Region samples (see the module docstring): ``contacts (n, 2, 3)``, ``normals (n, 2, 3)``,
    ``width (n,)``, ``faces (n, 2)``, ``region (n,)`` for :class:`grasplan.antipodal.Candidates`.

    Works on the areas' boundary edges only (exact overlap moments by Green's theorem, lattice by
    scanlines), so the cost follows the length of the areas' outlines, not their triangle count.
    ``geo``: the mesh's :class:`grasplan.antipodal._FaceGeometry`; lengths in metres."""
    adjacency = mesh_edge_adjacency(mesh)
    admit, creases = _admitted(mesh, convex, geo, tol, adjacency)
    areas = convex_areas(mesh, admit, tol, adjacency, geo=geo)
    lab = areas.label
    ids = np.flatnonzero(lab >= 0)
    empty = (np.zeros((0, 2, 3)), np.zeros((0, 2, 3)), np.zeros(0), np.zeros((0, 2), np.int64), np.zeros(0, np.int64))
    if len(ids) < 2:
        return empty
    V = np.asarray(mesh.vertices, dtype=np.float64)
    F = np.asarray(mesh.faces, dtype=np.int64)
    nA = len(areas.area)
    eps = tol.distance
    # ---- candidate regions: area pairs anti-parallel within beta whose discs can overlap ----
    keys = [P * nA + Q for P, Q, _ in _area_pairs(areas, geo, ids, max_opening=max_opening, beta_deg=beta_deg,
                                                 tol=tol)]
    key = np.unique(np.concatenate(keys)) if keys else np.zeros(0, np.int64)
    if len(key) == 0:
        return empty
    RP, RQ = key // nA, key % nA
    R = len(key)
    a = areas.normal[RP] - areas.normal[RQ]
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    t1, t2 = _frame(a)
    org = areas.centroid[RP]
    scale = 1e6 * eps
    shift3 = _SHIFT * scale * (_SHIFT_DIR[0] * t1 + _SHIFT_DIR[1] * t2)      # Q's generic shift (3D)
    eu, ev, estart, ecount = area_edges(F, lab, nA, adjacency)
    batches = _batches(ecount[RP] + ecount[RQ], _EDGE_CHUNK)

    def segments(s, e, origin, b1, b2):
        reg, poly, u, v = _region_edges(RP[s:e], RQ[s:e], eu, ev, estart, ecount)
        gr = reg + s
        sh = np.where(poly[:, None] == 1, shift3[gr], 0.0)
        A3, B3 = V[u] + sh - origin[gr], V[v] + sh - origin[gr]
        return (reg, poly, np.einsum("ij,ij->i", A3, b1[gr]), np.einsum("ij,ij->i", A3, b2[gr]),
                np.einsum("ij,ij->i", B3, b1[gr]), np.einsum("ij,ij->i", B3, b2[gr]))

    # ---- pass 1: exact moments of every overlap (Green's theorem over the clipped outlines) ----
    S = np.zeros((R, 6))
    corners = []
    for s, e in batches:
        reg, poly, x0, y0, x1, y1 = segments(s, e, org, t1, t2)
        L = np.hypot(x1 - x0, y1 - y0)
        nr = e - s
        h = np.bincount(reg, weights=L, minlength=nr) / np.maximum(np.bincount(reg, minlength=nr), 1)
        h = np.maximum(h, 1e-6 * eps)[reg]
        r, xa, ya, xb, yb = _inside_parts(reg, poly, x0, y0, x1, y1, h)
        M = _green(xa, ya, xb, yb)
        for c in range(6):
            S[s:e, c] += np.bincount(reg[r], weights=M[:, c], minlength=nr)
        corners.append((reg[r] + s, xa, ya))
    A = S[:, 0]
    live = A > tol.area
    A = np.where(live, A, 1.0)
    gx, gy = S[:, 1] / A, S[:, 2] / A
    cxx, cyy, cxy = S[:, 3] / A - gx * gx, S[:, 4] / A - gy * gy, S[:, 5] / A - gx * gy
    aniso = np.hypot(cxx - cyy, 2 * cxy) > 1e-6 * np.abs(cxx + cyy)
    theta = 0.5 * np.arctan2(2 * cxy, cxx - cyy)
    iso = live & ~aniso
    if iso.any():
        # isotropic second moments (squares, disks): the direction to the overlap's farthest corner,
        # turned by 45 deg (a square gets an edge-aligned lattice); ties: smallest angle mod 90 deg
        c_r, c_x, c_y = (np.concatenate(v) for v in zip(*corners))
        sel = iso[c_r]
        c_r, dx, dy = c_r[sel], c_x[sel] - gx[c_r[sel]], c_y[sel] - gy[c_r[sel]]
        d2 = dx * dx + dy * dy
        far_d = np.full(R, -np.inf)
        np.maximum.at(far_d, c_r, d2)
        tied = d2 >= far_d[c_r] * (1 - 1e-9)
        far_t = np.full(R, np.inf)
        np.minimum.at(far_t, c_r[tied], np.mod(np.arctan2(dy[tied], dx[tied]), np.pi / 2))
        theta[iso] = far_t[iso] + np.pi / 4
    del corners
    ct, st = np.cos(theta)[:, None], np.sin(theta)[:, None]
    e1, e2 = ct * t1 + st * t2, -st * t1 + ct * t2
    g3 = org + gx[:, None] * t1 + gy[:, None] * t2      # centroid, in the plane through P's centroid
    small = A < spacing * spacing
    # ---- pass 2: lattice points whose cross of probes (+-eps) lies in the overlap: scanlines ----
    s_reg, s_q, f_reg, f_q, f_w = [], [], [], [], []
    offsets = (-eps, 0.0, eps)
    for s, e in batches:
        reg, poly, x0, y0, x1, y1 = segments(s, e, g3, e1, e2)
        keep = live[reg + s]
        reg, poly, x0, y0, x1, y1 = reg[keep], poly[keep], x0[keep], y0[keep], x1[keep], y1[keep]
        if len(reg) == 0:
            continue
        ir, j, xa, xb = _row_intervals(reg, poly, x0, y0, x1, y1, spacing, offsets, small[reg + s])
        gr = ir + s
        i0 = np.ceil((xa + eps) / spacing).astype(np.int64)
        i1 = np.floor((xb - eps) / spacing).astype(np.int64)
        sm = small[gr]
        i0, i1 = np.where(sm, np.maximum(i0, 0), i0), np.where(sm, np.minimum(i1, 0), i1)
        row, k = _expand(np.maximum(i1 - i0 + 1, 0))
        s_reg.append(gr[row])
        s_q.append(np.column_stack([(i0[row] + k) * spacing, j[row] * spacing]))
        z = (j == 0) & (xb - xa > 2 * eps)
        f_reg.append(gr[z])
        f_q.append(np.column_stack([0.5 * (xa[z] + xb[z]), np.zeros(int(z.sum()))]))
        f_w.append(xb[z] - xa[z])
    if not s_reg:
        return empty
    reg, q = np.concatenate(s_reg), np.concatenate(s_q)
    # regions the lattice misses (thinner than a pitch and off the lattice, or the centroid outside a
    # sub-cell region): the middle of their widest interval on the centroid's scanline
    fr, fq, fw = np.concatenate(f_reg), np.concatenate(f_q), np.concatenate(f_w)
    miss = ~np.isin(fr, reg)
    if miss.any():
        fr, fq, fw = fr[miss], fq[miss], fw[miss]
        o = np.lexsort((-fw, fr))
        o = o[np.r_[True, fr[o][1:] != fr[o][:-1]]]
        reg, q = np.concatenate([reg, fr[o]]), np.vstack([q, fq[o]])
    o = np.lexsort((q[:, 0], q[:, 1], reg))
    reg, q = reg[o], q[o]
    if len(reg) == 0:
        return empty
    x = g3[reg] + q[:, :1] * e1[reg] + q[:, 1:] * e2[reg]
    ax = a[reg]
    # ---- the faces under each sample: located in each area's own plane ----
    members = ids[np.argsort(lab[ids], kind="stable")]
    count = np.bincount(lab[ids], minlength=nA)
    start = np.cumsum(count) - count
    fidx = []
    for side in (RP, RQ):
        ar = side[reg]
        n_a, c_a = areas.normal[ar], areas.centroid[ar]
        y = x + (np.einsum("ij,ij->i", n_a, c_a - x) / np.einsum("ij,ij->i", n_a, ax))[:, None] * ax
        used = np.unique(ar)
        b1, b2 = _frame(areas.normal[used])
        pos = np.searchsorted(used, ar)
        qa = np.column_stack([np.einsum("ij,ij->i", y - areas.centroid[ar], b1[pos]),
                              np.einsum("ij,ij->i", y - areas.centroid[ar], b2[pos])])
        rr, kk = _expand(count[used])
        faces = members[start[used][rr] + kk]
        T = geo.tri[faces] - areas.centroid[used][rr][:, None]
        tri2 = np.stack([np.einsum("bkj,bj->bk", T, b1[rr]), np.einsum("bkj,bj->bk", T, b2[rr])], axis=-1)
        pick = _locate(pos, qa, rr, tri2)
        fidx.append(np.where(pick >= 0, faces[np.maximum(pick, 0)], -1))
    si, sj = fidx
    ok = (si >= 0) & (sj >= 0)
    reg, x, ax, si, sj = reg[ok], x[ok], ax[ok], si[ok], sj[ok]
    p0 = x + (np.einsum("ij,ij->i", geo.n[si], geo.tri[si, 0] - x) / np.einsum("ij,ij->i", geo.n[si], ax))[:, None] * ax
    p1 = x + (np.einsum("ij,ij->i", geo.n[sj], geo.tri[sj, 0] - x) / np.einsum("ij,ij->i", geo.n[sj], ax))[:, None] * ax
    ok = ~_near_creases(p0, p1, creases)
    reg, si, sj, p0, p1 = reg[ok], si[ok], sj[ok], p0[ok], p1[ok]
    # region ids: rank among the live regions (pose- and tessellation-independent)
    rid = np.cumsum(live) - 1
    return _finish(reg, rid[reg], si, sj, p0, p1, small, geo, mu, eps, max_opening, spacing)


#: samples closer than this to a rising (concave) edge of an admitted face are dropped, m (the BLM's
#: default boundary-layer width: the strip the BLM would have split off and called concave)
CONCAVE_MARGIN = 1e-4
#: a neighbour whose far corner lies more than this above a face's plane makes that edge rising, m
#: (the convexity stage's default d_shift)
RISE = 1e-5


def concave_edges(mesh, geo, tol, adjacency=None) -> np.ndarray:
    """(m, 3) bool: edge k (corner k -> k+1) of each face is *rising*: the face across it has its far
    corner more than :data:`RISE` above this face's plane (a concave edge seen from this face)."""
    F = np.asarray(mesh.faces, dtype=np.int64)
    m = len(F)
    out = np.zeros((m, 3), dtype=bool)
    adj, edges, far, slot = edge_adjacency(F, slots=True) if adjacency is None else adjacency
    if len(adj) == 0:
        return out
    V = np.asarray(mesh.vertices, dtype=np.float64)
    flat = out.reshape(-1)
    for side in (0, 1):
        f, g_far = adj[:, side], far[:, 1 - side]
        h = np.einsum("ij,ij->i", geo.n[f], V[g_far] - V[edges[:, 0]])
        flat[slot[h > RISE + tol.distance, side]] = True
    return out


def _admitted(mesh, convex, geo, tol, adjacency=None):
    """Faces that hold contact areas, and the rising edges samples must keep away from.

    A face the paper calls concave only because some neighbours rise above it (a shallow crease the
    BLM does not split, its surfaces being within 180 - gamma) still has convex points away from
    those edges: it is admitted, and samples closer than :data:`CONCAVE_MARGIN` to one of its rising
    edges are dropped (the strip the BLM would have split off, applied per point). A face rising on
    all three sides stays out. Returns ``admit (m,) bool`` and the crease segments ``(a, b)`` (s, 3)."""
    convex = np.asarray(convex, dtype=bool)
    rising = concave_edges(mesh, geo, tol, adjacency)
    admit = convex | (geo.valid & ~rising.all(axis=1))
    bad = rising & ~convex[:, None] & admit[:, None]
    f, k = np.nonzero(bad)
    V = np.asarray(mesh.vertices, dtype=np.float64)
    F = np.asarray(mesh.faces, dtype=np.int64)
    return admit, (V[F[f, k]], V[F[f, (k + 1) % 3]])


def _near_creases(p0, p1, creases) -> np.ndarray:
    """(k,) bool: either contact within :data:`CONCAVE_MARGIN` of a crease segment."""
    a, b = creases
    if len(a) == 0 or len(p0) == 0:
        return np.zeros(len(p0), dtype=bool)
    near = _near_segments(np.vstack([p0, p1]), a, b, CONCAVE_MARGIN)
    return near[:len(p0)] | near[len(p0):]


def _near_segments(p: np.ndarray, a: np.ndarray, b: np.ndarray, r: float) -> np.ndarray:
    """(k,) bool: points ``p`` (k, 3) within about ``r`` of any segment ``a -> b`` (s, 3) (segments
    sampled every r / 2; error below r / 4)."""
    L = np.linalg.norm(b - a, axis=1)
    # segments whose midpoint lies further than L/2 + r from every point cannot be within r of one
    # (margin 1.5 r): dropped before they are sampled (the result is the same)
    near = any_within(0.5 * (a + b), p, 0.5 * L + 1.5 * r)
    if not near.any():
        return np.zeros(len(p), dtype=bool)
    a, b, L = a[near], b[near], L[near]
    n = np.ceil(L / (0.5 * r)).astype(np.int64) + 1
    row, k = _expand(n)
    t = k / np.maximum(n[row] - 1, 1)
    pts = a[row] + t[:, None] * (b[row] - a[row])
    return any_within(p, pts, r)


def _finish(reg, rid, si, sj, p0, p1, small, geo, mu, eps, max_opening, spacing):
    """The paper's per-sample rules and the curved-surface deduplication; the Candidates arrays."""
    d = p1 - p0
    w = np.linalg.norm(d, axis=1)
    dn = d / np.maximum(w, 1e-300)[:, None]
    cosf = np.cos(np.arctan(mu)) - 1e-12
    ok = ((np.einsum("ij,ij->i", geo.n[si], -d) > 0) & (np.einsum("ij,ij->i", geo.n[sj], d) > 0) & (w > eps)
          & (np.einsum("ij,ij->i", -geo.n[si], dn) >= cosf) & (np.einsum("ij,ij->i", geo.n[sj], dn) >= cosf)
          & (w <= max_opening))
    reg, rid, si, sj, p0, p1, w = reg[ok], rid[ok], si[ok], sj[ok], p0[ok], p1[ok], w[ok]
    contacts = np.stack([p0, p1], axis=1)
    normals = np.stack([geo.n[si], geo.n[sj]], axis=1)
    faces = np.stack([si, sj], axis=1).astype(np.int64)
    sm = small[reg]
    if sm.any():
        idx = np.flatnonzero(sm)
        sub = Candidates(contacts[idx], normals[idx], w[idx], faces[idx])
        drop = np.ones(len(idx), dtype=bool)
        drop[thin_candidates(sub, spacing=spacing, axis_step_deg=CURVED_AXIS_STEP_DEG)] = False
        keep = np.ones(len(reg), dtype=bool)
        keep[idx[drop]] = False
        contacts, normals, w, faces, rid = contacts[keep], normals[keep], w[keep], faces[keep], rid[keep]
    return contacts, normals, w, faces, rid.astype(np.int64)


def area_edges(F: np.ndarray, label: np.ndarray, n_areas: int, adjacency=None):
    """Directed boundary edges of every area (winding of their faces), grouped by area:
    ``(from, to, start, count)``, vertex ids and per-area offsets. With the mesh's
    ``edge_adjacency(F, slots=True)`` an edge is inner when its two faces share an area (edges of
    three or more faces count as boundary), without another sort."""
    if adjacency is None:
        flags = area_boundary_edges(F, label) & (label[:, None] >= 0)
    else:
        adj, slot = adjacency[0], adjacency[3]
        inner = (label[adj[:, 0]] == label[adj[:, 1]]) & (label[adj[:, 0]] >= 0)
        flags = np.repeat(label >= 0, 3)
        flags[slot[inner].ravel()] = False
        flags = flags.reshape(-1, 3)
    f, k = np.nonzero(flags)
    u, v, lab = F[f, k], F[f, (k + 1) % 3], label[f]
    o = np.lexsort((v, u, lab))
    u, v, lab = u[o], v[o], lab[o]
    count = np.bincount(lab, minlength=n_areas)
    return u, v, np.cumsum(count) - count, count
