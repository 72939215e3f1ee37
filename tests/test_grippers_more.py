"""The grippers of issue 23: Robotiq 2F-85 / 2F-140 and OnRobot RG2 / RG6 (pads on an arc: the TCP
moves along z with the opening), SCHUNK EGP 25 / EGP 64 (stroke: they close only to max_opening -
stroke), and the gripper's mass and centre of mass (YAML, JSON, RAPID tload).

* the arcs against the makers' own linkages (the joint constants of Robotiq's and OnRobot's URDFs,
  written out here as planar chains, not grasplan's model);
* ``grasplan grasps`` on TLess20 with every new gripper: collision-free grasps whose widths fit the
  stroke, re-checked with python-fcl (boxes placed here at the grasp's TCP offset), not coal.
"""
from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from grasplan.errors import ConfigError
from grasplan.gripper.load import gripper_from_json, load_gripper

NEW = ["robotiq_2f_85", "robotiq_2f_140", "onrobot_rg2", "onrobot_rg6", "schunk_egp_25", "schunk_egp_64"]
#: figures each YAML must carry (the makers' values cited in its comments; docs/grippers.md, "Gripper
#: figures and their sources", says which are verified)
DATASHEET = {  # name: (max_opening m, stroke m or None, grip force N, mass kg)
    "robotiq_2f_85": (0.085, None, 235.0, 0.9),  # Robotiq product sheet: 85 mm, 20-235 N, 0.9 kg
    "robotiq_2f_140": (0.140, None, 125.0, 1.0),  # Robotiq product sheet: 140 mm, 10-125 N, 1 kg
    "onrobot_rg2": (0.110, None, 40.0, 0.78),
    "onrobot_rg6": (0.160, None, 120.0, 1.25),
    "schunk_egp_25": (0.040, 0.006, 35.0, 0.14),
    "schunk_egp_64": (0.060, 0.020, 300.0, 0.93),
}


@pytest.mark.parametrize("name", NEW)
def test_loads_with_datasheet_figures_mass_and_com(name):
    g = load_gripper(name)
    mo, stroke, force, mass = DATASHEET[name]
    assert g.name == name
    assert g.max_opening == pytest.approx(mo) and g.grip_force == pytest.approx(force)
    assert g.mass == pytest.approx(mass)
    assert g.com is not None and g.com.shape == (3,) and 0 < g.com[2] < g.T_flange_tcp[2, 3]
    assert g.stroke == (None if stroke is None else pytest.approx(stroke))
    assert g.min_opening == pytest.approx(0.0 if stroke is None else mo - stroke)
    linkage = name.startswith(("robotiq", "onrobot"))  # the makers' URDFs: pads on four-bar linkages
    assert g.kind == ("parallel_linkage" if linkage else "parallel_jaw")
    assert g.moving_tcp == linkage


@pytest.mark.parametrize("name", NEW + ["schunk_egp_c_40", "round_mesh_jaws"])
def test_json_round_trip_keeps_mass_com_stroke_and_arc(name):
    g = load_gripper(name)
    d = json.loads(json.dumps(g.to_json(definition=True)))
    back = gripper_from_json(d)
    assert type(back) is type(g)
    assert back.mass == g.mass and back.stroke == g.stroke
    np.testing.assert_allclose(back.com, g.com)
    o = np.linspace(0.0, g.max_opening, 7)
    np.testing.assert_allclose(back.tcp_offset(o), g.tcp_offset(o), atol=1e-12)
    for w in (0.3 * g.max_opening, g.max_opening):
        np.testing.assert_allclose(back.T_flange_tcp_at(w), g.T_flange_tcp_at(w), atol=1e-12)


# --------------------------------------------------------------------------------------------------
# the arc
# --------------------------------------------------------------------------------------------------
def _robotiq_85_pad(t):
    """(inner face x, z) of the +x pad of a 2F-85 at finger joint t (rad, 0 open .. 0.8 closed), mm,
    from Robotiq's URDF: knuckle pivot (30.60114, 54.90452), knuckle + finger-tip joint offsets
    (31.52616 + 5.63134, -3.76347 + 47.18515), pad inner face 25.25865 inwards of the tip joint."""
    kx, kz = 30.60114, 54.90452
    fx, fz = 31.52616 + 5.63134, -3.76347 + 47.18515
    return kx + fx * math.cos(t) - fz * math.sin(t) - 25.25865, kz + fx * math.sin(t) + fz * math.cos(t)


