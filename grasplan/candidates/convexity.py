"""Stage 3: convex/concave classification per triangle (Vogt et al. 2021, Sec. III-B).

The paper's rule, for every triangle ``T_k``:

* auxiliary point ``p = c_k + d_shift * n_k`` (centroid shifted along the outward face normal);
* hull ``H_k`` = convex hull of ``T_k`` and its adjacent triangles;
* ``T_k`` is **convex** when ``p`` lies outside ``H_k`` or on its boundary, **concave** when ``p``
  lies strictly inside; a flat (degenerate, coplanar) neighbourhood is convex.

:func:`classify_convexity` decides it exactly and vectorised, without building any hull.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Literal

import numpy as np

from ..geometry.meshdata import MeshData, TriangleMesh, edge_adjacency
from ..geometry.tolerance import Tolerance

if TYPE_CHECKING:  # scipy loads with the first mesh; importing this module stays cheap
    import scipy.sparse as sp

Neighbourhood = Literal["edge", "vertex"]

#: max (faces x constraint-pairs x constraints) elements processed per NumPy batch
_BATCH_ELEMS = 4_000_000


def mesh_edge_adjacency(mesh: TriangleMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``edge_adjacency(mesh.faces, slots=True)``, computed once per :class:`grasplan.geometry.meshdata.
    MeshData` (:attr:`~grasplan.geometry.meshdata.MeshData.edge_adjacency`: loading, the BLM, convexity
    and the regions share it), else on each call."""
    if isinstance(mesh, MeshData):
        return mesh.edge_adjacency
    adj, edge, far, slot = edge_adjacency(mesh.faces, slots=True)
    return adj, edge, far, slot


class _Rows:
    """CSR-like rows of vertex ids (``indptr``, ``indices``), what :func:`classify_convexity` reads."""

    def __init__(self, indptr: np.ndarray, indices: np.ndarray):
        self.indptr, self.indices = indptr, indices


def _edge_rows(faces: np.ndarray, adjacency: tuple[np.ndarray, ...] | None = None) -> _Rows:
    """Row k: the 3 vertices of face k, then the far vertex of each face sharing an edge with it (the
    same sets as ``neighbour_vertices(mesh, "edge")``, built without sparse products);
    ``adjacency``: the faces' :func:`edge_adjacency` when known."""
    F = np.asarray(faces, dtype=np.int64)
    m = len(F)
    adj, _, far = (edge_adjacency(F) if adjacency is None else adjacency)[:3]
    owner = np.concatenate([np.repeat(np.arange(m), 3), adj[:, 0], adj[:, 1]])
    vert = np.concatenate([F.ravel(), far[:, 1], far[:, 0]])
    o = np.argsort(owner, kind="stable")
    counts = np.bincount(owner, minlength=m)
    return _Rows(np.r_[0, np.cumsum(counts)], vert[o])


def neighbour_vertices(mesh: TriangleMesh, neighbourhood: Neighbourhood = "edge") -> sp.csr_matrix:
    """``(m, n_vertices)`` boolean CSR: row k marks the vertices of face k and its adjacent faces
    (built with scipy.sparse and trimesh's face adjacency: the tests' independent check of the
    vectorised rows)."""
    import scipy.sparse as sp
    import trimesh.graph

    faces = np.asarray(mesh.faces, dtype=np.int64)
    m, nv = len(faces), len(mesh.vertices)
    rows = np.repeat(np.arange(m), 3)
    A = sp.csr_matrix((np.ones(3 * m, dtype=np.int32), (rows, faces.ravel())), shape=(m, nv))
    if neighbourhood == "vertex":
        N = (A @ A.T).tocsr()                     # faces sharing >= 1 vertex (incl. itself)
    elif neighbourhood == "edge":
        adj = np.asarray(trimesh.graph.face_adjacency(faces), dtype=np.int64).reshape(-1, 2)
        ii = np.concatenate([adj[:, 0], adj[:, 1], np.arange(m)])
        jj = np.concatenate([adj[:, 1], adj[:, 0], np.arange(m)])
        N = sp.csr_matrix((np.ones(len(ii), dtype=np.int32), (ii, jj)), shape=(m, m))
    else:
        raise ValueError(f"neighbourhood must be 'edge' or 'vertex', got {neighbourhood!r}")
    V = (N @ A).tocsr()
    V.data[:] = 1
    V.sort_indices()
    return V


