"""Region candidates (method="regions"): samples lie on both convex areas and in the friction
cone, do not depend on the tessellation or the part's pose, and the chunked search changes nothing."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, Phase, example, given, settings
from hypothesis import strategies as st
import regions_reference
from regions_reference import find_regions_pairs
from test_antipodal import point_triangle_distance

from grasplan.candidates import antipodal_base as ap
from grasplan.candidates import regions as rg
from grasplan.candidates.antipodal_base import Candidates
from grasplan.candidates.pipeline import find_candidates
from grasplan.candidates.region_areas import convex_areas
from grasplan.candidates.region_creases import CONCAVE_MARGIN
from grasplan.candidates.regions import find_regions
from grasplan.geometry.tolerance import Tolerance

MU, BETA, SPACING = 0.3, 2.0, 0.002


def _regions(mesh, convex=None, tol=None, **kw):
    convex = np.ones(len(mesh.faces), bool) if convex is None else convex
    tol = Tolerance.for_mesh(mesh.vertices) if tol is None else tol
    return find_candidates(mesh, convex, method="regions", spacing=kw.pop("spacing", SPACING), mu=MU,
                           beta_deg=BETA, tol=tol, **kw)


def _slab_pair(size=(0.020, 0.012), gap=0.010, subdivide=None):
    """Two opposite rectangles (2 triangles each; optionally subdivided) facing away: a slab's faces."""
    w, h = size
    q = np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]], float)
    V = np.vstack([q, q + [0, 0, gap]])
    F = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7]])    # bottom normal -z, top +z
    if subdivide:
        V, F = trimesh.remesh.subdivide_to_size(V, F, subdivide)
    return trimesh.Trimesh(V, F, process=subdivide is not None)   # merge the subdivision's duplicate vertices


def _sorted(c: Candidates):
    key = np.round(c.contacts.reshape(len(c), 6) / 1e-9).astype(np.int64)
    o = np.lexsort(key.T[::-1])
    return c.contacts[o]


def _same_pairs(a: np.ndarray, b: np.ndarray, atol: float) -> bool:
    """The contact pairs ``a`` and ``b`` (n, 2, 3) are the same set within ``atol`` (m, per
    coordinate): a one-to-one matching exists (not a sort, whose order two contacts within
    ``atol`` of a rounding boundary can swap)."""
    from scipy.optimize import linear_sum_assignment

    if a.shape != b.shape:
        return False
    A, B = a.reshape(len(a), 6), b.reshape(len(b), 6)
    D = np.abs(A[:, None, :] - B[None, :, :]).max(axis=2)
    rows, cols = linear_sum_assignment(D)
    return bool(np.all(D[rows, cols] <= atol))


def test_samples_on_both_areas_inside_friction_cone():
    mesh = trimesh.creation.box(extents=[0.060, 0.045, 0.014])
    tol = Tolerance.for_mesh(mesh.vertices)
    c = _regions(mesh)
    assert len(c) > 100
    # each contact on its own triangle, the two faces in the region's two (distinct) areas
    for k in range(2):
        assert point_triangle_distance(mesh.triangles[c.faces[:, k]], c.contacts[:, k]).max() <= tol.distance
    areas = convex_areas(mesh, np.ones(len(mesh.faces), bool), tol)
    la, lb = areas.label[c.faces[:, 0]], areas.label[c.faces[:, 1]]
    assert (la != lb).all()
    for r in np.unique(c.region):        # one region = one pair of areas
        sel = c.region == r
        assert len(np.unique(la[sel])) == 1 and len(np.unique(lb[sel])) == 1
    d = c.contacts[:, 1] - c.contacts[:, 0]
    w = np.linalg.norm(d, axis=1)
    assert np.allclose(w, c.width) and (w <= 0.05).all()
    dn = d / w[:, None]
    half = np.arctan(MU)
    assert (np.arccos(np.clip(np.einsum("ij,ij->i", dn, -c.normals[:, 0]), -1, 1)) <= half + 1e-9).all()
    assert (np.arccos(np.clip(np.einsum("ij,ij->i", dn, c.normals[:, 1]), -1, 1)) <= half + 1e-9).all()
    assert np.allclose(c.normals, mesh.face_normals[c.faces])
    # the 60 mm pair is wider than the opening: only the 45 mm and 14 mm pairs; lattice counts of a
    # 2 mm grid centred on each rectangle strictly inside (60 x 14: 29 x 7, 60 x 45: 29 x 23)
    widths = np.unique(np.round(c.width, 9))
    assert np.allclose(widths, [0.014, 0.045])
    assert np.count_nonzero(np.isclose(c.width, 0.014)) == 29 * 23
    assert np.count_nonzero(np.isclose(c.width, 0.045)) == 29 * 7


