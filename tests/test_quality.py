"""Contact patches, gravity margin, Ferrari-Canny epsilon and the scoring file (issue 11)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from grasplan.errors import ConfigError, InputError
from grasplan.gripper.load import load_gripper
from grasplan.part.mass import mass_properties
from grasplan.grasps.patches import contact_patches, pad_rectangle
from grasplan.geometry.polygons import polygon_moments
from grasplan.grasps.quality_kernels import accumulate_pairs, slab_polygons
from grasplan.grasps.quality import Quality, grasp_quality, score_quality_terms
from grasplan.results.quality_json import CONTACT_TYPES
from grasplan.config.scoring import load_score_weights, load_scoring
from grasplan.grasps.wrench import G, LOAD

MU = 0.3
BOX = (0.12, 0.03, 0.03)


@pytest.fixture(scope="module")
def gripper():
    return load_gripper("schunk_egp_c_40")


@pytest.fixture(scope="module")
def box():
    return trimesh.creation.box(BOX)


def top_grasp(x: float, y: float = 0.0, half_width: float = 0.015):
    """A grasp from above (TCP z = -part z) closing along part y, centred at (x, y, 0)."""
    T = np.eye(4)
    T[:3, 0] = [0, 1, 0]
    T[:3, 2] = [0, 0, -1]
    T[:3, 1] = np.cross(T[:3, 2], T[:3, 0])
    T[:3, 3] = [x, y, 0]
    c = np.array([[x, y - half_width, 0], [x, y + half_width, 0]])
    n = np.array([[0, -1.0, 0], [0, 1.0, 0]])
    return T, c, n


def grasps(xs):
    T, C, N = zip(*(top_grasp(x) for x in xs))
    return np.array(T), np.array(C), np.array(N), np.full(len(xs), 0.03)


def on_table(z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = [0.45, 0.0, z]
    return T


# -- clipping and moments against independent estimates ---------------------------------------------
def test_clip_triangle_area_matches_monte_carlo():
    rng = np.random.default_rng(1)
    tri = rng.uniform(-1, 1, size=(40, 3, 2))
    lo, hi = -0.3, 0.5
    # the compiled pad clip: triangle k in the plane x = 0 of grasp k's TCP frame, the pad [lo, hi]^2
    P = np.ascontiguousarray(np.concatenate([np.zeros((40, 3, 1)), tri], axis=2))
    mom = np.zeros((40, 2, 2, 6))
    R = np.repeat(np.eye(3)[None], 40, axis=0)
    accumulate_pairs(P, np.full(40, 3), np.ones(40), np.zeros(40, dtype=bool), np.arange(40), np.arange(40),
                     np.zeros((40, 3)), R, np.array([lo, hi, lo, hi]), mom, 1)
    m = mom[:, 1, 0]
    assert not mom[:, 0].any() and not mom[:, 1, 1].any()  # jaw 1 only; no face flagged flat
    # Monte Carlo: points in the square, inside each triangle by barycentric signs
    pts = rng.uniform(lo, hi, size=(200_000, 2))
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]

    def side(p, q, r):
        return (q[:, None, 0] - p[:, None, 0]) * (r[None, :, 1] - p[:, None, 1]) - \
               (q[:, None, 1] - p[:, None, 1]) * (r[None, :, 0] - p[:, None, 0])

    s1, s2, s3 = side(a, b, pts), side(b, c, pts), side(c, a, pts)
    inside = ((s1 >= 0) & (s2 >= 0) & (s3 >= 0)) | ((s1 <= 0) & (s2 <= 0) & (s3 <= 0))
    mc_area = inside.mean(axis=1) * (hi - lo) ** 2
    np.testing.assert_allclose(m[:, 0], mc_area, atol=0.01)
    mc_mean_y = np.where(inside.sum(1) > 0, (inside * pts[None, :, 0]).sum(1) / np.maximum(inside.sum(1), 1), 0)
    big = mc_area > 0.05
    np.testing.assert_allclose((m[big, 1] / m[big, 0]), mc_mean_y[big], atol=0.01)


def test_slab_clip_keeps_the_part_of_a_polygon_within_the_depth():
    """A unit square in the plane y = 0 crossing the contact plane x = 0: clipped to |x| <= 0.1
    it is the 0.2 x 1 strip; a square wholly beyond the slab is dropped."""
    sq = np.array([[-0.5, 0, 0], [0.5, 0, 0], [0.5, 0, 1], [-0.5, 0, 1]], dtype=np.float64)
    far = sq + [2.0, 0, 0]
    pts = np.concatenate([sq, far])
    keep, poly, n = slab_polygons(pts, np.array([0, 4]), np.array([4, 4]), np.array([0, 1]), np.array([0, 0]),
                                  np.zeros((1, 3)), np.array([[1.0, 0, 0]]), 0.1)
    assert keep.tolist() == [True, False] and n.tolist() == [4]
    got = poly[0, :4]
    assert sorted(map(tuple, np.round(got[:, [0, 2]], 12))) == [(-0.1, 0.0), (-0.1, 1.0), (0.1, 0.0), (0.1, 1.0)]
    A = polygon_moments(got[None, :, 0], got[None, :, 2], n)[0, 0]
    assert A == pytest.approx(0.2)


def test_polygon_moments_of_a_rectangle():
    Y = np.array([[0.0, 2.0, 2.0, 0.0]])
    Z = np.array([[0.0, 0.0, 1.0, 1.0]])
    A, Sy, Sz, Syy, Szz, Syz = polygon_moments(Y, Z, np.array([4]))[0]
    assert (A, Sy, Sz) == pytest.approx((2.0, 2.0, 1.0))
    assert (Syy, Szz, Syz) == pytest.approx((2.0 * 4 / 3, 2.0 / 3, 1.0))
    # clockwise order gives the same unsigned moments
    assert polygon_moments(Y[:, ::-1], Z[:, ::-1], np.array([4]))[0] == pytest.approx([A, Sy, Sz, Syy, Szz, Syz])


# -- contact patches ---------------------------------------------------------------------------------
def test_box_face_patch_is_pad_times_overlap(gripper, box):
    (y0, y1), (z0, z1) = pad_rectangle(gripper)
    T, C, _N, _w = grasps([0.0, 0.052])
    area, kind, widths = contact_patches(box, gripper, T, C)
    # centre: the pad (y0..y1 along part x) overlaps the face over its height; TCP z = -part z
    overlap_z = min(z1, 0.015) - max(z0, -0.015)
    expected = np.array([(y1 - y0) * overlap_z, (min(0.06, 0.052 + y1) - (0.052 + y0)) * overlap_z])
    np.testing.assert_allclose(area, np.repeat(expected[:, None], 2, axis=1), rtol=1e-9)
    assert (np.array(CONTACT_TYPES)[kind] == "surface").all()
    np.testing.assert_allclose(widths[0, 0], sorted([y1 - y0, overlap_z]), rtol=1e-9)


def test_patch_does_not_depend_on_chunking(gripper):
    part = trimesh.creation.box(BOX).subdivide().subdivide()
    T, C, _N, _w = grasps(np.linspace(-0.05, 0.05, 9))
    a1, k1, _w1 = contact_patches(part, gripper, T, C)
    a2, k2, _w2 = contact_patches(part, gripper, T, C, max_pairs=50)
    np.testing.assert_allclose(a1, a2, rtol=1e-12)
    assert (k1 == k2).all()
    np.testing.assert_allclose(a1, contact_patches(trimesh.creation.box(BOX), gripper, T, C)[0], rtol=1e-9)


def test_cylinder_side_is_a_line_and_sphere_a_point(gripper):
    cyl = trimesh.creation.cylinder(radius=0.012, height=0.1, sections=256)  # axis along z
    T = np.eye(4)
    T[:3, 0] = [1, 0, 0]
    T[:3, 2] = [0, 1, 0]  # approach along y, pad long side along the cylinder axis (TCP z x x = part z... )
    T[:3, 1] = np.cross(T[:3, 2], T[:3, 0])
    C = np.array([[[-0.012, 0, 0], [0.012, 0, 0]]])
    area, kind, _ = contact_patches(cyl, gripper, T[None], C)
    assert (np.array(CONTACT_TYPES)[kind[0]] == "line").all()
    sph = trimesh.creation.icosphere(subdivisions=5, radius=0.012)
    area_s, kind_s, _ = contact_patches(sph, gripper, T[None], C)
    assert (np.array(CONTACT_TYPES)[kind_s[0]] == "point").all()
    assert (area_s < area).all()


# -- gravity margin and epsilon ------------------------------------------------------------------------
def test_gravity_margin_centre_matches_hand_calculation(gripper, box):
    mp = mass_properties(box, mass=0.2)
    T, C, N, w = grasps([0.0])
    q = grasp_quality(box, mp, gripper, T, C, N, w, T_world_part=on_table(0.015), mu=MU)
    # through the centre of mass from above: the worst load is the lift's, m (g + lift_accel) straight
    # down (the shake's, m sqrt(g^2 + 5^2), is smaller), half per contact, no torque; each contact is
    # pressed with half the gripping force (grip_force = sum of the jaws)
    lift = 0.5 * 0.10 * (math.pi / 0.5) ** 2            # 10 cm in 0.5 s, cosine profile: 1.97 m/s^2
    assert LOAD.lift_accel == pytest.approx(lift) and math.hypot(G, 5.0) < G + lift
    assert q.gravity_margin[0] == pytest.approx(MU * (gripper.grip_force / 2) / (0.5 * 0.2 * (G + lift)), rel=1e-9)
    q2 = grasp_quality(box, mp, gripper, T, C, N, w, T_world_part=on_table(0.015), mu=MU, grip_force=10.0)
    assert q2.gravity_margin[0] == pytest.approx(q.gravity_margin[0] * 10.0 / gripper.grip_force, rel=1e-9)


def test_gravity_margin_falls_away_from_centre_of_mass(gripper, box):
    mp = mass_properties(box)
    T, C, N, w = grasps(np.linspace(0.0, 0.05, 6))
    q = grasp_quality(box, mp, gripper, T, C, N, w, T_world_part=on_table(0.015), mu=MU)
    assert np.all(np.diff(q.gravity_margin) < 0)


def test_epsilon_centre_beats_off_centre(gripper, box):
    mp = mass_properties(box)
    T, C, N, w = grasps([0.0, 0.02, 0.045])
    q = grasp_quality(box, mp, gripper, T, C, N, w, T_world_part=on_table(0.015), mu=MU)
    assert q.epsilon[0] > q.epsilon[1] > q.epsilon[2] > 0
    # no friction: two opposite point forces cannot resist tangential loads
    q0 = grasp_quality(box, mp, gripper, T, C, N, w, T_world_part=on_table(0.015), mu=0.0)
    assert (q0.epsilon == 0).all()


def test_quality_json_and_bad_input(gripper, box):
    mp = mass_properties(box)
    T, C, N, w = grasps([0.0, 0.01])
    q = grasp_quality(box, mp, gripper, T, C, N, w, T_world_part=on_table(0.015), mu=MU)
    j = q.to_json(1, score=0.5)
    assert set(j) == {"contact", "gravity_margin", "epsilon", "score"}
    assert [c["type"] for c in j["contact"]] == ["surface", "surface"]
    assert j["contact"][0]["area_m2"] == pytest.approx(q.contact_area[1, 0])
    with pytest.raises(InputError, match="contacts and normals"):
        grasp_quality(box, mp, gripper, T, C[:1], N, w, T_world_part=on_table(0.015), mu=MU)
    with pytest.raises(InputError, match="mu"):
        grasp_quality(box, mp, gripper, T, C, N, w, T_world_part=on_table(0.015), mu=-1.0)
    with pytest.raises(InputError, match="grip_force"):
        grasp_quality(box, mp, gripper, T, C, N, w, T_world_part=on_table(0.015), mu=MU, grip_force=0.0)


# -- scoring file ------------------------------------------------------------------------------------
def test_packaged_weights_include_reachability_and_physical_terms():
    names = dict(load_score_weights())
    assert {"center", "top", "width", "gravity_margin", "epsilon"} <= set(names)
    assert all(v >= 0 for v in names.values()) and sum(names.values()) > 0


def test_score_terms_are_normalised_and_monotonic(gripper, box):
    mp = mass_properties(box)
    T, C, N, w = grasps(np.linspace(0.0, 0.05, 6))
    q = grasp_quality(box, mp, gripper, T, C, N, w, T_world_part=on_table(0.015), mu=MU)
    terms = score_quality_terms(q)
    for v in terms.values():
        assert v.shape == (6,) and np.all((v >= 0) & (v <= 1))
    assert np.all(np.diff(terms["gravity_margin"]) <= 0) and terms["gravity_margin"][0] > terms["gravity_margin"][-1]
    cfg = load_scoring()
    assert terms["gravity_margin"][0] == pytest.approx(
        min(1.0, 0.5 + 0.5 * math.log(q.gravity_margin[0]) / math.log(cfg.gravity_margin_ref)))


def test_gravity_margin_term_ranks_grasps_that_slip():
    """Issue 11: a part too heavy for the gripper has no grasp with margin >= 1; the term still
    orders those (1/2 at the threshold, 0 at the reference's inverse), so the score leads with the
    grasps closest to holding instead of leaving them to the geometric terms."""
    cfg = load_scoring()
    ref = cfg.gravity_margin_ref
    m = np.array([1.0 / (2 * ref), 1.0 / ref, ref ** -0.5, ref ** -0.1, 1.0, math.sqrt(ref), ref, 2 * ref])
    t = score_quality_terms(Quality(contact_area=np.ones((8, 2)), contact_type=np.zeros((8, 2), dtype=np.int8),
                                    contact_width=np.ones((8, 2, 2)), gravity_margin=m, epsilon=np.zeros(8),
                                    grip_force=140.0, mu=0.3), cfg)["gravity_margin"]
    np.testing.assert_allclose(t, [0.0, 0.0, 0.25, 0.45, 0.5, 0.75, 1.0, 1.0], atol=1e-12)
    assert np.all(np.diff(t[1:7]) > 0)


@pytest.mark.parametrize("text, match", [
    ("weights: {center: -1}", "must be >= 0"),
    ("weights: {}", "weights"),
    ("weights: {center: 1}\nnormalisation: {gravity_margin_ref: 0.5}", "must be > 1"),
    ("weights: {center: 1}\nextra: 2", "unknown fields"),
    ("weights: [1, 2", "not valid YAML"),
])
def test_bad_scoring_file_is_config_error(tmp_path, text, match):
    p = tmp_path / "scoring.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=match):
        load_scoring(p)


def test_holding_warning_names_the_grip_force_that_would_hold(gripper, box):
    """Friction and torsion are proportional to the gripping force and the pad-pressure moment grows
    with it too, so the force the warning names (grip_force / best margin) brings the best grasp to
    at least 1 (recomputed here, not assumed); a part that is held gets no warning."""
    from grasplan.grasps.quality import holding_warning

    heavy = mass_properties(box, density=60000.0)  # far too heavy for 140 N
    T, C, N, w = grasps(np.linspace(0.0, 0.05, 6))
    q = grasp_quality(box, heavy, gripper, T, C, N, w, T_world_part=on_table(0.015), mu=MU)
    best = float(q.gravity_margin.max())
    assert best < 1
    msg = holding_warning(q, heavy, part="box.stl")
    need = q.grip_force / best
    assert f"best gravity_margin is {best:.2f}" in msg and f"about {need:.0f} N" in msg and "--density" in msg
    q2 = grasp_quality(box, heavy, gripper, T, C, N, w, T_world_part=on_table(0.015), mu=MU, grip_force=need)
    assert float(q2.gravity_margin.max()) >= 1.0 - 1e-9
    light = mass_properties(box)
    q3 = grasp_quality(box, light, gripper, T, C, N, w, T_world_part=on_table(0.015), mu=MU)
    assert q3.gravity_margin.max() >= 1 and holding_warning(q3, light) == ""
    assert holding_warning(None, heavy) == "" and holding_warning(q, None) == ""


# -- issue 22: the simulation's load, the pad-pressure moment --------------------------------------
def _gravity_only():
    from grasplan.grasps.wrench import LoadModel
    return LoadModel(lift_height=0.0, shake_accel=0.0)


def _mp(mass, com):
    from grasplan.part.mass import MassProperties
    return MassProperties(mass=mass, com=np.asarray(com, float), inertia=np.eye(3) * 1e-4, volume=1e-4,
                          density=mass / 1e-4, watertight_used=True)


@pytest.mark.parametrize("press_w", [0.0, 0.006, 0.012, 0.1])
def test_pad_pressure_moment_matches_hand_calculation(press_w):
    """A grasp whose centre of mass lies d along the closing axis: gravity's moment m g d is carried
    by both pads' pressure up to F (w0 + w1) / 6, the rest by the tangential couple over the width."""
    from grasplan.grasps.wrench import PRESSURE_ARM, gravity_margin
    m, d, width, F = 0.5, 0.01, 0.02, 70.0
    T = np.eye(4)[None]                        # TCP = part frame = world: closing axis x, gravity -z
    pw = np.full((1, 2), press_w)
    gm = gravity_margin(_mp(m, [d, 0, 0]), np.eye(4), T, np.array([width]), np.full((1, 2), 1e-4), mu=MU,
                        normal_force=F, patch_width=pw, load=_gravity_only())[0]
    # the margin is the factor s on the load: s m g / 2 per contact plus the couple of what the
    # pressure (which does not grow with the load) leaves of s m g d
    cap = F * PRESSURE_ARM * 2 * press_w
    s = MU * F / (0.5 * m * G)
    if s * m * G * d > cap:
        s = (MU * F + cap / width) / (0.5 * m * G + m * G * d / width)
    assert gm == pytest.approx(s, rel=1e-9)
    no_press = gravity_margin(_mp(m, [d, 0, 0]), np.eye(4), T, np.array([width]), np.full((1, 2), 1e-4), mu=MU,
                              normal_force=F, load=_gravity_only())[0]
    assert gm >= no_press and (gm > no_press) == (press_w > 0)


def test_margin_checks_the_simulated_lift_and_shake():
    """The loads of the margin are the simulation's profile: every acceleration the simulation applies
    lies in the convex hull of LOAD.accelerations() (the margin is convex in the load), and its peaks
    reach them (within the control-period sampling)."""
    from grasplan.sim.simulate import _profile
    from grasplan.grasps.wrench import LOAD
    acc = _profile()[0]
    A = LOAD.accelerations()
    vert = np.abs(acc[:, :2]).max(axis=1) == 0
    assert np.all(np.abs(acc[vert, 2]) <= LOAD.lift_accel + 1e-9)
    assert np.all(acc[~vert, 2] == 0) and np.all(np.hypot(acc[~vert, 0], acc[~vert, 1]) <= LOAD.shake_accel + 1e-9)
    assert np.abs(acc[:, 2]).max() >= 0.99 * LOAD.lift_accel and np.abs(acc[:, 0]).max() >= 0.99 * LOAD.shake_accel
    for v in ([1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]):   # the simulated shake axes are checked loads
        assert np.any(np.all(np.isclose(A, LOAD.shake_accel * np.array(v, float)), axis=1))
    assert LOAD.peak_g() == pytest.approx((G + LOAD.lift_accel) / G)


def test_margin_twist_and_closing_axis_load_match_hand_calculation():
    """Issue 22, second round. (a) Twist: the centre of mass c off the contact axis, gravity across
    it: each pad carries m g / 2 and the two patches' torsion ellipses the rest, so the load factor
    is 2 mu F L / (m g sqrt(c^2 + L^2)) with L = (2/3) a; with unequal patches the two ellipses'
    torsions add. (b) Closing axis tilted from the horizontal: the
    lower jaw is pressed harder, the upper one with F - s f_x / 2, which slips first."""
    from grasplan.grasps.wrench import gravity_margin, torsion_length
    m, F, width = 0.4, 70.0, 0.03
    c = 0.02
    T = np.eye(4)[None]  # closing axis x horizontal, gravity -z; centre of mass at y = c
    area = np.full((1, 2), 1e-4)
    L = float(torsion_length(area)[0, 0])
    gm = gravity_margin(_mp(m, [0, c, 0]), np.eye(4), T, np.array([width]), area, mu=MU, normal_force=F,
                        load=_gravity_only())[0]
    assert gm == pytest.approx(2 * MU * F * L / (m * G * math.hypot(c, L)), rel=1e-8)
    # unequal patches: s m g c = L0 sqrt((mu F)^2 - (s m g / 2)^2) + L1 sqrt(...) = (L0 + L1) sqrt(...)
    area2 = np.array([[1e-4, 4e-4]])
    L0, L1 = torsion_length(area2)[0]
    gm2 = gravity_margin(_mp(m, [0, c, 0]), np.eye(4), T, np.array([width]), area2, mu=MU, normal_force=F,
                         load=_gravity_only())[0]
    assert gm2 == pytest.approx((L0 + L1) * MU * F / (m * G * math.hypot(c, (L0 + L1) / 2)), rel=1e-8)
    # (b) closing axis tilted 60 deg: f_x = -m g sin, f_t = m g cos; the jaw on the +x side is the upper one
    th = math.radians(60.0)
    T3 = np.eye(4)
    T3[:3, 0] = [math.cos(th), 0.0, math.sin(th)]
    T3[:3, 2] = [-math.sin(th), 0.0, math.cos(th)]
    big = np.full((1, 2), 1e-3)
    gm3 = gravity_margin(_mp(m, [0, 0, 0]), np.eye(4), T3[None], np.array([width]), big, mu=MU, normal_force=F,
                         load=_gravity_only())[0]
    fx, ft = m * G * math.sin(th), m * G * math.cos(th)
    assert gm3 == pytest.approx(MU * F / (0.5 * ft + 0.5 * MU * fx), rel=1e-8)
