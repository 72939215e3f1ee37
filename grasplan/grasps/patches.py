"""Contact patches between a parallel-jaw gripper's finger pads and a part.

For ``M`` grasps of a part (TCP frames ``T_part_tcp`` (M, 4, 4), contacts ``(M, 2, 3)``; metres,
part frame), per jaw:

The finger pad is the inner face of the gripper's own finger geometry (``Gripper.finger``: the
points of its shape on its inner face ``x = 0``, bounded by their y/z extent,
:func:`pad_rectangle`), placed on the plane through the contact, perpendicular to the closing axis.
The patch is the part surface inside the pad rectangle and within ``CONTACT_DEPTH`` (0.1 mm, the
pad's compliance) of that plane, facing the pad: every such triangle is clipped exactly to the box
``|x - x_contact| <= depth`` x pad rectangle (vectorised Sutherland-Hodgman,
:mod:`grasplan.geometry.polygons`) and its projection on the pad is integrated (area, first and second
moments). ``area`` is m^2; ``type`` is ``surface`` when the part faces parallel to the pad (within
``FLAT_DEG``) cover a patch at least ``MIN_SIDE`` (2 mm) wide in every direction, else ``line``
when the patch is at least ``MIN_SIDE`` long and ``LINE_ASPECT`` (2) times longer than wide, else
``point`` (indices into :data:`grasplan.results.quality_json.CONTACT_TYPES`). Widths are those of the
uniform rectangle with the same second moments.

Exactly coplanar edge-connected areas (``MERGE_MIN_FACES`` faces or more) are first replaced by
their boundary loops (:func:`patch_elements`; holes weigh -1), so a finely tessellated flat face
costs one polygon. Elements are paired with distinct contacts by a dense centroid test (pad reach +
the element's radius), clipped to the contact's slab once per (contact, element), then to the pad
rectangle per roll, in chunks of at most ``MAX_PAIRS`` triangle-equivalent pairs: memory stays bounded.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import ConfigError
from ..geometry.grouping import expand
from ..gripper.model import Gripper
from ..geometry.meshdata import TriangleMesh, edge_adjacency
from ..geometry.polygons import clip_polygons, equivalent_widths, polygon_moments

#: part surface within this distance of the pad plane touches the pad, m (pad compliance)
CONTACT_DEPTH = 1e-4
#: part faces within this angle of the pad's plane count as flat contact, degrees
FLAT_DEG = 1.0
#: a patch narrower than this in every direction is a point, in one direction a line, m
MIN_SIDE = 2e-3
#: a non-flat patch at least this many times longer than wide (and MIN_SIDE long) is a line
LINE_ASPECT = 2.0
#: largest (grasp, face) pairs held at once by the patch computation
MAX_PAIRS = 400_000
#: parts with at least this many elements find the faces near each contact by visiting the grid
#: cells its slab crosses (:func:`_near_faces_slab`) instead of the dense (faces x contacts) test, and take the moments of an element lying within the disc the pad
#: covers at every roll once per contact, turned to each roll (:func:`_rotated`), instead of
#: clipping it once per roll (the same moments up to rounding)
GRID_FACES = 50_000
#: exactly coplanar edge-connected areas of at least this many faces are merged into their
#: boundary loops (one polygon instead of thousands of triangles on finely tessellated faces)
MERGE_MIN_FACES = 3
#: a merged loop keeps at most this many vertices after dropping collinear ones (else its
#: area stays triangles, bounding the padded polygon arrays)
MERGE_MAX_VERTS = 256
#: elements are processed in classes of at most these many vertices (bounded padding)
VERTEX_CLASSES = (3, 8, 32, MERGE_MAX_VERTS)
#: faces are coplanar when the far vertex of each lies within this fraction of the part's
#: size from the neighbour's plane and their normals agree to within 1 - this cosine
COPLANAR_TOL = 1e-12


def pad_rectangle(gripper: Gripper) -> np.ndarray:
    """The +x jaw's pad in the TCP frame at opening 0: ``[[y0, y1], [z0, z1]]`` (m), the y/z extent
    of the finger's points on its inner face (x = 0). The -x jaw's pad is ``[[-y1, -y0], [z0, z1]]``."""
    pts = np.asarray(gripper.finger.corners(), dtype=np.float64)
    tol = 1e-6 + 1e-3 * float(np.ptp(pts[:, 0]))
    face = pts[pts[:, 0] <= pts[:, 0].min() + tol]
    rect = np.array([[face[:, 1].min(), face[:, 1].max()], [face[:, 2].min(), face[:, 2].max()]])
    if np.any(rect[:, 1] - rect[:, 0] <= 0):
        raise ConfigError(f"gripper {gripper.name}: the finger has no flat inner face on x = 0 to grip with "
                          "(give a finger whose inner face is a plane)")
    return rect


def _accumulate(mom, j, poly, n, nx, w, o, R, g, rect, cos_flat, M) -> None:
    """Clip the polygons ``poly`` (K, V, 3) (part frame, the first ``n[k]`` vertices valid, already
    clipped to the contact's slab ``|x - x_contact| <= depth``) paired with grasps ``g`` (K,) (TCP
    origin ``o``, rotation ``R``) to jaw ``j``'s pad rectangle and add their moments."""
    y_lo, y_hi, z_lo, z_hi = rect
    P = np.matmul(poly - o[:, None], R)  # v_tcp = R^T (v - o)
    K, V = P.shape[:2]
    valid = np.arange(V)[None, :] < n[:, None]
    Y, Z = P[..., 1], P[..., 2]
    ymin = np.where(valid, Y, np.inf).min(axis=1)
    ymax = np.where(valid, Y, -np.inf).max(axis=1)
    zmin = np.where(valid, Z, np.inf).min(axis=1)
    zmax = np.where(valid, Z, -np.inf).max(axis=1)
    meets = (ymin <= y_hi) & (ymax >= y_lo) & (zmin <= z_hi) & (zmax >= z_lo)  # cull before clipping
    P, n, g, nx, w = P[meets], n[meets], g[meets], nx[meets], w[meets]
    K = len(P)
    for axis, lo, hi in ((1, y_lo, y_hi), (2, z_lo, z_hi)):
        P, n = clip_polygons(P, n, axis, np.full(K, lo), keep_below=False)
        P, n = clip_polygons(P, n, axis, np.full(K, hi), keep_below=True)
    if len(P) == 0 or P.shape[1] == 0:
        return
    m6 = polygon_moments(P[..., 1], P[..., 2], n) * w[:, None]  # holes of merged areas subtract
    flat = np.abs(nx) >= cos_flat
    for k in range(6):
        mom[:, j, 0, k] += np.bincount(g, weights=m6[:, k], minlength=M)
        mom[:, j, 1, k] += np.bincount(g, weights=m6[:, k] * flat, minlength=M)


