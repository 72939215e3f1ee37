"""grasplan pick / grasplan.Picker: picks from piles, re-checked independently with python-fcl.

Scenes are built here from the example bracket (40 x 30 x 20 mm) resting on the bin floor: a row
of instances, a neighbour blocking an instance's best grasp, a cloud blocking it, a stacked pair.
Every pick is re-checked by tests/pick_recheck.py (python-fcl: robot, jaws, bin, table, every other
instance present, the cloud's leaf cubes, the carried part during the lift)."""
from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from pick_recheck import recheck_pick  # noqa: E402

from grasplan.cell.model import load_cell  # noqa: E402
from grasplan.errors import InputError  # noqa: E402
from grasplan.part.mesh import load_part  # noqa: E402
from grasplan.pick import Picker, PickParams  # noqa: E402
from grasplan.pick.rank import instance_order, rank_grasps  # noqa: E402
from grasplan.piles.scene_file import Instance, Scene, ScenePart  # noqa: E402
from grasplan.cell.resting import stable_pose  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BRACKET = ROOT / "examples" / "parts" / "bracket.stl"
BOX = ROOT / "examples" / "parts" / "box.stl"


@pytest.fixture(scope="module")
def picker():
    pk = Picker("ur5", gripper="long_stroke_50", params=PickParams(grasps_per_instance=8))
    pk.add_part("bracket", load_part(BRACKET))
    pk.add_part("box", load_part(BOX))
    return pk


@pytest.fixture(scope="module")
def rest():
    """The bracket's resting pose on the bin floor (at the floor's centre)."""
    return stable_pose(load_part(BRACKET).mesh, load_cell("bin"))


def at(T, dx=0.0, dy=0.0, dz=0.0):
    out = np.array(T, dtype=np.float64)
    out[:3, 3] += [dx, dy, dz]
    return out


def scene(*instances, cloud=None):
    return Scene(instances=tuple(Instance(i, p, T) for i, p, T in instances), cell="bin", cloud=cloud)


def meshes(picker):
    return {n: picker._parts[n].mesh for n in picker.parts()}


def assert_rechecked(picker, res, present, cloud=None, resolution=0.005):
    """Every pick of ``res`` is free for python-fcl against ``present[pick]`` (default: the scene)."""
    assert res.picks
    for p in res.picks:
        insts = present.get(p.instance, res.scene.instances) if isinstance(present, dict) else res.scene.instances
        rep = recheck_pick(picker.robot, picker.gripper, res.cell, p, insts, meshes(picker), cloud=cloud,
                           resolution=resolution, lift_contact=res.params.lift_contact,
                           lift_depth=res.params.lift_depth)
        assert rep.configs > 20
        assert rep.ok, (p.instance, rep.problems)
        # the pick holds its part where the scene says, and the motion reaches the grasp
        np.testing.assert_allclose(p.T_world_tcp, p.T_world_part @ p.T_part_tcp, atol=1e-9)
        np.testing.assert_allclose(p.motion.q_grasp, p.motion.path[p.motion.grasp_index])


def test_row_of_instances_every_pick_rechecked(picker, rest):
    sc = scene(("a", "bracket", at(rest, -0.08)), ("b", "bracket", rest), ("c", "bracket", at(rest, 0.08, 0.03)))
    res = picker.plan(sc)
    assert {r.status for r in res.instances} == {"picked"}, [r.reason for r in res.instances]
    assert [p.instance for p in res.picks] == [r for r in instance_order(
        sc.ids, {i: (picker._cells[res.cell].world.instances[i].center, picker._cells[res.cell].world.instances[i].half)
                 for i in sc.ids}) if res.report(r).status == "picked"]
    assert_rechecked(picker, res, {})
    assert res.timing_s["first_pick"] <= res.timing_s["plan"]
    doc = res.to_json()
    from grasplan.schemas.documents import validate

    assert validate(json.loads(json.dumps(doc))) == "grasplan.picks/1"


def _best_free(picker, sc, iid):
    """The pick a scene of ``iid`` alone gives (its best feasible grasp)."""
    res = picker.plan(sc)
    return res.pick(iid)