def test_robotiq_85_tcp_offset_follows_robotiqs_linkage():
    g = load_gripper("robotiq_2f_85")
    x_open, z_open = _robotiq_85_pad(0.0)
    assert 2 * x_open == pytest.approx(85.0, abs=0.1)  # the chain reproduces the datasheet stroke
    for t in np.linspace(0.0, 0.79, 12):
        x, z = _robotiq_85_pad(t)
        assert float(g.tcp_offset(2 * x / 1000.0)) * 1000.0 == pytest.approx(z - z_open, abs=0.05)
    # closed: the pads are 13.5 mm further out than open
    assert float(g.tcp_offset(0.0)) == pytest.approx(0.0135, abs=2e-4)
    assert float(g.tcp_offset(g.max_opening)) == 0.0


def _robotiq_140_pad(t):
    """(inner face x, pad centre z) of the +x pad of a 2F-140 at finger_joint t (rad, 0 open .. 0.7
    closed; negative: further open), mm, from Robotiq's URDF (robotiq_arg2f_140_model_macro.xacro):
    outer knuckle pivot (30.601, 54.905), joint roll pi/2 + 0.725 - t, knuckle -> inner finger
    (18.21999 + 81.75540, 26.00182 - 28.22034), inner finger -> pad centre 27.22034 in and 45.75540
    out, pad 7.5 thick."""
    a = math.pi / 2 + 0.725 - t
    ly, lz = 18.21998610742 + 81.7554015893473, 26.0018192872234 - 28.2203446692936
    y = -30.601 + ly * math.cos(a) - lz * math.sin(a) + 27.2203446692936 + 3.75
    z = 54.905 + ly * math.sin(a) + lz * math.cos(a) + 45.7554015893473
    return -y, z


def _onrobot_tip(t, pivot, link, tip):
    """(fingertip x, z) of an OnRobot RG gripper's +x fingertip frame at finger_joint t (rad, 0 closed),
    mm, from OnRobot's URDF: the finger pivot (x, z) from base_link, the outer proximal link (along,
    across) and the finger base -> fingertip offset (out, in); the finger base keeps its orientation."""
    (px, pz), (la, lc), (ta, tc) = pivot, link, tip
    x = px + la * math.sin(t) + lc * math.cos(t) - tc
    z = pz + la * math.cos(t) - lc * math.sin(t) + ta
    return x, z


@pytest.mark.parametrize("name, chain, t_open, t_closed", [
    # t_open: the URDF's open limit (2F-140) or OnRobot's cad_finger_upper (RG2, RG6)
    ("robotiq_2f_140", _robotiq_140_pad, 0.0, 0.7),
    ("onrobot_rg2", lambda t: _onrobot_tip(t, (16.95, 123.34), (54.9431524395901, -2.5), (36.5, 14.5)),
     math.asin(105.0 / 110.0) + math.asin(2.5 / 55.0), 0.0),
    ("onrobot_rg6", lambda t: _onrobot_tip(t, (23.85, 135.3), (79.8896739261193, -4.2), (47.9, 19.6)),
     math.asin(151.6 / 160.0) + math.asin(4.2 / 80.0), 0.0),
])
def test_arcs_follow_the_makers_linkages(name, chain, t_open, t_closed):
    """grasplan's arc (radius, center_x) reproduces the maker's linkage: the TCP's travel along z
    between any two openings of the URDF chain, within 0.1 mm; and the chain spans the stroke
    (OnRobot: 0 to max_opening exactly; 2F-140: the URDF's open limit stops at 128.5 mm, short of
    the product sheet's 140 mm, which the arc reaches by extending the same circle)."""
    g = load_gripper(name)
    ts = np.linspace(t_open, t_closed, 15)
    xz = np.array([chain(float(t)) for t in ts])
    widths, z = 2.0 * xz[:, 0] / 1000.0, xz[:, 1] / 1000.0
    assert widths.min() == pytest.approx(0.0, abs=2e-4)
    if name.startswith("onrobot"):
        assert widths.max() == pytest.approx(g.max_opening, abs=2e-4)
    else:
        assert widths.max() == pytest.approx(0.1285, abs=5e-4) and widths.max() < g.max_opening
    off = g.tcp_offset(np.clip(widths, 0.0, None))
    np.testing.assert_allclose(off - off[0], z - z[0], atol=1e-4)
    # closing moves the pads away from the flange: by the chain's own travel
    assert float(g.tcp_offset(0.0)) > 0.02


