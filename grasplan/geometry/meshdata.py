"""A triangle mesh as plain NumPy arrays: what the load and candidate stages need, without trimesh.

:class:`MeshData` is the mesh; :class:`TriangleMesh` is the Protocol of what the stages read of a
``MeshData`` or a ``trimesh.Trimesh``. This is a base module (it imports nothing of grasplan):
besides the mesh it holds the mesh helpers the stages share, :func:`edge_adjacency` (faces sharing
an edge, one sort), :func:`connected_components`, :func:`polyhedron_integrals` (volume, centre of
mass and inertia of a closed mesh; :mod:`grasplan.part.mass` builds the part's mass properties on
it) and :func:`convex_hull`.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Literal, Protocol, TypeVar, overload

import numpy as np

if TYPE_CHECKING:
    import trimesh as _trimesh  # as _trimesh: in MeshData's body ``trimesh`` is its property


_T = TypeVar("_T")

#: trimesh's zero threshold of a cross product's length (``trimesh.util.TOL_ZERO``)
_TOL_ZERO = float(np.finfo(np.float64).resolution * 100)


def connected_components(n: int, edges: np.ndarray) -> tuple[int, np.ndarray]:
    """``(count, label (n,))`` of the graph on ``n`` nodes with undirected ``edges (k, 2)``: min-label
    hooking with pointer jumping (O(log n) rounds of vectorised work), labels renumbered 0.."""
    parent = np.arange(n, dtype=np.int64)
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    while len(e):
        pa, pb = parent[e[:, 0]], parent[e[:, 1]]
        diff = pa != pb
        if not diff.any():
            break
        lo, hi = np.minimum(pa[diff], pb[diff]), np.maximum(pa[diff], pb[diff])
        np.minimum.at(parent, hi, lo)
        while True:  # pointer jumping: every node points at its root
            nxt = parent[parent]
            if np.array_equal(nxt, parent):
                break
            parent = nxt
        e = e[diff]
    _, label = np.unique(parent, return_inverse=True)
    return int(label.max()) + 1 if n else 0, label.reshape(-1)


@overload
def edge_adjacency(faces: np.ndarray, *, slots: Literal[False] = ...) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
@overload
def edge_adjacency(faces: np.ndarray, *, slots: Literal[True]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...

def edge_adjacency(faces: np.ndarray, *, slots: bool = False
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Pairs of faces sharing an edge (edges with exactly two faces, as ``trimesh.face_adjacency``),
    by one int64 sort instead of trimesh's row hashing (several times faster at 250k faces).

    Returns ``adj (k, 2)`` face ids, ``edge (k, 2)`` the shared vertex ids and ``unshared (k, 2)`` the
    vertex of each face opposite the edge, ordered by edge; with ``slots=True`` also ``(k, 2)`` the
    edge's slot ``3 * face + corner`` in each face (edge ``corner -> corner + 1``)."""
    F = np.ascontiguousarray(faces, dtype=np.int64)
    m = len(F)
    if m == 0:
        z = np.zeros((0, 2), dtype=np.int64)
        return (z, z, z, z) if slots else (z, z, z)
    out = _edge_adjacency(F)
    return out if slots else out[:3]