def test_face_pair_and_its_subdivision_give_the_same_samples():
    coarse = _regions(_slab_pair())
    fine_mesh = _slab_pair(subdivide=0.00025)
    assert len(fine_mesh.faces) >= 10_000
    fine = _regions(fine_mesh)
    assert len(coarse) == 9 * 5
    assert len(fine) == len(coarse)
    assert np.allclose(_sorted(fine), _sorted(coarse), atol=1e-9)


def test_region_centroid_is_sampled_for_a_strip_thinner_than_the_pitch():
    # a 1 mm wide strip (thinner than the 2 mm pitch, offset from the lattice) still gets its centroid
    c = _regions(_slab_pair(size=(0.020, 0.001)))
    assert len(c) == 9
    assert np.allclose(c.contacts[:, 0, 1], 0.0005)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow],
          phases=[Phase.explicit, Phase.generate])
@example(quat=(-1.192092896e-07, 1.5121473584271007e-178, -0.5159052053362955, 0.4303415655092875),
         shift=(-1.5440332287494821e-117, 1.8005810977333151e-124, 0.4218199235097695))  # a sort once swapped two
@given(quat=st.tuples(*[st.floats(-1, 1) for _ in range(4)]).filter(lambda q: np.linalg.norm(q) > 0.1),
       shift=st.tuples(*[st.floats(-0.5, 0.5) for _ in range(3)]))
def test_invariant_under_rigid_motion(quat, shift):
    base = trimesh.Trimesh(*trimesh.remesh.subdivide_to_size(
        trimesh.creation.box(extents=[0.031, 0.022, 0.013]).vertices,
        trimesh.creation.box(extents=[0.031, 0.022, 0.013]).faces, 0.004), process=False)
    tol = Tolerance.for_mesh(base.vertices)
    T = trimesh.transformations.quaternion_matrix(np.asarray(quat) / np.linalg.norm(quat))
    T[:3, 3] = shift
    moved = base.copy()
    moved.apply_transform(T)
    a, b = _regions(base, tol=tol), _regions(moved, tol=tol)
    assert len(a) > 0 and len(a) == len(b)
    assert np.array_equal(a.region, b.region)
    back = a.transformed(T)
    assert _same_pairs(back.contacts, b.contacts, tol.distance)


def test_chunked_search_equals_unchunked(monkeypatch, example_part):
    from grasplan.candidates.convexity import classify_convexity
    from grasplan.part.mesh import load_part

    part = load_part(example_part("gear.stl"), units="mm")
    convex = classify_convexity(part.mesh, tol=part.tol)
    ref = _regions(part.mesh, convex, part.tol)
    paper_ref = find_candidates(part.mesh, convex, tol=part.tol, method="paper")
    monkeypatch.setattr(ap, "_QUERY_ROWS", 7)
    monkeypatch.setattr(regions_reference, "_CHUNK", 101)
    monkeypatch.setattr(rg, "_EDGE_CHUNK", 50)
    small = _regions(part.mesh, convex, part.tol)
    paper_small = find_candidates(part.mesh, convex, tol=part.tol, method="paper")
    assert len(ref) > 0
    assert np.array_equal(ref.faces, small.faces) and np.array_equal(ref.contacts, small.contacts)
    assert np.array_equal(paper_ref.faces, paper_small.faces)


