"""The closed-form Ferrari-Canny epsilon (grasplan.grasps.wrench.ferrari_canny_pair) against Qhull; merged patch
elements (grasplan.grasps.patches.patch_elements) against raw triangles."""
import numpy as np
import pytest

from grasplan.grasps import patches, wrench

#: Qhull's joggle (QJ) moves facet offsets by ~1e-11 absolute on these wrench sets
ABS_TOL = 1e-10
REL_TOL = 1e-9


def _random_grasps(rng, m, antipodal_share=0.5):
    C = rng.normal(size=(m, 2, 3)) * 0.02
    N = rng.normal(size=(m, 2, 3))
    N /= np.linalg.norm(N, axis=2, keepdims=True)
    d = C[:, 1] - C[:, 0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    anti = rng.random(m) < antipodal_share
    N[anti, 0] = -d[anti]  # outward normals of a parallel-jaw grasp: contact 0 faces away from contact 1
    N[anti, 1] = d[anti]
    near = rng.random(m) < 0.25  # nearly antipodal: small tilts inside the friction cone
    N[near] += rng.normal(size=(near.sum(), 2, 3)) * 0.05
    N /= np.linalg.norm(N, axis=2, keepdims=True)
    tors = rng.uniform(3e-4, 3e-3, size=(m, 2))
    return C, N, tors


def _agree(fast, ref):
    return np.abs(fast - ref) <= np.maximum(REL_TOL * np.abs(ref), ABS_TOL)


def _support_at_qhull_facet(W):
    """h(n) = max_i w_i . n at the unit normal n of Qhull's nearest facet, on the unjoggled wrenches:
    an upper bound of the exact epsilon that does not depend on the joggle."""
    from scipy.spatial import ConvexHull

    out = []
    for w in W:
        eq = ConvexHull(w, qhull_options=wrench.QHULL_OPTIONS).equations
        out.append(float((w @ eq[np.argmin(-eq[:, -1]), :6]).max()))
    return np.array(out)


def _check(fast, exact, W):
    """Where the closed form decides, it equals Qhull within REL_TOL / ABS_TOL; where Qhull's joggle
    (up to ~3e-10 x the largest coordinate) makes them differ more, the closed form is at most the
    support value at Qhull's nearest facet normal on the unjoggled set (an upper bound of the exact
    epsilon), so it is the more exact one."""
    ref = wrench.ferrari_canny(W)
    scale = np.abs(W).max(axis=(1, 2))  # the joggle is relative to the largest coordinate
    loose = exact & ~_agree(fast, ref)
    assert np.all(np.abs(fast[loose] - ref[loose]) <= 3e-10 * scale[loose])
    idx = np.flatnonzero(loose)
    if len(idx):  # the closed form is a supporting facet's offset (>= exact) and never above h(n_qhull)
        assert np.all(fast[idx] <= _support_at_qhull_facet(W[idx]) + 1e-13 * scale[idx])
    return ref


@pytest.mark.parametrize("mu", [0.1, 0.3, 0.6, 1.2])
def test_pair_matches_qhull_on_random_grasps(mu):
    rng = np.random.default_rng(int(mu * 100))
    C, N, tors = _random_grasps(rng, 1500)
    com = rng.normal(size=3) * 0.005
    rho = 0.05
    eps, exact = wrench.ferrari_canny_pair(C, N, com, rho, mu, tors)
    assert exact.mean() > 0.95  # the closed form decides almost all of them itself
    ref = _check(eps, exact, wrench.contact_wrenches(C, N, com, rho, mu, tors))
    # both zero and positive values occur, so the comparison covers inside and outside cases
    assert (ref[exact] > 0).sum() > 100 and (ref[exact] == 0).sum() > 100


def test_pair_matches_qhull_on_exact_parallel_jaw_grasps():
    """Exactly antipodal contacts through and beside the centre of mass (symmetric wrench sets)."""
    rng = np.random.default_rng(7)
    m = 800
    axis = rng.normal(size=(m, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    mid = rng.normal(size=(m, 3)) * 0.01
    mid[:100] = 0.0  # through the centre of mass
    half = rng.uniform(0.002, 0.03, size=m)[:, None]
    C = np.stack([mid - half * axis, mid + half * axis], axis=1)
    N = np.stack([-axis, axis], axis=1)
    tors = np.repeat(rng.uniform(3e-4, 3e-3, size=(m, 1)), 2, axis=1)
    eps, exact = wrench.ferrari_canny_pair(C, N, np.zeros(3), 0.04, 0.5, tors)
    ref = _check(eps, exact, wrench.contact_wrenches(C, N, np.zeros(3), 0.04, 0.5, tors))
    assert (ref > 0).all()  # antipodal soft-finger grasps with friction resist every wrench


def test_epsilon_dedup_equals_qhull_including_degenerate_sets():
    """epsilon_dedup (closed form + Qhull fallback) equals Qhull on every row, degenerate ones too."""
    rng = np.random.default_rng(3)
    C, N, _ = _random_grasps(rng, 300)
    C[:10, 1] = C[:10, 0]  # coincident contacts: the torques are dependent (flat wrench set)
    N[:10, 1] = -N[:10, 0]
    area = rng.uniform(0, 4e-5, size=(300, 2))
    com, rho, mu = np.zeros(3), 0.05, 0.4
    got = wrench.epsilon_dedup(C, N, area, com, rho, mu)
    tors = (2.0 / 3.0) * mu * wrench.quantised_patch_radius(area)
    _, exact = wrench.ferrari_canny_pair(C, N, com, rho, mu, tors)
    _check(got, np.ones(len(got), dtype=bool), wrench.contact_wrenches(C, N, com, rho, mu, tors))
    assert not exact[:10].any()  # the flat sets went to Qhull


def test_pair_without_friction_is_zero_and_defers():
    rng = np.random.default_rng(1)
    C, N, tors = _random_grasps(rng, 20)
    eps, exact = wrench.ferrari_canny_pair(C, N, np.zeros(3), 0.05, 0.0, tors)
    assert np.all(eps == 0) and not exact.any()
    assert np.all(wrench.ferrari_canny(wrench.contact_wrenches(C, N, np.zeros(3), 0.05, 0.0, tors)) == 0)


def test_pair_invariant_under_rigid_motion_of_the_grasp():
    """Rotating contacts, normals and centre of mass together leaves epsilon unchanged (up to the
    cone edges' phase, which the tangent basis fixes per normal: compare with Qhull both times)."""
    rng = np.random.default_rng(11)
    C, N, tors = _random_grasps(rng, 200, antipodal_share=1.0)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    com = np.array([0.001, -0.002, 0.0005])
    e0, x0 = wrench.ferrari_canny_pair(C, N, com, 0.05, 0.5, tors)
    e1, x1 = wrench.ferrari_canny_pair(C @ q.T + 0.1, N @ q.T, com @ q.T + 0.1, 0.05, 0.5, tors)
    _check(e1, x1, wrench.contact_wrenches(C @ q.T + 0.1, N @ q.T, com @ q.T + 0.1, 0.05, 0.5, tors))
    # the 8-edge cone's phase changes with the frame: epsilon moves by well under 10 %
    both = x0 & x1 & (e0 > 0)
    assert both.sum() > 150
    assert np.all(np.abs(e1[both] - e0[both]) <= 0.1 * e0[both])


def test_pair_of_a_grasp_does_not_depend_on_the_others_computed_with_it():
    """Each grasp's epsilon and decision are its own: the same bits alone, in a batch of 1,500 and in
    a batch whose other grasps' contacts lie a thousand times farther out."""
    rng = np.random.default_rng(5)
    C, N, tors = _random_grasps(rng, 1500)
    com = np.array([0.001, 0.0, -0.001])
    eps, exact = wrench.ferrari_canny_pair(C, N, com, 0.05, 0.4, tors)
    for i in (0, 17, 1024, 1499):
        e1, x1 = wrench.ferrari_canny_pair(C[i:i + 1], N[i:i + 1], com, 0.05, 0.4, tors[i:i + 1])
        assert e1[0] == eps[i] and x1[0] == exact[i]
    C2 = C.copy()
    C2[1:] = com + (C[1:] - com) * 1e3
    e2, x2 = wrench.ferrari_canny_pair(C2, N, com, 0.05, 0.4, tors)
    assert e2[0] == eps[0] and x2[0] == exact[0]


def test_near_pairs_equal_the_direct_distance_test():
    """The compiled near test of the dense patch search (:func:`grasplan.grasps.patch_search.near_pairs`)
    against the test written with the centroid's offset from the contact, on random elements and
    contacts with tolerances drawn around the distances: the same pairs, in (face, contact) order,
    with n . axis; the chunked search yields each pair once."""
    from grasplan.grasps.patch_search import near_faces_dense, near_pairs

    rng = np.random.default_rng(3)
    F, U = 400, 90
    cent = rng.normal(size=(F, 3)) * 0.02
    fn = rng.normal(size=(F, 3))
    fn /= np.linalg.norm(fn, axis=1, keepdims=True)
    cu = rng.normal(size=(U, 3)) * 0.02
    axu = rng.normal(size=(U, 3))
    axu /= np.linalg.norm(axu, axis=1, keepdims=True)
    slab = rng.uniform(0.0, 0.01, F)
    lat = rng.uniform(0.0, 0.03, F) ** 2
    cent_sq = np.einsum("fi,fi->f", cent, cent)
    for j in (0, 1):
        d = cent[:, None] - cu[None]
        xs = np.einsum("fbi,bi->fb", d, axu)
        nx = fn @ axu.T
        ref = (np.abs(xs) <= slab[:, None]) & (np.einsum("fbi,fbi->fb", d, d) - xs * xs <= lat[:, None]) & \
            ((nx < 0) if j == 0 else (nx > 0))
        # pairs within 1e-12 of a bound may fall either way in rounding: none are drawn here
        margin = np.minimum(np.abs(np.abs(xs) - slab[:, None]),
                            np.abs(np.einsum("fbi,fbi->fb", d, d) - xs * xs - lat[:, None]))
        assert margin.min() > 1e-12
        f, b, n = near_pairs(cent, fn, cent_sq, slab, lat, cu, axu, j)
        rf, rb = np.nonzero(ref)
        assert 100 < len(rf) < F * U // 2
        assert np.array_equal(f, rf) and np.array_equal(b, rb)
        assert np.allclose(n, nx[rf, rb], rtol=0, atol=1e-15)
        chunks = list(near_faces_dense(cent, fn, cent_sq, slab, lat, cu, axu, j, max_pairs=F * 7))
        assert len(chunks) > 5
        got = sorted(zip(np.concatenate([c[0] for c in chunks]).tolist(), np.concatenate([c[1] for c in chunks]).tolist()))
        assert got == sorted(zip(rf.tolist(), rb.tolist()))


def test_within_disc_equals_the_vertex_distances_to_the_closing_axis():
    """The compiled disc test of the patches (:func:`grasplan.grasps.quality_kernels.within_disc`)
    against each valid vertex's distance to the closing axis written with a cross product: padded
    polygons (the padding lies far out and must not count), polygons with no valid vertex (never
    within), radii drawn on both sides of the disc."""
    from grasplan.grasps.quality_kernels import within_disc

    rng = np.random.default_rng(8)
    K, V, M = 500, 9, 40
    R = np.stack([np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(M)])
    o = rng.normal(size=(M, 3)) * 0.01
    ref = rng.integers(0, M, K)
    npx = rng.integers(0, V + 1, K)
    radius = rng.uniform(0.0, 0.02, (K, V))
    u = rng.normal(size=(K, V, 3))
    u -= np.einsum("kvi,ki->kv", u, R[ref][:, :, 0])[..., None] * R[ref][:, None, :, 0]
    u /= np.linalg.norm(u, axis=2, keepdims=True)
    poly = o[ref][:, None] + rng.normal(size=(K, V, 1)) * R[ref][:, None, :, 0] + radius[..., None] * u
    poly[np.arange(V)[None, :] >= npx[:, None]] = 1.0  # padding, 1 m out
    disc = 0.012
    dist = np.linalg.norm(np.cross(poly - o[ref][:, None], R[ref][:, None, :, 0]), axis=2)
    valid = np.arange(V)[None, :] < npx[:, None]
    ref_in = (npx > 0) & np.all(~valid | (dist < disc), axis=1)
    assert np.all(np.abs(dist[valid] - disc) > 1e-12)  # none drawn on the rim, where rounding decides
    got = within_disc(poly, npx.astype(np.int64), o, R, ref.astype(np.int64), disc * disc)
    assert 50 < ref_in.sum() < K - 50
    assert np.array_equal(got, ref_in)


# ------------------------------------------------------------------------------------------------
# contact patches: coplanar areas merged into boundary loops
# ------------------------------------------------------------------------------------------------
def _loop_areas(pts, first, count, normal, weight):
    P = patches.gather_polygons(pts, first, count, np.arange(len(count)))
    V = P.shape[1]
    nxt = (np.arange(V)[None] + 1) % count[:, None]
    Pn = np.take_along_axis(P, nxt[..., None].repeat(3, 2), 1)
    valid = np.arange(V)[None] < count[:, None]
    cr = np.where(valid[..., None], np.cross(P, Pn), 0.0).sum(axis=1)
    return 0.5 * np.abs(np.einsum("ei,ei->e", cr, normal)) * weight


def _fine_box(size):
    import trimesh

    b = trimesh.creation.box((0.06, 0.045, 0.014))
    v, f = trimesh.remesh.subdivide_to_size(b.vertices, b.faces, size)
    return trimesh.Trimesh(v, f)


def test_elements_of_a_subdivided_box_are_its_six_faces():
    mesh = _fine_box(0.002)
    pts, first, count, normal, weight = patches.patch_elements(mesh)
    assert len(count) == 6 and np.all(count == 4) and np.all(weight == 1)
    assert _loop_areas(pts, first, count, normal, weight).sum() == pytest.approx(mesh.area, rel=1e-12)


def test_elements_keep_holes_with_negative_weight():
    import trimesh

    ring = trimesh.creation.annulus(r_min=0.01, r_max=0.02, height=0.005, sections=48)
    pts, first, count, normal, weight = patches.patch_elements(ring)
    assert (weight < 0).sum() == 2  # the bore of each flat end
    assert _loop_areas(pts, first, count, normal, weight).sum() == pytest.approx(ring.area, rel=1e-12)
    assert len(count) < len(ring.faces)


def test_merged_patches_equal_triangle_patches(monkeypatch):
    """The patch of the merged areas equals the patch of the raw triangles (fine box, plate with a bore)."""
    import trimesh

    from grasplan.gripper.load import load_gripper

    g = load_gripper("schunk_egp_c_40")
    rng = np.random.default_rng(5)
    for mesh, half in ((_fine_box(0.0015), 0.0225), (trimesh.creation.annulus(0.004, 0.02, 0.006, sections=64), 0.003)):
        m = 40
        T = np.tile(np.eye(4), (m, 1, 1))
        ang = rng.uniform(0, 2 * np.pi, m)
        # closing along part y (box) / z (plate faces), rolls about the closing axis, offsets on the face
        ax = np.array([0.0, 1.0, 0.0]) if half > 0.01 else np.array([0.0, 0.0, 1.0])
        e1 = np.array([1.0, 0.0, 0.0])
        e2 = np.cross(ax, e1)
        T[:, :3, 0] = ax
        T[:, :3, 1] = np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2
        T[:, :3, 2] = np.cross(T[:, :3, 0], T[:, :3, 1])
        off = rng.uniform(-0.012, 0.012, size=(m, 2))
        T[:, :3, 3] = off[:, :1] * e1 + off[:, 1:] * e2
        C = T[:, None, :3, 3] + np.array([-half, half])[None, :, None] * ax
        merged = patches.contact_patches(mesh, g, T, C)
        monkeypatch.setattr(patches, "MERGE_MIN_FACES", 10 ** 9)
        raw = patches.contact_patches(mesh, g, T, C)
        monkeypatch.undo()
        assert np.all(raw[0] > 0)  # the test touches the faces
        np.testing.assert_allclose(merged[0], raw[0], rtol=1e-9, atol=1e-15)
        np.testing.assert_array_equal(merged[1], raw[1])
        np.testing.assert_allclose(merged[2], raw[2], rtol=1e-9, atol=1e-12)