def classify_convexity(
    mesh: TriangleMesh,
    *,
    d_shift: float = 1e-5,
    tol: Tolerance | None = None,
    neighbourhood: Neighbourhood = "edge",
) -> np.ndarray:
    """Classify every face of ``mesh`` as convex (True) or concave (False) by the paper's rule
    (module docstring), exactly and without building a hull: the face plane (``w = 0`` of
    :func:`_lp_feasible`) settles almost every face at once; the rest go to :func:`_lp_feasible`.
    Open meshes and non-manifold edges never fail: an edge with no (or several) partner faces simply
    contributes the partners trimesh reports (none for a boundary edge).

    Parameters
    ----------
    mesh : TriangleMesh
        Metres; outward-facing winding (normals from the winding).
    d_shift : float
        Shift of the auxiliary point along the face normal, metres (paper: 0.01 mm).
    tol : Tolerance, optional
        Part tolerance; ``tol.distance`` (1e-6 of the part size) decides "on the hull boundary".
        Default: from the mesh.
    neighbourhood : {"edge", "vertex"}
        Which adjacent triangles span the hull: ``"edge"`` those sharing an edge (at most 6 points);
        ``"vertex"`` those sharing a vertex (the paper's "all adjacent triangles" read literally; it
        also marks faces touching a concave edge only at a corner as concave, lowering the candidate
        count before the BLM: docs/candidates.md).

    Returns
    -------
    (m,) bool
    """
    if not (np.isfinite(d_shift) and d_shift > 0):
        raise ValueError(f"d_shift must be a positive length in metres, got {d_shift!r}")
    V = np.asarray(mesh.vertices, dtype=np.float64)
    F = np.asarray(mesh.faces, dtype=np.int64)
    m = len(F)
    if m == 0:
        return np.zeros(0, dtype=bool)
    if tol is None:
        tol = Tolerance.for_mesh(V)
    eps = float(tol.distance)

    tri = V[F]                                            # (m, 3, 3)
    c = tri.mean(axis=1)
    cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nrm = np.linalg.norm(cr, axis=1)
    ok = nrm > 0
    n = np.zeros_like(cr)
    n[ok] = cr[ok] / nrm[ok, None]

    if neighbourhood == "edge":
        # w = 0 (the face plane supports p) unless a neighbour's far vertex rises above the plane by
        # more than d_shift + eps (the face's own vertices lie in it): one height per (face, edge
        # neighbour), no per-face rows (the same heights, operation for operation, as the rows give)
        adjacency = mesh_edge_adjacency(mesh)
        adj, far = adjacency[0], adjacency[2]
        above = np.zeros(m, dtype=bool)
        for mine, theirs in ((0, 1), (1, 0)):
            f = adj[:, mine]
            h = np.einsum("ij,ij->i", V[far[:, theirs]] - c[f], n[f])
            above[f[h > d_shift + eps]] = True
        convex = ~above
        Nb = None
    else:
        Nb = neighbour_vertices(mesh, neighbourhood)
        counts = np.diff(Nb.indptr)
        face_of = np.repeat(np.arange(m), counts)
        q = V[Nb.indices] - c[face_of]                    # (nnz, 3) offsets from the centroid
        h = np.einsum("ij,ij->i", q, n[face_of])          # heights above the face plane
        hmax = np.maximum.reduceat(h, Nb.indptr[:-1])      # rows are contiguous, >= 3 entries each
        convex = hmax <= d_shift + eps                    # w = 0: the face plane supports p
    convex |= ~ok                                         # degenerate face: no normal, call it convex
    slow = np.flatnonzero(~convex)
    if len(slow) == 0:
        return convex
    if Nb is None:  # the undecided faces' hull points: own vertices and the neighbours' far ones
        Nb = _edge_rows(F, adjacency)
        counts = np.diff(Nb.indptr)

    # In-plane 2D coordinates for the undecided faces, padded to K constraints per face.
    e1 = tri[:, 1] - tri[:, 0]
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(n, e1)
    k_of = counts[slow]
    order = np.argsort(k_of, kind="stable")
    slow, k_of = slow[order], k_of[order]
    start = 0
    while start < len(slow):
        K = int(k_of[start])
        npairs = K * (K - 1) // 2
        per_face = max(1, npairs * K)
        # grow the batch while faces have the same K and fit in memory
        limit = max(1, _BATCH_ELEMS // per_face)
        stop = min(len(slow), start + limit)
        stop = start + int(np.searchsorted(k_of[start:stop], K, side="right"))
        idx = slow[start:stop]
        convex[idx] = _lp_feasible(idx, K, Nb, V, c, n, e1, e2, d_shift, eps)
        start = stop
    return convex


def _lp_feasible(idx: np.ndarray, K: int, Nb: _Rows | sp.csr_matrix, V: np.ndarray, c: np.ndarray, n: np.ndarray,
                 e1: np.ndarray, e2: np.ndarray, d_shift: float, eps: float) -> np.ndarray:
    """For faces ``idx`` that all have exactly ``K`` hull points: is ``{w : w.t_q <= d - h_q}`` non-empty?

    ``p`` is outside or on the boundary of ``conv(S)`` iff some plane through ``p`` has all of ``S``
    on one closed side: ``u . (q - p) <= 0`` for all ``q`` in ``S``, ``u != 0``. Because ``S``
    contains the triangle and ``c_k`` is interior to it, such a ``u`` has ``u . n_k > 0``; scaling to
    ``u = n_k + w`` (``w`` in the face plane) turns the question into this 2D linear feasibility
    problem, ``w . t_q <= d_shift - h_q`` for every hull point q, with ``h_q = n_k . (q - c_k)``
    (height above the face plane) and ``t_q`` the in-plane offset of ``q`` from ``c_k``. The
    triangle's own vertices bound ``w``, so the feasible set is a bounded polygon and is non-empty
    iff one of its vertices (the intersection of two constraint lines) satisfies all constraints
    (within ``eps`` = ``tol.distance``, 1e-6 of the part size): every constraint pair is tried,
    batched with NumPy. This is exactly the Qhull/Delaunay test of the paper (cross-checked against
    ``scipy.spatial.Delaunay`` in the tests)."""
    len(idx)
    cols = Nb.indices[(Nb.indptr[idx][:, None] + np.arange(K)[None, :])]   # (b, K)
    q = V[cols] - c[idx][:, None, :]                                      # (b, K, 3)
    h = np.einsum("bkj,bj->bk", q, n[idx])
    t = np.stack([np.einsum("bkj,bj->bk", q, e1[idx]), np.einsum("bkj,bj->bk", q, e2[idx])], axis=-1)  # (b,K,2)
    rhs = d_shift - h                                                      # (b, K)
    ia, ib = np.triu_indices(K, 1)
    A0, A1 = t[:, ia], t[:, ib]                                            # (b, P, 2)
    r0, r1 = rhs[:, ia], rhs[:, ib]
    det = A0[..., 0] * A1[..., 1] - A0[..., 1] * A1[..., 0]
    scale = np.linalg.norm(A0, axis=-1) * np.linalg.norm(A1, axis=-1)
    good = np.abs(det) > 1e-12 * np.maximum(scale, 1e-300)
    safe = np.where(good, det, 1.0)
    wx = (r0 * A1[..., 1] - r1 * A0[..., 1]) / safe
    wy = (A0[..., 0] * r1 - A1[..., 0] * r0) / safe                        # (b, P)
    # slack of every constraint at every candidate vertex: w.t_q - rhs_q <= tol (scaled by |u| = sqrt(1+|w|^2))
    lhs = wx[:, :, None] * t[:, None, :, 0] + wy[:, :, None] * t[:, None, :, 1] - rhs[:, None, :]
    unorm = np.sqrt(1.0 + wx * wx + wy * wy)
    feasible = good & (lhs.max(axis=2) <= eps * unorm)
    return feasible.any(axis=1)