def test_neighbour_blocking_the_best_grasp_is_named(picker, rest):
    alone = scene(("a", "bracket", rest))
    best = _best_free(picker, alone, "a")
    # a box floating where that grasp's gripper body is, 60 mm above the TCP (not touching the bracket)
    T_b = best.T_world_tcp @ np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -0.06], [0, 0, 0, 1.0]])
    sc = scene(("a", "bracket", rest), ("b", "box", T_b))
    res = picker.plan(sc)
    rep = res.report("a")
    assert "b" in rep.blocked_by, rep
    if rep.status == "picked":
        p = res.pick("a")
        assert not np.allclose(p.T_part_tcp, best.T_part_tcp)
        assert_rechecked(picker, res, {})
    else:  # every other grasp collides or has no motion: the reason says so
        assert rep.status in ("blocked", "ik_collision", "lift_collision", "unreachable", "no_path"), rep
        assert "instance:b" in rep.reason
    # the blocked grasp itself: the gripper check names b
    st = picker._cells[res.cell]
    st.world.set_instances(sc.instances)
    first, bodies = st.world.gripper_hits("bracket", "a", best.T_world_tcp[None], np.array([best.width]))
    assert first[0] >= 0 and bodies[first[0]].name == "instance:b"


def test_cloud_blocking_the_best_grasp(picker, rest, tmp_path):
    from grasplan.piles.scene_file import CloudSpec

    alone = scene(("a", "bracket", rest))
    best = _best_free(picker, alone, "a")
    # a 3 x 3 x 3 block of points 60 mm above that grasp's TCP (inside the gripper body there)
    g = np.stack(np.meshgrid(*[np.linspace(-0.01, 0.01, 3)] * 3, indexing="ij"), -1).reshape(-1, 3)
    centre = (best.T_world_tcp @ [0, 0, -0.06, 1.0])[:3]
    pts = centre + g
    np.save(tmp_path / "scan.npy", pts)
    sc = Scene(instances=(Instance("a", "bracket", rest),), cell="bin",
               cloud=CloudSpec(path=str(tmp_path / "scan.npy"), resolution=0.005))
    res = picker.plan(sc)
    rep = res.report("a")
    assert "cloud" in rep.reason and rep.blocked_by == ()
    if rep.status == "picked":
        p = res.pick("a")
        assert not np.allclose(p.T_part_tcp, best.T_part_tcp)
        assert_rechecked(picker, res, {}, cloud=pts, resolution=0.005)
    else:
        assert rep.status in ("cloud", "ik_collision", "lift_collision", "unreachable", "no_path"), rep


def test_stacked_pair_top_first_bottom_blocked_by_it(picker, rest):
    sc = scene(("bottom", "bracket", rest), ("top", "bracket", at(rest, dz=0.0201)))
    res = picker.plan(sc)
    assert res.picks[0].instance == "top"
    bottom = res.report("bottom")
    assert bottom.status == "blocked" and bottom.blocked_by == ("top",), bottom
    assert_rechecked(picker, res, {})
    seq = picker.plan(sc, sequence=True)
    assert [p.instance for p in seq.picks] == ["top", "bottom"]
    assert seq.report("bottom").status == "picked"
    # each pick re-checked against what was still in the pile when it was planned
    top_present = list(sc.instances)
    assert_rechecked(picker, seq, {"top": top_present, "bottom": [i for i in sc.instances if i.id == "bottom"]})


def test_warm_picker_moves_and_removes_without_reload(picker, rest):
    sc = scene(("a", "bracket", at(rest, -0.06)), ("b", "bracket", at(rest, 0.06)))
    res = picker.plan(sc)
    st = picker._cells[res.cell]
    scenes = dict(st.scenes)
    moved = sc.with_poses({"b": at(rest, 0.07, 0.02)})
    res2 = picker.plan(moved.without("a"))
    assert st.scenes == scenes  # the same CollisionScene objects: nothing rebuilt
    assert [r.id for r in res2.instances] == ["b"] and res2.report("b").status == "picked"
    np.testing.assert_allclose(res2.pick("b").T_world_part, at(rest, 0.07, 0.02))
    assert_rechecked(picker, res2, {})
    # a parsed document naming a part the picker knows (the README's vision loop)
    doc = {"schema": "grasplan.scene/1", "cell": "bin", "parts": {"bracket": {}},
           "instances": [{"id": "b", "part": "bracket", "T": at(rest, 0.07, 0.02).tolist()}]}
    res3 = picker.plan(doc, max_picks=1)
    assert st.scenes == scenes and res3.report("b").status == "picked"
    np.testing.assert_allclose(res3.pick("b").motion.path, res2.pick("b").motion.path)  # deterministic


