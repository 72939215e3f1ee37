"""``grasplan clutter`` (issue 21) with the real planner (``grasplan.Picker``): a lone part is picked
on the first attempt, a part under another is not picked before the one on top, the CLI's short
seeded round writes a report whose totals add up from its picks, bad input exits 3 writing
nothing, and the ``--view`` page renders in headless Chromium listing every pick with its outcome.

The example parts collide through their convex hulls (``--decomposition hull``: no CoACD run)."""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from grasplan.cell.model import load_cell
from grasplan.cli import main
from grasplan.clutter.execute import SUCCESS
from grasplan.clutter.report import CLUTTER_SCHEMA, FAILURES
from grasplan.clutter.rounds import NO_PLAN, clear_pile, run_round
from grasplan.clutter.world import ClutterWorld
from grasplan.sim.drop import DropParams, PileItem
from grasplan.gripper.load import load_gripper
from grasplan.part.mesh import load_part
from grasplan.pick import Picker, PickParams
from grasplan.sim.pileworld import part_body
from grasplan.piles.scene_file import Instance, Scene, ScenePart

from test_viewer import CANVAS_X0, CANVAS_Y0, CANVAS_Y1, needs_chromium, read_png, run_chromium

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "parts"
BOX, BRACKET = EXAMPLES / "box.stl", EXAMPLES / "bracket.stl"


@pytest.fixture(scope="module")
def cell():
    return load_cell("bin")


@pytest.fixture(scope="module")
def gripper():
    return load_gripper("schunk_egp_c_40")


def _picker(cell, gripper, params: PickParams | None = None, **parts):
    p = Picker("ur5", gripper=gripper, cell=cell, params=params or PickParams())
    for name, part in parts.items():
        p.add_part(name, part)
    return p


def test_a_lone_part_is_picked_on_the_first_attempt(cell, gripper):
    part = load_part(BRACKET)
    picker = _picker(cell, gripper, bracket=part)
    rr = run_round(cell, [PileItem("bracket", part, 1)], gripper, lambda s: picker.plan(s, max_picks=1),
                   drop=DropParams(seed=2, decomposition="hull", material="plastic"))
    assert [a.outcome for a in rr.attempts] == [SUCCESS], [a.reason for a in rr.attempts]
    assert rr.ended == "empty" and rr.removed == 1
    ex = rr.attempts[0].execution
    assert ex is not None and ex.lift >= 0.05 and ex.held_at_close and ex.fixed_force == 0.0


