"""The depth-tolerant lift rule (PickParams.lift_depth, grasplan/pick/depth.py): a part sliding up
beside a neighbour it touches is picked, one whose lift drags it through a neighbour is refused
naming it; every accepted lift contact re-checked by python-fcl plus an independent depth
(tests/pick_recheck.py: trimesh samples, winding number, exact closest points)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from pick_recheck import mesh_depth, recheck_pick  # noqa: E402

from grasplan.cell.model import load_cell  # noqa: E402
from grasplan.cell.shapes import bvh  # noqa: E402
from grasplan.part.mesh import load_part  # noqa: E402
from grasplan.geometry.meshdata import convex_hull  # noqa: E402
from grasplan.pick import Picker, PickParams  # noqa: E402
from grasplan.pick.depth import PartDepth, pair_depth  # noqa: E402
from grasplan.piles.scene_file import Instance, Scene  # noqa: E402
from grasplan.cell.resting import stable_pose  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BRACKET = ROOT / "examples" / "parts" / "bracket.stl"


def _depth_model(mesh):
    return PartDepth.build(mesh, bvh(mesh.vertices, mesh.faces), np.asarray(convex_hull(np.asarray(mesh.vertices)).vertices))


@pytest.fixture(scope="module")
def bracket():
    return load_part(BRACKET)


@pytest.fixture(scope="module")
def rest(bracket):
    return stable_pose(bracket.mesh, load_cell("bin"))


def at(T, dx=0.0, dy=0.0, dz=0.0):
    out = np.array(T, dtype=np.float64)
    out[:3, 3] += [dx, dy, dz]
    return out


def _world_extent(mesh, T):
    w = np.asarray(mesh.vertices) @ T[:3, :3].T + T[:3, 3]
    return w.min(axis=0), w.max(axis=0)


@pytest.mark.parametrize("axis,overlap", [(0, 0.0005), (1, 0.0015), (2, 0.003)])
def test_pair_depth_agrees_with_independent_depth(bracket, rest, axis, overlap):
    m = bracket.mesh
    lo, hi = _world_extent(m, rest)
    d = np.zeros(3)
    d[axis] = (hi - lo)[axis] - overlap  # the copy shifted so that the two overlap by `overlap` along the axis
    Tb = at(rest, *d)
    model = _depth_model(m)
    got = pair_depth(model, rest, model, Tb)
    ref = mesh_depth(m, rest, m, Tb)
    assert got == pytest.approx(ref, abs=3e-4)
    assert got <= overlap + 1e-6          # no point is deeper than the overlap of the boxes
    # "deeper than stop?" answered both ways (the k-d tree filter skips points within stop of the surface)
    assert pair_depth(model, rest, model, Tb, stop=0.5 * ref) > 0.5 * ref
    assert pair_depth(model, rest, model, Tb, stop=ref + 3e-4) <= ref + 3e-4
    apart = pair_depth(model, rest, model, at(Tb, *(0.01 * np.eye(3)[axis])))
    assert apart == 0.0
    # capped: exact below the cap, at least the cap otherwise (the resting depth's use)
    for cap in (0.25 * got, 0.9 * got, got + 1e-4, 2 * got + 1e-3):
        assert min(pair_depth(model, rest, model, Tb, cap=cap), cap) == pytest.approx(min(got, cap), abs=1e-12)


def _scene(rest, gap_axis: int, dz_b: float, overlap: float, mesh):
    lo, hi = _world_extent(mesh, rest)
    d = np.zeros(3)
    d[gap_axis] = (hi - lo)[gap_axis] - overlap
    return Scene(instances=(Instance("a", "bracket", rest), Instance("b", "bracket", at(rest, d[0], d[1], d[2] + dz_b))), cell="bin")


@pytest.mark.parametrize("gap_axis", [0, 1])
def test_sliding_up_beside_a_touching_neighbour_is_picked_and_rechecked(bracket, rest, gap_axis):
    # straight lifts only (a lift tilted away from b would leave it without touching)
    strict = Picker("ur5", gripper="long_stroke_50", params=PickParams(grasps_per_instance=8, lift_depth=0.0, max_lift_tilt_deg=0.0))
    strict.add_part("bracket", bracket)
    sc = _scene(rest, gap_axis, 0.0, 0.0005, bracket.mesh)  # side by side, 0.5 mm of pose noise
    a = strict.plan(sc).report("a")
    assert a.status == "blocked" and a.blocked_by == ("b",), a      # the strict rule: dragged through b
    tol = Picker("ur5", gripper="long_stroke_50", params=PickParams(grasps_per_instance=8, lift_depth=0.001, max_lift_tilt_deg=0.0))
    tol.add_part("bracket", bracket)
    res = tol.plan(sc)
    assert res.report("a").status == "picked", res.report("a")
    pick = res.pick("a")
    rep = recheck_pick(tol.robot, tol.gripper, res.cell, pick, sc.instances, {"bracket": bracket.mesh},
                       lift_contact=res.params.lift_contact, lift_depth=res.params.lift_depth)
    assert rep.ok, rep.problems
    assert rep.lift_depths and max(rep.lift_depths) <= 0.001 + 3e-4   # it did touch b along the lift, shallowly
    # the same pick re-checked with the strict rule fails: the tolerance is what let it through
    strict_rep = recheck_pick(tol.robot, tol.gripper, res.cell, pick, sc.instances, {"bracket": bracket.mesh},
                              lift_contact=res.params.lift_contact, lift_depth=0.0)
    assert not strict_rep.ok and "instance_b" in strict_rep.problems[0]


def test_dragged_through_a_neighbour_deeper_than_the_tolerance_is_refused(bracket, rest):
    # lift_carry off: b lying on a would be raised (tests/test_pick_carry.py)
    pk = Picker("ur5", gripper="long_stroke_50", params=PickParams(grasps_per_instance=8, lift_depth=0.001, lift_carry=False))
    pk.add_part("bracket", bracket)
    lo, hi = _world_extent(bracket.mesh, rest)
    # b lies across a's far half, resting on it (0.2 mm of pose noise): lifting a pushes into b
    sc = Scene(instances=(Instance("a", "bracket", rest),
                          Instance("b", "bracket", at(rest, 0.5 * (hi - lo)[0], dz=(hi - lo)[2] - 0.0002))), cell="bin")
    res = pk.plan(sc)
    a = res.report("a")
    assert a.status == "blocked" and a.blocked_by == ("b",), a
    assert "instance:b" in a.reason and "mm deeper than the 0.2 mm of resting overlap counted; at most 1 mm allowed" in a.reason, a.reason
    assert "tilted lifts (15/30/45 deg from the retreat)" in a.reason, a.reason  # b lies on it: no way up


BOX = ROOT / "examples" / "parts" / "box.stl"


@pytest.fixture(scope="module")
def leaning():
    """Two 30 x 20 x 10 mm boxes: b rests on a's +x edge, overlapping it by 1.5 mm in x (lying on it):
    a's straight lift pushes 1.5 mm into b, beyond the 1 mm of --lift-depth."""
    box = load_part(BOX)
    rest = stable_pose(box.mesh, load_cell("bin"))
    lo, hi = _world_extent(box.mesh, rest)
    b = at(rest, (hi - lo)[0] - 0.0015, 0.0, (hi - lo)[2])
    return box, Scene(instances=(Instance("a", "box", rest), Instance("b", "box", b)), cell="bin")