def _edge_adjacency(F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`edge_adjacency` with slots."""
    a, b = F.ravel(), np.roll(F, -1, axis=1).ravel()            # edge k of face f: corner k -> k+1
    far = F[:, [2, 0, 1]].ravel()
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * (int(F.max()) + 1) + hi
    o = np.argsort(key, kind="stable")
    k = key[o]
    start = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    cnt = np.diff(np.r_[start, len(k)])
    two = start[cnt == 2]
    i, j = o[two], o[two + 1]
    out = (np.stack([i // 3, j // 3], axis=1), np.stack([lo[i], hi[i]], axis=1), np.stack([far[i], far[j]], axis=1),
           np.stack([i, j], axis=1))
    for arr in out:
        arr.flags.writeable = False
    return out


def polyhedron_integrals(triangles: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """``(volume, centre of mass (3,), inertia (3, 3) about it)`` at unit density of the solid
    bounded by ``triangles (n, 3, 3)`` (outward winding; signed: inward gives negative volume and
    inertia), by the divergence theorem: D. Eberly, "Polyhedral mass properties (revisited)",
    2002 (the formulation of ``trimesh.triangles.mass_properties``, whose operations this repeats)."""
    t = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    t0, t1, t2 = t[:, 0, :], t[:, 1, :], t[:, 2, :]
    d = t[:, 1:, :] - t[:, :2, :]
    crosses = np.cross(d[:, 0], d[:, 1])
    f1 = t0 + t1 + t2
    f2 = t0 ** 2 + t1 ** 2 + t0 * t1 + t2 * f1
    f3 = t0 ** 3 + t0 ** 2 * t1 + t0 * t1 ** 2 + t1 ** 3 + t2 * f2
    g0 = f2 + (t0 + f1) * t0
    g1 = f2 + (t1 + f1) * t1
    g2 = f2 + (t2 + f1) * t2
    integral = np.zeros((10, len(f1)))
    integral[0] = crosses[:, 0] * f1[:, 0]
    integral[1:4] = (crosses * f2).T
    integral[4:7] = (crosses * f3).T
    for i in range(3):
        j = (i + 1) % 3
        integral[i + 7] = crosses[:, i] * (t0[:, j] * g0[:, i] + t1[:, j] * g1[:, i] + t2[:, j] * g2[:, i])
    s = integral.sum(axis=1) / np.array([6, 24, 24, 24, 60, 60, 60, 120, 120, 120], dtype=np.float64)
    volume = float(s[0])
    with np.errstate(invalid="ignore", divide="ignore"):
        com = s[1:4] / volume
    inertia = np.zeros((3, 3))
    inertia[0, 0] = s[5] + s[6] - volume * (com[[1, 2]] ** 2).sum()
    inertia[1, 1] = s[4] + s[6] - volume * (com[[0, 2]] ** 2).sum()
    inertia[2, 2] = s[4] + s[5] - volume * (com[[0, 1]] ** 2).sum()
    inertia[0, 1] = inertia[1, 0] = -(s[7] - volume * np.prod(com[[0, 1]]))
    inertia[1, 2] = inertia[2, 1] = -(s[8] - volume * np.prod(com[[1, 2]]))
    inertia[0, 2] = inertia[2, 0] = -(s[9] - volume * np.prod(com[[0, 2]]))
    return volume, com, inertia


class TriangleMesh(Protocol):
    """What the pipeline's stages read of a triangle mesh (metres). :class:`MeshData` satisfies it,
    and so does a ``trimesh.Trimesh``; annotate a stage's mesh argument with this, not with either."""

    @property
    def vertices(self) -> np.ndarray: ...          # (n, 3) float64

    @property
    def faces(self) -> np.ndarray: ...             # (m, 3) int

    @property
    def face_normals(self) -> np.ndarray: ...      # (m, 3) unit

    @property
    def area_faces(self) -> np.ndarray: ...        # (m,)

    @property
    def triangles(self) -> np.ndarray: ...         # (m, 3, 3)

    @property
    def bounds(self) -> np.ndarray: ...            # (2, 3)

    @property
    def extents(self) -> np.ndarray: ...           # (3,)

    @property
    def is_watertight(self) -> bool: ...           # every edge shared by exactly two faces

    @property
    def convex_hull(self) -> TriangleMesh: ...     # of the vertices, outward wound

    @property
    def center_mass(self) -> np.ndarray: ...       # (3,) of the enclosed solid (watertight meshes)

    @property
    def centroid(self) -> np.ndarray: ...          # (3,) area-weighted centre of the surface


class MeshData:
    """An immutable triangle mesh.

    Importing trimesh costs 0.5-0.9 s (it pulls in ``scipy.spatial`` and ``networkx``), more than
    loading a part and computing its candidates. This class computes the part of
    ``trimesh.Trimesh``'s interface the load and candidate stages read (``vertices``, ``faces``,
    ``face_normals``, ``area_faces``, ``area``, ``triangles``, ``triangles_center``, ``bounds``,
    ``extents``, ``is_watertight``, ``is_winding_consistent``, ``body_count``, ``convex_hull``,
    ``volume``, ``center_mass``) with NumPy and scipy's Qhull alone, each once and cached. Everything
    else (``centroid``, ``face_adjacency``, ``ray``, ...) is read from an equal ``trimesh.Trimesh``
    built on first use (:attr:`trimesh`), so a ``MeshData`` can stand wherever a read-only trimesh
    was used.

    Immutable by contract: its arrays are shared, never written (stages that change geometry build
    a new one). Lengths are whatever the caller's are (the pipeline's are metres).

    Parameters
    ----------
    vertices : (n, 3) float64
    faces : (m, 3) int64
    face_normals : (m, 3) float64, optional
        Unit normals to record instead of computing them from the winding (the BLM keeps each new
        triangle's parent normal).
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, face_normals: np.ndarray | None = None):
        self._vertices = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
        self._faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
        self._cache: dict = {}
        if face_normals is not None:
            fn = np.ascontiguousarray(face_normals, dtype=np.float64).reshape(-1, 3)
            if len(fn) != len(self._faces):
                raise ValueError(f"MeshData: {len(fn)} face normals for {len(self._faces)} faces")
            self._cache["face_normals"] = fn

    # -- pickling (Ray workers, multiprocessing): arrays and recorded normals, not the caches ---
    def __getstate__(self) -> dict:
        return {"vertices": self._vertices, "faces": self._faces,
                "face_normals": self._cache.get("face_normals")}

    def __setstate__(self, state: dict) -> None:
        MeshData.__init__(self, state["vertices"], state["faces"], state["face_normals"])

    def __repr__(self) -> str:
        return f"MeshData(vertices={len(self._vertices)}, faces={len(self._faces)})"

    def _cached(self, name: str, compute: Callable[[], _T]) -> _T:
        c = self._cache
        if name not in c:
            c[name] = compute()
        return c[name]

    @property
    def vertices(self) -> np.ndarray:
        """(n, 3) float64."""
        return self._vertices

    @property
    def faces(self) -> np.ndarray:
        """(m, 3) int64."""
        return self._faces

    @property
    def triangles(self) -> np.ndarray:
        """(m, 3, 3) float64: the corners of each face."""
        return self._cached("triangles", lambda: self._vertices[self._faces])

    @property
    def triangles_cross(self) -> np.ndarray:
        """(m, 3) float64: (b - a) x (c - b) per face (trimesh's operands, bit-identical results)."""
        def f() -> np.ndarray:
            t = self.triangles
            d = t[:, 1:, :] - t[:, :2, :]
            return np.cross(d[:, 0], d[:, 1])
        return self._cached("triangles_cross", f)

    @property
    def area_faces(self) -> np.ndarray:
        """(m,) float64."""
        return self._cached("area_faces", lambda: np.sqrt((self.triangles_cross ** 2).sum(axis=1)) / 2.0)

    @property
    def area(self) -> float:
        return self._cached("area", lambda: float(self.area_faces.sum()))

    @property
    def face_normals(self) -> np.ndarray:
        """(m, 3) float64 unit normals by the right-hand rule (zero for a face without area), computed
        as trimesh does (same operations, so the same bits)."""
        def f() -> np.ndarray:
            c = self.triangles_cross
            norm = np.sqrt(np.dot(c * c, [1.0, 1.0, 1.0]))
            valid = norm > _TOL_ZERO
            norm[valid] **= -1
            return np.where(valid[:, None], c * norm.reshape((-1, 1)), 0.0)
        return self._cached("face_normals", f)

    @property
    def triangles_center(self) -> np.ndarray:
        """(m, 3) float64: face centroids."""
        return self._cached("triangles_center", lambda: self.triangles.mean(axis=1))

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64: min and max corner of the referenced vertices' box."""
        def f() -> np.ndarray:
            if not len(self._faces):
                v = self._vertices
            else:
                used = np.zeros(len(self._vertices), dtype=bool)
                used[self._faces.ravel()] = True
                v = self._vertices[used]
            return np.array([v.min(axis=0), v.max(axis=0)])
        return self._cached("bounds", f)

    @property
    def extents(self) -> np.ndarray:
        """(3,) float64: size of :attr:`bounds`."""
        return np.ptp(self.bounds, axis=0)

    @property
    def edge_adjacency(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:func:`edge_adjacency` of the faces with slots, once (watertightness, winding, the BLM and
        convexity share it)."""
        return self.derived("edge_adjacency", lambda: edge_adjacency(self._faces, slots=True))

    @property
    def is_watertight(self) -> bool:
        """Every edge belongs to exactly two faces (as trimesh's ``is_watertight``): the edges with
        exactly two faces pair up all ``3 m`` face edges."""
        return self._cached("is_watertight",
                            lambda: len(self._faces) > 0 and 2 * len(self.edge_adjacency[0]) == 3 * len(self._faces))

    @property
    def is_winding_consistent(self) -> bool:
        """Every edge with exactly two faces is walked in opposite directions by them (the two
        directed edges start at different vertices)."""
        def f() -> bool:
            slot = self.edge_adjacency[3]
            a = self._faces.ravel()
            return bool(np.all(a[slot[:, 0]] != a[slot[:, 1]]))
        return self._cached("is_winding_consistent", f)

    def with_faces(self, keep: np.ndarray) -> MeshData:
        """The mesh of the faces ``keep`` (bool mask) with unreferenced vertices dropped (order
        kept); the kept faces' cross products, areas and normals carry over (same bits)."""
        keep = np.asarray(keep, dtype=bool)
        fk = self._faces[keep]
        used = np.zeros(len(self._vertices), dtype=bool)
        used[fk.ravel()] = True
        remap = np.cumsum(used) - 1
        out = MeshData(self._vertices[used], remap[fk])
        for name in ("triangles_cross", "area_faces", "face_normals"):
            if name in self._cache:
                out._cache[name] = self._cache[name][keep]
        return out

    @property
    def body_count(self) -> int:
        """Connected groups of vertices (joined by face edges), as trimesh's ``body_count``."""
        def f() -> int:
            F = self._faces
            e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]]]) if len(F) else np.zeros((0, 2), dtype=np.int64)
            return connected_components(len(self._vertices), e)[0]
        return self._cached("body_count", f)

    @property
    def convex_hull(self) -> MeshData:
        """The convex hull of the vertices (:func:`convex_hull`; raises scipy's ``QhullError`` for
        flat or degenerate points)."""
        return self._cached("convex_hull", lambda: convex_hull(self._vertices))

    def _integrals(self) -> tuple[float, np.ndarray, np.ndarray]:
        return self._cached("integrals", lambda: polyhedron_integrals(self.triangles))

    @property
    def volume(self) -> float:
        """Signed volume enclosed (divergence theorem; positive for outward normals)."""
        return self._integrals()[0]

    @property
    def center_mass(self) -> np.ndarray:
        """(3,) centre of mass of the enclosed solid at uniform density."""
        return self._integrals()[1]

    @property
    def trimesh(self) -> _trimesh.Trimesh:
        """An equal ``trimesh.Trimesh`` (built once, on first use; imports trimesh). Read-only."""
        def f() -> _trimesh.Trimesh:
            import trimesh

            return trimesh.Trimesh(vertices=self._vertices, faces=self._faces,
                                   face_normals=self._cache.get("face_normals"), process=False, validate=False)
        return self._cached("trimesh", f)

    def derived(self, key: str, compute: Callable[[], _T]) -> _T:
        """``compute()`` once per mesh: a stage's per-part data that depends on nothing but the
        geometry (e.g. the quality step's merged flat faces), cached with the mesh; treat the
        result as read-only."""
        return self._cached(f"derived:{key}", compute)

    def copy(self) -> _trimesh.Trimesh:
        """A mutable ``trimesh.Trimesh`` copy (what a copy is for: changing the geometry)."""
        return self.trimesh.copy()

    def __getattr__(self, name: str) -> Any:
        # only called for what the class does not define: read it from the equal trimesh, but never
        # change it in place (the arrays are shared)
        if name.startswith("_"):
            raise AttributeError(name)
        if name.startswith(_MUTATING_PREFIXES) or name in _MUTATING:
            raise AttributeError(f"MeshData.{name}: a MeshData is immutable (its arrays are shared); "
                                 f"change a copy instead: mesh.copy().{name}(...) (a trimesh.Trimesh)")
        return getattr(self.trimesh, name)


