"""Physical grasp quality: contact patches, gravity margin and Ferrari-Canny epsilon (issue 11).

For ``M`` parallel-jaw grasps of a part (TCP frames ``T_part_tcp`` (M, 4, 4), contacts
``(M, 2, 3)`` with outward unit normals, widths ``(M,)``; metres, part frame):

**Contact patch** (per jaw). The finger pad is the inner face of the gripper's own finger
geometry (``Gripper.finger``: the points of its shape on its inner face ``x = 0``, bounded by their
y/z extent), placed on the plane through the contact, perpendicular to the closing axis. The patch
is the part surface inside the pad rectangle and within ``CONTACT_DEPTH`` (0.1 mm, the pad's
compliance) of that plane, facing the pad: every such triangle is clipped exactly to the
box ``|x - x_contact| <= depth`` x pad rectangle (vectorised Sutherland-Hodgman) and its
projection on the pad is integrated (area, first and second moments). ``area`` is m^2; ``type``
is ``surface`` when the part faces parallel to the pad (within ``FLAT_DEG``) cover a patch at least
``MIN_SIDE`` (2 mm) wide in every direction, else ``line`` when the patch is at least ``MIN_SIDE``
long and ``LINE_ASPECT`` (2) times longer than wide, else ``point``. Widths are those of the uniform rectangle with the same second moments.
Exactly coplanar edge-connected areas (``MERGE_MIN_FACES`` faces or more) are first replaced by
their boundary loops (:func:`patch_elements`; holes weigh -1), so a finely tessellated flat face
costs one polygon. Elements are paired with distinct contacts by a dense centroid test (pad reach +
the element's radius), clipped to the contact's slab once per (contact, element), then to the pad
rectangle per roll, in chunks of at most ``MAX_PAIRS`` triangle-equivalent pairs: memory stays bounded.

**Grip force.** ``grip_force`` (gripper YAML, N) is the datasheet gripping force, which Schunk (and
most makers of parallel grippers) define as the arithmetic sum of the forces of the jaws: each of
the two contacts is pressed with the normal force ``F = grip_force / 2`` (70 N for the EGP-C 40's
140 N). ``CONTACTS_PER_GRIP`` is that 2.

**Gravity margin** (soft-finger model). Each contact is pressed with ``F`` (N, above). A contact
resists a tangential force ``|t| <= mu F`` and a torque about the closing axis
``|tau| <= (2/3) mu F a`` (uniform pressure on a disc of radius ``a = sqrt(area / pi)``, at least
``MIN_PATCH_RADIUS``), combined elliptically: ``(|t| / (mu F))^2 + (tau / tau_max)^2 <= 1``. The
load is the part's weight plus a 1 g acceleration in the worst direction: ``f = m g (g_hat + u)``
for unit ``u`` (``N_DIRECTIONS`` Fibonacci directions and ``u = g_hat``), applied at the centre of
mass, whose offset from the contact axis is the lever arm. Forces along the closing axis are held
by the jaws' mechanism; tangential force is shared equally; the torque about the closing axis is
held by torsional friction (shared by capacity); the torque perpendicular to it by a couple of
opposite tangential forces ``|tau_perp| / width`` at the two contacts. ``gravity_margin`` =
1 / (largest utilisation over both contacts and every direction): below 1 the part slips.

**Epsilon** (Ferrari-Canny L1). Two soft-finger contacts, unit normal force each: the friction
cone linearised with ``CONE_EDGES`` (8) edges ``nu + mu (cos k t1 + sin k t2)`` plus the pure normal
force with torsion ``+-(2/3) mu a nu``; torques about the centre of mass divided by the part's
radius ``rho`` (largest distance of the part's vertices from the centre of mass), so wrenches are
in newtons. ``epsilon`` is the radius of the largest origin-centred ball inside the convex hull
of the 20 wrenches; 0 when the origin is outside or the hull is flat. It is computed in closed form
(:func:`ferrari_canny_pair`: each contact's wrenches are a linear image of one bipyramid, so the
hull's facets come from 304 face pairs, each a 2 x 2 solve, vectorised over grasps; ~0.08 ms per
distinct wrench set instead of ~0.6 ms per Qhull call); the rare degenerate sets it cannot decide
(flat, origin on a candidate plane) go to Qhull (scipy ConvexHull, :func:`ferrari_canny`). The two
agree within 1e-9 relative or 1e-10 absolute (Qhull's joggle), tests/test_quality_fast.py.
For speed the torsion radius of epsilon is rounded down to a 5 % geometric grid
(``RADIUS_STEP``), so the rolls of one candidate (same contacts) share one hull computation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from .errors import ConfigError, InputError
from .gripper.model import Gripper
from .mass import MassProperties
from .scoring import (  # noqa: F401
    DEFAULT_SCORING,
    SCORING_FILE,
    ScoringConfig,
    epsilon_term,
    gravity_margin_term,
    load_score_weights,
    load_scoring,
)
from .quality_json import CONTACT_TYPES
from .transforms import check_transform

if TYPE_CHECKING:
    import trimesh

#: part surface within this distance of the pad plane touches the pad, m (pad compliance)
CONTACT_DEPTH = 1e-4
#: part faces within this angle of the pad's plane count as flat contact, degrees
FLAT_DEG = 1.0
#: a patch narrower than this in every direction is a point, in one direction a line, m
MIN_SIDE = 2e-3
#: a non-flat patch at least this many times longer than wide (and MIN_SIDE long) is a line
LINE_ASPECT = 2.0
#: torsional friction radius of a point or line contact on a compliant pad, m
MIN_PATCH_RADIUS = 5e-4
#: epsilon: patch radii are rounded down to a geometric grid of this relative step (shared Qhull calls)
RADIUS_STEP = 0.05
#: Qhull options of epsilon: joggled input (simplicial facets; ~40 % faster on these symmetric wrench
#: sets, facet offsets within 1e-10 of the exact hull; deterministic), no precision warnings
QHULL_OPTIONS = "QJ Pp"
#: epsilon below this (N per N) is 0: the joggle's size, wrench sets that are flat or touch the origin
EPSILON_TOL = 1e-9
#: edges of the linearised friction cone
CONE_EDGES = 8
#: load directions sampled for the worst-case 1 g acceleration
N_DIRECTIONS = 64
#: standard gravity, m/s^2
G = 9.81
#: largest (grasp, face) pairs held at once by the patch computation
MAX_PAIRS = 400_000
#: the gripper's ``grip_force`` is the sum over its jaws: each contact gets grip_force / this
CONTACTS_PER_GRIP = 2


@dataclass(frozen=True)
class Quality:
    """Quality of ``M`` grasps.

    Attributes
    ----------
    contact_area : (M, 2) float64
        Patch area per jaw (jaw 0 touches contact 0, on the TCP's -x side), m^2.
    contact_type : (M, 2) int8
        Index into ``CONTACT_TYPES`` ("point", "line", "surface").
    contact_width : (M, 2, 2) float64
        Equivalent (min, max) widths of each patch, m.
    gravity_margin : (M,) float64
        Friction available / friction needed under gravity + 1 g worst case; < 1 slips.
    epsilon : (M,) float64
        Ferrari-Canny L1 quality (wrench units: N per N of normal force), >= 0.
    grip_force : float
        The gripping force used, N (sum of both jaws; each contact is pressed with half of it).
    mu : float
        Friction coefficient used.
    """

    contact_area: np.ndarray
    contact_type: np.ndarray
    contact_width: np.ndarray
    gravity_margin: np.ndarray
    epsilon: np.ndarray
    grip_force: float
    mu: float

    def __len__(self) -> int:
        return len(self.epsilon)

    def to_json(self, i: int, *, score: float | None = None) -> dict:
        """The ``quality`` object of grasp ``i`` (areas m^2; ``score`` added when given)."""
        out = {
            "contact": [{"area_m2": float(self.contact_area[i, j]),
                         "type": CONTACT_TYPES[int(self.contact_type[i, j])]}
                        for j in range(2)],
            "gravity_margin": float(self.gravity_margin[i]),
            "epsilon": float(self.epsilon[i]),
        }
        if score is not None:
            out["score"] = float(score)
        return out


# ------------------------------------------------------------------------------------------------
# finger pad
# ------------------------------------------------------------------------------------------------
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


# ------------------------------------------------------------------------------------------------
# polygon clipping and moments, vectorised over polygons
# ------------------------------------------------------------------------------------------------
def _gather(P: np.ndarray, idx: np.ndarray) -> np.ndarray:
    return np.take_along_axis(P, idx[..., None].repeat(P.shape[-1], axis=-1), axis=1)


def clip_polygons(P: np.ndarray, n: np.ndarray, axis: int, bound: np.ndarray, keep_below: bool):
    """Clip convex polygons to a half-space (Sutherland-Hodgman, all polygons at once).

    ``P`` (K, N, d) vertices (the first ``n[k]`` valid, in order), ``n`` (K,) counts; keeps
    ``p[axis] <= bound`` (``keep_below``) or ``p[axis] >= bound``, ``bound`` (K,). Returns the
    clipped ``(P', n')`` with ``P'`` (K, N', d)."""
    K, N, _ = P.shape
    if K == 0 or N == 0:
        return P, n
    sgn = 1.0 if keep_below else -1.0
    # only polygons with a vertex outside the half-space change (most lie inside the pad's box)
    valid = np.arange(N)[None, :] < n[:, None]
    need = np.any(valid & (sgn * (P[..., axis] - bound[:, None]) > 0), axis=1)
    if not need.all():
        if not need.any():
            return P, n
        Pc, nc = _clip_all(P[need], n[need], axis, bound[need], sgn)
        out = np.zeros((K, max(N, Pc.shape[1]), P.shape[2]))
        out[~need, :N] = P[~need]
        out[need, :Pc.shape[1]] = Pc
        n_out = n.copy()
        n_out[need] = nc
        return out, n_out
    return _clip_all(P, n, axis, bound, sgn)


def _clip_all(P: np.ndarray, n: np.ndarray, axis: int, bound: np.ndarray, sgn: float):
    K, N, _ = P.shape
    i = np.arange(N)
    valid = i[None, :] < n[:, None]
    nxt = (i[None, :] + 1) % np.maximum(n[:, None], 1)
    Q = _gather(P, nxt)
    dp = sgn * (P[..., axis] - bound[:, None])
    dq = sgn * (Q[..., axis] - bound[:, None])
    in_p = dp <= 0
    cross = valid & (in_p != (dq <= 0))
    t = np.divide(dp, dp - dq, out=np.zeros_like(dp), where=cross)
    X = P + t[..., None] * (Q - P)
    out = np.stack([P, X], axis=2).reshape(K, 2 * N, -1)
    keep = np.stack([valid & in_p, cross], axis=2).reshape(K, 2 * N)
    order = np.argsort(~keep, axis=1, kind="stable")
    n_new = keep.sum(axis=1)
    m = int(n_new.max())
    return _gather(out, order[:, :m]), n_new


def polygon_moments(Y: np.ndarray, Z: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Area integrals of polygons in the (y, z) plane: ``(K, 6)`` = unsigned ``[A, int y, int z,
    int y^2, int z^2, int yz]``. ``Y``, ``Z`` (K, N), the first ``n[k]`` vertices valid."""
    K, N = Y.shape
    out = np.zeros((K, 6))
    if K == 0 or N == 0:
        return out
    i = np.arange(N)
    valid = i[None, :] < n[:, None]
    nxt = (i[None, :] + 1) % np.maximum(n[:, None], 1)
    Y1, Z1 = np.take_along_axis(Y, nxt, 1), np.take_along_axis(Z, nxt, 1)
    c = np.where(valid, Y * Z1 - Y1 * Z, 0.0)
    A = 0.5 * c.sum(1)
    out[:, 0] = A
    out[:, 1] = ((Y + Y1) * c).sum(1) / 6.0
    out[:, 2] = ((Z + Z1) * c).sum(1) / 6.0
    out[:, 3] = ((Y * Y + Y * Y1 + Y1 * Y1) * c).sum(1) / 12.0
    out[:, 4] = ((Z * Z + Z * Z1 + Z1 * Z1) * c).sum(1) / 12.0
    out[:, 5] = ((Y * Z1 + 2 * Y * Z + 2 * Y1 * Z1 + Y1 * Z) * c).sum(1) / 24.0
    return out * np.sign(A)[:, None]


