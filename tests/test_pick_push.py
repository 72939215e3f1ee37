"""``grasplan pick --push`` (grasplan/pick/push.py): when nothing can be picked, a push of a part
boxed in by a bin wall, away from it; checked against the picks schema, against Pinocchio's
forward kinematics along its joint path (the path comes from the closed-form IK and line
tracker), and against the geometry of the part and the wall. ``--min-gravity-margin 100`` makes
every grasp too weak to plan (code ``grasps_weak``), so the push is what is left."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from grasplan.cell.model import load_cell
from grasplan.cell.resting import stable_pose
from grasplan.cli import main
from grasplan.part.mesh import load_part
from grasplan.pick import Picker
from grasplan.pick.codes import PUSHABLE, PickStatus, pushable
from grasplan.pick.push import CLEAR, MAX_PUSH, MIN_PUSH, TIP_GAP
from grasplan.piles.scene_file import Instance, Scene, ScenePart
from grasplan.robot.description import load_robot

from test_viewer import needs_chromium, run_chromium

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "parts"
BOX = EXAMPLES / "box.stl"
SCHEMA = Path(__file__).resolve().parents[1] / "grasplan" / "schemas" / "picks.schema.json"


def _near_wall(gap: float) -> np.ndarray:
    """The box resting in the bin, its hull ``gap`` from the +x wall's inner face."""
    cell = load_cell("bin")
    part = load_part(BOX)
    T = stable_pose(part.mesh, cell).copy()
    hull = np.asarray(part.mesh.vertices) @ T[:3, :3].T + T[:3, 3]
    wall_x = float(cell.bin.T_world_bin[0, 3]) + 0.5 * cell.bin.inner[0]
    T[0, 3] += wall_x - gap - hull[:, 0].max()
    return T


def _scene_file(tmp_path: Path, T: np.ndarray) -> Path:
    doc = {"schema": "grasplan.scene/1", "cell": "bin", "parts": {"box": {"mesh": str(BOX), "units": "auto"}},
           "instances": [{"id": "box_0", "part": "box", "T": T.tolist()}]}
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


@pytest.fixture(scope="module")
def pushed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("push")
    T = _near_wall(0.025)
    out = tmp / "p.json"
    r = CliRunner().invoke(main, ["pick", str(_scene_file(tmp, T)), "--push", "--min-gravity-margin", "100",
                                  "--gripper", "long_stroke_50", "-o", str(out)])
    return r, out, T


def test_a_part_that_would_pass_between_the_closed_jaws_is_not_pushed(tmp_path):
    """The default EGP-C 40's jaws close to 30 mm: the box (at most 30 mm across the push, centred
    between the fingers) would pass between them, so no push is planned and push_tried says why;
    the same check passes for jaws that close fully."""
    from grasplan.pick.push import Candidate, passes_between_jaws

    T = _near_wall(0.025)
    out = tmp_path / "p.json"
    r = CliRunner().invoke(main, ["pick", str(_scene_file(tmp_path, T)), "--push", "--min-gravity-margin", "100",
                                  "-o", str(out)])
    assert r.exit_code == 4, r.output
    doc = json.loads(out.read_text())
    assert "push" not in doc or doc["push"] is None
    assert any("would pass between the closed jaws (30.0 mm apart)" in t for t in doc["push_tried"]), doc["push_tried"]
    hull = np.asarray(load_part(BOX).mesh.vertices)
    c = Candidate(Instance("b", "box", T), "bin_wall_+x", 0.025, np.array([-1.0, 0.0, 0.0]))
    com = hull.mean(axis=0)
    across = hull @ T[:3, :3].T @ np.array([0.0, 1.0, 0.0])  # the box's extent across the push (world y)
    half = 0.5 * float(np.ptp(across))
    assert passes_between_jaws(c, hull, com, 0.030) and not passes_between_jaws(c, hull, com, 0.0)
    assert passes_between_jaws(c, hull, com, 2 * half - 0.003) != passes_between_jaws(c, hull, com, 2 * half - 0.005)


def test_which_reports_a_push_may_help():
    for status in PUSHABLE:
        assert pushable(status, None)
    assert pushable(PickStatus.NO_GRASP, "grasps_weak")  # the better grasps collided
    assert not pushable(PickStatus.NO_GRASP, "no_grasp_from_above")
    assert not pushable(PickStatus.NOT_TRIED, "budget_spent") and not pushable(PickStatus.PICKED, "planned")


