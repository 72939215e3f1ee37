"""Grasp quality wired into grasps and plan (issue 11): the score terms, the one scoring YAML,
quality in the JSON / CSV outputs, --mass / --density, plan ranking and plan --simulate."""
from __future__ import annotations

import csv
import io
import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from grasplan.cli import main
from grasplan.errors import ConfigError, InputError
from grasplan.config.params import DEFAULT_SCORE_WEIGHTS, GraspParams, PlanParams
from grasplan.grasps.quality import Quality
from grasplan.results.quality_json import CONTACT_TYPES
from grasplan.grasps.ranking import distinct_order
from grasplan.config.scoring import (
    TERMS, ScoringConfig, load_scoring, score_grasps, with_scoring_file
)
from grasplan.sim.simulate import SimResult, rank_held_first, with_sim

BRACKET = ["--units", "mm"]


@pytest.fixture(scope="module")
def bracket(tmp_path_factory):
    from conftest import EXAMPLE_PARTS

    return EXAMPLE_PARTS / "bracket.stl"


def run(args, code=0):
    r = CliRunner().invoke(main, [str(a) for a in args])
    assert r.exit_code == code, (r.output, r.exception)
    return r


@pytest.fixture(scope="module")
def grasps_doc(bracket, tmp_path_factory):
    out = tmp_path_factory.mktemp("grasps") / "g.json"
    run(["grasps", bracket, *BRACKET, "-o", out])
    return json.loads(out.read_text())


# -- the one definition of the weights ------------------------------------------------------------------
def test_defaults_are_read_from_the_packaged_yaml(tmp_path):
    cfg = load_scoring()
    assert DEFAULT_SCORE_WEIGHTS == cfg.weights
    assert GraspParams().score_weights == cfg.weights
    assert dict(GraspParams().score_refs) == {"gravity_margin_ref": cfg.gravity_margin_ref, "epsilon_ref": cfg.epsilon_ref}
    assert PlanParams().score_weights is None  # the plan uses the grasp stage's score unless told otherwise
    assert {"center", "top", "width", "gravity_margin", "epsilon"} <= set(dict(cfg.weights)) <= set(TERMS)
    user = tmp_path / "s.yaml"
    user.write_text("weights: {top: 2, gravity_margin: 1}\nnormalisation: {gravity_margin_ref: 7}\n")
    gp = with_scoring_file(GraspParams(), user)
    assert gp.score_weights == (("top", 2.0), ("gravity_margin", 1.0))
    assert dict(gp.score_refs)["gravity_margin_ref"] == 7.0
    assert dict(gp.score_refs)["epsilon_ref"] == cfg.epsilon_ref  # omitted: the packaged file's
    user.write_text("weights: {top: 1}\n")
    assert load_scoring(user).refs == cfg.refs
    assert GraspParams.from_json(json.loads(json.dumps(gp.to_json()))) == gp