@pytest.mark.parametrize("name", ["robotiq_2f_85", "robotiq_2f_140", "onrobot_rg2", "onrobot_rg6"])
def test_moving_tcp_is_used_for_fingers_flange_and_grasp_frame(name):
    g = load_gripper(name)
    for w in (0.2 * g.max_opening, 0.5 * g.max_opening, 0.9 * g.max_opening):
        dz = float(g.tcp_offset(w))
        # T_flange_tcp_at(w): the TCP moves by the offset along the tool z
        T = g.T_flange_tcp_at(w)
        np.testing.assert_allclose(T[:3, 3], g.T_flange_tcp[:3, 3] + dz * g.T_flange_tcp[:3, 2], atol=1e-12)
        # in the grasp's TCP frame the pads stand at x = +-w/2 around z = 0 (the contacts)
        Tg = g.T_tcp_gripper(w)
        left, right = (f.moved(Tg) for f in g.fingers(w))
        rc, lc = right.corners(), left.corners()
        assert rc[:, 0].min() == pytest.approx(w / 2) and lc[:, 0].max() == pytest.approx(-w / 2)
        assert rc[:, 2].min() < 0 < rc[:, 2].max()
        # the flange seen from the grasp TCP: T_tcp_gripper(w) @ inv(T_flange_tcp) = inv(T_flange_tcp_at(w))
        np.testing.assert_allclose(Tg @ np.linalg.inv(g.T_flange_tcp), np.linalg.inv(T), atol=1e-12)
    # the closing sweep holds the finger at every opening in between
    lo, hi = 0.3 * g.max_opening, 0.45 * g.max_opening
    sweep = g.swept_fingers(hi, lo)[1]
    c = sweep.T_tcp_box[:3, 3]
    h = 0.5 * np.asarray(sweep.extents)
    for o in np.linspace(lo, hi, 11):
        p = g.fingers(o)[1].corners()
        assert np.all(np.abs(p - c) <= h + 1e-12)
    # batch form
    ws = np.array([0.01, 0.02])
    np.testing.assert_allclose(g.T_tcp_gripper(ws)[:, 2, 3], -g.tcp_offset(ws))


def test_straight_jaws_have_no_tcp_offset():
    g = load_gripper("schunk_egp_64")
    assert not g.moving_tcp
    np.testing.assert_allclose(g.T_flange_tcp_at(0.05), g.T_flange_tcp)
    np.testing.assert_allclose(g.T_tcp_gripper(np.array([0.01, 0.05])), np.broadcast_to(np.eye(4), (2, 4, 4)))


# --------------------------------------------------------------------------------------------------
# validation
# --------------------------------------------------------------------------------------------------
_BASE = ("max_opening: 0.05\nT_flange_tcp: {xyz: [0, 0, 0.1], rpy_deg: [0, 0, 0]}\n"
         "body:\n  - box: {size: [0.05, 0.04, 0.06], center: [0, 0, -0.07]}\n"
         "fingers:\n  box: {size: [0.008, 0.016, 0.04], center_y: 0.0, center_z: -0.012}\n")


@pytest.mark.parametrize("extra, match", [
    ("mass: 0.5\n", "com: missing"),
    ("com: [0, 0, 0.05]\n", "mass: missing"),
    ("mass: -1\ncom: [0, 0, 0.05]\n", "mass"),
    ("mass: 500\ncom: [0, 0, 0.05]\n", "mass"),
    ("mass: 0.5\ncom: [0, 0, 5]\n", "com: .* more than 1"),
    ("mass: 0.5\ncom: [0, 0]\n", "com"),
    ("mass: 0.5\ncom: [0, .nan, 0]\n", "com"),
    ("stroke: 0.08\n", "stroke: .*more than max_opening"),
    ("stroke: -0.01\n", "stroke"),
    ("kind: parallel_linkage\n", "arc: missing"),
    ("kind: parallel_linkage\narc: {radius: 0.01, center_x: 0.0}\n", "arc: radius .* shorter"),
    ("kind: parallel_linkage\narc: {radius: 0.05}\n", "arc: expected"),
])
def test_bad_mass_com_stroke_arc_name_the_field(tmp_path, extra, match):
    p = tmp_path / "g.yaml"
    p.write_text(_BASE + extra)
    with pytest.raises(ConfigError, match=match) as e:
        load_gripper(p)
    assert str(p) in str(e.value)


