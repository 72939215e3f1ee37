"""MuJoCo lift-and-shake check (issue 11): a block held through its centre, slipping at its end."""
from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from grasplan.errors import InputError
from grasplan.gripper.load import load_gripper
from grasplan.part.mass import mass_properties
from grasplan.grasps.quality import grasp_quality
from grasplan.sim.simulate import convex_pieces, simulate_grasps

BLOCK = (0.12, 0.03, 0.03)


def top_grasp(x: float) -> np.ndarray:
    """TCP from above (z = -part z), closing along part y, centred at part (x, 0, 0)."""
    T = np.eye(4)
    T[:3, 0] = [0, 1, 0]
    T[:3, 2] = [0, 0, -1]
    T[:3, 1] = np.cross(T[:3, 2], T[:3, 0])
    T[:3, 3] = [x, 0, 0]
    return T


@pytest.fixture(scope="module")
def setup():
    block = trimesh.creation.box(BLOCK)
    T_world_part = np.eye(4)
    T_world_part[:3, 3] = [0.45, 0.0, BLOCK[2] / 2]  # resting on the table z = 0
    return block, load_gripper("schunk_egp_c_40"), T_world_part


def test_centre_grasp_of_a_light_block_holds(setup):
    block, g, Twp = setup
    r = simulate_grasps(block, g, Twp, top_grasp(0.0)[None], [BLOCK[1]], mass=0.2, decomposition="hull")
    assert r.success.tolist() == [True]
    assert r.slip_m[0] < 1e-3 and r.turn_deg[0] < 1.0


def test_end_grasp_with_low_grip_force_slips_and_quality_predicts_it(setup):
    block, g, Twp = setup
    T = np.array([top_grasp(0.0), top_grasp(0.05)])
    r = simulate_grasps(block, g, Twp, T, [BLOCK[1]] * 2, mass=0.2, grip_force=16.0, decomposition="hull")
    assert r.success.tolist() == [True, False]
    assert r.slip_m[1] > 5e-3 or r.turn_deg[1] > 5.0
    C = np.array([[[x, -0.015, 0], [x, 0.015, 0]] for x in (0.0, 0.05)])
    N = np.array([[[0, -1.0, 0], [0, 1.0, 0]]] * 2)
    q = grasp_quality(block, mass_properties(block, mass=0.2), g, T, C, N, np.full(2, BLOCK[1]),
                      T_world_part=Twp, mu=0.3, grip_force=16.0)
    assert q.gravity_margin[1] < 1.0 < q.gravity_margin[0]


def test_simulation_is_deterministic(setup):
    block, g, Twp = setup
    T = np.array([top_grasp(0.04)])
    a = simulate_grasps(block, g, Twp, T, [BLOCK[1]], mass=0.2, grip_force=24.0, decomposition="hull")
    b = simulate_grasps(block, g, Twp, T, [BLOCK[1]], mass=0.2, grip_force=24.0, decomposition="hull")
    assert a.slip_m.tolist() == b.slip_m.tolist() and a.turn_deg.tolist() == b.turn_deg.tolist()


def test_bad_input_is_input_error(setup):
    block, g, Twp = setup
    with pytest.raises(InputError, match="wider"):
        simulate_grasps(block, g, Twp, top_grasp(0.0)[None], [0.2], decomposition="hull")
    with pytest.raises(InputError, match="width"):
        simulate_grasps(block, g, Twp, top_grasp(0.0)[None], [0.03, 0.03], decomposition="hull")
    with pytest.raises(InputError, match="decomposition"):
        simulate_grasps(block, g, Twp, top_grasp(0.0)[None], [0.03], decomposition="vhacd")
    with pytest.raises(InputError, match="T_part_tcp"):
        simulate_grasps(block, g, Twp, np.zeros((1, 4, 4)), [0.03], decomposition="hull")


def test_coacd_pieces_are_cached_atomically(tmp_path, monkeypatch):
    monkeypatch.setenv("GRASPLAN_CACHE_DIR", str(tmp_path))
    # an L-shaped (concave) part: two boxes
    a = trimesh.creation.box([0.06, 0.02, 0.02])
    b = trimesh.creation.box([0.02, 0.06, 0.02])
    b.apply_translation([0.02, 0.02, 0])
    part = trimesh.boolean.union([a, b], engine="manifold") if trimesh.boolean.engines_available else a
    pieces = convex_pieces(part, decomposition="coacd", seed=0)
    files = list((tmp_path / "coacd").glob("*.npz"))
    assert len(files) == 1 and not list((tmp_path / "coacd").glob(".*tmp"))
    again = convex_pieces(part, decomposition="coacd", seed=0)
    assert len(again) == len(pieces) and all(np.array_equal(p, q) for p, q in zip(pieces, again))
    # every piece lies within the part's bounds
    lo, hi = part.bounds
    assert all(np.all(p >= lo - 1e-3) and np.all(p <= hi + 1e-3) for p in pieces)


