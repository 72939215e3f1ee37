"""The boundary layer mesher (BLM; Vogt et al. 2021, Sec. III-A), exact and vectorised.

:func:`boundary_layer` inserts a thin layer of triangles of width ``alpha`` along every surface
boundary of a part's mesh without changing its geometry, in the paper's four steps:

1. surface subdivision: faces into facets and facets into surfaces (:func:`cluster_surfaces`);
2. edge determination: mesh edges between two surfaces (:func:`_boundary_edges`);
3. edge shifting, in closed form instead of SLSQP (:func:`_shift_edges`);
4. boundary layer insertion and remeshing inside the faces that own a boundary edge
   (:func:`_sub_triangles`, :func:`_assemble`); no original edge is split.

Everything per face is NumPy array work; there is no Python loop over faces.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .convexity import mesh_edge_adjacency
from ..errors import InputError, MeshError
from ..geometry.meshdata import MeshData, connected_components, edge_adjacency
from ..geometry.tolerance import Tolerance

if TYPE_CHECKING:
    from ..geometry.meshdata import TriangleMesh

#: sin(theta) floor for the shift s = alpha / sin(theta): s <= 2 alpha at near-tangent/knife edges
SIN_FLOOR = 0.5
#: barycentric offset of the new points from a parent's non-boundary edges
DELTA_INNER = 0.05
#: smallest homothety ratio left for the inner part of a split face
LAMBDA_MIN = 0.1
#: a split is refused when a sub-triangle would have less than this many ``tol.area``
AREA_SAFETY = 10.0

# sub-triangle templates over the 6 labels (p0, p1, p2, q0, q1, q2)
_ONE_EDGE = np.array([(0, 1, 4), (0, 4, 3), (3, 4, 2), (4, 1, 2), (0, 3, 2)], dtype=np.int64)
_ONE_EDGE_STRIP = np.array([True, True, False, False, False])
_RING = np.array([(0, 1, 4), (0, 4, 3), (1, 2, 5), (1, 5, 4), (2, 0, 3), (2, 3, 5), (3, 4, 5)], dtype=np.int64)


def _rotate_labels(tmpl: np.ndarray, k: int) -> np.ndarray:
    """The template ``tmpl`` with its corner labels turned by ``k`` (edge 0 becomes edge k)."""
    return (tmpl % 3 + k) % 3 + 3 * (tmpl // 3)


_ONE_EDGE_ROT = np.stack([_rotate_labels(_ONE_EDGE, k) for k in range(3)])  # (3, 5, 3)


@dataclass(frozen=True)
class BLMResult:
    """The remeshed part and what the BLM found.

    mesh : MeshData, metres, same geometry as the input (original vertices keep their
        indices; new vertices are appended)
    surface : (m_out,) int64, surface id of each output face (0 .. surfaces-1)
    facets : int, surfaces : int
    shifted_vertices : int, new (shifted) vertices inserted
    parent : (m_out,) int64, input face each output face lies in
    strip : (m_out,) bool, output face lies in the boundary layer (touches a boundary edge)
    boundary_edges : int, mesh edges on a surface boundary
    split_faces : int, input faces that were subdivided
    clamped : int, split faces whose layer was narrowed to fit (face thinner than the layer)
    thin_kept : int, faces with a boundary edge left whole because they are thinner than the layer
    tiny_kept : int, faces left whole because a sub-triangle would be degenerate
    """

    mesh: MeshData
    surface: np.ndarray
    facets: int
    surfaces: int
    shifted_vertices: int
    parent: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    strip: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    boundary_edges: int = 0
    split_faces: int = 0
    clamped: int = 0
    thin_kept: int = 0
    tiny_kept: int = 0

    def counts(self) -> dict[str, int]:
        """The result's counts, as the ``blm`` block of the outputs."""
        return {
            "triangles_in": int(len(np.unique(self.parent))) if len(self.parent) else 0,
            "triangles_out": int(len(self.mesh.faces)),
            "facets": self.facets,
            "surfaces": self.surfaces,
            "boundary_edges": self.boundary_edges,
            "shifted_vertices": self.shifted_vertices,
            "split_faces": self.split_faces,
            "clamped": self.clamped,
            "thin_kept": self.thin_kept,
            "tiny_kept": self.tiny_kept,
        }