def test_mass_and_com_round_trip_and_default_none(tmp_path):
    p = tmp_path / "g.yaml"
    p.write_text(_BASE + "mass: 0.5\ncom: [0.001, 0, 0.04]\nstroke: 0.012\n")
    g = load_gripper(p)
    assert g.mass == 0.5 and g.com.tolist() == [0.001, 0.0, 0.04] and g.min_opening == pytest.approx(0.038)
    q = tmp_path / "h.yaml"
    q.write_text(_BASE)
    h = load_gripper(q)
    assert h.mass is None and h.com is None and h.min_opening == 0.0 and "mass" not in h.to_json()


# --------------------------------------------------------------------------------------------------
# RAPID tload
# --------------------------------------------------------------------------------------------------
def test_rapid_tload_uses_the_gripper_mass_and_com():
    from grasplan.export.rapid import PLACEHOLDER_MASS_KG, tool_load

    class _MP:  # the two fields tool_load reads
        gripper_mass = 0.925
        gripper_com = np.array([0.0, 0.001, 0.045])

    T = np.eye(4)
    T[2, 3] = 0.132
    lines = tool_load(_MP(), T)
    nums = [float(v) for v in lines[-1].replace("[", "").replace("]", "").split(",")]
    assert nums == pytest.approx([0.925, 0.0, 1.0, 45.0, 1, 0, 0, 0, 0, 0, 0])  # kg, cog mm, aom, inertia
    assert "PLACEHOLDER" not in " ".join(lines)
    _MP.gripper_mass = None
    lines = tool_load(_MP(), T)
    assert "PLACEHOLDER" in lines[0] and lines[-1].startswith(f"[{PLACEHOLDER_MASS_KG:g}")


# --------------------------------------------------------------------------------------------------
# TLess20: every new gripper grasps it, collision-free (python-fcl), widths within the stroke
# --------------------------------------------------------------------------------------------------
def _fcl_shape(shape, T):
    import fcl

    from fcl_recheck import bvh, fcl_tf

    if hasattr(shape, "extents"):
        return fcl.CollisionObject(fcl.Box(*np.asarray(shape.extents, dtype=float)), fcl_tf(T @ shape.T_tcp_box))
    return fcl.CollisionObject(bvh(shape.vertices, shape.faces), fcl_tf(T))


def _hits(gripper, T_world_tcp, width, opening, part_obj, table_obj):
    """Names of the gripper shapes (body, both jaws at ``opening``) that touch the part or the table,
    the gripper placed for a grasp of ``width`` (its TCP offset applied here, from its own methods)."""
    import fcl

    T = T_world_tcp @ gripper.T_tcp_gripper(width)
    out = []
    shapes = [(f"body_{k}", s) for k, s in enumerate(gripper.body)] + list(zip(("jaw-", "jaw+"), gripper.fingers(opening)))
    for name, s in shapes:
        o = _fcl_shape(s, T)
        for what, other in (("part", part_obj), ("table", table_obj)):
            if fcl.collide(o, other, fcl.CollisionRequest(), fcl.CollisionResult()):
                out.append(f"{name} vs {what}")
    return out


