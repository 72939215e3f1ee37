"""Mass properties against closed forms (box, sphere) and the not-watertight fallback."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from conftest import EXAMPLE_PARTS
from grasplan.errors import InputError
from grasplan.part.mass import mass_properties


def box_inertia(m: float, a: float, b: float, c: float) -> np.ndarray:
    """Closed form: solid box of side lengths a, b, c about its centre."""
    return m / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def test_box_matches_closed_form_rotated_and_offset():
    ext = np.array([0.12, 0.05, 0.02])
    R = Rotation.from_euler("xyz", [20, -35, 70], degrees=True).as_matrix()
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = [0.3, -0.1, 0.05]
    box = trimesh.creation.box(ext, transform=T)
    mp = mass_properties(box, density=2700.0)
    m = 2700.0 * ext.prod()
    assert mp.watertight_used and not mp.warnings
    assert mp.mass == pytest.approx(m, rel=1e-9)
    assert mp.volume == pytest.approx(ext.prod(), rel=1e-9)
    np.testing.assert_allclose(mp.com, T[:3, 3], atol=1e-12)
    np.testing.assert_allclose(mp.inertia, R @ box_inertia(m, *ext) @ R.T, atol=1e-12 * m)


def test_given_mass_sets_density():
    box = trimesh.creation.box([0.1, 0.03, 0.03])
    mp = mass_properties(box, mass=0.2)
    assert mp.mass == pytest.approx(0.2)
    assert mp.density == pytest.approx(0.2 / (0.1 * 0.03 * 0.03))
    np.testing.assert_allclose(mp.inertia, box_inertia(0.2, 0.1, 0.03, 0.03), rtol=1e-9)


def test_sphere_converges_to_closed_form():
    s = trimesh.creation.icosphere(subdivisions=5, radius=0.05)
    mp = mass_properties(s)  # steel
    m = 7850.0 * 4.0 / 3.0 * np.pi * 0.05**3
    assert mp.mass == pytest.approx(m, rel=2e-3)
    np.testing.assert_allclose(np.diag(mp.inertia), 0.4 * m * 0.05**2, rtol=5e-3)


def test_not_watertight_uses_hull_with_warning():
    box = trimesh.creation.box([0.1, 0.04, 0.02])
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-2], process=False)
    assert not open_box.is_watertight
    mp = mass_properties(open_box, density=1000.0)
    assert not mp.watertight_used
    assert any("convex hull" in w for w in mp.warnings)
    assert mp.mass == pytest.approx(1000.0 * 0.1 * 0.04 * 0.02, rel=1e-9)


def test_inverted_normals_give_the_same_body():
    box = trimesh.creation.box([0.1, 0.04, 0.02])
    inv = box.copy()
    inv.invert()
    a, b = mass_properties(box), mass_properties(inv)
    assert b.mass == pytest.approx(a.mass)
    np.testing.assert_allclose(b.inertia, a.inertia, rtol=1e-9)
    assert b.warnings


@pytest.mark.parametrize("make", [lambda: trimesh.creation.annulus(0.01, 0.03, 0.02, sections=40),
                                  lambda: trimesh.creation.box([0.1, 0.04, 0.02]),
                                  lambda: trimesh.load(EXAMPLE_PARTS / "bracket.stl"),
                                  lambda: trimesh.load(EXAMPLE_PARTS / "gear.stl")])
def test_centre_of_mass_equals_trimesh_bit_for_bit(make):
    """The one centre of mass: mass_properties gives trimesh's own ``center_mass`` of a watertight
    solid, and of the convex hull of an open mesh, to the bit, for a MeshData as for a trimesh
    (the stable poses and the quality share it). The bracket is concave and asymmetric: its
    solid's and its hull's centres differ."""
    from grasplan.geometry.meshdata import MeshData

    tm = make()
    tm.apply_translation([0.013, -0.007, 0.021])
    keep = np.ones(len(tm.faces), dtype=bool)
    keep[::7] = False
    opened = trimesh.Trimesh(tm.vertices, tm.faces[keep], process=False)
    assert tm.is_watertight and not opened.is_watertight
    for mesh, ref in ((tm, tm.center_mass), (opened, opened.convex_hull.center_mass)):
        for m in (mesh, MeshData(mesh.vertices, mesh.faces)):
            mp = mass_properties(m)
            assert mp.watertight_used == (mesh is tm)
            assert np.array_equal(mp.com, ref)
    if not np.allclose(tm.center_mass, opened.convex_hull.center_mass):  # the two cases are told apart
        assert not np.array_equal(mass_properties(tm).com, mass_properties(opened).com)


@pytest.mark.parametrize("kw", [{"density": 0.0}, {"density": -1.0}, {"density": float("nan")}, {"mass": 0.0},
                                {"mass": "heavy"}])
def test_bad_density_or_mass_is_input_error(kw):
    with pytest.raises(InputError, match="density|mass"):
        mass_properties(trimesh.creation.box([0.1, 0.1, 0.1]), **kw)


def test_flat_mesh_is_input_error():
    flat = trimesh.Trimesh([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.1, 0.1, 0]], [[0, 1, 2], [1, 3, 2]])
    with pytest.raises(InputError, match="no volume|volume"):
        mass_properties(flat)


def test_single_triangle_is_input_error_and_the_grasp_stage_goes_on_without_quality():
    tri = trimesh.Trimesh([[0, 0, 0], [0.03, 0, 0], [0, 0.02, 0]], [[0, 1, 2]], process=False)
    with pytest.raises(InputError, match="flat or degenerate|no volume"):
        mass_properties(tri)
    from types import SimpleNamespace

    from grasplan.gripper.load import load_gripper
    from grasplan.config.params import GraspParams
    from grasplan.grasps.quality import quality_and_score

    cands = SimpleNamespace(width=np.array([0.02]), contacts=np.zeros((1, 2, 3)), normals=np.zeros((1, 2, 3)))
    T = np.eye(4)[None]
    q, mp, score, note = quality_and_score(tri, load_gripper("schunk_egp_c_40"), np.eye(4), T, [0], cands,
                                           np.array(["ok"]), 0.3, GraspParams())
    assert q is None and mp is None and "no grasp quality" in note
    assert np.isfinite(score[0]) and 0 <= score[0] <= 1  # the reachability terms still score it
    with pytest.raises(InputError, match="flat or degenerate"):  # a mass asked for: the reason, not silence
        quality_and_score(tri, load_gripper("schunk_egp_c_40"), np.eye(4), T, [0], cands, np.array(["ok"]), 0.3,
                          GraspParams(mass=0.1))
