"""Stage 4, ``method="paper"``: antipodal pairs of convex faces (Vogt et al. 2021, Sec. III-B).

:func:`find_face_pairs` finds the candidate pairs among a mesh's convex faces: a streamed 6D line
search proposes pairs, :func:`evaluate_pairs` applies the paper's rules 1.-6. to them and places
the two contacts (:func:`_place_contacts`). ``search="brute"`` evaluates every pair instead.
"""
from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import Literal

import numpy as np

from .antipodal_base import Candidates, FaceGeometry, clip_edges, perpendicular_frame, project_triangles, stream_pairs
from ..geometry.tolerance import Tolerance

#: reason codes of :func:`evaluate_pairs` (index = code)
REASONS = ("ok", "not_antiparallel", "too_far", "no_overlap", "not_facing_away", "outside_friction_cone", "too_wide")
_CHUNK = 32_768   # pairs per evaluation batch: keeps the temporaries in cache (measured fastest)


def find_face_pairs(
    geo: FaceGeometry,
    ids: np.ndarray,
    *,
    max_opening: float,
    beta_deg: float,
    epsilon: float,
    mu: float,
    tol: Tolerance,
    search: Literal["index", "brute"] = "index",
) -> Candidates:
    """The paper's candidates among the faces ``ids`` (convex, non-degenerate) of a mesh whose
    :class:`~grasplan.candidates.antipodal_base.FaceGeometry` is ``geo`` (rules 1.-6. of :func:`evaluate_pairs`).
    Arguments as :func:`grasplan.candidates.pipeline.find_candidates`, which validates them.

    Search: every convex face is an oriented element of the streamed 6D line search
    (:func:`grasplan.candidates.antipodal_base.stream_pairs`, lateral bound ``epsilon / 2`` per face, reach
    ``max_opening + epsilon``), which returns a superset of the pairs that can pass 1.-3. (no pair is
    lost; brute force agrees in the tests); the exact filters then run vectorised on those pairs only.
    ``search="brute"`` evaluates every pair of convex faces (the O(m^2) reference).

    Returns candidates sorted by face pair ``(i, j)``, ``i < j``, contact 0 on face i, ``region`` -1.
    """
    batches: Iterable[tuple[np.ndarray, np.ndarray]]
    if search == "index":
        found = stream_pairs(geo.c[ids], geo.n[ids], np.full(len(ids), 0.5 * epsilon),
                             reach=max_opening + epsilon, beta_deg=beta_deg, tol=tol)
        batches = ((ids[i], ids[j]) for i, j in found)
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


def _all_pairs(ids: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray]]:
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


def evaluate_pairs(
    geo: FaceGeometry,
    i: np.ndarray,
    j: np.ndarray,
    *,
    max_opening: float,
    beta_deg: float,
    epsilon: float,
    mu: float,
    tol: Tolerance,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Apply rules 1.-6. to face pairs ``(i[k], j[k])``.

    A pair of convex faces ``(i, j)``, ``i < j``, with outward unit normals ``n_i``, ``n_j`` and
    centroids (the paper's auxiliary points) ``c_i``, ``c_j`` is a candidate when

    1. normals anti-parallel within beta: ``n_i . n_j <= -cos(beta)``;
    2. coarse distance gate: ``|c_i - c_j| <= max_opening + epsilon`` (the paper's centroid distance,
       relaxed by epsilon because centroids may sit up to epsilon off the closing axis; the binding
       limit is 6.);
    3. the paper's overlap test, made symmetric: with the closing axis ``a = (n_i - n_j)/|n_i - n_j|``
       (the bisector of the two normals), ``s = c_i - a |c_i - c_j|`` lies within epsilon of ``c_j``;
    4. contacts (:func:`_place_contacts`) facing away from each other, so the jaws squeeze from
       outside: ``n_i . (p_i - p_j) > 0`` and ``n_j . (p_j - p_i) > 0``;
    5. the closing axis ``d = (p_j - p_i)/|p_j - p_i|`` inside both friction cones:
       ``angle(d, -n_i) <= atan(mu)`` and ``angle(d, n_j) <= atan(mu)``;
    6. width ``|p_j - p_i| <= max_opening``.

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


def _cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _place_contacts(Ti: np.ndarray, Tj: np.ndarray, ni: np.ndarray, nj: np.ndarray, a: np.ndarray,
                    origin: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """Contacts on triangles ``Ti``/``Tj`` (b, 3, 3) for closing axis ``a`` (b, 3).

    Both triangles are projected along ``a`` onto the plane perpendicular to it. If the projections
    overlap, the 2D point is the area centroid of the overlap polygon; it is lifted along ``a`` onto
    each face's plane, so both contacts lie inside their triangles and the closing axis is exactly
    ``a`` (within beta/2 of both normals). If the projections do not overlap (small triangles offset
    by up to epsilon), the contacts are the closest pair of points of the two projected triangles,
    lifted onto their faces; the axis then tilts by ``atan(gap / width)`` and the friction-cone test
    (rule 5. of :func:`evaluate_pairs`) decides whether the pair is kept."""
    e1, e2 = perpendicular_frame(a)                      # basis of the plane perpendicular to a
    Pi = project_triangles(Ti, origin, e1, e2)           # (b, 3, 2)
    Pj = project_triangles(Tj, origin, e1, e2)
    qi, qj = _overlap_or_closest(Pi, Pj, eps)
    p0 = _lift(qi, Ti, ni, a, e1, e2, origin)
    p1 = _lift(qj, Tj, nj, a, e1, e2, origin)
    return p0, p1


def _lift(q: np.ndarray, T: np.ndarray, n: np.ndarray, a: np.ndarray, e1: np.ndarray, e2: np.ndarray,
          origin: np.ndarray) -> np.ndarray:
    x0 = origin + q[:, :1] * e1 + q[:, 1:] * e2
    s = np.einsum("ij,ij->i", n, T[:, 0] - x0) / np.einsum("ij,ij->i", n, a)
    return x0 + s[:, None] * a


def _ccw(P: np.ndarray) -> np.ndarray:
    flip = _cross2(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]) < 0
    P = P.copy()
    P[flip] = P[flip][:, [0, 2, 1]]
    return P


def _clamp_to_triangle(q: np.ndarray, P: np.ndarray) -> np.ndarray:
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


def _overlap_or_closest(Pi: np.ndarray, Pj: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
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
        rx, ry, t0, t1 = clip_edges(xs, ys, xt, yt, ext, eyt, margin)
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