@pytest.mark.slow
@pytest.mark.paper
@pytest.mark.parametrize("name", NEW)
def test_tless20_grasps_collision_free_within_the_stroke(name, paper, tmp_path):
    import fcl
    from click.testing import CliRunner

    from fcl_recheck import bvh, fcl_tf
    from grasplan.cli import main
    from grasplan.part.mesh import load_part

    path = paper("TLess20.stl")
    out = tmp_path / "g.json"
    # `grasplan grasps` (roll step 30 deg keeps the test short; the default 15 deg finds twice as many)
    r = CliRunner().invoke(main, ["grasps", str(path), "--gripper", name, "--roll-step", "30", "-o", str(out)])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    assert doc["gripper"]["name"] == name and doc["gripper"]["mass"] == pytest.approx(DATASHEET[name][3])
    g = gripper_from_json(doc["gripper"])
    ok = [e for e in doc["grasps"] if e["status"] == "ok"]
    assert len(ok) >= 10, f"{name}: {len(ok)} collision-free grasps"
    widths = np.array([e["width"] for e in ok])
    assert widths.max() <= g.max_opening + 1e-9 and widths.min() >= g.min_opening - 1e-9
    # re-check a seeded sample with python-fcl: body and jaws at the pre-grasp and the closing stop
    part = load_part(path)
    T_world_part = np.asarray(doc["part"]["T_world_part"])
    part_obj = fcl.CollisionObject(bvh(part.mesh.vertices, part.mesh.faces), fcl_tf(T_world_part))
    z = float(doc["cell"]["table"]["z"])
    table_obj = fcl.CollisionObject(fcl.Halfspace(np.array([0.0, 0.0, 1.0]), z - 1e-4))
    rng = np.random.default_rng(0)
    for e in rng.choice(np.array(ok, dtype=object), size=min(40, len(ok)), replace=False):
        T_world_tcp = T_world_part @ np.asarray(e["T_part_tcp"])
        w = float(e["width"])
        for opening in (float(g.pregrasp_opening(w)), float(g.close_to_opening(w))):
            assert _hits(g, T_world_tcp, w, opening, part_obj, table_obj) == [], (name, e["id"], opening)
    # the check can fail: jaws shut inside the part
    e = ok[0]
    T_world_tcp = T_world_part @ np.asarray(e["T_part_tcp"])
    assert any("part" in h for h in _hits(g, T_world_tcp, float(e["width"]), 0.0, part_obj, table_obj))


# --------------------------------------------------------------------------------------------------
# a moving TCP through planning, the plan reader and the robot programs
# --------------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_robotiq_plan_uses_the_tcp_at_the_grasp_width(tmp_path, example_part):
    """The bracket planned on the UR5 with the 2F-85: FK(q_grasp) reaches each grasp TCP through
    T_flange_tcp_at(width) (not the constant T_flange_tcp), the path re-checks free with python-fcl
    (fingers along their arc), the plan loads (its FK check) and the RAPID / URScript tool is the
    TCP at the grasp's width with the gripper's load."""
    import pinocchio as pin
    from click.testing import CliRunner

    import fcl_recheck
    from grasplan.cli import main
    from grasplan.results.reader import load_result

    out = tmp_path / "plan.json"
    r = CliRunner().invoke(main, ["plan", str(example_part("bracket.stl")), "--units", "mm", "--robot", "ur5",
                                  "--gripper", "robotiq_2f_85", "--top", "3", "-o", str(out)])
    assert r.exit_code == 0, r.output
    res = load_result(out)  # runs the FK check of every planned grasp
    g = res.gripper
    assert g.moving_tcp
    doc = json.loads(out.read_text())
    planned = [e for e in doc["grasps"] if e["status"] == "planned"]
    assert len(planned) == 3
    model = pin.buildModelFromUrdf(str(res.robot.urdf_path))
    data = model.createData()
    fid = model.getFrameId(res.robot.tool_frame)
    for e in planned:
        pin.framesForwardKinematics(model, data, np.asarray(e["q_grasp"]))
        T_tool = data.oMf[fid].homogeneous
        T_grasp = np.asarray(doc["part"]["T_world_part"]) @ np.asarray(e["T_part_tcp"])
        np.testing.assert_allclose(T_tool @ g.T_flange_tcp_at(e["width"]), T_grasp, atol=1e-5)
        # the constant T_flange_tcp would miss by the offset (so the check above can fail)
        miss = np.linalg.norm((T_tool @ g.T_flange_tcp)[:3, 3] - T_grasp[:3, 3])
        assert miss == pytest.approx(float(g.tcp_offset(e["width"])), abs=1e-5) and miss > 1e-3
    reports = fcl_recheck.recheck_result(res, step=0.01)
    assert not {i: rep.problems for i, rep in reports.items() if rep.problems}
    for fmt, needle in (("rapid", "PERS tooldata"), ("urscript", "set_tcp")):
        dest = tmp_path / f"prog_{fmt}"
        r = CliRunner().invoke(main, ["export", str(out), "--format", fmt, "-o", str(dest)])
        assert r.exit_code == 0, r.output
        line = next(ln for ln in dest.read_text().splitlines() if needle in ln)
        nums = np.array([float(v) for v in re.findall(r"-?\d+\.\d+", line)])
        tool_z = nums[2] * (1.0 if fmt == "urscript" else 1e-3)  # m (URScript) / mm (RAPID)
        # the exported grasp's TCP at its width, not the constant one
        assert any(abs(tool_z - g.T_flange_tcp_at(e["width"])[2, 3]) < 2e-6 for e in planned), line
        assert abs(tool_z - g.T_flange_tcp[2, 3]) > 1e-3
        if fmt == "rapid":  # tload: mass, cog (mm): the gripper file's
            assert nums[7:11] == pytest.approx([g.mass, *(1000.0 * g.com)], abs=1e-3)
            assert nums[7] == pytest.approx(0.9)  # Robotiq product sheet


