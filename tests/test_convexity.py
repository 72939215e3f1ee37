"""Convexity classification: exact against Qhull (scipy Delaunay/ConvexHull), robust on odd meshes."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial import ConvexHull, Delaunay, QhullError

from grasplan.candidates.convexity import classify_convexity, neighbour_vertices
from grasplan.part.mesh import load_part
from grasplan.geometry.tolerance import Tolerance


def _heightfield(rng, n=7, noise=1e-4, size=0.01):
    """Open, bumpy grid mesh in metres with upward normals (boundary edges on purpose)."""
    x, y = np.meshgrid(np.linspace(0, size, n), np.linspace(0, size, n), indexing="ij")
    # a dome (convex) plus noise (concave dents), and a flat corner (degenerate hull)
    z = -40.0 * ((x - size / 2) ** 2 + (y - size / 2) ** 2) + rng.normal(scale=noise, size=x.shape)
    z[: n // 2 + 1, : n // 2 + 1] = 0.0
    V = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    F = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            F += [[a, b, c], [a, c, d]]
    return trimesh.Trimesh(V, np.array(F), process=False)


def _qhull_convex(points, p, tol):
    """Reference: True (convex) when p is outside the hull of points or on its boundary; None if unclear."""
    try:
        hull = ConvexHull(points)
    except QhullError:
        return True  # flat (coplanar) neighbourhood: convex by the paper's rule
    signed = hull.equations[:, :3] @ p + hull.equations[:, 3]   # > 0 outside a facet
    margin = signed.max()
    if abs(margin) < 10 * tol:
        return None  # on the boundary within tolerance: ambiguous for the reference, skip
    inside_delaunay = Delaunay(points).find_simplex(p) >= 0
    assert inside_delaunay == (margin < 0)   # the two Qhull views agree
    return bool(margin > 0)


@pytest.mark.parametrize("neighbourhood", ["edge", "vertex"])
@pytest.mark.parametrize("seed", range(2))
def test_matches_qhull_on_random_open_meshes(seed, neighbourhood):
    rng = np.random.default_rng(seed)
    mesh = _heightfield(rng)
    tol = Tolerance.for_mesh(mesh.vertices)
    d_shift = 1e-5
    got = classify_convexity(mesh, d_shift=d_shift, tol=tol, neighbourhood=neighbourhood)

    # independent neighbourhoods, face by face
    F, V = mesh.faces, mesh.vertices
    checked = {True: 0, False: 0}
    for k in range(len(F)):
        if neighbourhood == "edge":
            nb = [f for f in range(len(F)) if len(set(F[f]) & set(F[k])) >= 2]
        else:
            nb = [f for f in range(len(F)) if len(set(F[f]) & set(F[k])) >= 1]
        pts = V[np.unique(F[nb].ravel())]
        p = V[F[k]].mean(axis=0) + d_shift * mesh.face_normals[k]
        ref = _qhull_convex(pts, p, tol.distance)
        if ref is None:
            continue
        assert got[k] == ref, f"face {k}: classify_convexity={got[k]}, Qhull={ref}"
        checked[ref] += 1
    assert checked[True] > 5 and checked[False] > 5, checked   # both outcomes exercised


def test_neighbourhood_sets():
    mesh = trimesh.creation.box(extents=[1, 1, 1])
    Ve = neighbour_vertices(mesh, "edge")
    Vv = neighbour_vertices(mesh, "vertex")
    assert (np.diff(Ve.indptr) == 6).all()        # own 3 + 3 opposite vertices
    assert (np.diff(Vv.indptr) >= 6).all() and (np.diff(Vv.indptr) > 6).any()
    with pytest.raises(ValueError):
        classify_convexity(mesh, neighbourhood="face")  # type: ignore[arg-type]


def test_convex_solids_are_all_convex():
    for mesh in (trimesh.creation.box(extents=[0.03, 0.02, 0.01]), trimesh.creation.icosphere(2, radius=0.02),
                 trimesh.creation.cylinder(radius=0.01, height=0.03, sections=32)):
        for nb in ("edge", "vertex"):
            assert classify_convexity(mesh, neighbourhood=nb).all()


def test_inverted_box_is_concave():
    mesh = trimesh.creation.box(extents=[0.03, 0.02, 0.01])
    mesh.invert()   # normals inwards: every face now sees its neighbours above it
    assert not classify_convexity(mesh).any()


def test_flat_and_degenerate_inputs():
    # a flat square: degenerate hull everywhere -> convex
    flat = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]], process=False)
    assert classify_convexity(flat, d_shift=1e-3).all()
    # single triangle (all edges are boundary edges)
    tri = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], process=False)
    assert classify_convexity(tri).tolist() == [True]
    # non-manifold edge shared by three faces, one of them folding up above face 0
    V = [[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0.3, 1.0]]
    F = [[0, 1, 2], [1, 0, 3], [0, 1, 4]]
    nm = trimesh.Trimesh(V, F, process=False)
    for nb in ("edge", "vertex"):
        out = classify_convexity(nm, d_shift=1e-3, neighbourhood=nb)
        assert out.shape == (3,) and out.dtype == bool
    with pytest.raises(ValueError):
        classify_convexity(tri, d_shift=0.0)


def test_bracket_notch_faces_are_concave(example_part):
    part = load_part(example_part("bracket.stl"), units="mm")
    convex = classify_convexity(part.mesh, tol=part.tol)
    # independent rule for a polyhedron: a face next to a concave (reflex) edge is concave
    m = part.mesh
    concave_edge_faces = np.unique(m.face_adjacency[~m.face_adjacency_convex].ravel())
    assert len(concave_edge_faces) > 0
    assert not convex[concave_edge_faces].any()
    others = np.setdiff1d(np.arange(len(m.faces)), concave_edge_faces)
    assert convex[others].all()


def test_rigid_motion_invariance(example_part):
    part = load_part(example_part("gear.stl"), units="mm")
    rng = np.random.default_rng(3)
    T = trimesh.transformations.random_rotation_matrix(rng.random(3))
    T[:3, 3] = rng.normal(size=3)
    moved = part.mesh.copy()
    moved.apply_transform(T)
    for nb in ("edge", "vertex"):
        a = classify_convexity(part.mesh, tol=part.tol, neighbourhood=nb)
        b = classify_convexity(moved, tol=part.tol, neighbourhood=nb)
        assert np.array_equal(a, b)