def test_straight_lift_through_a_leaning_neighbour_is_replaced_by_a_tilted_one(leaning, tmp_path):
    box, sc = leaning
    # straight lifts only, none raising b (lift_carry: tests/test_pick_carry.py)
    straight = Picker("ur5", gripper="long_stroke_50", params=PickParams(grasps_per_instance=8, max_lift_tilt_deg=0.0, lift_carry=False))
    straight.add_part("box", box)
    a = straight.plan(sc).report("a")
    assert a.status == "blocked" and a.blocked_by == ("b",) and "tilted" not in a.reason, a
    pk = Picker("ur5", gripper="long_stroke_50", params=PickParams(grasps_per_instance=8))
    pk.add_part("box", box)
    res = pk.plan(sc)
    rep = res.report("a")
    assert rep.status == "picked" and "deg from the retreat" in rep.reason, rep
    pick = res.pick("a")
    assert pick.carries == ()  # a clean tilted lift comes before one raising b
    lift = pick.T_world_lifted[:3, 3] - pick.T_world_tcp[:3, 3]
    assert np.linalg.norm(lift) == pytest.approx(res.cell.retreat_distance)
    tilt = np.degrees(np.arccos(lift[2] / np.linalg.norm(lift)))
    assert tilt == pytest.approx(15.0, abs=1e-6) or tilt == pytest.approx(30.0) or tilt == pytest.approx(45.0)
    assert lift[0] < 0  # away from b (on a's +x edge)
    np.testing.assert_allclose(pick.T_world_lifted[:3, :3], pick.T_world_tcp[:3, :3])
    # the motion's lift segment ends at the pick's own lifted TCP (forward kinematics, not the record)
    from fcl_recheck import RobotLinks as Links  # Pinocchio FK from the URDF, not grasplan's

    l0, l1 = pick.motion.segment("lift")
    tcp = Links(res.robot, res.gripper.T_flange_tcp).fk_tcp(np.asarray(pick.motion.path)[l1])
    np.testing.assert_allclose(tcp[:3, 3], pick.T_world_lifted[:3, 3], atol=5e-4)
    # re-checked independently (python-fcl, trimesh depths) along the pick's own lift: it touches b, shallowly
    rc = recheck_pick(pk.robot, pk.gripper, res.cell, pick, sc.instances, {"box": box.mesh},
                      lift_contact=res.params.lift_contact, lift_depth=res.params.lift_depth)
    assert rc.ok, rc.problems
    # and the independent depth confirms the straight lift was rightly refused: 5 mm up, a is > 1 mm into b
    up = at(sc.instances[0].T_world_part, dz=0.005)
    assert mesh_depth(box.mesh, up, box.mesh, sc.instances[1].T_world_part) > 0.001 + 3e-4
    # the picks file and a robot program follow the pick's own lift (the export checks its lift segment)
    from click.testing import CliRunner

    from grasplan.cli import main

    out = res.write(tmp_path / "picks.json")
    r = CliRunner().invoke(main, ["export", str(out), "--format", "urscript", "--instance", "a",
                                  "-o", str(tmp_path / "a.script")])
    assert r.exit_code == 0, r.output


