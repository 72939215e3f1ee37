"""Stage 4's base, shared by both candidate methods: the candidate type, per-face geometry, the
streamed search for anti-parallel pairs (:func:`stream_pairs`) and the 2D clipping of projected
triangles.

The two methods build on it: the paper's one contact pair per pair of convex faces
(:mod:`grasplan.candidates.antipodal`) and the sampled contact regions (:mod:`grasplan.candidates.regions`);
:func:`grasplan.candidates.pipeline.find_candidates` chooses between them. Nothing here imports either.
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ..geometry.gridsearch import pairs_within
from ..geometry.tolerance import Tolerance


@dataclass(frozen=True, init=False)
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
        samples, numbered among the overlapping area pairs in sorted order (:mod:`grasplan.candidates.regions`);
        ``method="paper"``: -1 (each face pair is its own region). Defaults to -1 when not given.
    """

    contacts: np.ndarray
    normals: np.ndarray
    width: np.ndarray
    faces: np.ndarray
    region: np.ndarray

    def __init__(self, contacts: np.ndarray, normals: np.ndarray, width: np.ndarray, faces: np.ndarray,
                 region: np.ndarray | None = None) -> None:
        n = len(width)
        for name, value in (("contacts", contacts), ("normals", normals), ("width", width), ("faces", faces),
                            ("region", np.full(n, -1, dtype=np.int64) if region is None else region)):
            object.__setattr__(self, name, value)
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

    def subset(self, index: np.ndarray | slice) -> "Candidates":
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


@dataclass(frozen=True)
class FaceGeometry:
    """Per-face geometry of a triangle mesh, computed once and shared by both candidate methods."""

    tri: np.ndarray     #: (m, 3, 3) corners
    c: np.ndarray       #: (m, 3) centroids (the paper's auxiliary points)
    n: np.ndarray       #: (m, 3) unit normals (zero for a degenerate face)
    valid: np.ndarray   #: (m,) bool, non-degenerate

    @classmethod
    def of(cls, V: np.ndarray, F: np.ndarray) -> "FaceGeometry":
        """From vertices ``V`` (n, 3) and faces ``F`` (m, 3)."""
        tri = V[F]
        cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        nrm = np.linalg.norm(cr, axis=1)
        valid = nrm > 0
        n = np.zeros_like(cr)
        n[valid] = cr[valid] / nrm[valid, None]
        return cls(tri, tri.mean(axis=1), n, valid)


#: rows of the query side per range query of :func:`stream_pairs` (bounds each call's output)
_QUERY_ROWS = 4096
#: size classes of :func:`stream_pairs`: lateral bounds within a class differ by at most this factor
_CLASS_RATIO = 4.0


def stream_pairs(c: np.ndarray, n: np.ndarray, lateral: np.ndarray, *, reach: float, beta_deg: float,
                 tol: Tolerance, progress: dict | None = None) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Chunks ``(a, b)`` (int64 index arrays, ``a < b``) of the pairs of oriented elements that may be
    anti-parallel within beta with lateral offset ``<= lateral[a] + lateral[b]``.

    Elements are planar pieces (faces, or coplanar areas) with centroid ``c`` (k, 3), unit normal
    ``n`` (k, 3) and ``lateral`` (k,) m, the largest distance from the centroid to the piece's
    boundary (any larger value is safe). ``reach`` (m) bounds the centroids' distance along the
    closing axis. Each element is the line through its centroid along its normal, in 6D
    ``x = (K n, (c - o) x n)``; a pair that can pass has ``|x_a + x_b| <= sqrt(2) M`` with ``M`` the
    lateral bound plus ``reach sin(beta/2)`` plus ``R |n_a + n_b|`` (an antipodal pair has
    ``x_a ~ -x_b``: the direction parts differ by at most the chord of beta, the moment parts by the
    lateral offset), so fixed-radius range queries of ``x`` against ``-x``
    (:func:`grasplan.geometry.gridsearch.pairs_within`, a uniform grid on three of the six coordinates)
    find them in ``O(k log k + p)`` for ``p`` pairs of neighbouring cells. Elements are split into size
    classes (``lateral`` within a factor :data:`_CLASS_RATIO`), so one large piece does not widen the
    radius for all small ones, and each range query holds at most :data:`_QUERY_ROWS` elements:
    no array grows with k^2. Every qualifying pair is yielded exactly once (a superset of the
    pairs passing the exact tests; the tests check it against brute force). ``progress`` (a dict)
    gets ``"done"``, the share of the query rows searched so far, after each chunk."""
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
    n_a = {int(q): int(np.count_nonzero(inA & (cls == q))) for q in classes}
    n_b = {int(q): int(np.count_nonzero(inB & (cls == q))) for q in classes}
    total = max(1, sum(n_a[int(qa)] for qa in classes for qb in classes if n_b[int(qb)]))
    done = 0
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
                    if progress is not None:
                        progress["done"] = (done + (int(i[-1]) + 1 if len(i) else 0)) / total
                    if len(a):
                        yield np.minimum(a, b), np.maximum(a, b)
                done += len(As)


def perpendicular_frame(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal ``e1, e2`` (b, 3) perpendicular to unit ``a`` (b, 3) (a fixed function of a)."""
    helper = np.where(np.abs(a[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    e1 = np.cross(a, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(a, e1)


def project_triangles(T: np.ndarray, origin: np.ndarray, e1: np.ndarray, e2: np.ndarray) -> np.ndarray:
    """Triangles ``T`` (b, 3, 3) -> 2D (b, 3, 2) in the planes (``origin`` (b, 3), ``e1``, ``e2`` (b, 3))."""
    d = T - origin[:, None]
    return np.stack([np.einsum("bkj,bj->bk", d, e1), np.einsum("bkj,bj->bk", d, e2)], axis=-1)


def clip_edges(xs: np.ndarray, ys: np.ndarray, xt: np.ndarray, yt: np.ndarray, ext: np.ndarray, eyt: np.ndarray,
               margin: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
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