#: trimesh methods that change a mesh in place: refused on a MeshData (use ``copy()``)
_MUTATING_PREFIXES = ("apply_", "update_", "remove_", "fix_", "merge_", "fill_", "unmerge_")
_MUTATING = frozenset({"invert", "process", "rezero", "subdivide_to_size", "fix_normals"})


#: Qhull options of :func:`convex_hull` (trimesh's: scale to the unit box, keep coplanar, triangulate)
QHULL_OPTIONS = "QbB Pp Qt"


def convex_hull(points: np.ndarray) -> MeshData:
    """Convex hull of ``points (n, 3)`` as a :class:`MeshData` with outward-wound faces: the
    construction of ``trimesh.convex.convex_hull`` (Qhull ``QbB Pp Qt``, retried with ``QJ``;
    vertices in input order; zero-area faces dropped; a face whose normal points towards the
    area-weighted centroid is flipped), same faces and bits, without importing trimesh."""
    from scipy.spatial import ConvexHull, QhullError

    P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    try:
        hull = ConvexHull(P, qhull_options=QHULL_OPTIONS)
    except QhullError:
        hull = ConvexHull(P, qhull_options="QJ")
    vid = np.sort(hull.vertices)
    mask = np.zeros(len(hull.points), dtype=np.int64)
    mask[vid] = np.arange(len(vid))
    faces = mask[hull.simplices].copy()
    vertices = hull.points[vid].copy()
    probe = MeshData(vertices, faces)
    cr = probe.triangles_cross
    norm = np.sqrt(np.dot(cr * cr, [1.0, 1.0, 1.0]))
    valid = norm > _TOL_ZERO
    faces, cr, norm = faces[valid], cr[valid], norm[valid]
    normals = cr / norm[:, None]
    area = np.sqrt((cr ** 2).sum(axis=1)) / 2.0
    centre = vertices[faces].mean(axis=1)
    centroid = np.average(centre, weights=area, axis=0) if area.sum() > 0 else vertices.mean(axis=0)
    back = np.einsum("ij,ij->i", normals, centre - centroid) < 0.0
    faces[back] = np.fliplr(faces[back])
    return MeshData(vertices, faces)  # normals from the (now outward) winding, as trimesh ends with