@pytest.mark.parametrize("cap,picked", [(0.003, True), (0.001, False)])
def test_a_neighbour_overlapping_at_rest_blocks_only_when_the_lift_goes_deeper(cap, picked):
    """Side by side, 2.5 mm into each other at rest (a pose estimate's error): the straight lift slides
    a up beside b at that depth, no deeper: picked when the resting depth counts (up to --overlap-tol
    3 mm), refused when only 1 mm of it may count (2.5 - 1 > 1 mm of --lift-depth)."""
    box = load_part(BOX)
    rest = stable_pose(box.mesh, load_cell("bin"))
    lo, hi = _world_extent(box.mesh, rest)
    sc = Scene(instances=(Instance("a", "box", rest), Instance("b", "box", at(rest, (hi - lo)[0] - 0.0025))), cell="bin")
    pk = Picker("ur5", gripper="long_stroke_50", params=PickParams(grasps_per_instance=8, max_lift_tilt_deg=0.0, overlap_tol=cap))
    pk.add_part("box", box)
    res = pk.plan(sc)
    a = res.report("a")
    if not picked:
        assert a.status == "blocked" and "mm deeper than the 1.0 mm of resting overlap counted" in a.reason, a
        return
    assert a.status == "picked", a
    rc = recheck_pick(pk.robot, pk.gripper, res.cell, res.pick("a"), sc.instances, {"box": box.mesh},
                      lift_contact=res.params.lift_contact, lift_depth=res.params.lift_depth, rest_cap=cap)
    assert rc.ok, rc.problems
    assert rc.lift_depths and max(rc.lift_depths) <= 0.001 + 3e-4
    # the absolute rule (no resting depth counted) refuses the same lift: 2.5 mm deep along it
    absolute = recheck_pick(pk.robot, pk.gripper, res.cell, res.pick("a"), sc.instances, {"box": box.mesh},
                            lift_contact=res.params.lift_contact, lift_depth=res.params.lift_depth)
    assert not absolute.ok and "instance_b" in absolute.problems[0]