def _components(n: int, pairs: np.ndarray) -> np.ndarray:
    """Connected-component label (n,) of an undirected graph given as (k, 2) pairs."""
    if len(pairs) == 0:
        return np.arange(n, dtype=np.int64)
    return connected_components(n, pairs)[1]


def _renumber_by_first(labels: np.ndarray) -> np.ndarray:
    """Relabel so ids follow the order of first appearance (lowest index first)."""
    _, first, inv = np.unique(labels, return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[inv.ravel()]


def _facet_normals(facet: np.ndarray, nf: int, normals: np.ndarray, areas: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(area (nf,), unit area-weighted normal (nf, 3), lowest face index (nf,))`` of each facet."""
    m = len(facet)
    f_area = np.bincount(facet, weights=areas, minlength=nf)
    f_n: np.ndarray = np.stack([np.bincount(facet, weights=areas * normals[:, i], minlength=nf) for i in range(3)],
                               axis=1)
    norm = np.linalg.norm(f_n, axis=1)
    # a facet whose area-weighted normal cancels (cannot happen for a real plane): use its first face
    first_face = np.full(nf, m, dtype=np.int64)
    np.minimum.at(first_face, facet, np.arange(m))
    bad = norm <= 1e-300
    f_n[bad] = normals[first_face[bad]]
    norm[bad] = 1.0
    f_n /= norm[:, None]
    return f_area, f_n, first_face


def _grow_surfaces(f_surf: np.ndarray, seeds: np.ndarray, pairs: np.ndarray, f_n: np.ndarray, cos_thr: float,
                   next_id: int) -> None:
    """Seeded region growing over the facet graph ``pairs`` (k, 2), in place on ``f_surf`` (nf,).

    Each seed in ``seeds`` (in order) not yet in a surface starts surface ``next_id, next_id + 1,
    ...``; a facet joins it when it is connected to the seed through facets of the surface and its
    normal lies within the cone ``cos_thr`` of the seed facet's normal (breadth-first waves, each a
    vectorised CSR gather)."""
    nf = len(f_surf)
    # neighbours of each facet as CSR rows (sorted, no duplicates)
    key = np.unique(np.r_[pairs[:, 0], pairs[:, 1]] * nf + np.r_[pairs[:, 1], pairs[:, 0]])
    indices = key % nf
    indptr = np.r_[0, np.cumsum(np.bincount(key // nf, minlength=nf))]
    for s in seeds.tolist():
        if f_surf[s] >= 0:
            continue
        sid = next_id
        next_id += 1
        ok = (f_n @ f_n[s]) >= cos_thr - 1e-12   # admissible: within the cone of the seed normal
        f_surf[s] = sid
        frontier = np.array([s], dtype=np.int64)
        while len(frontier):
            starts = indptr[frontier]
            cnt = indptr[frontier + 1] - starts
            total = int(cnt.sum())
            if total == 0:
                break
            csum = np.cumsum(cnt)
            nb = indices[np.repeat(starts - (csum - cnt), cnt) + np.arange(total)]
            nb = np.unique(nb[(f_surf[nb] < 0) & ok[nb]])
            f_surf[nb] = sid
            frontier = nb


def cluster_surfaces(mesh: TriangleMesh, *, gamma_deg: float = 135.0, tol: Tolerance | None = None,
                     adjacency: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Facets and surfaces of ``mesh`` (the BLM's step 1, surface subdivision).

    Faces are clustered into *facets* (edge-connected faces whose normals differ by less than
    ``tol.planar_deg``) and facets into *surfaces*. ``gamma_deg`` is read as the dihedral angle
    between faces (the paper's Table I calls gamma = 95 deg "coarse, few surfaces", which only
    fits that reading): two facets may share a surface when their normals deviate by at most
    ``180 - gamma_deg`` degrees (45 deg at the default 135 deg).

    Clustering is seeded region growing (the paper's eq. 1 compares a facet's normal with the
    *surface's* normal): seeds are taken in order of decreasing facet area; a facet joins the
    seed's surface when (a) it is edge-connected to the surface through edges whose dihedral
    deviation is at most ``180 - gamma`` (a sharp edge is always a surface boundary) and (b) its
    normal is within ``180 - gamma`` of the seed facet's normal (so a finely tessellated fillet
    cannot chain two perpendicular faces into one surface). The grown surface is the connected
    component of the seed among the admissible facets, so it does not depend on the visiting
    order; seeds are ordered by area rounded to 1e-9 of the largest facet, ties by the lowest face
    index, and ids are renumbered by their lowest face index: the result is deterministic and
    invariant under rigid motions. Smooth regions (connected over edges with deviation <= 180 -
    gamma) whose normals all lie within the cone of their largest facet are taken whole; only the
    other regions run the region growing (:func:`_grow_surfaces`).

    ``adjacency`` (k, 2): the mesh's face pairs sharing an edge when the caller has them
    (:func:`grasplan.geometry.meshdata.edge_adjacency`). Returns ``(facet (m,) int64, surface (m,)
    int64, n_facets, n_surfaces)``.
    """
    tol = tol or Tolerance.for_mesh(mesh.vertices)
    m = len(mesh.faces)
    thr = np.radians(180.0 - gamma_deg)
    cos_thr = np.cos(thr)
    adj = edge_adjacency(mesh.faces)[0] if adjacency is None else adjacency  # trimesh's face_adjacency pairs
    normals = np.asarray(mesh.face_normals, dtype=np.float64)
    areas = np.asarray(mesh.area_faces, dtype=np.float64)
    dots = np.einsum("ij,ij->i", normals[adj[:, 0]], normals[adj[:, 1]]) if len(adj) else np.zeros(0)
    ang = np.arccos(np.clip(dots, -1.0, 1.0))

    facet = _renumber_by_first(_components(m, adj[ang < np.radians(tol.planar_deg)]))
    nf = int(facet.max()) + 1
    f_area, f_n, first_face = _facet_normals(facet, nf, normals, areas)

    smooth = ang <= thr + 1e-12
    region = _components(m, adj[smooth])           # smooth regions (face level)
    f_region = region[first_face]                   # facets never straddle regions (planar < thr)
    nr = int(region.max()) + 1 if m else 0

    # seed order: largest facet first (area rounded so rigid motions do not flip near-ties)
    key = np.round(f_area / max(f_area.max(), 1e-300), 9)
    order = np.lexsort((first_face, -key))
    # seed facet of each region = first facet of that region in seed order
    seed_of_region = np.full(nr, -1, dtype=np.int64)
    regs, first_pos = np.unique(f_region[order], return_index=True)
    seed_of_region[regs] = order[first_pos]
    within = np.einsum("ij,ij->i", f_n, f_n[seed_of_region[f_region]]) >= cos_thr - 1e-12
    narrow = np.ones(nr, dtype=bool)
    np.logical_and.at(narrow, f_region, within)

    f_surf = np.full(nf, -1, dtype=np.int64)
    # narrow regions: one surface each (label by region id, renumbered at the end)
    nar = narrow[f_region]
    f_surf[nar] = f_region[nar]
    if np.any(~nar):
        # facet graph over smooth edges, restricted to wide regions
        fa = facet[adj[smooth]]
        fa = fa[(fa[:, 0] != fa[:, 1]) & ~nar[fa[:, 0]]]
        _grow_surfaces(f_surf, order[~nar[order]], fa, f_n, cos_thr, nr)
    surface = _renumber_by_first(f_surf[facet])
    return facet, surface, nf, int(surface.max()) + 1 if m else 0


#: a boundary layer wider than this fraction of the part's diagonal is a units mistake, not a choice
MAX_ALPHA_FRACTION = 0.1


def _checked_arrays(mesh: TriangleMesh, alpha: float, gamma_deg: float, tol: Tolerance | None
                    ) -> tuple[np.ndarray, np.ndarray, Tolerance]:
    """``(vertices (n, 3) float64, faces (m, 3) int64, tol)`` of ``mesh``, after checking ``alpha`` and ``gamma_deg``."""
    if not (np.isfinite(alpha) and alpha > 0):
        raise InputError(f"alpha must be a positive length in metres, got {alpha!r}")
    if not (np.isfinite(gamma_deg) and 90.0 < gamma_deg <= 180.0):
        raise InputError(f"gamma must be in (90, 180] degrees, got {gamma_deg!r}")
    V = np.asarray(mesh.vertices, dtype=np.float64)
    F = np.asarray(mesh.faces, dtype=np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
        raise MeshError(f"BLM needs a triangle mesh with vertices (n, 3) and faces (m, 3), got {V.shape} and {F.shape}")
    tol = tol or Tolerance.for_mesh(V)
    if alpha > MAX_ALPHA_FRACTION * tol.scale:
        raise InputError(
            f"alpha = {alpha:g} m is {alpha / tol.scale:.0%} of the part's size ({tol.scale:.4g} m "
            f"diagonal): the boundary layer would swallow its faces. A bare number is metres: did you mean "
            f"{alpha:g}mm? (the paper uses 0.001-2 mm)"
        )
    return V, F, tol


@dataclass(frozen=True)
class _BoundaryEdges:
    """Surface-boundary edges per face (local edge k = (p_k, p_k+1)).

    count : mesh edges on a surface boundary
    mask : (m, 3) bool, edge k of the face is a boundary edge
    sin_nb : (m, 3) float64, sine of the angle between the face's and the neighbour's normal
        (the largest over several neighbours)
    """

    count: int
    mask: np.ndarray
    sin_nb: np.ndarray


def _boundary_edges(F: np.ndarray, normals: np.ndarray, surface: np.ndarray, adj: np.ndarray,
                    unshared: np.ndarray) -> _BoundaryEdges:
    """The BLM's step 2, edge determination: mesh edges whose two faces lie in different surfaces
    (the paper's eq. 2). ``adj`` (k, 2) face pairs sharing an edge, ``unshared`` (k, 2) the vertex
    of each face opposite that edge."""
    m = len(F)
    is_b = surface[adj[:, 0]] != surface[adj[:, 1]]
    badj, bun = adj[is_b], unshared[is_b]
    n_boundary_edges = int(len(badj))
    bmask = np.zeros((m, 3), dtype=bool)
    sin_nb = np.zeros((m, 3), dtype=np.float64)
    if n_boundary_edges:
        sin_t = np.linalg.norm(np.cross(normals[badj[:, 0]], normals[badj[:, 1]]), axis=1)
        for side in (0, 1):
            f = badj[:, side]
            j = np.argmax(F[f] == bun[:, side][:, None], axis=1)  # position of the unshared vertex
            k = (j + 1) % 3                                         # the edge opposite it
            bmask[f, k] = True
            # several neighbours (non-manifold edge): keep the largest sine (narrowest shift)
            np.maximum.at(sin_nb, (f, k), sin_t)
    return _BoundaryEdges(n_boundary_edges, bmask, sin_nb)


@dataclass(frozen=True)
class _Shift:
    """The shifted points inside each face owning a boundary edge.

    cand : (c,) int64, the faces with a boundary edge
    P : (c, 3, 3) their corners; Q : (c, 3, 3) the inner (shifted) points, labels q0 q1 q2
    bm : (c, 3) bool, which of their edges are boundary edges
    thin : (c,) bool, the face is thinner than the layer (stays whole)
    clamp : (c,) bool, the layer was narrowed to leave ``LAMBDA_MIN`` of the face
    """

    cand: np.ndarray
    P: np.ndarray
    Q: np.ndarray
    bm: np.ndarray
    thin: np.ndarray
    clamp: np.ndarray


def _shift_edges(V: np.ndarray, F: np.ndarray, edges: _BoundaryEdges, alpha: float) -> _Shift:
    """The BLM's step 3, edge shifting, in closed form.

    The paper shifts a boundary edge's vertices inside the face's plane (constraint 2) to distance
    ``alpha`` from the neighbouring facet's plane (constraint 1) with SLSQP. Here it is exact: a
    point in the face's plane at in-plane distance ``s`` from the shared edge is at distance ``s *
    sin(theta)`` from the neighbour's plane (``theta`` = angle between the normals), so ``s = alpha /
    sin(theta)``; ``sin(theta)`` is floored at :data:`SIN_FLOOR` (``s <= 2 alpha``) so near-tangent and
    knife edges keep a narrow layer. At a corner (two or three boundary edges) the new vertex is the
    intersection of the offset lines, shifted equally from both edges.

    In barycentric coordinates, "distance >= d_k from edge k" is "beta_opp(k) >= d_k / h_k"; the
    region between the three offset lines is a triangle homothetic to the parent with ratio
    ``lambda = 1 - sum_k delta_k``, whose corners are the inner points. Non-boundary edges get the
    offset :data:`DELTA_INNER` so the new points stay strictly inside. A parent thinner than the
    layer (``sum delta_boundary >= 1``) already is a strip (``thin``); when the layer would leave less
    than :data:`LAMBDA_MIN` of it, the boundary offsets are scaled down (``clamp``)."""
    bmask, sin_nb = edges.mask, edges.sin_nb
    nb_count = bmask.sum(axis=1)
    cand = np.flatnonzero(nb_count > 0)
    P = V[F[cand]]                                          # (c, 3, 3)
    e = np.roll(P, -1, axis=1) - P                          # edge k = p_k+1 - p_k
    L = np.linalg.norm(e, axis=2)                           # (c, 3)
    area2 = np.linalg.norm(np.cross(e[:, 0], -e[:, 2]), axis=1)   # 2 * area
    h = area2[:, None] / np.maximum(L, 1e-300)              # height over edge k
    s = alpha / np.maximum(sin_nb[cand], SIN_FLOOR)         # in-plane shift per boundary edge
    bm = bmask[cand]
    delta_b = np.where(bm, s / np.maximum(h, 1e-300), 0.0)
    delta_i = np.where(bm, 0.0, DELTA_INNER)
    sum_b = delta_b.sum(axis=1)
    thin = sum_b >= 1.0                                     # parent already thinner than the layer
    room = 1.0 - LAMBDA_MIN - delta_i.sum(axis=1)
    clamp = ~thin & (sum_b > room)
    delta_b = np.where(clamp[:, None], delta_b * (room / np.maximum(sum_b, 1e-300))[:, None], delta_b)
    delta = delta_b + delta_i                               # per edge k
    lam = 1.0 - delta.sum(axis=1)
    # barycentric weight of vertex j from the constraint on its opposite edge (j + 1) % 3
    D = np.roll(delta, -1, axis=1)                          # D[:, j] = delta[:, (j + 1) % 3]
    Q = np.einsum("cj,cjx->cx", D, P)[:, None, :] + lam[:, None, None] * P   # (c, 3, 3) inner points
    return _Shift(cand, P, Q, bm, thin, clamp)


@dataclass(frozen=True)
class _Split:
    """How each face of :class:`_Shift` is cut.

    one : (c,) bool, the face has one boundary edge; k_one : (c,) int64, that edge
    tmpl : (c, 7, 3) int64, its sub-triangles over the labels p0 p1 p2 q0 q1 q2 (rows of -1 unused)
    tiny : (c,) bool, a sub-triangle would be degenerate (the face stays whole)
    split : (c,) bool, the face is cut
    """

    one: np.ndarray
    k_one: np.ndarray
    tmpl: np.ndarray
    tiny: np.ndarray
    split: np.ndarray


def _sub_triangles(shift: _Shift, nb_count: np.ndarray, min_area: float) -> _Split:
    """The BLM's step 4, boundary layer insertion: the sub-triangles of each face owning a boundary edge.

    One boundary edge (a, b), opposite c, new a', b' on the offset line: strip (a, b, b'), (a, b',
    a'); rest (a', b', c), (b', b, c), (a, a', c) -> 5 faces. Two or three boundary edges: the inner
    triangle (q0, q1, q2) and one trapezoid per parent edge, each as two triangles (p_k, p_k+1,
    q_k+1), (p_k, q_k+1, q_k) -> 7 faces. Every new point lies strictly inside its parent, so no
    edge is split, no T-junction appears and a watertight input stays watertight; every
    sub-triangle keeps its parent's winding and plane (area per surface, volume and orientation
    unchanged). A face whose smallest sub-triangle would have at most ``min_area`` stays whole
    (``tiny``), as does a ``thin`` one."""
    C = np.concatenate([shift.P, shift.Q], axis=1)          # (c, 6, 3) labels p0 p1 p2 q0 q1 q2
    one = nb_count[shift.cand] == 1
    k_one = np.argmax(shift.bm, axis=1)                     # the boundary edge (one-edge case)
    tmpl = np.where(one[:, None, None], np.pad(_ONE_EDGE_ROT[k_one], ((0, 0), (0, 2), (0, 0)), constant_values=-1), _RING[None])
    # smallest sub-triangle area per candidate (sub-triangles of the template; -1 rows ignored)
    valid_row = tmpl[:, :, 0] >= 0
    t_safe = np.where(tmpl < 0, 0, tmpl)
    tri = np.take_along_axis(C[:, None, :, :], t_safe[..., None], axis=2)  # (c, 7, 3, 3)
    sub_area = 0.5 * np.linalg.norm(np.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0]), axis=2)
    smallest = np.where(valid_row, sub_area, np.inf).min(axis=1)
    tiny = ~shift.thin & (smallest <= min_area)
    split = ~shift.thin & ~tiny
    return _Split(one, k_one, tmpl, tiny, split)