def test_simulation_payload_is_gripper_plus_part_in_the_flange_frame():
    """simulate's flange load: the gripper's mass/com (its file) and the part at its centre of mass,
    worked out by hand for a top grasp 10 mm off the part's centre."""
    import trimesh

    from grasplan.part.mass import mass_properties
    from grasplan.sim.simulate import flange_payload

    mp = mass_properties(trimesh.creation.box(extents=(0.12, 0.03, 0.03)), density=1000.0)
    T = np.eye(4)  # TCP from above, closing along part y, at part (0.01, 0, 0): TCP y = part x
    T[:3, 0], T[:3, 2] = [0, 1, 0], [0, 0, -1]
    T[:3, 1] = np.cross(T[:3, 2], T[:3, 0])
    T[:3, 3] = [0.01, 0, 0]
    g = load_gripper("schunk_egp_c_40")
    kg, com = flange_payload(g, mp, T[None], np.array([0.03]))
    m_p = 0.12 * 0.03 * 0.03 * 1000.0
    assert kg[0] == pytest.approx(g.mass + m_p)
    expect = (g.mass * np.array([0, 0, 0.048]) + m_p * np.array([0.0, -0.01, 0.127])) / (g.mass + m_p)
    np.testing.assert_allclose(com[0], expect, atol=1e-9)
    # the Robotiq: the part rides at the TCP of the grasp width (further out when closed narrower)
    rq = load_gripper("robotiq_2f_85")
    _, c = flange_payload(rq, mp, T[None], np.array([0.03]))
    z_part = rq.T_flange_tcp_at(0.03)[2, 3]
    assert c[0, 2] == pytest.approx((rq.mass * rq.com[2] + m_p * z_part) / (rq.mass + m_p))
    # no gripper mass: no payload
    q = load_gripper("round_mesh_jaws")
    from dataclasses import replace as _replace
    assert flange_payload(_replace(q, mass=None, com=None), mp, T[None], np.array([0.03])) is None


def test_simulate_grasps_reports_the_payload():
    import trimesh

    from grasplan.sim.simulate import simulate_grasps

    block = trimesh.creation.box(extents=(0.12, 0.03, 0.03))
    T_world_part = np.eye(4)
    T_world_part[:3, 3] = [0.45, 0.0, 0.015]
    T = np.eye(4)
    T[:3, 0], T[:3, 2] = [0, 1, 0], [0, 0, -1]
    T[:3, 1] = np.cross(T[:3, 2], T[:3, 0])
    g = load_gripper("schunk_egp_c_40")
    res = simulate_grasps(block, g, T_world_part, T[None], np.array([0.03]), mass=0.2, decomposition="hull",
                          cache=False)
    assert res.payload_kg is not None and res.payload_kg[0] == pytest.approx(g.mass + 0.2)
    np.testing.assert_allclose(res.payload_com[0], (g.mass * g.com + 0.2 * np.array([0, 0, 0.127])) / (g.mass + 0.2),
                               atol=1e-9)
