"""Mass properties against closed forms (box, sphere) and the not-watertight fallback."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from grasplan.errors import InputError
from grasplan.mass import mass_properties


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

    from grasplan.gripper import load_gripper
    from grasplan.params import GraspParams
    from grasplan.quality import quality_and_score

    cands = SimpleNamespace(width=np.array([0.02]), contacts=np.zeros((1, 2, 3)), normals=np.zeros((1, 2, 3)))
    T = np.eye(4)[None]
    q, mp, score, note = quality_and_score(tri, load_gripper("schunk_egp_c_40"), np.eye(4), T, [0], cands,
                                           np.array(["ok"]), 0.3, GraspParams())
    assert q is None and mp is None and "no grasp quality" in note
    assert np.isfinite(score[0]) and 0 <= score[0] <= 1  # the reachability terms still score it
    with pytest.raises(InputError, match="flat or degenerate"):  # a mass asked for: the reason, not silence
        quality_and_score(tri, load_gripper("schunk_egp_c_40"), np.eye(4), T, [0], cands, np.array(["ok"]), 0.3,
                          GraspParams(mass=0.1))
