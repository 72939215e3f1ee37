"""Contact patches between a parallel-jaw gripper's finger pads and a part.

For ``M`` grasps of a part (TCP frames ``T_part_tcp`` (M, 4, 4), contacts ``(M, 2, 3)``; metres,
part frame), :func:`contact_patches` gives per jaw the patch's area, its type (point, line or
surface contact) and its equivalent widths. The part's surface is first reduced to elements
(:func:`patch_elements`: triangles, coplanar areas as their boundary loops); the elements near
each contact are clipped exactly to the pad's box (Sutherland-Hodgman: on the contact's slab
vectorised, :mod:`grasplan.geometry.polygons`; on the pad per grasp compiled,
:mod:`grasplan.grasps.quality_kernels`) and integrated, in chunks of at most ``MAX_PAIRS``
triangle-equivalent pairs: memory stays bounded.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from ..geometry.grouping import expand
from ..gripper.model import Gripper
from ..geometry.meshdata import TriangleMesh, edge_adjacency
from ..geometry.polygons import equivalent_widths, polygon_moments
from .quality_kernels import accumulate_pairs, slab_polygons, within_disc
from .patch_search import near_faces_dense, near_faces_slab

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
#: cells its slab crosses (:func:`grasplan.grasps.patch_search.near_faces_slab`) instead of the dense
#: (faces x contacts) test, and take the moments of an element lying within the disc the pad
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

#: ``pts`` (P, 3), ``first`` (E,), ``count`` (E,), ``normal`` (E, 3), ``weight`` (E,): see :func:`patch_elements`
Elements = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


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


@dataclass(frozen=True)
class _JawPass:
    """One jaw's pass over the grasps: the moments ``mom`` [grasp, jaw, (all, flat), 6] it adds to (in
    place), the jaw ``j``, the TCP origins ``o`` (M, 3) and rotations ``R`` (M, 3, 3), the pad ``rect``
    ``(y_lo, y_hi, z_lo, z_hi)`` in the TCP frame, the slab half-thickness ``depth``, the flat-contact
    cosine ``cos_flat`` and the pairs held at once ``max_pairs``."""

    mom: np.ndarray
    j: int
    o: np.ndarray
    R: np.ndarray
    rect: tuple[float, float, float, float]
    depth: float
    cos_flat: float
    max_pairs: int


def _accumulate(jp: _JawPass, poly: np.ndarray, n: np.ndarray, nx: np.ndarray, w: np.ndarray, src: np.ndarray,
                g: np.ndarray) -> None:
    """Clip the polygons ``poly`` (P, V, 3) (part frame, the first ``n[p]`` vertices valid, already
    clipped to the contact's slab ``|x - x_contact| <= depth``; face normal's x ``nx``, weight ``w``)
    of the pairs ``(src[k], g[k])`` (polygon, grasp) to the jaw's pad rectangle and add their
    moments (:func:`grasplan.grasps.quality_kernels.accumulate_pairs`)."""
    if len(src) == 0 or poly.shape[1] == 0:
        return
    accumulate_pairs(np.ascontiguousarray(poly, dtype=np.float64), np.ascontiguousarray(n, dtype=np.int64),
                     np.ascontiguousarray(w, dtype=np.float64), np.ascontiguousarray(np.abs(nx) >= jp.cos_flat),
                     np.ascontiguousarray(src, dtype=np.int64), np.ascontiguousarray(g, dtype=np.int64), jp.o, jp.R,
                     np.array(jp.rect, dtype=np.float64), jp.mom, jp.j)


def _doubling_steps(n: int) -> int:
    """Pointer-doubling rounds that reach across any cycle of at most ``n`` elements."""
    return max(1, math.ceil(math.log2(max(n, 2))) + 1)


def _triangle_elements(tris: np.ndarray, fn: np.ndarray) -> Elements:
    """The :data:`Elements` of the mesh's triangles ``tris`` (m, 3, 3) with normals ``fn``, unmerged."""
    m = len(tris)
    return tris.reshape(-1, 3), 3 * np.arange(m), np.full(m, 3), fn, np.ones(m)


