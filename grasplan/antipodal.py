"""Stage 4: antipodal pairs of convex faces (Vogt et al. 2021, Sec. III-B), sub-quadratic search.

A pair of convex faces ``(i, j)``, ``i < j``, with outward unit normals ``n_i``, ``n_j`` and
centroids (the paper's auxiliary points) ``c_i``, ``c_j`` is a candidate when

1. normals anti-parallel within beta: ``n_i . n_j <= -cos(beta)``;
2. coarse distance gate: ``|c_i - c_j| <= max_opening + epsilon`` (the paper's centroid distance,
   relaxed by epsilon because centroids may sit up to epsilon off the closing axis; the binding
   limit is 6.);
3. the paper's overlap test, made symmetric: with the closing axis ``a = (n_i - n_j)/|n_i - n_j|``
   (the bisector of the two normals), ``s = c_i - a |c_i - c_j|`` lies within epsilon of ``c_j``;
4. contacts (see below) facing away from each other, so the jaws squeeze from outside:
   ``n_i . (p_i - p_j) > 0`` and ``n_j . (p_j - p_i) > 0``;
5. the closing axis ``d = (p_j - p_i)/|p_j - p_i|`` inside both friction cones:
   ``angle(d, -n_i) <= atan(mu)`` and ``angle(d, n_j) <= atan(mu)``;
6. width ``|p_j - p_i| <= max_opening``.

Contact placement: both triangles are projected along ``a`` onto the plane perpendicular to it.
If the projections overlap, the 2D point is the area centroid of the overlap polygon; it is lifted
along ``a`` onto each face's plane, so both contacts lie inside their triangles and the closing
axis is exactly ``a`` (within beta/2 of both normals). If the projections do not overlap (small
triangles offset by up to epsilon), the contacts are the closest pair of points of the two
projected triangles, lifted onto their faces; the axis then tilts by ``atan(gap / width)`` and the
friction-cone test (5.) decides whether the pair is kept.

Search: every face is the oriented line through its centroid along its normal, written in
Pluecker-like 6D coordinates ``x = (K n, (c - o) x n)``. An antipodal pair has ``x_i ~ -x_j``:
the direction parts differ by at most the chord of beta, the moment parts by the lateral offset
(<= epsilon + ...). One fixed-radius range query over ``x`` against ``-x``
(:func:`grasplan.gridsearch.pairs_within`, a uniform grid on three of the six coordinates; a
``scipy.spatial.cKDTree`` until issue 10's import-time work) with a radius derived from beta,
epsilon, max_opening and the part radius returns a superset of the pairs that can pass 1.-3. (no
pair is lost; brute force agrees in the tests); the exact filters then run vectorised on those
pairs only. The cost is ``O(m log m + c)`` for c candidate pairs of neighbouring cells.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from .gridsearch import pairs_within
from .tolerance import Tolerance

if TYPE_CHECKING:  # trimesh (and scipy) load with the first mesh; importing this module stays cheap
    import trimesh


@dataclass(frozen=True)
class Candidates:
    """Antipodal contact pairs in the part frame (metres).

    Attributes
    ----------
    contacts : (n, 2, 3) float64
        Contact points on the part's surface; contact 0 -> contact 1 is the closing axis.
    normals : (n, 2, 3) float64
        Outward unit surface normals at the contacts.
    width : (n,) float64
        ``|contacts[:, 1] - contacts[:, 0]|``.
    faces : (n, 2) int64
        Face indices (into the mesh the search ran on) of the two contacts.
    region : (n,) int64
        Region id of each candidate: ``method="regions"``: the pair of convex areas whose overlap it
        samples, numbered among the overlapping area pairs in sorted order (:mod:`grasplan.regions`);
        ``method="paper"``: -1 (each face pair is its own region). Defaults to -1 when not given.
    """

    contacts: np.ndarray
    normals: np.ndarray
    width: np.ndarray
    faces: np.ndarray
    region: np.ndarray | None = None

    def __post_init__(self):
        n = len(self.width)
        if self.region is None:
            object.__setattr__(self, "region", np.full(n, -1, dtype=np.int64))
        for name, shape in (("contacts", (n, 2, 3)), ("normals", (n, 2, 3)), ("width", (n,)), ("faces", (n, 2)),
                            ("region", (n,))):
            a = getattr(self, name)
            if a.shape != shape:
                raise ValueError(f"Candidates.{name} must have shape {shape}, got {a.shape}")

    def __len__(self) -> int:
        return int(len(self.width))

    @classmethod
    def empty(cls) -> "Candidates":
        return cls(np.zeros((0, 2, 3)), np.zeros((0, 2, 3)), np.zeros(0), np.zeros((0, 2), dtype=np.int64))

    def subset(self, index) -> "Candidates":
        return Candidates(self.contacts[index], self.normals[index], self.width[index], self.faces[index],
                          self.region[index])

    def transformed(self, T: np.ndarray) -> "Candidates":
        """The same candidates after a rigid motion ``T`` (4, 4) of the part."""
        T = np.asarray(T, dtype=np.float64)
        R, t = T[:3, :3], T[:3, 3]
        return Candidates(self.contacts @ R.T + t, self.normals @ R.T, self.width.copy(), self.faces.copy(),
                          self.region.copy())

    def to_json(self) -> dict:
        return {
            "contacts": self.contacts.tolist(),
            "normals": self.normals.tolist(),
            "width": self.width.tolist(),
            "faces": self.faces.tolist(),
            "region": self.region.tolist(),
        }

    @classmethod
    def from_json(cls, d: dict) -> "Candidates":
        """Inverse of :meth:`to_json`; documents without ``region`` (older files) get -1."""
        if not d["width"]:
            return cls.empty()
        region = d.get("region")
        return cls(
            np.asarray(d["contacts"], dtype=np.float64).reshape(-1, 2, 3),
            np.asarray(d["normals"], dtype=np.float64).reshape(-1, 2, 3),
            np.asarray(d["width"], dtype=np.float64),
            np.asarray(d["faces"], dtype=np.int64).reshape(-1, 2),
            None if region is None else np.asarray(region, dtype=np.int64).reshape(-1),
        )


#: reason codes of :func:`evaluate_pairs` (index = code)
REASONS = ("ok", "not_antiparallel", "too_far", "no_overlap", "not_facing_away", "outside_friction_cone", "too_wide")
_CHUNK = 32_768   # pairs per evaluation batch: keeps the temporaries in cache (measured fastest)


def find_candidates(
    mesh: trimesh.Trimesh,
    convex: np.ndarray,
    *,
    max_opening: float = 0.05,
    beta_deg: float = 2.0,
    epsilon: float = 5e-3,
    mu: float = 0.3,
    tol: Tolerance | None = None,
    search: Literal["index", "brute"] = "index",
    method: Literal["regions", "paper"] = "paper",
    spacing: float = 0.002,
) -> Candidates:
    """Antipodal pairs of convex faces of ``mesh`` (see the module docstring for the rules).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Metres, outward winding.
    convex : (m,) bool
        Per face of ``mesh`` (from :func:`grasplan.convexity.classify_convexity`).
    max_opening, epsilon : float
        Metres.
    beta_deg : float
        Degrees.
    mu : float
        Friction coefficient (cone half-angle ``atan(mu)``).
    tol : Tolerance, optional
        Part tolerance (default: from the mesh).
    search : {"index", "brute"}
        ``method="paper"`` only. ``"index"``: the sub-quadratic 6D grid search, streamed in
        bounded chunks; ``"brute"``: every pair of convex faces (O(m^2) time, chunked; reference
        for tests and benchmarks).
    method : {"regions", "paper"}
        ``"paper"``: one contact pair per face pair (rules 1.-6. above, Vogt et al. 2021);
        ``"regions"``: sampled contact regions (:mod:`grasplan.regions`).
    spacing : float
        ``method="regions"``: lattice pitch of the samples, metres.

    Returns
    -------
    Candidates
        ``"paper"``: sorted by face pair ``(i, j)``, ``i < j``, contact 0 on face i, ``region`` -1.
        ``"regions"``: sorted by region, ``region`` set (see :mod:`grasplan.regions`).
    """
    F = np.asarray(mesh.faces, dtype=np.int64)
    convex = np.asarray(convex, dtype=bool)
    if convex.shape != (len(F),):
        raise ValueError(f"convex must have shape ({len(F)},), got {convex.shape}")
    for name, v in (("max_opening", max_opening), ("epsilon", epsilon)):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a positive length in metres, got {v!r}")
    if not 0.0 <= beta_deg < 90.0:
        raise ValueError(f"beta_deg must be in [0, 90), got {beta_deg!r}")
    if not (np.isfinite(mu) and mu >= 0):
        raise ValueError(f"mu must be >= 0, got {mu!r}")
    if search not in ("index", "brute"):
        raise ValueError(f"search must be 'index' or 'brute', got {search!r}")
    if method not in ("regions", "paper"):
        raise ValueError(f"method must be 'regions' or 'paper', got {method!r}")
    if method == "regions" and not (np.isfinite(spacing) and spacing > 0):
        raise ValueError(f"spacing must be a positive length in metres, got {spacing!r}")
    V = np.asarray(mesh.vertices, dtype=np.float64)
    if tol is None:
        tol = Tolerance.for_mesh(V)
    geo = _FaceGeometry.of(V, F)
    ids = np.flatnonzero(convex & geo.valid)
    if len(ids) < 2:
        return Candidates.empty()
    if method == "regions":
        from .regions import find_regions

        contacts, normals, width, faces, region = find_regions(
            mesh, convex, geo, max_opening=max_opening, beta_deg=beta_deg, mu=mu, spacing=spacing, tol=tol)
        return Candidates(contacts, normals, width, faces, region)
    if search == "index":
        batches = stream_pairs(geo.c[ids], geo.n[ids], np.full(len(ids), 0.5 * epsilon),
                               reach=max_opening + epsilon, beta_deg=beta_deg, tol=tol)
        batches = ((ids[i], ids[j]) for i, j in batches)
    else:
        batches = _all_pairs(ids)
    out = []
    for ci, cj in batches:
        for s in range(0, len(ci), _CHUNK):
            bi, bj = ci[s:s + _CHUNK], cj[s:s + _CHUNK]
            reason, contacts, width = evaluate_pairs(geo, bi, bj, max_opening=max_opening, beta_deg=beta_deg,
                                                     epsilon=epsilon, mu=mu, tol=tol)
            keep = reason == 0
            out.append((bi[keep], bj[keep], contacts[keep], width[keep]))
    if not out:
        return Candidates.empty()
    fi = np.concatenate([o[0] for o in out])
    fj = np.concatenate([o[1] for o in out])
    contacts = np.concatenate([o[2] for o in out]).reshape(-1, 2, 3)
    width = np.concatenate([o[3] for o in out])
    order = np.lexsort((fj, fi))
    faces = np.stack([fi, fj], axis=1)[order].astype(np.int64)
    normals = np.stack([geo.n[faces[:, 0]], geo.n[faces[:, 1]]], axis=1) if len(faces) else np.zeros((0, 2, 3))
    return Candidates(contacts[order], normals, width[order], faces)


#: rows of the query side per range query of :func:`stream_pairs` (bounds each call's output)
_QUERY_ROWS = 4096
#: size classes of :func:`stream_pairs`: lateral bounds within a class differ by at most this factor
_CLASS_RATIO = 4.0


def stream_pairs(c: np.ndarray, n: np.ndarray, lateral: np.ndarray, *, reach: float, beta_deg: float,
                 tol: Tolerance):
    """Chunks ``(a, b)`` (int64 index arrays, ``a < b``) of the pairs of oriented elements that may be
    anti-parallel within beta with lateral offset ``<= lateral[a] + lateral[b]``.

    Elements are planar pieces (faces, or coplanar areas) with centroid ``c`` (k, 3), unit normal
    ``n`` (k, 3) and ``lateral`` (k,) m, the largest distance from the centroid to the piece's
    boundary (any larger value is safe). ``reach`` (m) bounds the centroids' distance along the
    closing axis. Each element is the line through its centroid along its normal, in 6D
    ``x = (K n, (c - o) x n)``; a pair that can pass has ``|x_a + x_b| <= sqrt(2) M`` with ``M`` the
    lateral bound plus ``reach sin(beta/2)`` plus ``R |n_a + n_b|``. Elements are split into size
    classes (``lateral`` within a factor :data:`_CLASS_RATIO`), so one large piece does not widen the
    radius for all small ones, and each range query holds at most :data:`_QUERY_ROWS` elements:
    no array grows with k^2. Every qualifying pair is yielded exactly once (a superset of the
    pairs passing the exact tests; the tests check it against brute force)."""
    k = len(c)
    if k < 2:
        return
    o = 0.5 * (c.min(axis=0) + c.max(axis=0))
    R = float(np.linalg.norm(c - o, axis=1).max())
    half = np.radians(beta_deg) / 2.0
    cb = max(2.0 * np.sin(half), 1e-9)                 # chord |n_a + n_b| for an angle beta
    mom = np.cross(c - o, n)
    lat = np.maximum(np.asarray(lateral, dtype=np.float64), 0.0)
    base = max(float(lat.min()), tol.distance)
    cls = np.floor(np.log(np.maximum(lat, base) / base) / np.log(_CLASS_RATIO)).astype(np.int64)
    # Split the sphere of normals at a fixed generic direction h: every antipodal pair has one element
    # in A = {n.h >= -delta} and the other in B = {n.h <= delta} (delta >= |n_a + n_b|). A pair with
    # both elements in the band |n.h| <= delta is met twice (as (a, b) and (b, a)): kept once, a < b.
    h = np.array([1.0, np.sqrt(2.0), np.sqrt(3.0)]) / np.sqrt(6.0)
    nh = n @ h
    delta = cb * 1.01
    inA, inB = nh >= -delta, nh <= delta
    band = ~(inA ^ inB)
    classes = np.unique(cls)
    lat_max = {int(q): float(lat[cls == q].max()) for q in classes}
    for qa in classes:
        A = np.flatnonzero(inA & (cls == qa))
        if len(A) == 0:
            continue
        for qb in classes:
            B = np.flatnonzero(inB & (cls == qb))
            if len(B) == 0:
                continue
            M = lat_max[int(qa)] + lat_max[int(qb)] + reach * np.sin(half) + R * cb + 4 * tol.distance
            K = M / cb
            rho = np.sqrt(2.0) * M * (1.0 + 1e-9)
            YB = -np.hstack([K * n[B], mom[B]])
            for s in range(0, len(A), _QUERY_ROWS):
                As = A[s:s + _QUERY_ROWS]
                for i, j in pairs_within(np.hstack([K * n[As], mom[As]]), YB, rho):
                    a, b = As[i], B[j]
                    keep = (a != b) & ~(band[a] & band[b] & (a > b))
                    a, b = a[keep], b[keep]
                    if len(a):
                        yield np.minimum(a, b), np.maximum(a, b)


def _all_pairs(ids: np.ndarray):
    """Every pair ``(ids[a], ids[b])``, ``a < b``, in batches of about ``_CHUNK`` (the O(m^2) reference)."""
    m = len(ids)
    a = 0
    while a < m - 1:
        rows = max(1, _CHUNK // max(1, m - a - 1))
        r = np.arange(a, min(m - 1, a + rows))
        cnt = m - 1 - r
        ia = np.repeat(r, cnt)
        ib = np.arange(len(ia)) - np.repeat(np.cumsum(cnt) - cnt, cnt) + np.repeat(r + 1, cnt)
        yield ids[ia], ids[ib]
        a = int(r[-1]) + 1


@dataclass(frozen=True)
class _FaceGeometry:
    tri: np.ndarray     # (m, 3, 3)
    c: np.ndarray       # (m, 3) centroids
    n: np.ndarray       # (m, 3) unit normals
    valid: np.ndarray   # (m,) non-degenerate

    @classmethod
    def of(cls, V: np.ndarray, F: np.ndarray) -> "_FaceGeometry":
        tri = V[F]
        cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        nrm = np.linalg.norm(cr, axis=1)
        valid = nrm > 0
        n = np.zeros_like(cr)
        n[valid] = cr[valid] / nrm[valid, None]
        return cls(tri, tri.mean(axis=1), n, valid)


def evaluate_pairs(
    geo: "_FaceGeometry",
    i: np.ndarray,
    j: np.ndarray,
    *,
    max_opening: float,
    beta_deg: float,
    epsilon: float,
    mu: float,
    tol: Tolerance,
):
    """Apply rules 1.-6. to face pairs ``(i[k], j[k])``.

    Returns ``reason (k,) int8`` (index into :data:`REASONS`, 0 = candidate), ``contacts (k, 2, 3)``
    and ``width (k,)`` (contacts/width meaningful where reason == 0).
    """
    k = len(i)
    reason = np.zeros(k, dtype=np.int8)
    contacts = np.zeros((k, 2, 3))
    width = np.zeros(k)
    ni, nj = geo.n[i], geo.n[j]
    dot = np.einsum("ij,ij->i", ni, nj)
    reason[dot > -np.cos(np.radians(beta_deg)) + 1e-12] = 1
    ci, cj = geo.c[i], geo.c[j]
    dvec = cj - ci
    dist = np.sqrt(np.einsum("ij,ij->i", dvec, dvec))
    reason[(reason == 0) & (dist > max_opening + epsilon)] = 2
    a = ni - nj
    a /= np.maximum(np.sqrt(np.einsum("ij,ij->i", a, a)), 1e-300)[:, None]
    # |c_i - a dist - c_j|^2 = |d|^2 + dist^2 + 2 dist (a . d) with d = c_j - c_i  (= 2 dist (dist + a.d))
    miss2 = 2.0 * dist * (dist + np.einsum("ij,ij->i", a, dvec))
    reason[(reason == 0) & (miss2 > epsilon * epsilon)] = 3
    live = np.flatnonzero(reason == 0)
    if len(live) == 0:
        return reason, contacts, width
    p0, p1 = _place_contacts(geo.tri[i[live]], geo.tri[j[live]], ni[live], nj[live], a[live], ci[live], tol.distance)
    d = p1 - p0
    w = np.linalg.norm(d, axis=1)
    dn = d / np.maximum(w, 1e-300)[:, None]
    sub = np.zeros(len(live), dtype=np.int8)
    facing = (np.einsum("ij,ij->i", ni[live], -d) > 0) & (np.einsum("ij,ij->i", nj[live], d) > 0) & (w > tol.distance)
    sub[~facing] = 4
    cosf = np.cos(np.arctan(mu)) - 1e-12
    cone = (np.einsum("ij,ij->i", -ni[live], dn) >= cosf) & (np.einsum("ij,ij->i", nj[live], dn) >= cosf)
    sub[(sub == 0) & ~cone] = 5
    sub[(sub == 0) & (w > max_opening)] = 6
    reason[live] = sub
    contacts[live, 0] = p0
    contacts[live, 1] = p1
    width[live] = w
    return reason, contacts, width


def _cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _place_contacts(Ti, Tj, ni, nj, a, origin, eps):
    """Contacts on triangles ``Ti``/``Tj`` (b, 3, 3) for closing axis ``a`` (b, 3); see module doc."""
    # basis of the plane perpendicular to a
    helper = np.where(np.abs(a[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    e1 = np.cross(a, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(a, e1)
    Pi = np.stack([np.einsum("bkj,bj->bk", Ti - origin[:, None], e) for e in (e1, e2)], axis=-1)  # (b,3,2)
    Pj = np.stack([np.einsum("bkj,bj->bk", Tj - origin[:, None], e) for e in (e1, e2)], axis=-1)
    qi, qj = _overlap_or_closest(Pi, Pj, eps)
    p0 = _lift(qi, Ti, ni, a, e1, e2, origin)
    p1 = _lift(qj, Tj, nj, a, e1, e2, origin)
    return p0, p1


def _lift(q, T, n, a, e1, e2, origin):
    x0 = origin + q[:, :1] * e1 + q[:, 1:] * e2
    s = np.einsum("ij,ij->i", n, T[:, 0] - x0) / np.einsum("ij,ij->i", n, a)
    return x0 + s[:, None] * a


def _ccw(P):
    flip = _cross2(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]) < 0
    P = P.copy()
    P[flip] = P[flip][:, [0, 2, 1]]
    return P


def _clip_edges(xs, ys, xt, yt, ext, eyt, margin):
    """Parameter intervals [t0, t1] of the 3 edges of triangles S (b,3) inside CCW triangles T (b,3).

    Cyrus-Beck: edge k of S is ``p_k + t r_k``; inside T's edge e when ``alpha + beta t >= margin_e``.
    """
    rx, ry = np.roll(xs, -1, axis=1) - xs, np.roll(ys, -1, axis=1) - ys           # (b, 3)
    # (b, k=3 edges of S, e=3 edges of T)
    alpha = ext[:, None, :] * (ys[:, :, None] - yt[:, None, :]) - eyt[:, None, :] * (xs[:, :, None] - xt[:, None, :])
    beta = ext[:, None, :] * ry[:, :, None] - eyt[:, None, :] * rx[:, :, None]
    alpha = alpha - margin[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        root = -alpha / beta
    t0 = np.where(beta > 0, root, -np.inf).max(axis=2).clip(0.0, 1.0)
    t1 = np.where(beta < 0, root, np.inf).min(axis=2).clip(0.0, 1.0)
    blocked = ((beta == 0) & (alpha < 0)).any(axis=2)
    t1 = np.where(blocked, t0, t1)
    return rx, ry, t0, np.maximum(t1, t0)


def _clamp_to_triangle(q, P):
    """Points q (b, 2) moved to the nearest point of CCW triangles P (b, 3, 2) when outside them."""
    x, y = P[..., 0], P[..., 1]
    ex, ey = np.roll(x, -1, axis=1) - x, np.roll(y, -1, axis=1) - y
    dx, dy = q[:, :1] - x, q[:, 1:] - y
    inside = ((ex * dy - ey * dx) >= 0).all(axis=1)
    t = np.clip((dx * ex + dy * ey) / np.maximum(ex * ex + ey * ey, 1e-300), 0.0, 1.0)
    px, py = x + t * ex, y + t * ey
    k = ((q[:, :1] - px) ** 2 + (q[:, 1:] - py) ** 2).argmin(axis=1)
    r = np.arange(len(q))
    near = np.stack([px[r, k], py[r, k]], axis=1)
    return np.where(inside[:, None], q, near)


def _overlap_or_closest(Pi, Pj, eps):
    """2D contact points: area centroid of the overlap of triangles Pi, Pj (b,3,2), else the closest pair.

    The overlap's boundary is made of the parts of each triangle's edges that lie inside the other
    triangle (both counter-clockwise); Green's theorem over those directed segments gives its area
    and centroid without ordering any vertices. An edge lying on the other triangle's edge line is
    counted once (kept for triangle i, dropped for triangle j).
    """
    b = len(Pi)
    Pi, Pj = _ccw(Pi), _ccw(Pj)
    org = Pi.mean(axis=1, keepdims=True)                      # local origin for Green's sums
    Pi, Pj = Pi - org, Pj - org
    xa, ya, xb, yb = Pi[..., 0], Pi[..., 1], Pj[..., 0], Pj[..., 1]
    exa, eya = np.roll(xa, -1, axis=1) - xa, np.roll(ya, -1, axis=1) - ya
    exb, eyb = np.roll(xb, -1, axis=1) - xb, np.roll(yb, -1, axis=1) - yb
    la, lb = np.hypot(exa, eya), np.hypot(exb, eyb)
    M = np.zeros(b)
    Sx = np.zeros(b)
    Sy = np.zeros(b)
    for xs, ys, xt, yt, ext, eyt, margin in ((xa, ya, xb, yb, exb, eyb, -eps * lb),   # i's edges inside j (closed)
                                             (xb, yb, xa, ya, exa, eya, eps * la)):   # j's edges strictly inside i
        rx, ry, t0, t1 = _clip_edges(xs, ys, xt, yt, ext, eyt, margin)
        x0, y0 = xs + t0 * rx, ys + t0 * ry
        x1, y1 = xs + t1 * rx, ys + t1 * ry
        cr = x0 * y1 - x1 * y0
        M += cr.sum(axis=1)
        Sx += ((x0 + x1) * cr).sum(axis=1)
        Sy += ((y0 + y1) * cr).sum(axis=1)
    area = 0.5 * M
    over = area > eps * eps
    qi = np.zeros((b, 2))
    qj = np.zeros((b, 2))
    A = np.where(over, area, 1.0)
    gx, gy = Sx / (6.0 * A), Sy / (6.0 * A)
    # Triangles that only touch (within eps) leave an open boundary whose "centroid" is meaningless:
    # keep the overlap point only where it really lies inside both triangles, else use closest points.
    # "Inside" = exactly inside, or within eps of an edge *segment* (a margin on the edge lines alone
    # would reach far beyond the tip of a sliver's acute corner).
    for x, y, ex, ey, L in ((xa, ya, exa, eya, la), (xb, yb, exb, eyb, lb)):
        dx, dy = gx[:, None] - x, gy[:, None] - y
        inside = ((ex * dy - ey * dx) >= 0).all(axis=1)
        t = np.clip((dx * ex + dy * ey) / np.maximum(L * L, 1e-300), 0.0, 1.0)
        near = (((dx - t * ex) ** 2 + (dy - t * ey) ** 2).min(axis=1)) <= eps * eps
        over &= inside | near
    Pi, Pj = Pi + org, Pj + org
    if over.any():
        g = np.stack([gx[over] + org[over, 0, 0], gy[over] + org[over, 0, 1]], axis=1)
        # a point within eps outside a triangle is moved onto it, so each contact is exactly on its face
        qi[over] = _clamp_to_triangle(g, Pi[over])
        qj[over] = _clamp_to_triangle(g, Pj[over])
    far = ~over       # no overlap, or a zero-area one (touching): the closest pair of points
    if far.any():
        xa, ya, xb, yb = Pi[far, :, 0], Pi[far, :, 1], Pj[far, :, 0], Pj[far, :, 1]
        # vertex v of src vs edge e of dst, both directions: 18 point/segment pairs per face pair,
        # as separate x/y arrays of shape (f, 3 vertices, 3 edges)
        parts = []
        for sx, sy, dx, dy, src_is_i in ((xa, ya, xb, yb, True), (xb, yb, xa, ya, False)):
            px, py = dx[:, None, :], dy[:, None, :]
            ex, ey = np.roll(dx, -1, axis=1)[:, None, :] - px, np.roll(dy, -1, axis=1)[:, None, :] - py
            vx, vy = sx[:, :, None], sy[:, :, None]
            L2 = np.maximum(ex * ex + ey * ey, 1e-300)
            tt = np.clip(((vx - px) * ex + (vy - py) * ey) / L2, 0.0, 1.0)
            yx, yy = px + tt * ex, py + tt * ey                    # closest point on the edge
            vx, vy = np.broadcast_to(vx, yx.shape), np.broadcast_to(vy, yy.shape)
            d2 = (vx - yx) ** 2 + (vy - yy) ** 2
            f = len(sx)
            if src_is_i:
                parts.append((d2.reshape(f, 9), vx.reshape(f, 9), vy.reshape(f, 9), yx.reshape(f, 9), yy.reshape(f, 9)))
            else:
                parts.append((d2.reshape(f, 9), yx.reshape(f, 9), yy.reshape(f, 9), vx.reshape(f, 9), vy.reshape(f, 9)))
        D2, Xi, Yi, Xj, Yj = (np.concatenate([parts[0][k], parts[1][k]], axis=1) for k in range(5))
        # ties (parallel nearest edges) are averaged, so the choice does not depend on vertex order or pose
        dmin = np.sqrt(D2.min(axis=1, keepdims=True))
        tied = D2 <= (dmin + eps) ** 2
        wt = tied / tied.sum(axis=1, keepdims=True)
        qi[far, 0], qi[far, 1] = (Xi * wt).sum(axis=1), (Yi * wt).sum(axis=1)
        qj[far, 0], qj[far, 1] = (Xj * wt).sum(axis=1), (Yj * wt).sum(axis=1)
    return qi, qj