def _equivalent_widths(mom: np.ndarray) -> np.ndarray:
    """(..., 2) sorted widths of the uniform rectangle with the moments ``mom`` (..., 6)."""
    A = np.maximum(mom[..., 0], 1e-300)
    my, mz = mom[..., 1] / A, mom[..., 2] / A
    cyy = mom[..., 3] / A - my * my
    czz = mom[..., 4] / A - mz * mz
    cyz = mom[..., 5] / A - my * mz
    C = np.stack([np.stack([cyy, cyz], -1), np.stack([cyz, czz], -1)], -2)
    lam = np.linalg.eigvalsh(C)
    w = np.sqrt(12.0 * np.maximum(lam, 0.0))
    return np.where(mom[..., :1] > 0, w, 0.0)


# ------------------------------------------------------------------------------------------------
# contact patches
# ------------------------------------------------------------------------------------------------
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


#: patches: exactly coplanar edge-connected areas of at least this many faces are merged into their
#: boundary loops (one polygon instead of thousands of triangles on finely tessellated faces)
MERGE_MIN_FACES = 3
#: patches: a merged loop keeps at most this many vertices after dropping collinear ones (else its
#: area stays triangles, bounding the padded polygon arrays)
MERGE_MAX_VERTS = 256
#: patches: elements are processed in classes of at most these many vertices (bounded padding)
VERTEX_CLASSES = (3, 8, 32, MERGE_MAX_VERTS)
#: patches: faces are coplanar when the far vertex of each lies within this fraction of the part's
#: size from the neighbour's plane and their normals agree to within 1 - this cosine
COPLANAR_TOL = 1e-12