def _coplanar_labels(V: np.ndarray, Fc: np.ndarray, fn: np.ndarray) -> np.ndarray | None:
    """(m,) label of each face's exactly coplanar, edge-connected area (:data:`COPLANAR_TOL`), or
    None when no two neighbouring faces are coplanar."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    m = len(Fc)
    adj, edge, far = edge_adjacency(Fc)
    scale = float(np.ptp(V, axis=0).max()) or 1.0
    n0, n1 = fn[adj[:, 0]], fn[adj[:, 1]]
    same = (np.einsum("ij,ij->i", n0, n1) >= 1.0 - COPLANAR_TOL) & \
        (np.abs(np.einsum("ij,ij->i", V[far[:, 1]] - V[edge[:, 0]], n0)) <= COPLANAR_TOL * scale) & \
        (np.abs(np.einsum("ij,ij->i", V[far[:, 0]] - V[edge[:, 0]], n1)) <= COPLANAR_TOL * scale)
    adj = adj[same]
    if len(adj) == 0:
        return None
    g = coo_matrix((np.ones(len(adj)), (adj[:, 0], adj[:, 1])), shape=(m, m))
    return connected_components(g, directed=False)[1]


def _area_boundary(Fc: np.ndarray, lab: np.ndarray, merge: np.ndarray, nv: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(a, b, area)``: the directed boundary edges ``a -> b`` of the merged faces' areas: edges no
    other face of the same area shares."""
    fi = np.flatnonzero(merge)
    a = Fc[fi].ravel()
    b = np.roll(Fc[fi], -1, axis=1).ravel()
    el = np.repeat(lab[fi], 3)
    ukey = (el * nv + np.minimum(a, b)) * nv + np.maximum(a, b)
    _, inv, cnt = np.unique(ukey, return_inverse=True, return_counts=True)
    bd = cnt[inv.ravel()] == 1
    return a[bd], b[bd], el[bd]


