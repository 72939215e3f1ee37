"""``grasplan clutter --protocol pile|packed`` with ``--push`` and ``--max-occlusion`` on the example
parts (convex hulls): the report records the protocol and the options, the pile is on the table
without the bin, every pick is judged by the strict rule (lowest point 10 cm above the table)
and the totals carry intervals, the parts left and the pushes. Bad values exit 2 or 3, writing
nothing."""
from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from grasplan.cell.model import load_cell
from grasplan.cli import main
from grasplan.clutter.execute import SUCCESS
from grasplan.clutter.protocols import TABLE_CLEARANCE

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "parts"
BOX, BRACKET = EXAMPLES / "box.stl", EXAMPLES / "bracket.stl"


@pytest.mark.parametrize("protocol", ["pile", "packed"])
def test_a_protocol_round_is_recorded_and_judged_by_its_rules(tmp_path, protocol):
    out = tmp_path / "r.json"
    r = CliRunner().invoke(main, ["clutter", "--protocol", protocol, "--part", f"{BOX}:2", "--part", f"{BRACKET}:1",
                                  "--rounds", "2", "--seed", "1", "--decomposition", "hull", "--material", "plastic",
                                  "--push", "--max-occlusion", "0.9", "-o", str(out)])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    p = doc["params"]
    assert p["protocol"] == protocol and p["push"] is True and p["max_occlusion"] == 0.9
    assert p["pick"]["min_gravity_margin"] == 1.0 and p["execution"]["turn_max_deg"] == 15.0
    table_z = load_cell("bin").table_z
    for rj in doc["rounds"]:
        assert rj["protocol"] == protocol and rj["parts"] + len(rj["outside"]) == 3
        for a in rj["picks"]:
            if a["kind"] == "pick" and a["outcome"] == SUCCESS:
                assert a["execution"]["low_z_m"] >= table_z + TABLE_CLEARANCE - 1e-9
                assert a["execution"]["turned_in_jaws_deg"] <= 15.0
        assert {x["instance"] for x in rj["left"]}.isdisjoint(rj["outside"])
    tot = doc["total"]
    assert tot["parts"] == sum(rj["parts"] for rj in doc["rounds"])
    assert tot["left"]["n"] == sum(len(rj["left"]) for rj in doc["rounds"])
    assert tot["pushes"]["n"] == sum(rj["pushes"] for rj in doc["rounds"])
    assert (tot["gsr_ci95"] is None) == (len([rj for rj in doc["rounds"] if rj["attempts"]]) < 1)
    assert "95 % intervals" in r.output


@pytest.mark.parametrize("args, code, match", [
    (["--protocol", "heap"], 2, "heap"),
    (["--max-occlusion", "0"], 2, "max-occlusion"),
    (["--min-gravity-margin", "-1"], 2, "min-gravity-margin"),
])
def test_bad_protocol_options_are_refused(tmp_path, args, code, match):
    out = tmp_path / "r.json"
    r = CliRunner().invoke(main, ["clutter", "--part", f"{BOX}:1", "--rounds", "1", *args, "-o", str(out)])
    assert r.exit_code == code, r.output
    assert match in r.output and not out.exists()