def _doubling_steps(n: int) -> int:
    return max(1, math.ceil(math.log2(max(n, 2))) + 1)


def patch_elements(part_mesh: trimesh.Trimesh):
    """Surface elements of :func:`contact_patches`: the mesh's triangles, with each exactly coplanar,
    edge-connected area of at least ``MERGE_MIN_FACES`` faces replaced by its boundary loops (outer
    loops weight +1, holes -1; collinear boundary vertices dropped). Areas whose boundary is not a
    set of simple loops, or has a loop longer than ``MERGE_MAX_VERTS``, stay triangles.

    Returns ``pts`` (P, 3), ``first`` (E,), ``count`` (E,) (element e's vertices, in order:
    ``pts[first[e]:first[e] + count[e]]``), ``normal`` (E, 3) unit outward, ``weight`` (E,) +-1.
    No loop over faces; memory linear in the mesh."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from .convexity import edge_adjacency

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


def _patch_pairs(mom, j, f, gu, nx, pts, first, count, weight, cu, axu, gsize, gstart, members, o, R, depth,
                 rect, cos_flat, M, max_pairs) -> None:
    """Elements ``f`` near distinct contacts ``gu``: cull and clip on the contact slab once, then
    expand to every roll of the contact (at most ``max_pairs`` pairs at once) and accumulate."""
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


def contact_patches(part_mesh: trimesh.Trimesh, gripper: Gripper, T_part_tcp: np.ndarray, contacts: np.ndarray,
                    *, depth: float = CONTACT_DEPTH, flat_deg: float = FLAT_DEG, max_pairs: int = MAX_PAIRS):
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
    widths = _equivalent_widths(mom[:, :, 0])
    flat_widths = _equivalent_widths(mom[:, :, 1])
    line = (widths[..., 1] >= MIN_SIDE) & (widths[..., 1] >= LINE_ASPECT * widths[..., 0])
    kind = np.where(flat_widths[..., 0] >= MIN_SIDE, 2, np.where(line, 1, 0)).astype(np.int8)
    return area, kind, widths


# ------------------------------------------------------------------------------------------------
# gravity margin and epsilon
# ------------------------------------------------------------------------------------------------
def fibonacci_directions(n: int) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere (deterministic)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = k * math.pi * (3.0 - math.sqrt(5.0))
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def patch_radius(area: np.ndarray) -> np.ndarray:
    """Soft-finger disc radius ``max(sqrt(area / pi), MIN_PATCH_RADIUS)`` (m) of patch areas (m^2)."""
    return np.maximum(np.sqrt(np.maximum(area, 0.0) / math.pi), MIN_PATCH_RADIUS)


#: soft-finger torsion: the largest friction torque about a contact normal is ``mu * N * SOFT_FINGER
#: * radius`` (uniform pressure on a disc of that radius: the integral of ``r dF`` gives 2/3)
SOFT_FINGER = 2.0 / 3.0


def torsion_length(area: np.ndarray) -> np.ndarray:
    """Torsional friction per unit ``mu`` and newton of normal force (m) of patches of ``area``
    (m^2): ``SOFT_FINGER * patch_radius(area)``. The one definition used by
    :func:`gravity_margin`, epsilon and the MuJoCo check (:mod:`grasplan.simulate`)."""
    return SOFT_FINGER * patch_radius(area)


def gravity_margin(mass_props: MassProperties, T_world_part: np.ndarray, T_part_tcp: np.ndarray,
                   width: np.ndarray, area: np.ndarray, *, mu: float, normal_force: float,
                   accel_g: float = 1.0, straight_down_only: bool = False) -> np.ndarray:
    """(M,) friction available / needed to hold the part under gravity plus ``accel_g`` g in the
    worst direction (module docstring). ``area`` (M, 2) m^2, ``width`` (M,) m, ``normal_force``: N
    pressing each contact (``grip_force / CONTACTS_PER_GRIP``). ``straight_down_only``: the
    acceleration straight down only, one of the directions the margin takes the worst of, so the
    result is >= the margin (an upper bound, :func:`physical_bounds`)."""
    T = np.asarray(T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    R = T[:, :3, :3]
    g_hat = np.einsum("mji,j->mi", R, T_world_part[:3, :3].T @ np.array([0.0, 0.0, -1.0]))  # in TCP
    com = np.einsum("mji,mj->mi", R, mass_props.com - T[:, :3, 3])  # centre of mass in TCP
    u = g_hat[:, None] if straight_down_only else \
        np.concatenate([g_hat[:, None], np.broadcast_to(fibonacci_directions(N_DIRECTIONS), (len(T), N_DIRECTIONS, 3))], 1)
    f = mass_props.mass * G * (g_hat[:, None] + accel_g * u)  # (M, D, 3) load on the part, TCP frame
    t_max = mu * normal_force
    if t_max <= 0:  # no friction: nothing holds the part against a tangential load
        return np.zeros(len(T))
    fx, fy, fz = f[..., 0], f[..., 1], f[..., 2]
    cx, cy, cz = (com[:, k, None] for k in range(3))
    tau_x = cy * fz - cz * fy  # tau = com x f, component by component (no (M, D, 3) temporaries)
    tau_y = cz * fx - cx * fz
    tau_z = cx * fy - cy * fx
    inv_w = 1.0 / np.maximum(np.asarray(width, dtype=np.float64), 1e-9)[:, None]
    # the couple h = (tau_perp x x_hat) / width = (0, tau_z, -tau_y) / width at the two contacts
    hy, hz = tau_z * inv_w, -tau_y * inv_w
    tors_max = mu * normal_force * torsion_length(area).sum(axis=1)  # both contacts
    r_tors2 = (tau_x / tors_max[:, None]) ** 2
    a0 = (0.5 * fy - hy) ** 2 + (0.5 * fz - hz) ** 2
    a1 = (0.5 * fy + hy) ** 2 + (0.5 * fz + hz) ** 2
    demand = np.sqrt((np.maximum(a0, a1) / (t_max * t_max) + r_tors2).max(axis=1))  # worst contact, direction
    return 1.0 / np.maximum(demand, 1e-12)


def _tangent_basis(nu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.where(np.abs(nu[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    t1 = np.cross(nu, a)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    return t1, np.cross(nu, t1)


def contact_wrenches(contacts: np.ndarray, normals: np.ndarray, com: np.ndarray, rho: float, mu: float,
                     torsion: np.ndarray) -> np.ndarray:
    """(M, 2 * (CONE_EDGES + 2), 6) primitive wrenches (force N, torque / ``rho``) of two soft-finger
    contacts with unit normal force: the cone edges and the normal force with +-torsion.
    ``torsion`` (M, 2): torsional friction per newton of normal force, m."""
    nu = -np.asarray(normals, dtype=np.float64)
    nu = nu / np.linalg.norm(nu, axis=-1, keepdims=True)
    t1, t2 = _tangent_basis(nu)
    th = 2.0 * math.pi * np.arange(CONE_EDGES) / CONE_EDGES
    edges = nu[:, :, None] + mu * (np.cos(th)[:, None] * t1[:, :, None] + np.sin(th)[:, None] * t2[:, :, None])
    F = np.concatenate([edges, np.repeat(nu[:, :, None], 2, axis=2)], axis=2)  # (M, 2, E + 2, 3)
    r = (np.asarray(contacts, dtype=np.float64) - com)[:, :, None]
    tq = np.cross(r, F)
    tq[:, :, CONE_EDGES] += torsion[..., None] * nu
    tq[:, :, CONE_EDGES + 1] -= torsion[..., None] * nu
    W = np.concatenate([F, tq / rho], axis=3)
    return W.reshape(len(W), -1, 6)


def ferrari_canny(W: np.ndarray) -> np.ndarray:
    """(M,) L1 epsilon: distance from the origin to the hull of each wrench set ``W`` (M, k, 6);
    0 when the origin is not strictly inside or the hull is degenerate. One Qhull call per grasp."""
    out = np.zeros(len(W))
    for m in range(len(W)):
        try:
            eq = ConvexHull(W[m], qhull_options=QHULL_OPTIONS).equations
        except QhullError:
            continue
        d = -eq[:, -1]  # unit facet normals: n . x + b <= 0 inside
        e = float(d.min())
        out[m] = e if e > EPSILON_TOL else 0.0  # below the joggle: the origin is on the boundary (flat set)
    return out


#: exact epsilon: relative tolerance of the support test of a candidate facet (value units: 1 = on the plane)
FACET_TOL = 1e-10
#: exact epsilon: grasps processed at once (memory: ~ chunk x 304 candidates x 6 floats)
EPS_CHUNK = 1024


def _bipyramid_dirs(mu: float, tau: np.ndarray):
    """Local facet families of one contact's wrench bipyramid (coordinates (alpha, beta, gamma, s):
    force ``alpha nu + beta t1 + gamma t2`` and torsion ``s``; every primitive wrench has alpha = 1).
    Returns the triangle directions (B, 16, 4), the edge direction pairs (B, 24, 2, 4) and the 10
    local points (B, 10, 4); ``tau`` (B,) torsion radius, m."""
    B = len(tau)
    E = CONE_EDGES
    th = 2.0 * math.pi * np.arange(E) / E
    c = np.stack([np.cos(th), np.sin(th)], 1)  # (E, 2) cone directions
    half = math.pi / E
    m = np.stack([np.cos(th + half), np.sin(th + half)], 1) / math.cos(half)  # m . c_e = m . c_{e+1} = 1
    inv_t = 1.0 / tau
    tri = np.zeros((B, 2 * E, 4))
    tri[:, :, 0] = -1.0
    tri[:, :, 1:3] = np.tile(m / mu, (2, 1))
    tri[:, :, 3] = np.concatenate([np.ones(E), -np.ones(E)])[None] * inv_t[:, None]
    edge = np.zeros((B, 3 * E, 2, 4))
    edge[:, :E, 0, 0] = -1.0  # octagon edges (e, e+1): lambda (-1, m/mu, 0) + sigma e_s
    edge[:, :E, 0, 1:3] = m / mu
    edge[:, :E, 1, 3] = 1.0
    for k, sgn in enumerate((1.0, -1.0)):  # apex edges (apex +-, c_e): lambda (-1, c/mu, +-1/tau) + sigma c_perp
        sl = slice(E * (k + 1), E * (k + 2))
        edge[:, sl, 0, 0] = -1.0
        edge[:, sl, 0, 1:3] = c / mu
        edge[:, sl, 0, 3] = sgn * inv_t[:, None]
        edge[:, sl, 1, 1] = -c[:, 1]
        edge[:, sl, 1, 2] = c[:, 0]
    pts = np.zeros((B, E + 2, 4))
    pts[:, :, 0] = 1.0
    pts[:, :E, 1:3] = mu * c
    pts[:, E, 3] = tau
    pts[:, E + 1, 3] = -tau
    return tri, edge, pts


def ferrari_canny_pair(contacts: np.ndarray, normals: np.ndarray, com: np.ndarray, rho: float, mu: float,
                       torsion: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact Ferrari-Canny L1 epsilon of two soft-finger contacts without Qhull, vectorised over grasps.

    Each contact's primitive wrenches (:func:`contact_wrenches`) are a linear image of one
    bipyramid (the 8-gon of cone edges plus the two torsion points), so every facet of the hull of
    both sets is spanned by a face of each: (triangle, triangle), (edge, whole set) or (whole set,
    edge), 304 candidate hyperplanes. On the level set ``u . w = 1`` each candidate is a 2 x 2
    linear solve in closed form; it is a facet (origin inside) when every primitive wrench has
    ``u . w <= 1`` and it separates the origin when every one has ``u . w >= 1`` (epsilon 0).
    epsilon = min over facets of ``1 / |u|``. Returns ``(epsilon (M,), exact (M,) bool)``: rows with
    ``exact`` False (degenerate: flat wrench set, the origin on a candidate's plane) need
    :func:`ferrari_canny`."""
    C = np.asarray(contacts, dtype=np.float64)
    M = len(C)
    out = np.zeros(M)
    exact = np.zeros(M, dtype=bool)
    if M == 0 or not mu > 0:
        return out, exact
    nu = -np.asarray(normals, dtype=np.float64)
    nu = nu / np.linalg.norm(nu, axis=-1, keepdims=True)
    t1, t2 = _tangent_basis(nu)
    r = C - com
    tors = np.asarray(torsion, dtype=np.float64).reshape(M, 2)
    for s0 in range(0, M, EPS_CHUNK):
        sl = slice(s0, min(M, s0 + EPS_CHUNK))
        out[sl], exact[sl] = _fc_pair_chunk(nu[sl], t1[sl], t2[sl], r[sl], rho, mu, tors[sl])
    return out, exact