def _doubling_steps(n: int) -> int:
    return max(1, math.ceil(math.log2(max(n, 2))) + 1)


def patch_elements(part_mesh: TriangleMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Surface elements of :func:`contact_patches`: the mesh's triangles, with each exactly coplanar,
    edge-connected area of at least ``MERGE_MIN_FACES`` faces replaced by its boundary loops (outer
    loops weight +1, holes -1; collinear boundary vertices dropped). Areas whose boundary is not a
    set of simple loops, or has a loop longer than ``MERGE_MAX_VERTS``, stay triangles.

    Returns ``pts`` (P, 3), ``first`` (E,), ``count`` (E,) (element e's vertices, in order:
    ``pts[first[e]:first[e] + count[e]]``), ``normal`` (E, 3) unit outward, ``weight`` (E,) +-1.
    No loop over faces; memory linear in the mesh."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    V = np.asarray(part_mesh.vertices, dtype=np.float64)
    Fc = np.asarray(part_mesh.faces, dtype=np.int64)
    tris = V[Fc] if len(Fc) else np.zeros((0, 3, 3))
    fn = np.asarray(part_mesh.face_normals, dtype=np.float64) if len(Fc) else np.zeros((0, 3))
    m = len(Fc)

    def only_triangles():
        return tris.reshape(-1, 3), 3 * np.arange(m), np.full(m, 3), fn, np.ones(m)

    if m < MERGE_MIN_FACES:
        return only_triangles()
    adj, edge, far = edge_adjacency(Fc)
    scale = float(np.ptp(V, axis=0).max()) or 1.0
    n0, n1 = fn[adj[:, 0]], fn[adj[:, 1]]
    same = (np.einsum("ij,ij->i", n0, n1) >= 1.0 - COPLANAR_TOL) & \
        (np.abs(np.einsum("ij,ij->i", V[far[:, 1]] - V[edge[:, 0]], n0)) <= COPLANAR_TOL * scale) & \
        (np.abs(np.einsum("ij,ij->i", V[far[:, 0]] - V[edge[:, 0]], n1)) <= COPLANAR_TOL * scale)
    adj = adj[same]
    if len(adj) == 0:
        return only_triangles()
    g = coo_matrix((np.ones(len(adj)), (adj[:, 0], adj[:, 1])), shape=(m, m))
    _, lab = connected_components(g, directed=False)
    size = np.bincount(lab)
    merge = size[lab] >= MERGE_MIN_FACES  # per face
    L = int(lab.max()) + 1
    label_ok = np.bincount(lab, minlength=L) >= MERGE_MIN_FACES
    if not merge.any():
        return only_triangles()
    # directed boundary edges of the merged areas: an edge no other face of its area shares
    fi = np.flatnonzero(merge)
    a = Fc[fi].ravel()
    b = np.roll(Fc[fi], -1, axis=1).ravel()
    el = np.repeat(lab[fi], 3)
    nv = len(V)
    ukey = (el * nv + np.minimum(a, b)) * nv + np.maximum(a, b)
    _, inv, cnt = np.unique(ukey, return_inverse=True, return_counts=True)
    bd = cnt[inv.ravel()] == 1
    a, b, el = a[bd], b[bd], el[bd]
    if len(a) == 0:  # closed coplanar areas (no boundary): keep triangles
        return only_triangles()
    # chain: the successor of edge (a -> b) is the edge of the same area starting at b
    skey = el * nv + a
    o = np.argsort(skey, kind="stable")
    a, b, el, skey = a[o], b[o], el[o], skey[o]
    dup = np.r_[False, skey[1:] == skey[:-1]]
    label_ok[el[dup]] = False  # a vertex with two outgoing boundary edges: not simple loops
    want = el * nv + b
    nxt = np.searchsorted(skey, want)
    nxt = np.minimum(nxt, max(len(skey) - 1, 0))
    found = skey[nxt] == want if len(skey) else np.zeros(0, dtype=bool)
    label_ok[el[~found]] = False
    nxt = np.where(found, nxt, np.arange(len(nxt)))
    E = len(a)
    # cycle id (smallest edge index of the cycle) and rank from it by pointer doubling
    cyc = np.arange(E)
    p = nxt.copy()
    for _ in range(_doubling_steps(E)):
        cyc = np.minimum(cyc, cyc[p])
        p = p[p]
    head = cyc == np.arange(E)
    pred = np.empty(E, dtype=np.int64)
    pred[nxt] = np.arange(E)
    pred[head] = np.flatnonzero(head)
    dist = np.where(head, 0, 1)
    p = pred.copy()
    for _ in range(_doubling_steps(E)):
        dist = dist + dist[p]
        p = p[p]
    order = np.lexsort((dist, cyc))
    a, el, cyc = a[order], el[order], cyc[order]
    start = np.flatnonzero(np.r_[True, cyc[1:] != cyc[:-1]])
    clen = np.diff(np.r_[start, E])
    cid = np.repeat(np.arange(len(start)), clen)
    pos = np.arange(E) - start[cid]
    prv = start[cid] + (pos - 1) % clen[cid]
    nx_ = start[cid] + (pos + 1) % clen[cid]
    P0, P1, P2 = V[a[prv]], V[a], V[a[nx_]]
    d0, d1 = P1 - P0, P2 - P1
    cr = np.linalg.norm(np.cross(d0, d1), axis=1)
    straight = (cr <= COPLANAR_TOL * np.linalg.norm(d0, axis=1) * np.linalg.norm(d1, axis=1)) & \
        (np.einsum("ij,ij->i", d0, d1) > 0)
    keep = ~straight
    kc = np.bincount(cid, weights=keep, minlength=len(start)).astype(np.int64)
    loop_lab = el[start]
    bad_loop = (kc < 3) | (kc > MERGE_MAX_VERTS)
    label_ok[loop_lab[bad_loop]] = False
    # faces of areas that stay triangles
    tri_face = ~merge | ~label_ok[lab]
    use_loop = label_ok[loop_lab]
    cid_k, pts = cid[keep], V[a[keep]]
    sel = use_loop[cid_k]
    cid_k, pts = cid_k[sel], pts[sel]
    loops = np.flatnonzero(use_loop)
    remap = np.full(len(start), -1)
    remap[loops] = np.arange(len(loops))
    li = remap[cid_k]
    nL = len(loops)
    cntL = kc[loops]
    o2 = np.argsort(li, kind="stable")  # keep order within a loop (stable), loops in order
    pts_l = pts[o2]
    first_l = np.cumsum(cntL) - cntL
    # area normal (faces are coplanar: the first face's) and loop orientation (Newell) -> weight
    rep_face = np.zeros(L, dtype=np.int64)
    rep_face[lab[::-1]] = np.arange(m)[::-1]
    nrm_l = fn[rep_face[loop_lab[loops]]]
    lid = np.repeat(np.arange(nL), cntL)
    posl = np.arange(len(pts_l)) - first_l[lid]
    q = pts_l[first_l[lid] + (posl + 1) % cntL[lid]]
    newell = np.stack([np.bincount(lid, weights=c, minlength=nL) for c in np.cross(pts_l, q).T], axis=1)
    w_l = np.where(np.einsum("ij,ij->i", newell.reshape(-1, 3), nrm_l.reshape(-1, 3)) >= 0, 1.0, -1.0)
    ti = np.flatnonzero(tri_face)
    pts_all = np.concatenate([tris[ti].reshape(-1, 3), pts_l.reshape(-1, 3)])
    count = np.r_[np.full(len(ti), 3), cntL].astype(np.int64)
    first = np.cumsum(count) - count
    return pts_all, first, count, np.r_[fn[ti], nrm_l].reshape(-1, 3), np.r_[np.ones(len(ti)), w_l]


def gather_polygons(pts: np.ndarray, first: np.ndarray, count: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """(k, max count, 3) padded polygons ``idx`` of :func:`patch_elements` (padding repeats the last vertex)."""
    c = count[idx]
    vm = int(c.max()) if len(c) else 3
    j = np.minimum(np.arange(vm)[None, :], c[:, None] - 1)
    return pts[first[idx][:, None] + j]


def _rotated(mom, j, poly, n, nx, w, gu, gsize, gstart, members, o, R, cos_flat, M) -> None:
    """Moments of slab-clipped polygons ``poly`` (K, V, 3) of contacts ``gu`` that lie inside jaw
    ``j``'s pad at every roll: computed once per contact in the frame of its first pose, summed per
    contact, then turned to each pose of the contact (area kept, first moments as a vector, second
    moments as a tensor) and added. Every pose of a contact shares its TCP origin."""
    ref = members[gstart[gu]]
    P = np.matmul(poly - o[ref][:, None], R[ref])
    m6 = polygon_moments(P[..., 1], P[..., 2], n) * w[:, None]
    flat = np.abs(nx) >= cos_flat
    used, inv = np.unique(gu, return_inverse=True)
    inv = inv.reshape(-1)
    own, k = expand(gsize[used])
    g = members[gstart[used][own] + k]
    Rr, Rg = R[members[gstart[used]]][own], R[g]
    b11 = np.einsum("ki,ki->k", Rg[:, :, 1], Rr[:, :, 1])
    b12 = np.einsum("ki,ki->k", Rg[:, :, 1], Rr[:, :, 2])
    b21 = np.einsum("ki,ki->k", Rg[:, :, 2], Rr[:, :, 1])
    b22 = np.einsum("ki,ki->k", Rg[:, :, 2], Rr[:, :, 2])
    for slot, wt in ((0, m6), (1, m6 * flat[:, None])):
        S = np.stack([np.bincount(inv, weights=wt[:, c], minlength=len(used)) for c in range(6)], axis=1)[own]
        a, my, mz, yy, zz, yz = S.T
        out = (a, b11 * my + b12 * mz, b21 * my + b22 * mz,
               b11 * b11 * yy + 2 * b11 * b12 * yz + b12 * b12 * zz,
               b21 * b21 * yy + 2 * b21 * b22 * yz + b22 * b22 * zz,
               b11 * b21 * yy + (b11 * b22 + b12 * b21) * yz + b12 * b22 * zz)
        for c in range(6):
            mom[:, j, slot, c] += np.bincount(g, weights=out[c], minlength=M)


def _patch_pairs(mom, j, f, gu, nx, pts, first, count, weight, cu, axu, gsize, gstart, members, o, R, depth,
                 rect, cos_flat, M, max_pairs, disc: float = 0.0, same_origin: np.ndarray | None = None) -> None:
    """Elements ``f`` near distinct contacts ``gu``: cull and clip on the contact slab once, then
    expand to every roll of the contact (at most ``max_pairs`` pairs at once) and accumulate.
    ``disc`` > 0: elements within that distance of the closing axis through the TCP (inside the pad
    at every roll) of a contact whose poses share their origin (``same_origin`` per contact) go
    through :func:`_rotated` instead."""
    # exact cull and clip on the contact slab (x only, the same for every roll): once per
    # (contact, element), in the part frame with x = (v - contact) . axis as a clip coordinate
    polys = gather_polygons(pts, first, count, f)  # padding repeats a vertex: min / max unchanged
    x = np.einsum("kvi,ki->kv", polys - cu[gu][:, None], axu[gu])  # x - x_contact
    keep = (x.min(axis=1) <= depth) & (x.max(axis=1) >= -depth)
    gu, f, nx, x = gu[keep], f[keep], nx[keep], x[keep]
    Px = np.concatenate([x[..., None], polys[keep]], axis=2)  # (k, V, 4): x, part-frame point
    npx = count[f]
    Px, npx = clip_polygons(Px, npx, 0, np.full(len(Px), -depth), keep_below=False)
    Px, npx = clip_polygons(Px, npx, 0, np.full(len(Px), depth), keep_below=True)
    poly = Px[..., 1:]
    if disc > 0 and same_origin is not None and len(gu):
        ref = members[gstart[gu]]
        d = poly - o[ref][:, None]
        along = np.einsum("kvi,ki->kv", d, R[ref][:, :, 0])
        rho2 = np.einsum("kvi,kvi->kv", d, d) - along * along
        valid = np.arange(poly.shape[1])[None, :] < npx[:, None]
        fast = (npx > 0) & same_origin[gu] & (np.where(valid, rho2, 0.0).max(axis=1, initial=0.0) < disc * disc)
        if fast.any():
            _rotated(mom, j, poly[fast], npx[fast], nx[fast], weight[f[fast]], gu[fast], gsize, gstart, members, o, R,
                     cos_flat, M)
            slow = ~fast
            gu, f, nx, poly, npx = gu[slow], f[slow], nx[slow], poly[slow], npx[slow]
    # expand the survivors to every roll of their contact, in bounded sub-chunks
    nrep = gsize[gu]
    ends = np.cumsum(nrep)
    s0 = 0
    while s0 < len(gu):
        s1 = s0 + max(1, int(np.searchsorted(ends[s0:] - (ends[s0 - 1] if s0 else 0), max_pairs, side="right")))
        r = nrep[s0:s1]
        pu = np.repeat(np.arange(s0, s1), r)
        within = np.arange(len(pu)) - np.repeat(np.cumsum(r) - r, r)
        g = members[gstart[gu[pu]] + within]
        _accumulate(mom, j, poly[pu], npx[pu], nx[pu], weight[f[pu]], o[g], R[g], g, rect, cos_flat, M)
        s0 = s1


#: contacts per step of :func:`_near_faces_slab` (bounds its cell and pair arrays)
_SLAB_CONTACTS = 256


def _near_faces_slab(cent: np.ndarray, fn: np.ndarray, face_rad: np.ndarray, cu: np.ndarray, axu: np.ndarray,
                     slab_tol: np.ndarray, lat_tol: np.ndarray, pad_reach: float, j: int
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(face, contact, n . axis)`` of every element whose centroid passes the near test of
    :func:`contact_patches` (within ``slab_tol`` of the plane through contact ``cu`` normal to its
    axis ``axu``, laterally within ``sqrt(lat_tol)``, facing the jaw), sorted by (face, contact).

    Centroids are binned on a grid (faces in classes of radii within a factor 2, each with cells at
    least twice its slab thick); for each contact only the cells the slab crosses are visited: per
    column along the axis' dominant coordinate, the few cells within the slab's half-thickness (plus
    the plane's rise across a cell) of the plane at the column's centre. Every face passing the test
    lies in a visited cell; the same exact test then decides. Work: the visited cells and the faces
    in them, not faces x contacts."""
    fs: list[np.ndarray] = []
    bs: list[np.ndarray] = []
    ns: list[np.ndarray] = []
    base = max(float(face_rad.min(initial=0.0)), 1e-9)
    cls = np.floor(np.log2(np.maximum(face_rad, base) / base)).astype(np.int64)
    for c in np.unique(cls):
        rows = np.flatnonzero(cls == c)
        slab = float(slab_tol[rows].max())
        r3 = float(np.sqrt(slab * slab + lat_tol[rows].max()))
        h = max(2.0 * slab, r3 / 16.0)
        lo = cent[rows].min(axis=0)
        cell = np.floor((cent[rows] - lo) / h).astype(np.int64)
        dims = cell.max(axis=0) + 1
        key = np.ravel_multi_index(cell.T, tuple(int(d) for d in dims))
        order = np.argsort(key, kind="stable")
        ks = key[order]
        first = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
        ukey, ucount = ks[first], np.diff(np.r_[first, len(ks)])
        for s in range(0, len(cu), _SLAB_CONTACTS):
            b_all = np.arange(s, min(len(cu), s + _SLAB_CONTACTS))
            a = axu[b_all]
            k = np.argmax(np.abs(a), axis=1)
            i1, i2 = (k + 1) % 3, (k + 2) % 3
            r = np.arange(len(b_all))
            p = cu[b_all] - lo
            c1_lo = np.floor((p[r, i1] - r3) / h).astype(np.int64)
            c2_lo = np.floor((p[r, i2] - r3) / h).astype(np.int64)
            n1 = np.floor((p[r, i1] + r3) / h).astype(np.int64) - c1_lo + 1
            n2 = np.floor((p[r, i2] + r3) / h).astype(np.int64) - c2_lo + 1
            own, q = expand(n1 * n2)
            c1 = c1_lo[own] + q // n2[own]
            c2 = c2_lo[own] + q % n2[own]
            ak, a1, a2 = a[own, k[own]], a[own, i1[own]], a[own, i2[own]]
            t = np.einsum("ki,ki->k", p, a)[own]
            xk = (t - a1 * (c1 + 0.5) * h - a2 * (c2 + 0.5) * h) / ak          # the plane at the column centre
            ht = (slab + 0.5 * h * (np.abs(a1) + np.abs(a2))) / np.abs(ak) * (1 + 1e-9) + 1e-12
            k0 = np.floor((xk - ht) / h).astype(np.int64)
            own2, q2 = expand(np.floor((xk + ht) / h).astype(np.int64) - k0 + 1)
            ck = k0[own2] + q2
            o3 = own[own2]
            cc = np.zeros((len(o3), 3), dtype=np.int64)
            rr = np.arange(len(o3))
            cc[rr, k[o3]], cc[rr, i1[o3]], cc[rr, i2[o3]] = ck, c1[own2], c2[own2]
            inside = np.all((cc >= 0) & (cc < dims), axis=1)
            cc, o3 = cc[inside], o3[inside]
            qk = np.ravel_multi_index(cc.T, tuple(int(d) for d in dims)) if len(cc) else np.zeros(0, np.int64)
            pos = np.minimum(np.searchsorted(ukey, qk), max(len(ukey) - 1, 0))
            hit = (ukey[pos] == qk) if len(ukey) else np.zeros(len(qk), dtype=bool)
            pos, o3 = pos[hit], o3[hit]
            ow, q3 = expand(ucount[pos])
            f = rows[order[first[pos][ow] + q3]]
            b = b_all[o3[ow]]
            d = cent[f] - cu[b]
            xs = np.einsum("ki,ki->k", d, axu[b])
            nx = np.einsum("ki,ki->k", fn[f], axu[b])
            near = (np.abs(xs) <= slab_tol[f]) & (np.einsum("ki,ki->k", d, d) - xs * xs <= lat_tol[f]) & \
                ((nx < 0) if j == 0 else (nx > 0))
            fs.append(f[near])
            bs.append(b[near])
            ns.append(nx[near])
    if not fs:
        z = np.zeros(0, dtype=np.int64)
        return z, z, np.zeros(0)
    f, b, nx = np.concatenate(fs), np.concatenate(bs), np.concatenate(ns)
    o = np.lexsort((b, f))
    return f[o], b[o], nx[o]


def contact_patches(part_mesh: TriangleMesh, gripper: Gripper, T_part_tcp: np.ndarray, contacts: np.ndarray,
                    *, depth: float = CONTACT_DEPTH, flat_deg: float = FLAT_DEG,
                    max_pairs: int = MAX_PAIRS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Patch between each finger pad and the part (see the module docstring).

    Returns ``area`` (M, 2) m^2, ``type`` (M, 2) int8 into ``CONTACT_TYPES``, ``widths`` (M, 2, 2) m
    (sorted equivalent widths of the whole patch)."""
    T = np.asarray(T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    C = np.asarray(contacts, dtype=np.float64).reshape(-1, 2, 3)
    M = len(T)
    rect = pad_rectangle(gripper)
    # triangles; coplanar areas as loops (once per part: the rank-order evaluation calls this per chunk)
    derived = getattr(part_mesh, "derived", None)
    pts, first, count, fn, weight = derived("patch_elements", lambda: patch_elements(part_mesh)) if derived \
        else patch_elements(part_mesh)
    F = len(count)
    eid = np.repeat(np.arange(F), count)
    cent = np.stack([np.bincount(eid, weights=pts[:, d], minlength=F) for d in range(3)], axis=1) / \
        np.maximum(count, 1)[:, None]
    face_rad = np.zeros(F)
    if F:
        np.maximum.at(face_rad, eid, np.linalg.norm(pts - cent[eid], axis=1))
    # elements are processed in classes of similar vertex counts (padding stays small); the pairs
    # held at once are max_pairs triangle-equivalents
    vclass = np.searchsorted(np.array(VERTEX_CLASSES), count)
    pad_reach = math.hypot(np.abs(rect[0]).max(), np.abs(rect[1]).max()) + depth
    cent_sq = np.einsum("fi,fi->f", cent, cent)
    slab_tol = face_rad + depth  # a face meeting the slab has its centroid this close to the contact plane
    lat_tol = (pad_reach + face_rad) ** 2  # ... and this close (squared) to the contact, laterally
    cos_flat = math.cos(math.radians(flat_deg))
    # moments: [grasp, jaw, (all, flat), 6]
    mom = np.zeros((M, 2, 2, 6))
    R = T[:, :3, :3]
    o = T[:, :3, 3]
    for j in range(2):
        ysgn = -1.0 if j == 0 else 1.0
        y_lo, y_hi = sorted(ysgn * rect[0])
        z_lo, z_hi = rect[1]
        # the rolls of one candidate share the contact and the closing axis: the face search and the
        # slab cull (roll-independent) run once per distinct (contact, closing axis)
        key = np.concatenate([C[:, j], R[:, :, 0], np.einsum("mi,mi->m", C[:, j] - o, R[:, :, 0])[:, None]], axis=1)
        _, rep, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
        inv = inv.reshape(-1)
        U = len(rep)
        members = np.argsort(inv, kind="stable")
        gsize = np.bincount(inv, minlength=U)
        gstart = np.cumsum(gsize) - gsize
        cu, axu = C[rep, j], R[rep, :, 0]
        if F >= GRID_FACES:
            f, b, nx = _near_faces_slab(cent, fn, face_rad, cu, axu, slab_tol, lat_tol, pad_reach, j)
            # the disc the pad covers at every roll; contacts whose poses share the TCP origin
            disc = (1.0 - 1e-9) * min(-y_lo, y_hi, -z_lo, z_hi)
            ref_o = o[members[gstart[inv]]]
            same = np.bincount(inv, weights=np.any(o != ref_o, axis=1), minlength=U) == 0
            for cls in np.unique(vclass[f]):
                sel = vclass[f] == cls
                budget = max(1, (max_pairs * 3) // VERTEX_CLASSES[cls])
                _patch_pairs(mom, j, f[sel], b[sel], nx[sel], pts, first, count, weight, cu, axu, gsize, gstart,
                             members, o, R, depth, (y_lo, y_hi, z_lo, z_hi), cos_flat, M, budget,
                             disc=disc, same_origin=same)
            continue
        # faces near each contact's pad: a dense (faces x contacts) test on centroids, chunked so
        # that at most max_pairs (face, contact) pairs exist at once
        step = max(1, max_pairs // max(F, 1))
        for start in range(0, U if F else 0, step):
            stop = min(U, start + step)
            ax, c = axu[start:stop], cu[start:stop]
            xs = cent @ ax.T - np.einsum("bi,bi->b", c, ax)  # (F, b) centroid height over the contact plane
            nx_all = fn @ ax.T
            d2 = cent_sq[:, None] - 2.0 * (cent @ c.T) + np.einsum("bi,bi->b", c, c)  # squared distance
            near = (np.abs(xs) <= slab_tol[:, None]) & (d2 - xs * xs <= lat_tol[:, None]) & \
                ((nx_all < 0) if j == 0 else (nx_all > 0))
            f, b = np.nonzero(near)
            if len(f) == 0:
                continue
            for cls in np.unique(vclass[f]):
                sel = vclass[f] == cls
                budget = max(1, (max_pairs * 3) // VERTEX_CLASSES[cls])
                _patch_pairs(mom, j, f[sel], start + b[sel], nx_all[f[sel], b[sel]], pts, first, count, weight, cu, axu,
                             gsize, gstart, members, o, R, depth, (y_lo, y_hi, z_lo, z_hi), cos_flat, M, budget)
    area = mom[:, :, 0, 0]
    widths = equivalent_widths(mom[:, :, 0])
    flat_widths = equivalent_widths(mom[:, :, 1])
    line = (widths[..., 1] >= MIN_SIDE) & (widths[..., 1] >= LINE_ASPECT * widths[..., 0])
    kind = np.where(flat_widths[..., 0] >= MIN_SIDE, 2, np.where(line, 1, 0)).astype(np.int8)
    return area, kind, widths