@dataclass(frozen=True)
class _Remeshed:
    """The remeshed faces: ``V`` (n', 3), ``F`` (m', 3), ``parent`` (m',) input face of each,
    ``strip`` (m',) in the boundary layer, ``n_new`` vertices added, ``n_split`` faces cut."""

    V: np.ndarray
    F: np.ndarray
    parent: np.ndarray
    strip: np.ndarray
    n_new: int
    n_split: int


def _assemble(V: np.ndarray, F: np.ndarray, shift: _Shift, cut: _Split) -> _Remeshed:
    """The BLM's remeshing: faces not cut keep their order, then the sub-triangles of each cut face;
    the new vertices are appended after the original ones."""
    m = len(F)
    cand, bm = shift.cand, shift.bm
    keep_face = np.ones(m, dtype=bool)
    keep_face[cand[cut.split]] = False
    sp = np.flatnonzero(cut.split)
    one_sp, k_sp = cut.one[sp], cut.k_one[sp]
    # new vertex labels used: one-edge -> q_k, q_k+1 ; ring -> q0, q1, q2
    used = np.zeros((len(sp), 3), dtype=bool)
    used[~one_sp] = True
    r1 = np.flatnonzero(one_sp)
    used[r1, k_sp[r1]] = True
    used[r1, (k_sp[r1] + 1) % 3] = True
    n_new = int(used.sum())
    new_idx = np.full((len(sp), 3), -1, dtype=np.int64)
    new_idx[used] = len(V) + np.arange(n_new)
    new_V = shift.Q[sp][used]                               # row-major: same order as new_idx
    lab = np.concatenate([F[cand[sp]], new_idx], axis=1)   # (n_sp, 6) vertex index per label
    t_sp = cut.tmpl[sp]
    rows = np.flatnonzero((t_sp[:, :, 0] >= 0).ravel())
    sub_faces = np.take_along_axis(lab[:, None, :], np.where(t_sp < 0, 0, t_sp), axis=2).reshape(-1, 3)[rows]
    sub_parent = np.repeat(cand[sp], 7)[rows]
    strip_one = np.r_[_ONE_EDGE_STRIP, False, False]
    # ring: trapezoid (rows 2k, 2k+1) is strip when edge k is a boundary edge
    strip_ring = np.repeat(bm[sp], 2, axis=1)
    strip_ring = np.concatenate([strip_ring, np.zeros((len(sp), 1), dtype=bool)], axis=1)
    sub_strip = np.where(one_sp[:, None], strip_one[None], strip_ring).ravel()[rows]

    kept = np.flatnonzero(keep_face)
    kept_strip = np.zeros(m, dtype=bool)
    kept_strip[cand[shift.thin | cut.tiny]] = True
    out_F = np.concatenate([F[kept], sub_faces])
    out_V = np.concatenate([V, new_V])
    parent = np.concatenate([kept, sub_parent]).astype(np.int64)
    strip = np.concatenate([kept_strip[kept], sub_strip])
    return _Remeshed(out_V, out_F, parent, strip, n_new, int(len(sp)))