def test_a_boxed_in_part_gets_a_push_away_from_the_wall(pushed):
    r, out, T = pushed
    assert r.exit_code == 0, r.output
    assert "push box_0" in r.output
    doc = json.loads(out.read_text())
    import jsonschema

    jsonschema.validate(doc, json.loads(SCHEMA.read_text()))
    assert doc["picks"] == [] and doc["instances"][0]["status"] == "no_grasp"
    assert "predicted to slip" in doc["instances"][0]["reason"]
    p = doc["push"]
    cell = load_cell("bin")
    assert p["instance"] == "box_0" and p["against"] == "bin_wall_+x"
    assert p["gap_m"] == pytest.approx(0.025, abs=1e-6)
    np.testing.assert_allclose(p["direction"], -np.asarray(cell.bin.T_world_bin)[:3, 0], atol=1e-12)
    assert p["distance_m"] == pytest.approx(np.clip(CLEAR - 0.025 + TIP_GAP, MIN_PUSH, MAX_PUSH))
    start, end = np.array(p["T_world_start"]), np.array(p["T_world_end"])
    np.testing.assert_allclose(end[:3, 3] - start[:3, 3], p["distance_m"] * np.array(p["direction"]), atol=1e-12)
    # the fingers start behind the part: the start TCP is between the wall and the part's hull
    part = load_part(BOX)
    hull = np.asarray(part.mesh.vertices) @ T[:3, :3].T + T[:3, 3]
    wall_x = float(cell.bin.T_world_bin[0, 3]) + 0.5 * cell.bin.inner[0]
    assert hull[:, 0].max() < start[0, 3] < wall_x


def test_the_push_path_follows_its_poses_by_pinocchios_fk(pushed):
    _, out, _ = pushed
    p = json.loads(out.read_text())["push"]
    robot = load_robot("ur5")
    doc = json.loads(out.read_text())
    T_flange_tcp = np.array(doc["gripper"]["T_flange_tcp"])
    path = np.array(p["path"])
    labels = [s[0] for s in p["segments"]]
    assert labels == ["transit", "approach", "push", "retreat"]
    assert p["segments"][0][1] == 0 and p["segments"][-1][2] == len(path) - 1
    assert all(a[2] == b[1] for a, b in zip(p["segments"], p["segments"][1:]))
    tcp = np.array([robot.fk(q) @ T_flange_tcp for q in path])
    np.testing.assert_allclose(tcp[0], robot.fk(robot.q_home) @ T_flange_tcp, atol=1e-9)
    seg = {s[0]: (s[1], s[2]) for s in p["segments"]}
    for label, a, b in (("approach", "T_world_above", "T_world_start"), ("push", "T_world_start", "T_world_end"),
                        ("retreat", "T_world_end", "T_world_retreat")):
        i, j = seg[label]
        Ta, Tb = np.array(p[a]), np.array(p[b])
        np.testing.assert_allclose(tcp[i][:3, 3], Ta[:3, 3], atol=1e-4)
        np.testing.assert_allclose(tcp[j][:3, 3], Tb[:3, 3], atol=1e-4)
        d = (Tb[:3, 3] - Ta[:3, 3]) / np.linalg.norm(Tb[:3, 3] - Ta[:3, 3])
        off = tcp[i:j + 1, :3, 3] - Ta[:3, 3]
        dev = np.linalg.norm(off - (off @ d)[:, None] * d, axis=1)
        assert dev.max() <= 0.002 + 1e-9, label  # the straight-line tolerance (max_dev)
        np.testing.assert_allclose(tcp[i:j + 1, :3, :3], np.broadcast_to(Ta[:3, :3], (j - i + 1, 3, 3)), atol=2e-3)


def test_without_push_or_without_room_nothing_is_written_as_a_push(tmp_path):
    scene = _scene_file(tmp_path, _near_wall(0.025))
    out = tmp_path / "no.json"
    r = CliRunner().invoke(main, ["pick", str(scene), "--min-gravity-margin", "100", "-o", str(out)])
    assert r.exit_code == 4
    assert "push" not in json.loads(out.read_text())
    flush = _scene_file(tmp_path, _near_wall(0.0005))
    out2 = tmp_path / "flush.json"
    r2 = CliRunner().invoke(main, ["pick", str(flush), "--push", "--min-gravity-margin", "100", "-o", str(out2)])
    assert r2.exit_code == 4 and "no push either" in r2.output
    d = json.loads(out2.read_text())
    assert d["push"] is None and d["push_tried"] and "bin_wall_+x" in d["push_tried"][0]