def test_simulate_cli_writes_sim_per_grasp(tmp_path, example_part):
    from click.testing import CliRunner

    from grasplan.results import reader as result
    from grasplan.cli import main

    grasps_json = tmp_path / "grasps.json"
    runner = CliRunner()
    r = runner.invoke(main, ["grasps", str(example_part("box.stl")), "-o", str(grasps_json)])
    assert r.exit_code == 0, r.output
    loaded = result.load_result(grasps_json)
    out = tmp_path / "sim.json"
    r = runner.invoke(main, ["simulate", str(grasps_json), "--top", "3", "--decomposition", "hull", "-o", str(out)])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    assert doc["schema"] == "grasplan.sim/1" and len(doc["grasps"]) == 3
    assert doc["part"]["sha256"] == loaded.part.sha256 and doc["part"]["scale_to_m"] == loaded.part.scale_to_m
    assert doc["part"]["mass_kg"] == pytest.approx(json.loads(grasps_json.read_text())["part"]["mass_kg"])
    ok = set(np.flatnonzero(np.asarray(loaded.grasps.status) == "ok").tolist())
    # the best-scored collision-free grasps with the plan's diversity rule
    from grasplan.grasps.ranking import distinct_order

    g = loaded.grasps
    okr = np.flatnonzero(np.asarray(g.status) == "ok")
    expected = distinct_order(g.T_part_tcp, okr[np.lexsort((okr, -g.score[okr]))])[0][:3]
    assert [gr["id"] for gr in doc["grasps"]] == expected.tolist()
    assert doc["grasps"][0]["score"] == pytest.approx(np.nanmax(g.score))
    for gr in doc["grasps"]:
        assert gr["id"] in ok
        assert set(gr["sim"]) == {"success", "slip_m", "turn_deg"}
    assert doc["counts"]["held"] == sum(gr["sim"]["success"] for gr in doc["grasps"])
    # --mass overrides the file's density and is recorded
    out2 = tmp_path / "sim2.json"
    r = runner.invoke(main, ["simulate", str(grasps_json), "--top", "1", "--decomposition", "hull", "--mass", "0.5",
                             "-o", str(out2)])
    assert r.exit_code == 0, r.output
    assert json.loads(out2.read_text())["part"]["mass_kg"] == pytest.approx(0.5)
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    r = runner.invoke(main, ["simulate", str(bad), "-o", str(tmp_path / "x.json")])
    assert r.exit_code == 3 and not (tmp_path / "x.json").exists()


def _slabs(n: int) -> list[np.ndarray]:
    """BLOCK cut into n x 1 x n box pieces (vertices, part frame): a decomposition whose many pieces
    each touch the jaw pad, as CoACD's pieces of a real part do (SileaneGear: 24-31 contacts per jaw)."""
    ext = np.asarray(BLOCK)
    d = ext / [n, 1, n]
    corners = np.array([[a, b, c] for a in (0, 1) for b in (0, 1) for c in (0, 1)], dtype=np.float64) * d
    return [corners + (-ext / 2 + d * [i, 0, k]) for i in range(n) for k in range(n)]


def test_many_piece_contact_does_not_ring_the_jaws_out(setup, monkeypatch):
    """Issue 11: a 0.2 kg jaw with 1400 N s/m of damping (m/b 7x below the timestep) rang against a
    part of many convex pieces and ratcheted it out of a centred grasp; the drive's reflected inertia
    (``DRIVE_TAU``) keeps it still. The bare-jaw model is run too, to show the test can fail."""
    import grasplan.sim.simulate as S

    block, g, Twp = setup
    monkeypatch.setattr(S, "convex_pieces", lambda mesh, **kw: _slabs(8))
    T = top_grasp(0.0)[None]
    held = S.simulate_grasps(block, g, Twp, T, [BLOCK[1]], mass=0.3, decomposition="hull")
    assert held.success.tolist() == [True]
    assert held.slip_m[0] < 1e-4 and held.turn_deg[0] < 0.1
    monkeypatch.setattr(S, "DRIVE_TAU", 0.0)
    bare = S.simulate_grasps(block, g, Twp, T, [BLOCK[1]], mass=0.3, decomposition="hull")
    assert bare.slip_m[0] > 5 * max(held.slip_m[0], 2e-5)


def test_drive_inertia_sets_the_jaw_time_constant():
    """The jaws' effective mass (JAW_MASS + armature) over their damping is DRIVE_TAU, at least two
    timesteps, for any grip force."""
    import re

    import grasplan.sim.simulate as S

    assert S.DRIVE_TAU >= 2 * S.TIMESTEP
    block = trimesh.creation.box(BLOCK)
    g = load_gripper("schunk_egp_c_40")
    for force in (20.0, 140.0, 1000.0):
        xml = S.build_model_xml(S.convex_pieces(block, decomposition="hull"), mass_properties(block, mass=0.2), g,
                                mu=0.3, grip_force=force)
        joints = re.findall(r'<joint name="jaw\d"[^>]*damping="([^"]+)"\s+armature="([^"]+)"', xml)
        assert len(joints) == 2
        for b, a in joints:
            tau = (S.JAW_MASS + float(a)) / float(b)
            assert tau >= S.DRIVE_TAU - 1e-9