def test_scene_checks_below_floor_is_an_error_overlap_a_warning(picker, rest):
    with pytest.raises(InputError, match=r"instance 'a'.*below the bin floor"):
        picker.plan(scene(("a", "bracket", at(rest, dz=-0.005))))
    res = picker.plan(scene(("a", "bracket", rest), ("b", "bracket", at(rest, 0.035))), max_picks=1)
    assert any("'a' and 'b' interpenetrate" in w for w in res.warnings), res.warnings
    # parts 5 mm into each other cannot be lifted apart: each is blocked by the other
    assert res.picks == () and res.report("a").blocked_by == ("b",) and res.report("b").blocked_by == ("a",)
    res = picker.plan(scene(("a", "bracket", at(rest, -0.06)), ("b", "bracket", at(rest, 0.06))), max_picks=1)
    assert res.warnings == () and len(res.picks) == 1
    assert sorted(r.status for r in res.instances) == ["not_tried", "picked"]


def test_unknown_part_lists_the_known_ones(picker, rest):
    with pytest.raises(InputError, match="known parts: bracket, box"):
        picker.plan(scene(("a", "gear", rest)))


def test_rank_grasps_refuses_grasps_from_below():
    T_part_tcp = np.array([np.eye(4), np.diag([1.0, -1.0, -1.0, 1.0])])  # TCP z up, TCP z down
    rows, T = rank_grasps(np.eye(4), T_part_tcp, np.array([0.9, 0.1]), PickParams(max_tilt_deg=60))
    assert rows.tolist() == [1]
    np.testing.assert_allclose(T[0], T_part_tcp[1])


def test_cli_pick_writes_picks_and_exit_4_when_nothing_can_be_picked(tmp_path, rest):
    import yaml
    from click.testing import CliRunner

    from grasplan.cli import main

    doc = {"schema": "grasplan.scene/1", "cell": "bin",
           "parts": {"bracket": {"mesh": str(BRACKET), "units": "auto"}},
           "instances": [{"id": "a", "part": "bracket", "T": rest.tolist()},
                         {"id": "b", "part": "bracket", "T": at(rest, 0.07).tolist()}]}
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(doc))
    out = tmp_path / "picks.json"
    r = CliRunner().invoke(main, ["pick", str(tmp_path / "s.yaml"), "-o", str(out), "--sequence"])
    assert r.exit_code == 0, r.output
    d = json.loads(out.read_text())
    from grasplan.schemas.documents import validate

    assert validate(d) == "grasplan.picks/1"
    assert [p["instance"] for p in d["picks"]] and d["sequence"] is True
    assert {i["id"] for i in d["instances"]} == {"a", "b"} and "first_pick" in d["timing_s"]
    # read back: the same picks, motions re-checked by FK
    import grasplan

    back = grasplan.load_picks(out)
    assert [p.instance for p in back.picks] == [p["instance"] for p in d["picks"]]
    np.testing.assert_allclose(back.picks[-1].motion.path, d["picks"][-1]["path"])
    last, first = d["picks"][-1]["instance"], d["picks"][0]["instance"]
    script = tmp_path / "pick.script"
    r = CliRunner().invoke(main, ["export", str(out), "--format", "urscript", "--instance", last, "-o", str(script)])
    assert r.exit_code == 0, r.output
    assert "movej" in script.read_text()
    html = tmp_path / "view.html"
    r = CliRunner().invoke(main, ["view", str(out), "--instance", first, "-o", str(html)])
    assert r.exit_code == 0, r.output
    other = ({"a", "b"} - {first}).pop()
    assert f"instance_{other}" in html.read_text()  # still in the pile: drawn as an obstacle of the cell
    r = CliRunner().invoke(main, ["export", str(out), "--format", "urscript", "--instance", "nope", "-o", str(script)])
    assert r.exit_code == 3 and "picked: " in r.output
    # out of reach: on the table 2 m away
    doc2 = dict(doc, cell="table", instances=[{"id": "far", "part": "bracket", "T": at(rest, 1.6, 0, -0.01).tolist()}])
    (tmp_path / "far.yaml").write_text(yaml.safe_dump(doc2))
    out2 = tmp_path / "far.json"
    r = CliRunner().invoke(main, ["pick", str(tmp_path / "far.yaml"), "-o", str(out2)])
    assert r.exit_code == 4, r.output
    d2 = json.loads(out2.read_text())
    assert d2["picks"] == [] and d2["instances"][0]["status"] == "unreachable"
    r = CliRunner().invoke(main, ["export", str(out2), "--format", "urscript", "-o", str(tmp_path / "far.script")])
    assert r.exit_code == 3 and "has no pick (1 instances: 1 unreachable; e.g. far: " in r.output, r.output
    assert not (tmp_path / "far.script").exists()
    # the viewer shows the pile and why each instance cannot be picked
    r = CliRunner().invoke(main, ["view", str(out2), "-o", str(tmp_path / "far.html")])
    assert r.exit_code == 0, r.output
    page = (tmp_path / "far.html").read_text()
    data = json.loads(re.search(r'<script id="grasplan-data" type="application/json">(.*?)</script>', page,
                                re.S).group(1))
    assert data["counts"].get("planned", 0) == 0 and data["part"]["nf"] == len(load_part(BRACKET).mesh.faces)
    assert any(n.startswith(f"far (bracket): unreachable: {d2['instances'][0]['reason'][:40]}") for n in data["notes"])