def test_a_weak_grasp_filter_names_its_code_and_planning_without_it_picks():
    cell = load_cell("bin")
    picker = Picker("ur5", gripper="long_stroke_50", cell=cell)
    picker.add_part("box", load_part(BOX))
    sc = Scene(instances=(Instance("box_0", "box", _near_wall(0.04)),), cell="bin",
               parts=(ScenePart("box", mesh=str(BOX)),))
    assert len(picker.plan(sc).picks) == 1
    from grasplan.pick.params import PickParams

    strict = Picker("ur5", gripper="long_stroke_50", cell=cell, params=PickParams(min_gravity_margin=100.0))
    strict.add_part("box", load_part(BOX))
    rep = strict.plan(sc).instances[0]
    assert rep.status == "no_grasp" and str(rep.code) == "grasps_weak", rep


@pytest.fixture(scope="module")
def push_round():
    """A box 25 mm from the bin's +x wall that no grasp may take (``min_gravity_margin`` 100),
    cleared by ``clear_pile`` with pushes: ``(round, part, gripper, cell, gap before)``."""
    from grasplan.clutter.protocols import wall_distance
    from grasplan.clutter.rounds import clear_pile
    from grasplan.clutter.world import ClutterWorld
    from grasplan.gripper.load import load_gripper
    from grasplan.pick.params import PickParams
    from grasplan.sim.pileworld import part_body

    cell = load_cell("bin")
    gripper = load_gripper("long_stroke_50")
    part = load_part(BOX)
    body = part_body("box_0", part.mesh, density=1200.0, decomposition="hull")
    cw = ClutterWorld(cell, [body], gripper, mu=0.3)
    cw.world.place(0, _near_wall(0.025))
    cw.world.settle(lin=0.005, ang=0.05, hold=0.2, max_s=2.0)
    gap0 = wall_distance(cell.bin, cw.world.hull_world(0))
    scene = Scene(instances=(Instance("box_0", "box", cw.world.pose(0)),), cell="bin",
                  parts=(ScenePart("box", mesh=str(BOX)),))
    picker = Picker("ur5", gripper=gripper, cell=cell, params=PickParams(min_gravity_margin=100.0))
    picker.add_part("box", part)
    rr = clear_pile(cw, scene, {"box": part}, lambda s, skip=(): picker.plan(s, max_picks=1, push=True, push_skip=skip),
                    clear_z=float(cell.bin.T_world_bin[2, 3]) + cell.bin.height, record=True)
    return rr, part, gripper, cell, gap0, wall_distance(cell.bin, cw.world.hull_world(0))


def test_a_clutter_round_executes_the_planned_push_and_plans_again(push_round):
    """The round pushes the box (executed in MuJoCo: it ends farther from the wall by about the
    push's travel less the start gap), plans again, finds neither pick nor push and ends; the
    push is no grasp attempt."""
    from grasplan.clutter.report import round_json

    rr, _, _, _, gap0, gap1 = push_round
    assert [(a.kind, a.outcome) for a in rr.attempts] == [("push", "moved"), ("pick", "no_plan")], \
        [a.reason for a in rr.attempts]
    assert rr.executed == [] and rr.ended == "nothing_feasible"
    push = rr.attempts[0]
    travel = push.push["distance_m"]
    assert gap1 - gap0 == pytest.approx(push.push_execution.along_m, abs=0.003)
    assert travel - 0.01 < gap1 - gap0 < travel + 0.002  # the fingers start a few mm behind the part
    rj = round_json(rr)
    assert rj["pushes"] == 1 and rj["attempts"] == 0 and rj["picks"][0]["kind"] == "push"
    assert rj["left"][0]["wall_m"] == pytest.approx(gap1)


@needs_chromium
def test_the_replay_page_plays_a_push(tmp_path, push_round):
    """The push of the round above in ``grasplan clutter --view``'s page, in headless Chromium:
    named a push, with its samples (the part seen moving along with the gripper)."""
    from grasplan.clutter.replay import write_replay
    from grasplan.clutter.report import round_json, total_json

    rr, part, gripper, cell, _, _ = push_round
    page = tmp_path / "push.html"
    write_replay(page, [rr], {"box": part}, gripper, cell, total=total_json([round_json(rr)]), title="push")
    text = page.read_text()
    data = json.loads(re.search(r'<script id="grasplan-data" type="application/json">(.*?)</script>', text, re.S)
                      .group(1))
    a = data["rounds"][0]["attempts"][0]
    assert a["kind"] == "push" and a["outcome"] == "moved" and a["samples"] > 10
    dom = run_chromium(page, tmp_path, "--dump-dom", fragment="#pick=0:0").stdout
    assert "round 1, push 1: box_0 (box)" in dom