def _fc_pair_chunk(nu, t1, t2, r, rho, mu, tors):
    B = len(nu)
    # phi_k = L_k^T u: (a + b x r_k / rho, b . nu_k / rho); Lt (B, 8, 6) stacks both contacts
    Lt = np.zeros((B, 8, 6))
    for k in range(2):
        Lt[:, 4 * k:4 * k + 3, :3] = np.eye(3)
        rx = r[:, k] / rho
        # (b x r) = -[r]x b: the rows of -[r]x
        Lt[:, 4 * k, 3:] = np.stack([np.zeros(B), rx[:, 2], -rx[:, 1]], 1)
        Lt[:, 4 * k + 1, 3:] = np.stack([-rx[:, 2], np.zeros(B), rx[:, 0]], 1)
        Lt[:, 4 * k + 2, 3:] = np.stack([rx[:, 1], -rx[:, 0], np.zeros(B)], 1)
        Lt[:, 4 * k + 3, 3:] = nu[:, k] / rho
    U, S, _ = np.linalg.svd(Lt)
    ok = S[:, -1] > 1e-9 * S[:, 0]  # full rank: the wrench set spans R^6
    N = U[:, :, 6:]  # (B, 8, 2): (phi1, phi2) is an image iff N^T phi = 0
    G = np.swapaxes(U[:, :, :6], 1, 2) / np.where(S > 0, S, 1.0)[..., None]  # |u| = |G phi| (u = V G phi)
    Ek = np.zeros((B, 2, 4, 4))  # local (alpha, beta, gamma, s) -> q = (f, s)
    Ek[:, :, :3, 0], Ek[:, :, :3, 1], Ek[:, :, :3, 2] = nu, t1, t2
    Ek[:, :, 3, 3] = 1.0
    A = [np.matmul(np.swapaxes(N[:, 4 * k:4 * k + 4], 1, 2), Ek[:, k]) for k in range(2)]  # (B, 2, 4)
    GE = [np.matmul(G[:, :, 4 * k:4 * k + 4], Ek[:, k]) for k in range(2)]  # (B, 6, 4)
    At = [np.swapaxes(a, 1, 2) for a in A]  # (B, 4, 2)
    GEt = [np.swapaxes(a, 1, 2) for a in GE]  # (B, 4, 6)
    h = A[0][:, :, 0] + A[1][:, :, 0]
    g0 = GE[0][:, :, 0] + GE[1][:, :, 0]
    tri, edge, pts = zip(*(_bipyramid_dirs(mu, tors[:, k]) for k in range(2)))
    best = np.full(B, np.inf)
    outside = np.zeros(B, dtype=bool)
    singular = np.zeros(B, dtype=bool)
    tol = FACET_TOL
    # (triangle, triangle): phi_k = e_alpha + lambda_k k_k; supporting iff both lambda >= 0 (all <= 1),
    # separating iff both <= 0
    a1 = np.matmul(tri[0], At[0])  # (B, 16, 2)
    a2 = np.matmul(tri[1], At[1])
    det = a1[:, :, None, 0] * a2[:, None, :, 1] - a1[:, :, None, 1] * a2[:, None, :, 0]
    scale = np.linalg.norm(a1, axis=2)[:, :, None] * np.linalg.norm(a2, axis=2)[:, None, :]
    sing = np.abs(det) <= 1e-12 * scale
    dd = np.where(sing, 1.0, det)
    l1 = (-h[:, None, None, 0] * a2[:, None, :, 1] + h[:, None, None, 1] * a2[:, None, :, 0]) / dd
    l2 = (-a1[:, :, None, 0] * h[:, None, None, 1] + a1[:, :, None, 1] * h[:, None, None, 0]) / dd
    # a singular pair: a1 parallel to a2. Anti-parallel (or a zero column): a supporting hyperplane
    # through the origin holds both triangles (lambda1, lambda2 >= 0 at level 0), the origin is on the
    # hull's boundary: epsilon 0. Parallel: no such plane, and a facet through both faces holds more
    # points, so it is found from another pair; the pair is skipped.
    n1 = np.linalg.norm(a1, axis=2)[:, :, None]
    n2 = np.linalg.norm(a2, axis=2)[:, None, :]
    dot = a1[:, :, None, 0] * a2[:, None, :, 0] + a1[:, :, None, 1] * a2[:, None, :, 1]
    big = max(float(np.max(n1, initial=0.0)), float(np.max(n2, initial=0.0)), 1e-300)
    zero_col = (n1 <= 1e-12 * big) | (n2 <= 1e-12 * big)
    on_plane = sing & ((dot < 0) | zero_col)
    outside |= on_plane.any(axis=(1, 2))
    gt1 = np.matmul(tri[0], GEt[0])  # (B, 16, 6)
    gt2 = np.matmul(tri[1], GEt[1])
    sup = ~sing & (l1 >= -tol) & (l2 >= -tol)
    sep = ~sing & (l1 <= tol) & (l2 <= tol)
    bi, si, ti = np.nonzero(sup)  # |u| only where the plane supports (a few facets per grasp)
    u = g0[bi] + l1[bi, si, ti, None] * gt1[bi, si] + l2[bi, si, ti, None] * gt2[bi, ti]
    np.minimum.at(best, bi, 1.0 / np.linalg.norm(u, axis=1))
    outside |= sep.any(axis=(1, 2))
    # (edge of contact k, whole of the other): phi_k = e_alpha + lambda k + sigma k', phi_other = e_alpha
    for k in range(2):
        ne = edge[k].shape[1]
        ak = np.matmul(edge[k].reshape(B, 2 * ne, 4), At[k]).reshape(B, ne, 2, 2)
        det = ak[:, :, 0, 0] * ak[:, :, 1, 1] - ak[:, :, 0, 1] * ak[:, :, 1, 0]
        scale = np.linalg.norm(ak[:, :, 0], axis=2) * np.linalg.norm(ak[:, :, 1], axis=2)
        sing = np.abs(det) <= 1e-12 * scale
        dd = np.where(sing, 1.0, det)
        lam = (-h[:, None, 0] * ak[:, :, 1, 1] + h[:, None, 1] * ak[:, :, 1, 0]) / dd
        sig = (-ak[:, :, 0, 0] * h[:, None, 1] + ak[:, :, 0, 1] * h[:, None, 0]) / dd
        singular |= sing.any(axis=1)
        psi = lam[..., None] * edge[k][:, :, 0] + sig[..., None] * edge[k][:, :, 1]  # psi - e_alpha
        val = np.matmul(psi, np.swapaxes(pts[k], 1, 2))  # value - 1 at the 10 points
        sup = ~sing & (val.max(axis=2) <= tol)
        sep = ~sing & (val.min(axis=2) >= -tol)
        ge = np.matmul(edge[k].reshape(B, 2 * ne, 4), GEt[k]).reshape(B, ne, 2, 6)
        u = g0[:, None] + lam[..., None] * ge[:, :, 0] + sig[..., None] * ge[:, :, 1]
        un = np.linalg.norm(u, axis=2)
        best = np.minimum(best, np.where(sup, 1.0 / un, np.inf).min(axis=1))
        outside |= sep.any(axis=1)
    eps = np.where(outside | ~np.isfinite(best), 0.0, best)
    eps = np.where(eps > EPSILON_TOL, eps, 0.0)
    exact = ok & ~singular & (np.isfinite(best) | outside)
    return eps, exact