def _chain_loops(a: np.ndarray, b: np.ndarray, el: np.ndarray, nv: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The boundary edges chained into loops: ``(a, area, cycle, broken)``, the edges' start vertices
    and areas in loop order, each edge's loop (its smallest edge index) and the areas whose boundary
    is not a set of simple loops. The successor of edge ``a -> b`` is the edge of the same area
    starting at ``b``; loops and ranks by pointer doubling, no loop over edges."""
    skey = el * nv + a
    o = np.argsort(skey, kind="stable")
    a, b, el, skey = a[o], b[o], el[o], skey[o]
    dup = np.r_[False, skey[1:] == skey[:-1]]
    want = el * nv + b
    nxt = np.searchsorted(skey, want)
    nxt = np.minimum(nxt, max(len(skey) - 1, 0))
    found = skey[nxt] == want if len(skey) else np.zeros(0, dtype=bool)
    # a vertex with two outgoing boundary edges, or an edge without a successor: not simple loops
    broken = np.r_[el[dup], el[~found]]
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
    return a[order], el[order], cyc[order], broken


@dataclass(frozen=True)
class _Loops:
    """Boundary loops with their collinear vertices marked.

    start : (nL,) first edge of each loop; cid : (E,) loop of each edge; keep : (E,) the edge's
    start vertex is a corner (not collinear); kc : (nL,) corners per loop; area : (nL,) area label
    """

    start: np.ndarray
    cid: np.ndarray
    keep: np.ndarray
    kc: np.ndarray
    area: np.ndarray


def _loop_corners(V: np.ndarray, a: np.ndarray, el: np.ndarray, cyc: np.ndarray) -> _Loops:
    """The loops of chained edges (:func:`_chain_loops`), their collinear vertices dropped."""
    E = len(a)
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
    return _Loops(start, cid, keep, kc, el[start])


def _loop_polygons(V: np.ndarray, fn: np.ndarray, lab: np.ndarray, a: np.ndarray, loops: _Loops,
                   use_loop: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(pts, count, normal, weight)`` of the loops ``use_loop`` as elements: their corners in order,
    the area's normal (faces are coplanar: its first face's) and the loop's orientation against it
    (Newell): +1 for an outer loop, -1 for a hole."""
    m, L = len(lab), int(lab.max()) + 1
    cid_k, pts = loops.cid[loops.keep], V[a[loops.keep]]
    sel = use_loop[cid_k]
    cid_k, pts = cid_k[sel], pts[sel]
    chosen = np.flatnonzero(use_loop)
    remap = np.full(len(loops.start), -1)
    remap[chosen] = np.arange(len(chosen))
    li = remap[cid_k]
    nL = len(chosen)
    cntL = loops.kc[chosen]
    o2 = np.argsort(li, kind="stable")  # keep order within a loop (stable), loops in order
    pts_l = pts[o2]
    first_l = np.cumsum(cntL) - cntL
    rep_face = np.zeros(L, dtype=np.int64)
    rep_face[lab[::-1]] = np.arange(m)[::-1]
    nrm_l = fn[rep_face[loops.area[chosen]]]
    lid = np.repeat(np.arange(nL), cntL)
    posl = np.arange(len(pts_l)) - first_l[lid]
    q = pts_l[first_l[lid] + (posl + 1) % cntL[lid]]
    newell = np.stack([np.bincount(lid, weights=c, minlength=nL) for c in np.cross(pts_l, q).T], axis=1)
    w_l = np.where(np.einsum("ij,ij->i", newell.reshape(-1, 3), nrm_l.reshape(-1, 3)) >= 0, 1.0, -1.0)
    return pts_l, cntL, nrm_l, w_l


def patch_elements(part_mesh: TriangleMesh) -> Elements:
    """Surface elements of :func:`contact_patches`: the mesh's triangles, with each exactly coplanar,
    edge-connected area of at least ``MERGE_MIN_FACES`` faces replaced by its boundary loops (outer
    loops weight +1, holes -1; collinear boundary vertices dropped), so a finely tessellated flat
    face costs one polygon. Areas whose boundary is not a set of simple loops, or has a loop longer
    than ``MERGE_MAX_VERTS``, stay triangles.

    Returns ``pts`` (P, 3), ``first`` (E,), ``count`` (E,) (element e's vertices, in order:
    ``pts[first[e]:first[e] + count[e]]``), ``normal`` (E, 3) unit outward, ``weight`` (E,) +-1.
    No loop over faces; memory linear in the mesh."""
    V = np.asarray(part_mesh.vertices, dtype=np.float64)
    Fc = np.asarray(part_mesh.faces, dtype=np.int64)
    tris = V[Fc] if len(Fc) else np.zeros((0, 3, 3))
    fn = np.asarray(part_mesh.face_normals, dtype=np.float64) if len(Fc) else np.zeros((0, 3))
    if len(Fc) < MERGE_MIN_FACES:
        return _triangle_elements(tris, fn)
    lab = _coplanar_labels(V, Fc, fn)
    if lab is None:
        return _triangle_elements(tris, fn)
    size = np.bincount(lab)
    merge = size[lab] >= MERGE_MIN_FACES  # per face
    label_ok = np.bincount(lab, minlength=int(lab.max()) + 1) >= MERGE_MIN_FACES
    if not merge.any():
        return _triangle_elements(tris, fn)
    a, b, el = _area_boundary(Fc, lab, merge, len(V))
    if len(a) == 0:  # closed coplanar areas (no boundary): keep triangles
        return _triangle_elements(tris, fn)
    a, el, cyc, broken = _chain_loops(a, b, el, len(V))
    label_ok[broken] = False
    loops = _loop_corners(V, a, el, cyc)
    label_ok[loops.area[(loops.kc < 3) | (loops.kc > MERGE_MAX_VERTS)]] = False
    tri_face = ~merge | ~label_ok[lab]  # faces of areas that stay triangles
    pts_l, cntL, nrm_l, w_l = _loop_polygons(V, fn, lab, a, loops, label_ok[loops.area])
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


def _rotated(jp: _JawPass, poly: np.ndarray, n: np.ndarray, nx: np.ndarray, w: np.ndarray, gu: np.ndarray,
             ct: _Contacts) -> None:
    """Moments of slab-clipped polygons ``poly`` (K, V, 3) of contacts ``gu`` that lie inside the
    jaw's pad at every roll: computed once per contact in the frame of its first pose, summed per
    contact, then turned to each pose of the contact (area kept, first moments as a vector, second
    moments as a tensor) and added. Every pose of a contact shares its TCP origin."""
    mom, j, o, R, cos_flat, M = jp.mom, jp.j, jp.o, jp.R, jp.cos_flat, len(jp.o)
    gsize, gstart, members = ct.gsize, ct.gstart, ct.members
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


@dataclass(frozen=True)
class _Elements:
    """The part's surface elements (:func:`patch_elements`) and what the near tests read of them.

    pts, first, count, fn, weight : as :func:`patch_elements` returns them
    cent : (F, 3) vertex centroids; face_rad : (F,) largest vertex distance from the centroid
    vclass : (F,) index into :data:`VERTEX_CLASSES`
    slab_tol : (F,) an element meeting a contact's slab has its centroid this close to the contact plane
    lat_tol : (F,) ... and this close (squared) to the contact, laterally
    cent_sq : (F,) squared centroid norms
    """

    pts: np.ndarray
    first: np.ndarray
    count: np.ndarray
    fn: np.ndarray
    weight: np.ndarray
    cent: np.ndarray
    face_rad: np.ndarray
    vclass: np.ndarray
    slab_tol: np.ndarray
    lat_tol: np.ndarray
    cent_sq: np.ndarray


def _elements(part_mesh: TriangleMesh, pad_reach: float, depth: float) -> _Elements:
    """The :class:`_Elements` of ``part_mesh`` (its elements computed once per part when the mesh
    caches derived data: callers may call :func:`contact_patches` per chunk of grasps)."""
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
    cent_sq = np.einsum("fi,fi->f", cent, cent)
    slab_tol = face_rad + depth
    lat_tol = (pad_reach + face_rad) ** 2
    return _Elements(pts, first, count, fn, weight, cent, face_rad, vclass, slab_tol, lat_tol, cent_sq)


@dataclass(frozen=True)
class _Contacts:
    """The distinct (contact, closing axis) of one jaw over the grasps: the rolls of one candidate
    share them, so the face search and the slab cull (roll-independent) run once per distinct contact.

    inv : (M,) each grasp's contact; members : (M,) grasps grouped by contact (``gsize`` from
    ``gstart`` each); cu, axu : (U, 3) each contact's point and closing axis
    """

    inv: np.ndarray
    members: np.ndarray
    gsize: np.ndarray
    gstart: np.ndarray
    cu: np.ndarray
    axu: np.ndarray


def _distinct_contacts(C: np.ndarray, R: np.ndarray, o: np.ndarray, j: int) -> _Contacts:
    """The :class:`_Contacts` of jaw ``j`` for contacts ``C`` (M, 2, 3) and TCP poses ``R``, ``o``."""
    key = np.concatenate([C[:, j], R[:, :, 0], np.einsum("mi,mi->m", C[:, j] - o, R[:, :, 0])[:, None]], axis=1)
    _, rep, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    U = len(rep)
    members = np.argsort(inv, kind="stable")
    gsize = np.bincount(inv, minlength=U)
    gstart = np.cumsum(gsize) - gsize
    return _Contacts(inv, members, gsize, gstart, np.ascontiguousarray(C[rep, j]), np.ascontiguousarray(R[rep, :, 0]))


def _patch_pairs(jp: _JawPass, f: np.ndarray, gu: np.ndarray, nx: np.ndarray, el: _Elements, ct: _Contacts,
                 max_pairs: int, disc: float = 0.0, same_origin: np.ndarray | None = None) -> None:
    """Elements ``f`` near distinct contacts ``gu``: cull and clip on the contact slab once, then
    expand to every roll of the contact (at most ``max_pairs`` pairs at once) and accumulate.
    ``disc`` > 0: elements within that distance of the closing axis through the TCP (inside the pad
    at every roll) of a contact whose poses share their origin (``same_origin`` per contact) go
    through :func:`_rotated` instead."""
    count, weight, gsize, gstart, members = el.count, el.weight, ct.gsize, ct.gstart, ct.members
    o, R, depth = jp.o, jp.R, jp.depth
    # exact cull and clip on the contact slab (x only, the same for every roll): once per
    # (contact, element), compiled (grasplan.grasps.quality_kernels.slab_polygons)
    keep, poly, npx = slab_polygons(el.pts, el.first, count, np.ascontiguousarray(f, dtype=np.int64),
                                    np.ascontiguousarray(gu, dtype=np.int64), ct.cu, ct.axu, float(depth))
    gu, f, nx = gu[keep], f[keep], nx[keep]
    if disc > 0 and same_origin is not None and len(gu):
        fast = same_origin[gu] & within_disc(np.ascontiguousarray(poly), np.ascontiguousarray(npx, dtype=np.int64), o, R,
                                             members[gstart[gu]], disc * disc)
        if fast.any():
            _rotated(jp, poly[fast], npx[fast], nx[fast], weight[f[fast]], gu[fast], ct)
            slow = ~fast
            gu, f, nx, poly, npx = gu[slow], f[slow], nx[slow], poly[slow], npx[slow]
    # pair the survivors with every roll of their contact, in bounded sub-chunks
    nrep = gsize[gu]
    ends = np.cumsum(nrep)
    wf = weight[f]
    s0 = 0
    while s0 < len(gu):
        s1 = s0 + max(1, int(np.searchsorted(ends[s0:] - (ends[s0 - 1] if s0 else 0), max_pairs, side="right")))
        r = nrep[s0:s1]
        pu = np.repeat(np.arange(s0, s1), r)
        within = np.arange(len(pu)) - np.repeat(np.cumsum(r) - r, r)
        g = members[gstart[gu[pu]] + within]
        _accumulate(jp, poly, npx, nx, wf, pu, g)
        s0 = s1


def _pairs_by_class(jp: _JawPass, f: np.ndarray, b: np.ndarray, nx: np.ndarray, el: _Elements, ct: _Contacts,
                    disc: float = 0.0, same_origin: np.ndarray | None = None) -> None:
    """:func:`_patch_pairs` of the (element ``f``, contact ``b``) pairs, one vertex class at a time,
    each with a budget of ``max_pairs`` triangle-equivalents."""
    for cls in np.unique(el.vclass[f]):
        sel = el.vclass[f] == cls
        budget = max(1, (jp.max_pairs * 3) // VERTEX_CLASSES[cls])
        _patch_pairs(jp, f[sel], b[sel], nx[sel], el, ct, budget, disc=disc, same_origin=same_origin)


def _dense_search(jp: _JawPass, el: _Elements, ct: _Contacts) -> None:
    """Elements near each contact's pad by the dense test (:func:`grasplan.grasps.patch_search.near_faces_dense`);
    their patches accumulated."""
    y_lo, y_hi, z_lo, z_hi = jp.rect
    disc = (1.0 - 1e-9) * min(-y_lo, y_hi, -z_lo, z_hi)
    ref_o = jp.o[ct.members[ct.gstart[ct.inv]]]
    same = np.bincount(ct.inv, weights=np.any(jp.o != ref_o, axis=1), minlength=len(ct.cu)) == 0
    for f, b, nx in near_faces_dense(el.cent, el.fn, el.cent_sq, el.slab_tol, el.lat_tol, ct.cu, ct.axu, jp.j,
                                     jp.max_pairs):
        _pairs_by_class(jp, f, b, nx, el, ct, disc=disc, same_origin=same)


def _grid_search(jp: _JawPass, el: _Elements, ct: _Contacts, pad_reach: float) -> None:
    """Elements near each contact's pad by visiting the grid cells its slab crosses
    (:func:`grasplan.grasps.patch_search.near_faces_slab`); their patches accumulated, the moments of elements inside the disc
    the pad covers at every roll turned per roll (:func:`_rotated`)."""
    y_lo, y_hi, z_lo, z_hi = jp.rect
    f, b, nx = near_faces_slab(el.cent, el.fn, el.face_rad, ct.cu, ct.axu, el.slab_tol, el.lat_tol, pad_reach, jp.j)
    # the disc the pad covers at every roll; contacts whose poses share the TCP origin
    disc = (1.0 - 1e-9) * min(-y_lo, y_hi, -z_lo, z_hi)
    ref_o = jp.o[ct.members[ct.gstart[ct.inv]]]
    same = np.bincount(ct.inv, weights=np.any(jp.o != ref_o, axis=1), minlength=len(ct.cu)) == 0
    _pairs_by_class(jp, f, b, nx, el, ct, disc=disc, same_origin=same)


def contact_patches(part_mesh: TriangleMesh, gripper: Gripper, T_part_tcp: np.ndarray, contacts: np.ndarray,
                    *, depth: float = CONTACT_DEPTH, flat_deg: float = FLAT_DEG,
                    max_pairs: int = MAX_PAIRS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Patch between each finger pad and the part.

    Per jaw, the finger pad is the inner face of the gripper's own finger geometry
    (:func:`pad_rectangle`), placed on the plane through the contact, perpendicular to the closing
    axis. The patch is the part surface inside the pad rectangle and within ``depth`` (the pad's
    compliance) of that plane, facing the pad: every such element is clipped exactly to the box
    ``|x - x_contact| <= depth`` x pad rectangle and its projection on the pad is integrated (area,
    first and second moments). Elements are paired with distinct contacts by a near test on their
    centroids (pad reach + the element's radius; :func:`_dense_search`, or :func:`_grid_search` from
    :data:`GRID_FACES` elements), clipped to the contact's slab once per (contact, element), then to
    the pad rectangle per roll. ``type`` is ``surface`` when the part faces parallel to the pad
    (within ``flat_deg``) cover a patch at least ``MIN_SIDE`` wide in every direction, else ``line``
    when the patch is at least ``MIN_SIDE`` long and ``LINE_ASPECT`` times longer than wide, else
    ``point``. Widths are those of the uniform rectangle with the same second moments.

    Returns ``area`` (M, 2) m^2, ``type`` (M, 2) int8 into
    :data:`grasplan.results.quality_json.CONTACT_TYPES`, ``widths`` (M, 2, 2) m (sorted equivalent
    widths of the whole patch)."""
    T = np.asarray(T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    C = np.asarray(contacts, dtype=np.float64).reshape(-1, 2, 3)
    M = len(T)
    rect = pad_rectangle(gripper)
    pad_reach = math.hypot(np.abs(rect[0]).max(), np.abs(rect[1]).max()) + depth
    el = _elements(part_mesh, pad_reach, depth)
    cos_flat = math.cos(math.radians(flat_deg))
    # moments: [grasp, jaw, (all, flat), 6]
    mom = np.zeros((M, 2, 2, 6))
    R = np.ascontiguousarray(T[:, :3, :3])
    o = np.ascontiguousarray(T[:, :3, 3])
    for j in range(2):
        ysgn = -1.0 if j == 0 else 1.0
        y_lo, y_hi = sorted(ysgn * rect[0])
        z_lo, z_hi = rect[1]
        jp = _JawPass(mom, j, o, R, (y_lo, y_hi, z_lo, z_hi), depth, cos_flat, max_pairs)
        ct = _distinct_contacts(C, R, o, j)
        if len(el.count) >= GRID_FACES:
            _grid_search(jp, el, ct, pad_reach)
        else:
            _dense_search(jp, el, ct)
    area = mom[:, :, 0, 0]
    widths = equivalent_widths(mom[:, :, 0])
    flat_widths = equivalent_widths(mom[:, :, 1])
    line = (widths[..., 1] >= MIN_SIDE) & (widths[..., 1] >= LINE_ASPECT * widths[..., 0])
    kind = np.where(flat_widths[..., 0] >= MIN_SIDE, 2, np.where(line, 1, 0)).astype(np.int8)
    return area, kind, widths