def test_broad_phase_agrees_with_every_pair(picker, rest):
    """A scene with extras checks through coal's broad phase: the same answer as every active pair."""
    sc = scene(("a", "bracket", at(rest, -0.05)), ("b", "bracket", at(rest, 0.05)), ("c", "box", at(rest, 0, 0.06, 0.006)))
    res = picker.plan(sc)
    st = picker._cells[res.cell]
    static, att = next(iter(st.variants.values()))
    rng = np.random.default_rng(3)
    q0 = res.picks[0].motion.q_grasp
    qs = np.vstack([res.picks[0].motion.path, q0 + rng.normal(0, 0.4, (300, 6))])
    qs = np.clip(qs, picker.robot.lower, picker.robot.upper)
    for s in (static, att):
        fast = [s.is_free(q, 0.02) for q in qs]
        ref = [s.is_free_exhaustive(q, 0.02) for q in qs]
        assert fast == ref
        assert 0 < sum(ref) < len(ref)  # both kinds of configuration were tested


def test_pick_and_place_rechecked(rest):
    """--place: the lifted part is carried to the place on the table beside the bin, lowered,
    released; the whole motion re-checked (the neighbour still in the bin)."""
    pk = Picker("ur5", gripper="long_stroke_50", params=PickParams(grasps_per_instance=8, place=tuple(map(tuple, at(rest, 0.0, 0.32, -0.01)))))
    pk.add_part("bracket", load_part(BRACKET))
    sc = scene(("a", "bracket", at(rest, -0.06)), ("b", "bracket", at(rest, 0.06)))
    res = pk.plan(sc, max_picks=1)
    assert len(res.picks) == 1, [r.reason for r in res.instances]
    m = res.picks[0].motion
    assert [s[0] for s in m.segments] == ["transit", "approach", "lift", "transfer", "descend", "retreat"]
    np.testing.assert_allclose(m.T_world_part_place, at(rest, 0.0, 0.32, -0.01))
    assert_rechecked(pk, res, {})
    doc = json.loads(json.dumps(res.to_json()))
    from grasplan.pick.reader import result_from_picks

    back = result_from_picks(doc)
    np.testing.assert_allclose(back.picks[0].motion.T_world_part_place, m.T_world_part_place)