def test_a_part_under_another_is_not_picked_before_the_one_on_top(cell, gripper):
    """Two boxes stacked flat and crossed at the bin's centre: the top one is picked first (the
    planner sees that lifting the bottom one would raise the top one: a pick that raises a
    neighbour comes after every clean one; without lift_carry it is blocked), then the bottom one."""
    part = load_part(BOX)
    body = part_body("box", part.mesh, density=1200.0, decomposition="hull")
    names = ("box_under", "box_on_top")
    bodies = [type(body)(name=n, pieces=body.pieces, mass=body.mass, hull=body.hull) for n in names]
    cw = ClutterWorld(cell, bodies, gripper, mu=0.3)
    floor = float(cell.bin.T_world_bin[2, 3])
    for k in range(2):
        T = np.eye(4)
        T[:3, 3] = [0.45, 0.0, floor + 0.005 + 0.0101 * k]
        if k:  # turned 90 deg: the top box (30 x 20 mm) crosses the bottom one
            T[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
        cw.world.place(k, T)
    s = cw.world.settle(lin=0.005, ang=0.05, hold=0.2, max_s=2.0)
    assert s.at_rest and cw.world.pose(1)[2, 3] > cw.world.pose(0)[2, 3] + 0.009  # still stacked
    scene = Scene(instances=tuple(Instance(n, "box", cw.world.pose(k)) for k, n in enumerate(names)), cell="bin",
                  parts=(ScenePart("box", mesh=str(BOX)),))
    picker = _picker(cell, gripper, box=part)
    first = picker.plan(scene)
    assert [p.instance for p in first.picks] == ["box_on_top", "box_under"]
    assert [p.carries for p in first.picks] == [(), ("box_on_top",)]
    assert picker.plan(scene, max_picks=1).picks[0].instance == "box_on_top"
    strict = _picker(cell, gripper, PickParams(lift_carry=False), box=part)
    under = strict.plan(scene).report("box_under")
    assert under.status == "blocked" and "box_on_top" in under.blocked_by, under
    rr = clear_pile(cw, scene, {"box": part}, lambda s: picker.plan(s, max_picks=1))
    assert [(a.instance, a.outcome) for a in rr.attempts] == [("box_on_top", SUCCESS), ("box_under", SUCCESS)], \
        [a.reason for a in rr.attempts]


# ------------------------------------------------------------------------------------------------
# the command: one short seeded round
# ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cli_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("clutter")
    out, page = tmp / "report.json", tmp / "clutter.html"
    r = CliRunner().invoke(main, ["clutter", "--cell", "bin", "--part", f"{BOX}:2", "--part", f"{BRACKET}:1",
                                  "--rounds", "1", "--seed", "4", "--decomposition", "hull", "--material", "plastic",
                                  "--pose-noise", "1mm,1deg",
                                  "--view", str(page), "-o", str(out)])
    assert r.exit_code == 0, r.output
    return r, json.loads(out.read_text()), page


def test_cli_report_adds_up_from_its_picks(cli_run):
    r, doc, _ = cli_run
    assert doc["schema"] == CLUTTER_SCHEMA
    for name, rec in doc["parts"].items():  # every output records the part's scale and sha256
        assert re.fullmatch(r"[0-9a-f]{64}", rec["sha256"]) and rec["scale_to_m"] == 0.001
    assert doc["params"]["pose_noise_m"] == pytest.approx(0.001) and doc["params"]["pose_noise_deg"] == 1.0
    (rj,) = doc["rounds"]
    executed = [p for p in rj["picks"] if p["outcome"] != NO_PLAN]
    held = [p for p in executed if p["outcome"] == SUCCESS]
    assert rj["parts"] == 3 and rj["attempts"] == len(executed) >= 1 and rj["successes"] == len(held)
    assert rj["gsr"] == pytest.approx(len(held) / len(executed)) and rj["dr"] == pytest.approx(len(held) / 3)
    assert sum(rj["failures"].values()) == len(rj["picks"]) - len(held) and set(rj["failures"]) == set(FAILURES)
    for p in executed:  # the noise as drawn: 1 mm at the centre of mass, 1 deg
        assert p["pose_error_deg"] == pytest.approx(1.0, abs=1e-6) and 0.0 < p["pose_error_mm"] < 40.0
        assert p["execution"]["sim_s"] > 1.0 and len(p["pick"]["T_world_tcp"]) == 4
    ends = {"empty": len(held) == 3, "two_failures": [p["outcome"] for p in rj["picks"][-2:]].count(SUCCESS) == 0,
            "nothing_feasible": rj["picks"][-1]["outcome"] == NO_PLAN}
    assert ends[rj["ended"]]
    tot = doc["total"]
    assert (tot["attempts"], tot["successes"], tot["parts"], tot["removed"]) == (
        rj["attempts"], rj["successes"], 3, rj["removed"])
    assert tot["plan_ms"]["cold_ms"] == rj["picks"][0]["plan_ms"]
    assert f"GSR {100 * tot['gsr']:.1f} %" in r.output


@pytest.mark.parametrize("args, match", [
    (["--pose-noise", "2mm"], "--pose-noise"),
    (["--pose-noise", "2mm,90deg"], "0..45 deg"),
    (["--cell", "table"], "no bin"),
    (["--view", "SAME"], "same file"),
])
def test_cli_refuses_bad_input_with_exit_3_and_writes_nothing(tmp_path, args, match):
    out = tmp_path / "r.json"
    args = [str(out) if a == "SAME" else a for a in args]
    r = CliRunner().invoke(main, ["clutter", "--part", f"{BOX}:1", "--rounds", "1", *args, "-o", str(out)])
    assert r.exit_code == 3, r.output
    assert match in r.output and not out.exists() and list(tmp_path.iterdir()) == []


def test_view_page_is_self_contained(cli_run):
    _, doc, page = cli_run
    text = page.read_text()
    assert "default-src 'none'" in text
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", text)
    data = json.loads(re.search(r'<script id="grasplan-data" type="application/json">(.*?)</script>', text, re.S)
                      .group(1))
    assert [a["outcome"] for a in data["rounds"][0]["attempts"]] == [p["outcome"] for p in doc["rounds"][0]["picks"]]


@needs_chromium
def test_view_renders_every_pick_in_chromium(cli_run, tmp_path):
    _, doc, page = cli_run
    picks = doc["rounds"][0]["picks"]
    r = run_chromium(page, tmp_path, "--dump-dom", fragment="#pick=0:0&play")
    status = re.search(r'<div id="render-status"([^>]*)>', r.stdout).group(1)
    assert 'data-ok="1"' in status, r.stdout[-2000:]
    assert f'data-listed="{len(picks)}"' in status and 'data-selected="0:0"' in status
    samples = int(re.search(r'data-sample="(\d+)"', status).group(1))
    assert samples > 20  # played to the end of the recorded simulation
    rows = re.findall(r'data-round="0" data-attempt="(\d+)" data-outcome="([a-z_]+)"', r.stdout)
    assert [o for _, o in rows] == [p["outcome"] for p in picks]
    png = tmp_path / "shot.png"
    run_chromium(page, tmp_path, f"--screenshot={png}", "--window-size=1280,800")
    img = read_png(png)[CANVAS_Y0:CANVAS_Y1, CANVAS_X0:, :3].astype(float)
    assert img.std(axis=(0, 1)).max() > 10  # the bin, the parts and the gripper, not a blank canvas
    assert math.isfinite(img.mean())


@needs_chromium
def test_view_names_and_colours_the_neighbour_a_lift_raises(cli_run, tmp_path):
    """A pick whose lift raises a neighbour (``lift_carries`` in the report) shows it: the page's
    data for pick 0 of round 0 made to raise another instance of the round, rendered in Chromium."""
    _, doc, page = cli_run
    text = page.read_text()
    m = re.search(r'(<script id="grasplan-data" type="application/json">)(.*?)(</script>)', text, re.S)
    data = json.loads(m.group(2))
    rd, a = data["rounds"][0], data["rounds"][0]["attempts"][0]
    assert a["pick"]["raises"] == doc["rounds"][0]["picks"][0]["pick"]["lift_carries"]  # the report's, as written
    other = next(i for i in rd["ids"] if i != a["instance"])
    a["pick"]["raises"] = [other]
    edited = tmp_path / "raised.html"
    edited.write_text(text[:m.start(2)] + json.dumps(data).replace("</", "<\\/") + text[m.end(2):])
    r = run_chromium(edited, tmp_path, "--dump-dom", fragment="#pick=0:0")
    assert 'data-ok="1"' in re.search(r'<div id="render-status"([^>]*)>', r.stdout).group(1), r.stdout[-2000:]
    assert f"the lift raises {other} lying on it (violet)" in r.stdout