def quantised_patch_radius(area: np.ndarray) -> np.ndarray:
    """:func:`patch_radius` rounded down to the geometric grid ``MIN_PATCH_RADIUS * (1 +
    RADIUS_STEP)^k`` (conservative: less torsion), so that grasps with the same contacts share one
    epsilon."""
    r = patch_radius(area)
    k = np.floor(np.log(r / MIN_PATCH_RADIUS) / math.log1p(RADIUS_STEP) + 1e-9)
    return MIN_PATCH_RADIUS * np.exp(np.maximum(k, 0.0) * math.log1p(RADIUS_STEP))


def epsilon_dedup(contacts: np.ndarray, normals: np.ndarray, area: np.ndarray, com: np.ndarray, rho: float,
                  mu: float) -> np.ndarray:
    """(M,) Ferrari-Canny epsilon, once per distinct wrench set (the rolls of one candidate share
    contacts and normals, and their patch radii are quantised (:func:`quantised_patch_radius`)):
    :func:`ferrari_canny_pair` (closed form, vectorised), Qhull (:func:`ferrari_canny`) only for the
    degenerate sets it does not decide."""
    M = len(contacts)
    if M == 0:
        return np.zeros(0)
    rq = quantised_patch_radius(area)
    key = np.concatenate([np.asarray(contacts, dtype=np.float64).reshape(M, 6),
                          np.asarray(normals, dtype=np.float64).reshape(M, 6), rq], axis=1)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    u = first
    Cu, Nu, tors = np.asarray(contacts)[u], np.asarray(normals)[u], SOFT_FINGER * mu * rq[u]
    eps, exact = ferrari_canny_pair(Cu, Nu, com, rho, mu, tors)
    if not exact.all():  # degenerate wrench sets: Qhull
        bad = np.flatnonzero(~exact)
        eps[bad] = ferrari_canny(contact_wrenches(Cu[bad], Nu[bad], com, rho, mu, tors[bad]))
    return eps[inverse.reshape(-1)]