def test_unknown_term_in_scoring_yaml_is_config_error(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("weights: {top: 1, reachability: 2}\n")
    with pytest.raises(ConfigError, match=r"unknown term\(s\) \['reachability'\]"):
        load_scoring(p)
    with pytest.raises(InputError, match="unknown term"):
        GraspParams(score_weights=(("nope", 1.0),))


# -- the physical terms ------------------------------------------------------------------------------
def _fake_quality(gm, eps):
    M = len(gm)
    return Quality(contact_area=np.zeros((M, 2)), contact_type=np.zeros((M, 2), dtype=np.int8),
                   contact_width=np.zeros((M, 2, 2)), gravity_margin=np.asarray(gm, float),
                   epsilon=np.asarray(eps, float), grip_force=140.0, mu=0.3)


def test_gravity_margin_and_epsilon_terms_follow_the_yaml_normalisation():
    import trimesh

    box = trimesh.creation.box((0.1, 0.03, 0.03))
    T = np.repeat(np.eye(4)[None], 4, axis=0)
    q = _fake_quality([0.5, 1.0, 3.0, 100.0], [0.0, 0.02, 0.05, 0.3])
    cfg = ScoringConfig(weights=(("gravity_margin", 1.0),), gravity_margin_ref=9.0, epsilon_ref=0.1)
    s = score_grasps(box, np.eye(4), T, np.full(4, 0.03), 0.05, cfg.weights, quality=q, scoring=cfg)
    # 1/2 at the threshold (margin 1), log-symmetric: 0.5 -> 1/2 - log 2 / (2 log 9), 3 -> 3/4
    np.testing.assert_allclose(s, [0.5 - 0.5 * math.log(2) / math.log(9), 0.5, 0.75, 1.0])
    s = score_grasps(box, np.eye(4), T, np.full(4, 0.03), 0.05, (("epsilon", 1.0),), quality=q, scoring=cfg)
    np.testing.assert_allclose(s, [0.0, 0.2, 0.5, 1.0])
    with pytest.raises(InputError, match="needs the grasps' quality"):
        score_grasps(box, np.eye(4), T, np.full(4, 0.03), 0.05, (("epsilon", 1.0),))


# -- grasps output ----------------------------------------------------------------------------------
def test_grasps_json_has_quality_for_ok_grasps_and_null_for_collisions(grasps_doc):
    g = grasps_doc["grasps"]
    ok = [x for x in g if x["status"] == "ok"]
    bad = [x for x in g if x["status"] != "ok"]
    assert ok and bad
    assert all(x["quality"] is None and "score" not in x for x in bad)
    for x in ok:
        q = x["quality"]
        assert set(q) == {"score", "gravity_margin", "hold_force_N", "epsilon", "contact"}
        assert q["hold_force_N"] > 0
        assert 0.0 <= q["score"] <= 1.0 and q["score"] == x["score"]
        assert q["gravity_margin"] > 0 and q["epsilon"] >= 0
        assert [set(c) for c in q["contact"]] == [{"area_m2", "type"}] * 2
        assert all(c["type"] in CONTACT_TYPES and c["area_m2"] >= 0 for c in q["contact"])
    # the bracket's flat faces under a 16 x 40 mm pad: surface contacts exist
    assert any(c["type"] == "surface" and c["area_m2"] > 1e-5 for x in ok for c in x["quality"]["contact"])
    part = grasps_doc["part"]
    assert part["mass_kg"] == pytest.approx(7850.0 * part["mass_kg"] / part["density"])
    assert len(part["com"]) == 3 and part["mass_from"] == "mesh"


def test_grasps_file_round_trips_quality(grasps_doc):
    from grasplan.results.reader import result_from_document

    res = result_from_document(grasps_doc)
    t = res.grasps
    ok = t.status.astype(str) == "ok"
    gm = np.array([x["quality"]["gravity_margin"] if x["quality"] else np.nan for x in grasps_doc["grasps"]])
    np.testing.assert_array_equal(t.gravity_margin, gm)
    assert np.all(np.isfinite(t.score[ok])) and np.all(np.isnan(t.score[~ok]))
    again = res.to_json()
    assert again["grasps"] == grasps_doc["grasps"] and again["part"]["mass_kg"] == grasps_doc["part"]["mass_kg"]
    broken = json.loads(json.dumps(grasps_doc))
    k = next(i for i, x in enumerate(broken["grasps"]) if x["quality"])
    broken["grasps"][k]["quality"]["contact"][0]["type"] = "blob"
    with pytest.raises(InputError, match=rf"grasps\[{k}\].*quality"):
        result_from_document(broken)


def test_mass_scales_gravity_margin_inversely(bracket, tmp_path):
    docs = []
    for m in ("0.1", "0.4"):
        out = tmp_path / f"g{m}.json"
        run(["grasps", bracket, *BRACKET, "--mass", m, "-o", out])
        docs.append(json.loads(out.read_text()))
    a, b = (np.array([x["quality"]["gravity_margin"] for x in d["grasps"] if x["quality"]]) for d in docs)
    assert len(a) == len(b) > 0
    np.testing.assert_allclose(a / b, 4.0, rtol=1e-9)  # 4 x the mass: a quarter of the margin
    assert docs[0]["part"]["mass_kg"] == pytest.approx(0.1) and docs[1]["params"]["mass"] == 0.4
    # --density gives the same part mass as --mass with the volume's density
    vol = docs[0]["part"]["mass_kg"] / docs[0]["part"]["density"]
    out = tmp_path / "gd.json"
    run(["grasps", bracket, *BRACKET, "--density", str(0.1 / vol), "-o", out])
    c = np.array([x["quality"]["gravity_margin"] for x in json.loads(out.read_text())["grasps"] if x["quality"]])
    np.testing.assert_allclose(c, a, rtol=1e-6)
    run(["grasps", bracket, *BRACKET, "--mass", "-1", "-o", tmp_path / "x.json"], code=3)
    assert not (tmp_path / "x.json").exists()


def test_scoring_option_changes_the_score(bracket, tmp_path, grasps_doc):
    yml = tmp_path / "top_only.yaml"
    yml.write_text("weights: {top: 1}\n")
    out = tmp_path / "g.json"
    run(["grasps", bracket, *BRACKET, "--scoring", yml, "-o", out])
    doc = json.loads(out.read_text())
    assert doc["params"]["score_weights"] == [["top", 1.0]]
    T_wp = np.array(doc["part"]["T_world_part"])
    for x in doc["grasps"]:
        if x["quality"]:
            z = T_wp[:3, :3] @ np.array(x["T_part_tcp"])[:3, 2]
            assert x["score"] == pytest.approx(max(0.0, -z[2]), abs=1e-8)  # poses rounded to 1e-10
    bad = tmp_path / "bad.yaml"
    bad.write_text("weights: {top: -1}\n")
    r = run(["grasps", bracket, *BRACKET, "--scoring", bad, "-o", tmp_path / "y.json"], code=3)
    assert "must be >= 0" in r.output


# -- plan: ranking by score, --simulate ----------------------------------------------------------------
@pytest.fixture(scope="module")
def plan_doc(bracket, tmp_path_factory):
    out = tmp_path_factory.mktemp("plan") / "p.json"
    # every pose in full: the tests below index the grasps by id
    run(["plan", bracket, *BRACKET, "--top", "3", "--simulate", "2", "--keep", "all", "-o", out])
    return out, json.loads(out.read_text())


def test_plan_ranks_by_score_with_the_diversity_rule(plan_doc, grasps_doc):
    _, doc = plan_doc
    g = doc["grasps"]
    ok = np.array([x["id"] for x in g if x["quality"] is not None])
    score = np.array([g[i]["score"] for i in ok])
    # the plan's scores are the grasp stage's (same weights, same quality)
    assert score.tolist() == [grasps_doc["grasps"][i]["score"] for i in ok]
    T = np.array([x["T_part_tcp"] for x in g])
    expected, _ = distinct_order(T, ok[np.lexsort((ok, -score))], min_distance=doc["plan_params"]["distinct_distance"],
                                 min_angle_deg=doc["plan_params"]["distinct_angle_deg"])
    # rank before the simulation re-ordered the simulated ones: compare the unsimulated tail
    ranked = sorted((x for x in g if x["rank"] is not None), key=lambda x: x["rank"])
    sim_ids = {x["id"] for x in g if x.get("sim")}
    assert [x["id"] for x in ranked if x["id"] not in sim_ids] == [i for i in expected.tolist() if i not in sim_ids]
    assert ranked[0]["score"] == pytest.approx(score.max()) or ranked[0]["id"] in sim_ids


def test_plan_simulate_writes_sim_and_ranks_held_first(plan_doc):
    from grasplan.results.reader import load_result

    path, doc = plan_doc
    simulated = [x for x in doc["grasps"] if x.get("sim")]
    assert len(simulated) == 2 and all(x["status"] == "planned" for x in simulated)
    assert all(set(x["sim"]) == {"success", "slip_m", "turn_deg"} for x in simulated)
    ranked = sorted((x for x in doc["grasps"] if x["rank"] is not None), key=lambda x: x["rank"])
    held = [bool(x.get("sim") and x["sim"]["success"]) for x in ranked]
    assert held == sorted(held, reverse=True)  # every held grasp before any other
    assert doc["plan_params"]["simulate"] == 2 and doc["timing_s"]["simulate"] > 0
    res = load_result(path)
    assert (res.grasps.sim_success >= 0).sum() == 2
    # CSV carries the quality and sim columns
    text = res.export("csv", path.with_suffix(".csv")).read_text()
    rows = list(csv.DictReader(io.StringIO(text)))
    for x in simulated:
        r = rows[x["id"]]
        assert r["sim_success"] == str(int(x["sim"]["success"]))
        assert float(r["gravity_margin"]) == pytest.approx(x["quality"]["gravity_margin"], rel=1e-8)
        assert r["contact0_type"] == x["quality"]["contact"][0]["type"]
    collided = next(x for x in doc["grasps"] if x["quality"] is None)
    assert rows[collided["id"]]["gravity_margin"] == "" and rows[collided["id"]]["sim_success"] == ""


def test_rank_held_first_is_stable_and_applied_to_a_plan(plan_doc):
    rank = np.array([2, -1, 0, 1, 3])
    new = rank_held_first(rank, np.array([1, -1, 0, 1, -1], dtype=np.int8))
    # held in rank order (row 3 then row 0), then the rest in rank order (row 2, row 4)
    assert new.tolist() == [1, -1, 2, 0, 3]
    from grasplan.results.reader import load_result

    path, _ = plan_doc
    compact = path.with_name("compact.json")
    load_result(path).write(compact)  # a compact plan: rows are not ids
    res = load_result(compact)
    ids = res.planned_ids()
    assert len(ids) >= 2 and res.grasps.index_of(ids[0]) != ids[0]
    # pretend the best planned grasp slipped and the second held: the second must come first
    fake = SimResult(success=np.array([False, True]), slip_m=np.array([0.02, 0.0]), turn_deg=np.zeros(2),
                     seconds=0.1, pieces=1)
    out = with_sim(res, np.array([res.grasps.index_of(i) for i in ids[:2]]), fake)
    assert out.planned_ids()[:2] == [ids[1], ids[0]]
    by_id = {g["id"]: g for g in out.to_json()["grasps"]}
    assert by_id[ids[0]]["sim"] == {"success": False, "slip_m": 0.02, "turn_deg": 0.0}


def test_simulate_cli_on_a_plan_takes_the_planned_grasps_in_rank_order(plan_doc, tmp_path):
    from grasplan.results.reader import load_result

    path, _ = plan_doc
    out = tmp_path / "sim.json"
    run(["simulate", path, "--top", "2", "--decomposition", "hull", "-o", out])
    doc = json.loads(out.read_text())
    assert [g["id"] for g in doc["grasps"]] == load_result(path).planned_ids()[:2]
    assert all(g["status"] == "planned" for g in doc["grasps"])
    assert doc["params"]["grip_force"] == 140.0 and doc["part"]["sha256"] == json.loads(path.read_text())["part"]["sha256"]