def test_a_push_keeps_the_part_in_the_cells_workspace(tmp_path):
    """The box by the +x wall, pushed along -x: with a workspace whose -x edge lies 25 mm beyond
    the box's centre of mass the push is shortened so that the centre of mass ends on the edge;
    with the edge 5 mm beyond it no push is planned and push_tried names the workspace."""
    from dataclasses import replace

    from grasplan.cell.regions import Workspace
    from grasplan.pick.params import PickParams

    T = _near_wall(0.025)
    part = load_part(BOX)
    com = T[:3, :3] @ np.asarray(part.mesh.vertices).mean(axis=0) + T[:3, 3]
    scene = Scene(instances=(Instance("box_0", "box", T),), cell="bin", parts=(ScenePart("box", mesh=str(BOX)),))
    for edge, pushed in ((0.025, True), (0.005, False)):
        cell = replace(load_cell("bin"), workspace=Workspace((com[0] - edge, -1.0), (1.0, 1.0)))
        picker = Picker("ur5", gripper="long_stroke_50", cell=cell, params=PickParams(min_gravity_margin=100.0))
        picker.add_part("box", part)
        res = picker.plan(scene, max_picks=1, push=True)
        doc = json.loads(res.to_json_text())
        if pushed:
            push = doc["push"]
            assert push is not None, doc.get("push_tried")
            travel = push["distance_m"] - TIP_GAP  # the fingers start TIP_GAP behind the part
            assert travel == pytest.approx(edge, abs=1e-6)
            assert cell.workspace.contains(com + travel * np.array([-1.0, 0.0, 0.0]))
        else:
            assert doc.get("push") is None
            assert any("the workspace's edge is within" in t for t in doc["push_tried"]), doc["push_tried"]


def test_the_clutter_workspace_is_the_bins_inner_floor():
    """``pile``'s planner cell: no bin, and a workspace that holds a point exactly when the
    clutter rule (``in_workspace``, in the bin frame) counts it in."""
    from grasplan.clutter.protocols import PROTOCOLS, in_workspace

    cell = load_cell("bin")
    pc = PROTOCOLS["pile"].planner_cell(cell)
    assert pc.bin is None and pc.workspace is not None and PROTOCOLS["bin"].planner_cell(cell).workspace is None
    b = cell.bin
    pts = np.random.default_rng(0).uniform([0.2, -0.2, 0.05], [0.7, 0.2, 0.06], (2000, 3))
    assert [pc.workspace.contains(p) for p in pts] == [in_workspace(b, p) for p in pts]
    again = type(pc).from_json(json.loads(json.dumps(pc.to_json())))
    assert again.workspace == pc.workspace and again == pc
    # a bin turned 30 deg about z: the workspace turns with it
    from dataclasses import replace

    from grasplan.cell.model import cell_from_dict

    yawed = cell_from_dict({"bin": {"inner": [0.30, 0.20], "wall": 0.01, "height": 0.15,
                                    "T": {"xyz": [0.45, 0.0, 0.01], "rpy_deg": [0, 0, 30]}}}, name="yawed")
    ws = PROTOCOLS["packed"].planner_cell(yawed).workspace
    assert ws.yaw_deg == pytest.approx(30.0)
    assert [ws.contains(p) for p in pts] == [in_workspace(yawed.bin, p) for p in pts]
    assert type(pc).from_json(json.loads(json.dumps(replace(pc, workspace=ws).to_json()))).workspace == ws


def test_a_workspace_travel_ends_on_its_edge():
    """``Workspace.travel_inside``: from points inside, along random horizontal directions, the
    point moved by the travel is inside and 0.1 mm further it is not (``contains``, the other
    method, as the judge); a turned rectangle too."""
    from grasplan.cell.regions import Workspace

    rng = np.random.default_rng(1)
    for ws in (Workspace((0.3, -0.1), (0.6, 0.1)), Workspace((0.3, -0.1), (0.6, 0.1), 25.0)):
        c = 0.5 * (np.array(ws.lo) + np.array(ws.hi))
        for _ in range(200):
            p = c + rng.uniform(-0.08, 0.08, 2)
            if not ws.contains(p):
                continue
            a = rng.uniform(0, 2 * np.pi)
            d = np.array([np.cos(a), np.sin(a)])
            t = ws.travel_inside(p, d)
            assert ws.contains(p + t * d) and not ws.contains(p + (t + 1e-4) * d)