def physical_bounds(part_mesh, mass_props: MassProperties, gripper: Gripper, T_part_tcp: np.ndarray,
                    candidate: np.ndarray, contacts: np.ndarray, normals: np.ndarray, width: np.ndarray, *,
                    T_world_part: np.ndarray, mu: float, grip_force: float | None = None) -> dict[str, np.ndarray]:
    """Upper bounds of ``gravity_margin`` and ``epsilon`` of ``M`` poses without their contact
    patches or collision status (the rank-order evaluation checks poses in the order of their
    score's upper bound, :class:`grasplan.grasps.LazyGrasps`). Both grow with the patch area (more
    torsional friction: the wrench set grows, the demand falls), and a patch is never larger than
    the finger's pad: each is computed with the pad's whole area on both jaws; the margin also
    with the load straight down only (it takes the worst of several directions), the epsilon once
    per candidate (its rolls share the contacts). ``T_part_tcp`` (M, 4, 4), ``candidate`` (M,)
    into ``contacts``/``normals`` (K, 2, 3); ``width`` (M,). Returns ``(M,)`` arrays."""
    T = np.asarray(T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    M = len(T)
    ci = np.asarray(candidate, dtype=np.int64).reshape(-1)
    rect = pad_rectangle(gripper)
    pad = float(np.prod(rect[:, 1] - rect[:, 0]))
    F = float(gripper.grip_force if grip_force is None else grip_force)
    Twp = np.asarray(T_world_part, dtype=np.float64)
    gm = np.empty(M)
    for s in range(0, M, 65536):  # (chunk, 1, 3) temporaries
        e = min(M, s + 65536)
        gm[s:e] = gravity_margin(mass_props, Twp, T[s:e], width[s:e], np.full((e - s, 2), pad), mu=mu,
                                 normal_force=F / CONTACTS_PER_GRIP, straight_down_only=True)
    used, inv = np.unique(ci, return_inverse=True)
    eps_c = epsilon_dedup(np.asarray(contacts, dtype=np.float64)[used], np.asarray(normals, dtype=np.float64)[used],
                          np.full((len(used), 2), pad), mass_props.com,
                          max(part_radius(part_mesh, mass_props.com), 1e-9), mu)
    return {"gravity_margin": gm, "epsilon": eps_c[inv.reshape(-1)]}


def part_radius(part_mesh: trimesh.Trimesh, com: np.ndarray) -> float:
    """Largest distance of the part's (hull) vertices from ``com``, m: the torque scale of epsilon."""
    v = np.asarray(part_mesh.convex_hull.vertices if len(part_mesh.vertices) > 64 else part_mesh.vertices)
    return float(np.linalg.norm(v - com, axis=1).max())


def grasp_quality(part_mesh: trimesh.Trimesh, mass_props: MassProperties, gripper: Gripper,
                  T_part_tcp: np.ndarray, contacts: np.ndarray, normals: np.ndarray, width: np.ndarray, *,
                  T_world_part: np.ndarray, mu: float, grip_force: float | None = None) -> Quality:
    """Contact patches, gravity margin and epsilon of ``M`` grasps (module docstring).

    Parameters
    ----------
    part_mesh : trimesh.Trimesh
        Part frame, metres.
    mass_props : MassProperties
        From :func:`grasplan.mass.mass_properties`.
    gripper : Gripper
        Its finger gives the pad; its ``grip_force`` (N, sum of both jaws) is used unless ``grip_force``.
    T_part_tcp : (M, 4, 4)
    contacts, normals : (M, 2, 3)
        Contact points (m) and outward unit surface normals, part frame; contact 0 on the TCP's -x side.
    width : (M,)
        Contact distance, m.
    T_world_part : (4, 4)
        The part's pose (gives the direction of gravity).
    mu : float
        Friction coefficient (>= 0).
    grip_force : float, optional
        Gripping force, N (sum of both jaws: each contact is pressed with half); default
        ``gripper.grip_force``.
    """
    T = check_transform(T_part_tcp, "T_part_tcp", batch=True) if len(np.shape(T_part_tcp)) == 3 else \
        check_transform(T_part_tcp, "T_part_tcp")[None]
    Twp = check_transform(T_world_part, "T_world_part")
    M = len(T)
    C = np.asarray(contacts, dtype=np.float64)
    N = np.asarray(normals, dtype=np.float64)
    w = np.asarray(width, dtype=np.float64).reshape(-1)
    if C.shape != (M, 2, 3) or N.shape != (M, 2, 3) or w.shape != (M,):
        raise InputError(f"grasp quality: expected contacts and normals (M, 2, 3) and width (M,) for M = {M} "
                         f"grasps, got {C.shape}, {N.shape}, {w.shape}")
    if not (np.all(np.isfinite(C)) and np.all(np.isfinite(N)) and np.all(np.isfinite(w))):
        raise InputError("grasp quality: contacts, normals or widths hold NaN or infinite values")
    if not (math.isfinite(mu) and mu >= 0):
        raise InputError(f"grasp quality: mu must be a finite number >= 0, got {mu!r}")
    F = float(gripper.grip_force if grip_force is None else grip_force)
    if not (math.isfinite(F) and F > 0):
        raise InputError(f"grasp quality: grip_force must be > 0 N, got {grip_force!r} (gripper YAML grip_force)")
    if M == 0:
        z2 = np.zeros((0, 2))
        return Quality(contact_area=z2, contact_type=np.zeros((0, 2), dtype=np.int8), contact_width=np.zeros((0, 2, 2)),
                       gravity_margin=np.zeros(0), epsilon=np.zeros(0), grip_force=F, mu=float(mu))
    area, kind, widths = contact_patches(part_mesh, gripper, T, C)
    margin = gravity_margin(mass_props, Twp, T, w, area, mu=mu, normal_force=F / CONTACTS_PER_GRIP)
    eps = epsilon_dedup(C, N, area, mass_props.com, max(part_radius(part_mesh, mass_props.com), 1e-9), mu)
    return Quality(contact_area=area, contact_type=kind, contact_width=widths, gravity_margin=margin,
                   epsilon=eps, grip_force=F, mu=float(mu))


def holding_warning(quality: Quality | None, mass_props: MassProperties | None, *, part: str = "the part") -> str:
    """A warning when no grasp of ``quality`` reaches ``gravity_margin >= 1`` ("" otherwise): the
    best margin, the grip force that would reach 1 (the margin is proportional to the gripping
    force: friction and soft-finger torsion both scale with it) and what to change."""
    if quality is None or mass_props is None or len(quality) == 0:
        return ""
    best = float(np.max(quality.gravity_margin))
    if not np.isfinite(best) or best >= 1.0:
        return ""
    need = quality.grip_force / max(best, 1e-12)
    return (f"no collision-free grasp is predicted to hold {part} ({mass_props.mass:.3g} kg, "
            f"{mass_props.density:.4g} kg/m^3) under gravity "
            f"+ 1 g: the best gravity_margin is {best:.2f} (< 1: it slips); it would take about {need:.0f} N of "
            f"grip force at mu {quality.mu:g} (the gripper gives {quality.grip_force:g} N). The ranking leads with the "
            f"grasps closest to holding; give the real material (--density, --mass), a stronger gripper "
            f"(grip_force in its YAML), or check them in simulation (grasplan simulate)")


# ------------------------------------------------------------------------------------------------
# scoring configuration
# ------------------------------------------------------------------------------------------------
def quality_columns(quality: Quality, rows: np.ndarray, M: int) -> dict:
    """Per-pose arrays of :class:`grasplan.result.GraspTable` for ``M`` poses whose rows ``rows``
    have ``quality`` (the others NaN, type -1): contact_area (M, 2), contact_type (M, 2) int8,
    gravity_margin (M,), epsilon (M,)."""
    rows = np.asarray(rows, dtype=np.int64)
    area = np.full((M, 2), np.nan)
    kind = np.full((M, 2), -1, dtype=np.int8)
    gm = np.full(M, np.nan)
    eps = np.full(M, np.nan)
    area[rows], kind[rows], gm[rows], eps[rows] = quality.contact_area, quality.contact_type, \
        quality.gravity_margin, quality.epsilon
    return {"contact_area": area, "contact_type": kind, "gravity_margin": gm, "epsilon": eps}


def quality_and_score(part_mesh: trimesh.Trimesh, gripper: Gripper, T_world_part: np.ndarray, T_part_tcp: np.ndarray,
                      candidate: np.ndarray, candidates, status: np.ndarray, mu: float, params, *,
                      mass_props: MassProperties | None = None):
    """The grasp stage's quality step: mass properties at ``params.density`` / ``params.mass``, the
    quality of the ``ok`` poses and the score of every pose (NaN where not ``ok``) with the weights
    ``params.score_weights`` / ``params.score_refs`` (a :class:`grasplan.params.GraspParams`).

    Returns ``(Quality of the ok rows, MassProperties, score (M,), note)``. A part without volume
    (flat, degenerate: no mass properties) has no quality: ``(None, None, score, note)`` with the
    score of the other terms and ``note`` saying why; ``note`` is "" otherwise. ``mass_props``: the
    part's mass properties at ``params`` when the caller already has them (chunked callers)."""
    from .mass import mass_properties
    from .scoring import PHYSICAL_TERMS, ScoringConfig, score_grasps

    T = np.asarray(T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    M = len(T)
    ok = np.flatnonzero(np.asarray(status).astype(str) == "ok")
    ci = np.asarray(candidate, dtype=np.int64)[ok]
    width = np.asarray(candidates.width, dtype=np.float64)[ci]
    cfg = ScoringConfig.from_params(params.score_weights, params.score_refs)
    try:
        mp = mass_props if mass_props is not None else mass_properties(part_mesh, density=params.density,
                                                                        mass=params.mass)
    except InputError as exc:
        if params.mass is not None or params.density != type(params)().density:
            raise  # the user asked for a mass: say why there is none
        note = f"no grasp quality: {exc}; the score uses only the other terms"
        weights = tuple((n, w) for n, w in cfg.weights if n not in PHYSICAL_TERMS)
        score = np.full(M, np.nan)
        if len(ok) and sum(w for _, w in weights) > 0:
            score[ok] = score_grasps(part_mesh, T_world_part, T[ok], width, float(gripper.max_opening), weights,
                                     scoring=cfg)
        return None, None, score, note
    q = grasp_quality(part_mesh, mp, gripper, T[ok], candidates.contacts[ci], candidates.normals[ci], width,
                      T_world_part=T_world_part, mu=mu)
    score = np.full(M, np.nan)
    if len(ok):
        score[ok] = score_grasps(part_mesh, T_world_part, T[ok], width, float(gripper.max_opening), cfg.weights,
                                 quality=q, scoring=cfg, com=mp.com)
    return q, mp, score, ""


def score_quality_terms(quality: Quality, config: ScoringConfig | None = None) -> dict[str, np.ndarray]:
    """Normalised quality terms, each (M,) in [0, 1], higher is better: the score's own
    :func:`grasplan.scoring.gravity_margin_term` and :func:`grasplan.scoring.epsilon_term`."""
    cfg = config if config is not None else DEFAULT_SCORING
    return {"gravity_margin": gravity_margin_term(quality.gravity_margin, cfg.gravity_margin_ref),
            "epsilon": epsilon_term(quality.epsilon, cfg.epsilon_ref)}