def boundary_layer(
    mesh: TriangleMesh, *, alpha: float = 1e-4, gamma_deg: float = 135.0, tol: Tolerance | None = None
) -> BLMResult:
    """Insert a boundary layer of width ``alpha`` along every surface boundary.

    Parameters
    ----------
    mesh : TriangleMesh
        The part in metres, vertices (n, 3), faces (m, 3), consistently wound (``load_part`` output).
    alpha : float
        Layer width, metres: distance of the shifted vertices from the neighbouring facet's plane
        (paper default 0.1 mm).
    gamma_deg : float
        Surface angle in degrees, in (90, 180]: facets join a surface when their normals deviate by
        at most ``180 - gamma_deg``.
    tol : Tolerance, optional
        The part's tolerances (default: built from the mesh's size).

    Returns
    -------
    BLMResult
        Same geometry; faces owning a surface-boundary edge are subdivided (5 or 7 faces).
    """
    V, F, tol = _checked_arrays(mesh, alpha, gamma_deg, tol)
    adj, _, unshared = mesh_edge_adjacency(mesh)[:3]  # face pairs, the vertex of each opposite the shared edge
    facet, surface, n_facets, n_surfaces = cluster_surfaces(mesh, gamma_deg=gamma_deg, tol=tol, adjacency=adj)
    normals = np.asarray(mesh.face_normals, dtype=np.float64)
    edges = _boundary_edges(F, normals, surface, adj, unshared)
    shift = _shift_edges(V, F, edges, alpha)
    cut = _sub_triangles(shift, edges.mask.sum(axis=1), AREA_SAFETY * tol.area)
    out = _assemble(V, F, shift, cut)
    return BLMResult(
        mesh=MeshData(out.V, out.F, face_normals=normals[out.parent]),
        surface=surface[out.parent],
        facets=int(n_facets),
        surfaces=int(n_surfaces),
        shifted_vertices=out.n_new,
        parent=out.parent,
        strip=out.strip,
        boundary_edges=edges.count,
        split_faces=out.n_split,
        clamped=int(np.count_nonzero(shift.clamp & cut.split)),
        thin_kept=int(np.count_nonzero(shift.thin)),
        tiny_kept=int(np.count_nonzero(cut.tiny)),
    )