def test_cli_refuses_an_output_over_a_file_the_scene_reads(tmp_path, rest):
    import shutil

    import yaml
    from click.testing import CliRunner

    from grasplan.cli import main

    mesh = tmp_path / "bracket.stl"
    shutil.copy(BRACKET, mesh)
    doc = {"schema": "grasplan.scene/1", "cell": "bin", "parts": {"bracket": {"mesh": "bracket.stl"}},
           "instances": [{"id": "a", "part": "bracket", "T": rest.tolist()}]}
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(doc))
    before = mesh.read_bytes()
    r = CliRunner().invoke(main, ["pick", str(tmp_path / "s.yaml"), "-o", str(mesh)])
    assert r.exit_code == 3, r.output
    assert mesh.read_bytes() == before


def test_lift_shortcut_still_checks_the_arm(picker, rest):
    """At the lift's waypoints the robot check skips only what the checks before IK decided (the
    gripper against the world, the carried part against the neighbours, the cloud and the cell): a
    neighbour where the wrist passes during the lift is still a lift collision of that link."""
    from grasplan.motion.lift_check import _drop_pairs, lift_collision, lift_precheck_drop
    from grasplan.motion.pickplace import T_tcp_part_of

    pk = picker.plan(scene(("a", "bracket", rest))).pick("a")
    s, e = pk.motion.segment("lift")
    lift = pk.motion.path[s:e + 1]
    T_x = picker.robot.frame_pose(lift[len(lift) // 2], "wrist_1_link")  # a bracket at the wrist, half-way up
    sc = scene(("a", "bracket", rest), ("x", "bracket", T_x))
    res = picker.plan(sc, max_picks=0)
    st = picker._cells[res.cell]
    static, att = picker._variants(st, sc.instances[0], list(sc.instances), False)
    att.move_attached(T_tcp_part_of(pk.T_part_tcp))
    drop = lift_precheck_drop(att)
    for (a, b, kind, group, extra), d in zip(att.pair_rows(), drop):
        gripper_world = (a.startswith("gripper:") or b.startswith("gripper:")) and kind != "self"
        part_world = group == "attached" and not (a.endswith("_link") or b.endswith("_link"))  # not the arm
        assert d == (gripper_world or part_world), (a, b)
    ids = _drop_pairs(att)[1]  # level 2: every pair the checks before IK decide
    active = att._active.copy()
    att.switch_pairs(ids, False)
    at_x = att.colliding_pairs(lift[len(lift) // 2], pk.width)  # the waypoint next to x, the pairs kept
    att.switch_pairs(ids, True)
    assert np.array_equal(att._active, active)
    assert any("instance:x" in (p[0], p[1]) and "link" in p[0] + p[1] for p in at_x), at_x
    assert not any(p[0].startswith("gripper:") or p[1].startswith("gripper:") for p in at_x if p[2] != "self"), at_x
    covered = np.ones(len(lift), dtype=bool)  # as if every waypoint passed the checks before IK
    for cov, d in ((None, None), (covered, ids)):
        pairs = lift_collision(att, lift, pk.width, 1, None, cov, d)
        assert pairs and any("instance:x" in (p[0], p[1]) and "link" in p[0] + p[1] for p in pairs), pairs
    assert np.array_equal(att._active, active)  # every pair switched back on


def test_resting_shortcut_matches_every_pair(picker, rest, monkeypatch):
    """lift_check.lift_collision decides a resting lift configuration with the part's support pairs
    switched off (and the pairs the checks before IK decided): on every lift of these plans its
    answer is the reference's, every configuration checked with every pair (a resting one may touch
    only supports, the others only neighbours within the depth rule), the same first colliding
    configuration reported; resting configurations in contact were met."""
    import grasplan.motion.lift_check as lift_check
    import grasplan.motion.grasp_motion as motion
    from grasplan.geometry.interpolation import interpolate_path

    seen = []
    orig = lift_check.lift_collision

    def reference(sc, path, width, n_touch, shallow, resting, record):
        n_touch = int(min(max(n_touch, 0), len(path) - 1))
        for k0, k1, support in ((n_touch, len(path), False), (0, n_touch + 1, True)):
            if support and n_touch == 0:
                continue
            for q in interpolate_path(path[k0:k1]):
                pairs = sc.colliding_pairs(q, width)
                rests = support and (resting is None or bool(resting(q[None])[0]))
                if rests and record:
                    seen.append(bool(pairs))
                    scenes.append((sc, np.array(q), width))
                if pairs and not (rests and lift_check._support_only(pairs)) and not (
                        shallow is not None and (names := lift_check._part_vs_instances(pairs)) and shallow(q, names)):
                    return pairs
        return None

    def both(sc, path, width, n_touch, shallow=None, covered=None, drop=None, resting=None):
        got = orig(sc, path, width, n_touch, shallow, covered, drop, resting)
        assert got == reference(sc, path, width, n_touch, shallow, resting, True)
        # no configuration may rest and no depth rule: a contact with a support is a hit (the pairs
        # the checks before IK decided stay off: they decided with the depth rule, so not here)
        never = lambda qs: np.zeros(len(qs), dtype=bool)  # noqa: E731
        for n in (n_touch, len(path) - 1):  # the lift's own split, and every waypoint a support one
            assert orig(sc, path, width, n, None, None, None, never) == reference(sc, path, width, n, None, never, False)
        # a model the boxes cannot serve (scene_open None): coal alone, the same answer
        with monkeypatch.context() as m:
            m.setattr(lift_check, "scene_open", lambda *a: None)
            assert orig(sc, path, width, n_touch, shallow, covered, drop, resting) == got
            assert orig(sc, path, width, len(path) - 1, None, None, None, None) == reference(
                sc, path, width, len(path) - 1, None, None, False)
        return got

    scenes: list = []

    monkeypatch.setattr(motion, "lift_collision", both)
    w = np.asarray(load_part(BRACKET).mesh.vertices) @ rest[:3, :3].T
    dx, dy = (w.max(axis=0) - w.min(axis=0))[:2] - 0.0003  # neighbours touching it, 0.3 mm into it
    res = picker.plan(scene(("a", "bracket", rest), ("b", "bracket", at(rest, dx)), ("c", "bracket", at(rest, -dx)),
                            ("d", "bracket", at(rest, 0.0, dy))))
    assert res.picks and any(seen)  # resting samples in contact were met
    # and a resting sample where the arm is in the table or the bin as well: not allowed either way
    sc, q, width = scenes[-1]
    bad = 0
    for k in range(1, 40):
        qb = q.copy()
        qb[1 + k % 3] += 0.05 * k * (-1) ** k
        pairs = sc.colliding_pairs(qb, width)
        if pairs and not lift_check._support_only(pairs):
            assert lift_check.sample_ok(sc, qb, width, True, None) is False
            # a path resting all along (the far end free: the arm at home): qb's pairs are still reported
            assert orig(sc, np.stack([qb, picker.robot.q_home]), width, 1) is not None
            bad += 1
    assert bad >= 3
    assert orig(sc, np.stack([picker.robot.q_home, picker.robot.q_home]), width, 1) is None


def test_warm_builds_what_the_first_plan_needs(rest, monkeypatch):
    """Picker.warm() (the service calls it at start): afterwards a first plan builds no depth probes,
    voxel grid or scene-check probe data (each builder here refuses to run)."""
    import grasplan.geometry.insidegrid as ig
    import grasplan.pick.depth as depth
    import grasplan.piles.checks as pc
    from grasplan.cell.model import load_cell as _load_cell

    pk = Picker("ur5", gripper="long_stroke_50", cell=_load_cell("bin"), params=PickParams(grasps_per_instance=8))
    pk.add_part("bracket", load_part(BRACKET))
    pk.warm()

    def refuse(*a, **k):
        raise AssertionError("built during the plan")

    monkeypatch.setattr(ig.InsideGrid, "build", classmethod(refuse))
    monkeypatch.setattr(depth.PartDepth, "build", classmethod(refuse))
    monkeypatch.setattr(pc, "surface_samples", refuse)
    w = np.asarray(load_part(BRACKET).mesh.vertices) @ rest[:3, :3].T
    dx = float(np.ptp(w[:, 0])) - 0.0003
    res = pk.plan(scene(("a", "bracket", rest), ("b", "bracket", at(rest, dx))))
    assert res.picks
    # without a fixed cell (the scene names it) warm() still builds every part's voxel grid
    free = Picker("ur5", gripper="long_stroke_50", params=PickParams(grasps_per_instance=8))
    free.add_part("box", load_part(BOX))
    monkeypatch.undo()
    free.warm()
    assert free._parts["box"].mesh in ig._GRIDS
