"""Compact plan files (``keep="collision_free"``, the default) against the full form (``keep="all"``):
the same grasps (read independently by tests/plan_docs.py and by grasplan's reader), the same
counts, valid against the schema in full, exports and view identical, older files (no ``keep``)
still read, and a malformed compact block refused with a message naming it."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from grasplan.config.params import PlanParams
from grasplan.errors import InputError
from grasplan.results.reader import load_result
from grasplan.schemas.documents import validate
from plan_docs import REJECTED, kept_grasps, status_counts

BRACKET = Path(__file__).resolve().parents[1] / "examples" / "parts" / "bracket.stl"


@pytest.fixture(scope="module")
def plans(tmp_path_factory):
    from grasplan import plan
    from grasplan.part.mesh import load_part

    res = plan(load_part(BRACKET, units="mm"), "ur5", planning=PlanParams(top=4, grasp_db="off"))  # every pose
    d = tmp_path_factory.mktemp("compact")
    res.write(d / "compact.json")
    res.write(d / "all.json", keep="all")
    return res, d / "compact.json", d / "all.json"


def test_compact_lists_every_collision_free_grasp_and_counts_the_rest(plans):
    res, compact, full = plans
    c, a = json.loads(compact.read_text()), json.loads(full.read_text())
    assert c["keep"] == "collision_free" and a["keep"] == "all"
    validate(c)  # the whole document, untried columns and rejected counts included
    validate(a)
    assert compact.stat().st_size * 5 < full.stat().st_size
    by_id = {g["id"]: g for g in a["grasps"]}
    kept = kept_grasps(c)
    assert [g["id"] for g in kept] == [g["id"] for g in a["grasps"] if g["status"] not in REJECTED]
    assert not any(g["status"] in ("not_tried", "not_checked") for g in c["grasps"])  # those are columns
    for g in kept:
        f = by_id[g["id"]]
        np.testing.assert_allclose(g["T_part_tcp"], f["T_part_tcp"], atol=2e-10)
        for k in ("candidate", "region", "contacts", "normals", "width", "roll", "status", "score", "rank",
                  "reason", "quality"):
            assert g[k] == f[k], (g["id"], k)
        for k in ("q_grasp", "q_pregrasp", "path", "segments"):
            assert g.get(k) == f.get(k)
    statuses = list(a["counts"])
    assert status_counts(c, statuses) == status_counts(a, statuses)
    assert {k: v for k, v in c["counts"].items()} == a["counts"]
    # per candidate: the rejected counts are those of the full file
    per = {}
    for g in a["grasps"]:
        if g["status"] in REJECTED:
            per.setdefault(g["candidate"], dict.fromkeys(REJECTED, 0))[g["status"]] += 1
    rej = c["rejected"]
    assert rej["candidate"] == sorted(per)
    for k, cand in enumerate(rej["candidate"]):
        assert {s: rej[s][k] for s in REJECTED} == per[cand]


def test_reader_gives_the_same_result_for_both_forms(plans):
    res, compact, full = plans
    c, a = load_result(compact), load_result(full)
    assert c.counts() == a.counts() == res.counts()
    assert c.planned_ids() == a.planned_ids() == res.planned_ids()
    assert c.planned() == a.planned()
    rows = [a.grasps.index_of(int(i)) for i in c.grasps.ids]
    for k in ("candidate", "region", "contacts", "normals", "width", "roll", "score", "rank", "gravity_margin",
              "epsilon", "contact_area", "contact_type"):
        np.testing.assert_array_equal(getattr(c.grasps, k), getattr(a.grasps, k)[rows], err_msg=k)
    np.testing.assert_allclose(c.grasps.T_part_tcp, a.grasps.T_part_tcp[rows], atol=2e-10)
    assert list(c.grasps.status) == list(a.grasps.status[rows])
    for gid in c.planned_ids():
        mc, ma = c.grasp(gid).motion, a.grasp(gid).motion
        assert mc is not None and ma is not None and np.array_equal(mc.path, ma.path)


@pytest.mark.parametrize("fmt", ["urscript", "joint-trajectory", "path-csv", "moveit-grasp"])
def test_exports_identical_from_both_forms(plans, tmp_path, fmt):
    from grasplan.export import write

    _, compact, full = plans
    out_c, out_a = write(load_result(compact), fmt, tmp_path / f"c_{fmt}"), write(load_result(full), fmt, tmp_path / f"a_{fmt}")
    assert Path(out_c).read_bytes() == Path(out_a).read_bytes()


def test_csv_lists_the_kept_grasps_with_their_ids(plans, tmp_path):
    import csv

    from grasplan.export import write

    _, compact, full = plans
    c = load_result(compact)
    text = Path(write(c, "csv", tmp_path / "c.csv")).read_text()
    rows = list(csv.DictReader(text.splitlines()))
    assert [int(r["id"]) for r in rows] == c.grasps.ids.tolist()
    planned = {int(r["id"]) for r in rows if r["status"] == "planned"}
    assert planned == set(c.planned_ids())
    a_rows = {int(r["id"]): r for r in csv.DictReader(Path(write(load_result(full), "csv", tmp_path / "a.csv"))
                                                      .read_text().splitlines())}
    for r in rows:  # the same text where the rows' poses agree to the written digits
        assert r["q_" + "shoulder_pan_joint"] == a_rows[int(r["id"])]["q_shoulder_pan_joint"]
        assert r["score"] == a_rows[int(r["id"])]["score"]


def test_view_of_a_compact_plan_says_what_is_counted(plans, tmp_path):
    from grasplan.viewer.page import build_data

    _, compact, full = plans
    data, notes = build_data(load_result(compact))
    assert any("--keep all" in n and "collision_table" in n for n in notes)
    planned = {k for k in data["robot"]["paths"]}
    assert planned == {str(i) for i in load_result(compact).planned_ids()}  # keyed by grasp id, not row
    data_a, notes_a = build_data(load_result(full))
    assert not any("--keep all" in n for n in notes_a) and set(data_a["robot"]["paths"]) == planned


def test_a_file_without_keep_reads_as_the_full_form(plans, tmp_path):
    _, _, full = plans
    doc = json.loads(full.read_text())
    del doc["keep"]  # as grasplan 0.2 wrote it
    res = load_result(doc)
    assert res.rejected is None and res.counts() == load_result(full).counts()


def _compact_doc(plans) -> dict:
    return json.loads(plans[1].read_text())


@pytest.mark.parametrize("edit, match", [
    (lambda d: d.pop("untried"), "'untried' and 'rejected' blocks"),
    (lambda d: d.pop("keep"), "'untried' and 'rejected' blocks"),
    (lambda d: d["untried"].update(frame=[10**6] * len(d["untried"]["frame"])), r"untried.frame indexes beyond"),
    (lambda d: d["untried"].update(roll=d["untried"]["roll"][:-1]), r"untried.roll malformed"),
    (lambda d: d["untried"].update(statuses=["planned"]), r"untried.statuses malformed"),
    (lambda d: d["untried"]["frames"]["T_part_tcp_roll0"][0][0].__setitem__(0, 2.0), r"T_part_tcp_roll0"),
    (lambda d: d["untried"]["frames"]["normals"][0][0].__setitem__(0, 5.0), r"untried\[\d+\]\.normals"),
    (lambda d: d["untried"]["id"].__setitem__(0, d["grasps"][0]["id"]), "both in"),
    (lambda d: d["untried"]["quality"]["epsilon"].__setitem__(0, -1.0), r"untried.quality"),
    (lambda d: d["untried"]["score"].__setitem__(0, True), r"untried.score malformed"),
    (lambda d: d["rejected"]["collision_part"].pop(), r"\$\.rejected malformed"),
    (lambda d: d["rejected"]["collision_part"].__setitem__(0, -3), r"\$\.rejected malformed"),
    (lambda d: d["untried"].update(extra=1), r"\$\.untried malformed"),
])
def test_malformed_compact_blocks_are_refused(plans, edit, match):
    doc = _compact_doc(plans)
    edit(doc)
    with pytest.raises(InputError, match=match):
        load_result(doc)


def test_cli_keep_option(tmp_path, example_part):
    from click.testing import CliRunner

    from grasplan.cli import main

    out = tmp_path / "p.json"
    r = CliRunner().invoke(main, ["plan", str(example_part("bracket.stl")), "--units", "mm", "--top", "2",
                                  "--keep", "all", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert json.loads(out.read_text())["keep"] == "all"
    r = CliRunner().invoke(main, ["plan", str(example_part("bracket.stl")), "--keep", "some", "-o", str(out)])
    assert r.exit_code == 2 and "collision_free" in r.output