def test_an_arena_too_small_for_the_contacts_is_an_error_not_a_result(setup, monkeypatch):
    """MuJoCo drops contacts silently when its arena is full: the simulation must refuse to report
    such a run (here with a 60 kB arena and a part of 64 pieces) instead of scoring it."""
    import grasplan.sim.simulate as S

    block, g, Twp = setup
    monkeypatch.setattr(S, "convex_pieces", lambda mesh, **kw: _slabs(8))
    monkeypatch.setattr(S, "_arena", lambda n: "60K")
    with pytest.raises(RuntimeError, match="ran out of contact/constraint memory"):
        S.simulate_grasps(block, g, Twp, top_grasp(0.0)[None], [BLOCK[1]], mass=0.3, decomposition="hull")


def test_jaw_torsion_is_the_soft_finger_torsion_of_each_grasps_patch(setup):
    """Issue 11: MuJoCo gives a pair of convex shapes one contact point, so each jaw's torsional
    friction is set per grasp from its own contact patch (the model gravity_margin uses), not a
    constant. Checked against the patch computed independently here, and an explicit area wins."""
    from grasplan.grasps.patches import contact_patches

    block, g, Twp = setup
    T = np.array([top_grasp(0.0), top_grasp(0.05)])
    C = np.array([[[x, -0.015, 0], [x, 0.015, 0]] for x in (0.0, 0.05)])
    area = contact_patches(block, g, T, C)[0]
    assert np.all(area > 1e-4)  # flat pad on a flat face: a surface patch
    r = simulate_grasps(block, g, Twp, T, [BLOCK[1]] * 2, mass=0.2, decomposition="hull")
    np.testing.assert_allclose(r.jaw_torsion_m, 0.3 * (2.0 / 3.0) * np.sqrt(area / np.pi), rtol=1e-12)
    tiny = np.full((2, 2), 1e-12)  # a point contact: the 0.5 mm floor of the patch radius
    r2 = simulate_grasps(block, g, Twp, T, [BLOCK[1]] * 2, mass=0.2, decomposition="hull", contact_area=tiny)
    np.testing.assert_allclose(r2.jaw_torsion_m, 0.3 * (2.0 / 3.0) * 5e-4, rtol=1e-12)
    with pytest.raises(InputError, match="contact areas"):
        simulate_grasps(block, g, Twp, T, [BLOCK[1]] * 2, mass=0.2, decomposition="hull", contact_area=np.ones(2))


@pytest.mark.parametrize("pieces", ["hull", "slabs"])
def test_twist_slips_at_the_patch_torsion_whatever_the_contact_points(setup, monkeypatch, pieces):
    """Issue 22: a block gripped 30 mm off its centre of mass, the load twisting it about the closing
    axis. Analytic holding limit: the soft-finger ellipse of the pad patches (tangential m g' / 2 per
    pad and the torque m g' d shared by both pads' torsion mu F (2/3) a) under the peak load of
    wrench.LOAD, i.e. the grip force F* = F / gravity_margin. The simulation must slip at 0.9 F* and
    hold at 1.1 F*, whether the part is one convex piece (MuJoCo: 4 contact points per pad at the
    corners of the overlap) or 16 slabs (a point per slab): each MuJoCo point used to carry the whole
    patch's torsion on top of the points' spread, and held down to 0.5 F*."""
    import grasplan.sim.simulate as S

    block, g, Twp = setup
    if pieces == "slabs":
        monkeypatch.setattr(S, "convex_pieces", lambda mesh, **kw: _slabs(4))
    x, mass = 0.03, 0.5
    T = top_grasp(x)[None]
    C = np.array([[[x, -0.015, 0], [x, 0.015, 0]]])
    N = np.array([[[0, -1.0, 0], [0, 1.0, 0]]])
    q = grasp_quality(block, mass_properties(block, mass=mass), g, T, C, N, np.full(1, BLOCK[1]),
                      T_world_part=Twp, mu=0.3, grip_force=100.0)
    f_star = 100.0 / q.gravity_margin[0]  # the margin grows in proportion to the grip force here
    assert 60.0 < f_star < 120.0
    r = S.simulate_grasps(block, g, Twp, T, [BLOCK[1]], mass=mass,
                          grip_force=0.9 * f_star, decomposition="hull")
    assert not r.success[0] and r.turn_deg[0] > 5.0
    r = S.simulate_grasps(block, g, Twp, T, [BLOCK[1]], mass=mass, grip_force=1.1 * f_star, decomposition="hull")
    assert r.success[0] and r.turn_deg[0] < 0.5