def test_stream_pairs_superset_of_brute_force_with_mixed_sizes():
    rng = np.random.default_rng(3)
    k = 400
    c = rng.uniform(-0.03, 0.03, (k, 3))
    n = rng.normal(size=(k, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[k // 2:] = -n[:k // 2] + rng.normal(scale=0.005, size=(k // 2, 3))     # near-antipodal partners
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    lat = rng.choice([1e-4, 1e-3, 2e-2], size=k)
    tol = Tolerance.for_scale(0.1)
    got = set()
    for a, b in ap.stream_pairs(c, n, lat, reach=0.05, beta_deg=BETA, tol=tol):
        pairs = list(zip(a.tolist(), b.tolist()))
        assert not (set(pairs) & got)                                         # each pair once
        got.update(pairs)
    A, B = np.triu_indices(k, 1)
    ok = np.einsum("ij,ij->i", n[A], n[B]) <= -np.cos(np.radians(BETA))
    d = c[B] - c[A]
    ax = n[A] - n[B]
    ax /= np.linalg.norm(ax, axis=1, keepdims=True)
    along = np.einsum("ij,ij->i", d, ax)
    lateral = np.linalg.norm(d - along[:, None] * ax, axis=1)
    ok &= (lateral <= lat[A] + lat[B]) & (np.abs(along) <= 0.05)
    want = set(zip(A[ok].tolist(), B[ok].tolist()))
    assert want and want <= got


def test_candidate_count_does_not_follow_the_tessellation():
    box = trimesh.creation.box(extents=[0.060, 0.045, 0.014])
    fine = trimesh.Trimesh(*trimesh.remesh.subdivide_to_size(box.vertices, box.faces, 0.0015), process=False)
    n0, n1 = len(_regions(box)), len(_regions(fine))
    assert abs(n1 - n0) <= 0.01 * n0


def test_region_json_round_trip_and_old_documents():
    c = _regions(trimesh.creation.box(extents=[0.03, 0.02, 0.01]))
    back = Candidates.from_json(c.to_json())
    assert np.array_equal(back.region, c.region) and (c.region >= 0).all()
    old = c.to_json()
    del old["region"]
    assert (Candidates.from_json(old).region == -1).all()
    assert np.array_equal(c.subset([2, 0]).region, c.region[[2, 0]])


def test_bad_spacing_and_method():
    mesh = _slab_pair()
    with pytest.raises(ValueError, match="spacing"):
        find_candidates(mesh, np.ones(4, bool), method="regions", spacing=0.0)
    with pytest.raises(ValueError, match="method"):
        find_candidates(mesh, np.ones(4, bool), method="faces")  # type: ignore[arg-type]


def test_part_pipeline_regions(example_part):
    from grasplan.candidates.pipeline import CandidateParams, compute_candidates
    from grasplan.part.mesh import load_part

    part = load_part(example_part("bracket.stl"), units="mm")
    try:
        params = CandidateParams(method="regions")
    except TypeError:
        pytest.skip("CandidateParams has no method field in this checkout")
    r = compute_candidates(part, params)
    assert len(r.candidates) > 0
    assert r.convex[r.candidates.faces].all()



def _key(c: Candidates):
    return set(map(tuple, np.round(c.contacts.reshape(len(c), 6) / 1e-9).astype(np.int64).tolist()))


@pytest.mark.parametrize("name", ["gear.stl", "bracket.stl"])
def test_boundary_method_equals_triangle_pair_reference(example_part, name):
    # two independent implementations of the same definition: outlines (Green + scanlines) vs every
    # overlapping triangle pair (clipping + point-in-triangle probes)
    from grasplan.candidates.antipodal_base import FaceGeometry
    from grasplan.candidates.convexity import classify_convexity
    from grasplan.part.mesh import load_part

    part = load_part(example_part(name), units="mm")
    mesh = part.mesh
    convex = classify_convexity(mesh, tol=part.tol)
    geo = FaceGeometry.of(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    kw = {"max_opening": 0.05, "beta_deg": BETA, "mu": MU, "spacing": SPACING, "tol": part.tol}
    new = Candidates(*find_regions(mesh, convex, geo, **kw))
    ref = Candidates(*find_regions_pairs(mesh, convex, geo, **kw))
    assert len(new) > 50
    assert _key(new) == _key(ref)


def _plate_with_hole(outer=0.030, hole=0.010, t=0.008, subdivide=None):
    """A square plate with a square through-hole (faces with a hole: non-convex regions)."""
    # 8 outer/inner corners per side, top and bottom rings of 8 triangles
    o, h = outer / 2, hole / 2
    ring = np.array([[-o, -o], [o, -o], [o, o], [-o, o], [-h, -h], [h, -h], [h, h], [-h, h]])
    V = np.vstack([np.column_stack([ring, np.zeros(8)]), np.column_stack([ring, np.full(8, t)])])
    top = np.array([[0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
    F = [top[:, ::-1], top + 8]
    for a, b in ((0, 1), (1, 2), (2, 3), (3, 0)):                  # outer walls, outward
        F.append(np.array([[a, b, b + 8], [a, b + 8, a + 8]]))
    for a, b in ((4, 5), (5, 6), (6, 7), (7, 4)):                  # hole walls, facing the hole
        F.append(np.array([[a, b + 8, b], [a, a + 8, b + 8]]))
    mesh = trimesh.Trimesh(V, np.vstack(F), process=False)
    if subdivide:
        mesh = trimesh.Trimesh(*trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, subdivide))
    return mesh


def test_region_with_a_hole_is_sampled_around_it_whatever_the_tessellation():
    coarse = _plate_with_hole()
    assert coarse.is_watertight and coarse.volume > 0
    fine = _plate_with_hole(subdivide=0.0007)
    assert len(fine.faces) > 20 * len(coarse.faces)
    c, f = _regions(coarse), _regions(fine)
    tol = Tolerance.for_mesh(coarse.vertices)
    thick = np.isclose(c.width, 0.008)
    # the plate's two faces: lattice points inside the ring, none in or on the hole or the rim
    mid = c.contacts[thick].mean(axis=1)[:, :2]
    inf = np.abs(mid).max(axis=1)
    assert thick.sum() > 100
    assert (inf > 0.005 + tol.distance).all() and (inf < 0.015 - tol.distance).all()
    # contact order follows the area numbering (lowest face index), which a subdivision may swap
    assert len(c) == len(f)
    assert np.allclose(_sorted(_unordered(c)), _sorted(_unordered(f)), atol=1e-9)


def _unordered(c: Candidates) -> Candidates:
    """The same pairs with contact 0 the lexicographically smaller contact (order-free comparison)."""
    key = np.round(c.contacts / 1e-9)
    swap = np.array([tuple(a) > tuple(b) for a, b in zip(key[:, 0].tolist(), key[:, 1].tolist())], dtype=bool)
    contacts = np.where(swap[:, None, None], c.contacts[:, ::-1], c.contacts)
    return Candidates(contacts, c.normals, c.width, c.faces, c.region)


def test_square_faces_invariant_under_rotation():
    # a cube's faces have isotropic second moments: the lattice frame comes from the farthest corner
    cube = trimesh.creation.box(extents=[0.021, 0.021, 0.021])
    tol = Tolerance.for_mesh(cube.vertices)
    a = _regions(cube, tol=tol)
    for angles in ((0.3, 0.0, 0.0), (0.1, 0.7, -1.2), (0.0, 0.0, np.pi / 4)):
        T = trimesh.transformations.euler_matrix(*angles)
        T[:3, 3] = [0.1, -0.2, 0.05]
        moved = cube.copy()
        moved.apply_transform(T)
        b = _regions(moved, tol=tol)
        assert len(a) == len(b) > 0
        assert _same_pairs(a.transformed(T).contacts, b.contacts, tol.distance)


def test_fast_edge_adjacency_matches_trimesh_and_sparse_neighbourhood(example_part):
    from grasplan.candidates.convexity import _edge_rows, neighbour_vertices
    from grasplan.geometry.meshdata import edge_adjacency
    from grasplan.part.mesh import load_part

    mesh = load_part(example_part("gear.stl"), units="mm").mesh
    adj, edge, far = edge_adjacency(mesh.faces)
    want = {tuple(sorted(p)) for p in np.asarray(mesh.face_adjacency).tolist()}
    assert {tuple(sorted(p)) for p in adj.tolist()} == want and len(adj) == len(want)
    F = np.asarray(mesh.faces)
    for (f, g), e, (uf, ug) in zip(adj[:50], edge[:50], far[:50]):
        assert set(e) <= set(F[f]) and set(e) <= set(F[g])
        assert uf in F[f] and uf not in e and ug in F[g] and ug not in e
    rows, ref = _edge_rows(F), neighbour_vertices(mesh, "edge")
    for k in range(0, len(F), 7):
        got = set(rows.indices[rows.indptr[k]:rows.indptr[k + 1]].tolist())
        assert got == set(ref.indices[ref.indptr[k]:ref.indptr[k + 1]].tolist())


def _block_with_shallow_lip():
    """A 30 x 20 mm block, 10 mm high on x in [0, 20] mm, with a lip rising at 15 deg from x = 20 to
    30 mm: the flat top's edge at x = 20 mm is a shallow concave crease (the BLM does not split it)."""
    prof = np.array([[0, 0], [0.030, 0], [0.030, 0.010 + 0.010 * np.tan(np.radians(15))], [0.020, 0.010], [0, 0.010]])
    n = len(prof)
    V = np.vstack([np.column_stack([prof[:, 0], np.zeros(n), prof[:, 1]]),
                   np.column_stack([prof[:, 0], np.full(n, 0.020), prof[:, 1]])])
    F = []
    for k in range(n):
        a, b = k, (k + 1) % n
        F += [[a, b, b + n], [a, b + n, a + n]]
    F += [[0, 2, 1], [0, 3, 2], [0, 4, 3]]                       # cap y = 0 (normal -y)
    F += [[n, n + 1, n + 2], [n, n + 2, n + 3], [n, n + 3, n + 4]]  # cap y = 20 mm
    mesh = trimesh.Trimesh(V, np.array(F), process=False)
    mesh.fix_normals()
    return mesh


def test_face_concave_only_at_a_shallow_crease_is_sampled_away_from_it():
    from grasplan.candidates.convexity import classify_convexity

    mesh = _block_with_shallow_lip()
    assert mesh.is_watertight and mesh.volume > 0
    tol = Tolerance.for_mesh(mesh.vertices)
    convex = classify_convexity(mesh, tol=tol)
    top = np.flatnonzero((mesh.face_normals[:, 2] > 0.999) & (mesh.triangles_center[:, 2] > 0.005))
    assert len(top) and not convex[top].all()          # the paper's rule: the top's triangle at the crease is concave
    # pitch 1.99 mm about the 20 x 20 mm overlap's centre: columns at 0.05 mm and 19.95 mm from x = 0
    c = _regions(mesh, convex, tol, spacing=0.00199)
    on_top = np.isclose(c.width, 0.010) & np.isclose(c.contacts[:, :, 2].max(axis=1), 0.010)
    assert on_top.sum() >= 9 * 9
    x = c.contacts[on_top][:, :, 0]
    assert (x <= 0.020 - CONCAVE_MARGIN + tol.distance).all()
    assert np.isclose(x.min(), 0.00005, atol=1e-9)      # 0.05 mm from a convex outline: sampled
    assert np.isclose(x.max(), 0.01796, atol=1e-9)      # 0.05 mm from the crease: dropped
    assert not convex[c.faces[on_top]].all()            # samples on the paper-concave triangle too


def test_curved_tolerance_chains_are_cut_into_patches():
    """Issue 22: on a 1000-sided cylinder neighbours differ by 0.36 deg (< planar_deg), so
    neighbour-to-neighbour grouping chains the whole side into one 'area' whose faces point every
    way. Areas are cut into patches whose faces stay within PATCH_DEG of the area normal; flat
    faces (caps, a box's sides) stay one area each, whatever their tessellation."""
    from grasplan.candidates.region_areas import PATCH_DEG
    cyl = trimesh.creation.cylinder(radius=0.01, height=0.03, sections=1000)
    tol = Tolerance.for_mesh(cyl.vertices)
    areas = convex_areas(cyl, np.ones(len(cyl.faces), bool), tol)
    fn = cyl.face_normals
    dev = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", fn, areas.normal[areas.label]), -1, 1)))
    assert dev.max() <= PATCH_DEG + 1e-9
    assert np.allclose(areas.spread[areas.label], np.radians(np.maximum.reduceat(dev[np.argsort(areas.label)],
                       np.r_[0, np.flatnonzero(np.diff(np.sort(areas.label))) + 1]))[areas.label], atol=1e-6)
    caps = np.abs(fn[:, 2]) > 0.99
    assert len(np.unique(areas.label[caps])) == 2                       # each cap one flat area
    side = np.unique(areas.label[~caps])
    assert 100 < len(side) < 1000                                       # patches, not one chain, not single faces
    box = trimesh.Trimesh(*trimesh.remesh.subdivide_to_size(*(lambda b: (b.vertices, b.faces))(
        trimesh.creation.box(extents=[0.06, 0.045, 0.014])), 0.002))
    ab = convex_areas(box, np.ones(len(box.faces), bool), Tolerance.for_mesh(box.vertices))
    assert len(ab.area) == 6 and np.all(ab.spread < 1e-9)
