"""``hold_force_N``, the grip force at which a grasp just holds (grip_force / gravity_margin): checked
on every collision-free grasp of the bracket by recomputing the margin at that force (the wrench
model itself, not the division), and carried alike by plan files (both forms), the CSV export and
picks files."""
from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np
import pytest

from grasplan.config.params import PlanParams
from grasplan.results.quality_json import hold_force

BRACKET = Path(__file__).resolve().parents[1] / "examples" / "parts" / "bracket.stl"


@pytest.fixture(scope="module")
def grasps():
    from grasplan.grasps.pipeline import compute_grasps
    from grasplan.part.mesh import load_part

    return compute_grasps(load_part(BRACKET, units="mm"))


def test_the_margin_at_the_hold_force_is_one_on_every_grasp(grasps):
    from grasplan.grasps.wrench import CONTACTS_PER_GRIP, gravity_margin, pressure_widths

    q = grasps.quality
    ok = np.flatnonzero(np.asarray(grasps.status).astype(str) == "ok")
    assert q is not None and len(ok) == len(q) > 100
    hold = q.hold_force
    assert np.all(np.isfinite(hold)) and np.all(hold > 0)
    T = grasps.table().T_part_tcp[ok]
    width = grasps.table().width[ok]

    def margin_at(rows: np.ndarray, force: np.ndarray) -> np.ndarray:  # grasp rows[k] pressed with force[k]
        return np.array([gravity_margin(grasps.mass_props, grasps.T_world_part, T[r:r + 1], width[r:r + 1],
                                        q.contact_area[r:r + 1], mu=q.mu, normal_force=f / CONTACTS_PER_GRIP,
                                        patch_width=pressure_widths(q.contact_type[r:r + 1], q.contact_width[r:r + 1]))[0]
                         for r, f in zip(rows.tolist(), force.tolist())])

    pick = np.unique(np.linspace(0, len(ok) - 1, 200).astype(int))  # 200 spread over the grasps, margins recomputed
    np.testing.assert_allclose(margin_at(pick, hold[pick]), 1.0, rtol=1e-6)
    assert np.all(margin_at(pick, 0.99 * hold[pick]) < 1.0) and np.all(margin_at(pick, 1.01 * hold[pick]) > 1.0)
    # and the formula on every grasp: the margin is proportional to the force
    np.testing.assert_allclose(hold * q.gravity_margin, q.grip_force, rtol=1e-12)


def test_no_force_holds_a_grasp_without_margin():
    assert np.isnan(hold_force(np.array([0.0, np.nan]), 140.0)).all()
    assert hold_force(np.array([2.0]), 140.0).tolist() == [70.0]


@pytest.mark.parametrize("keep", ["collision_free", "all"])
def test_plan_files_and_csv_carry_it(tmp_path, keep):
    from grasplan import plan
    from grasplan.part.mesh import load_part
    from grasplan.results.reader import load_result
    from plan_docs import kept_grasps

    res = plan(load_part(BRACKET, units="mm"), "ur5", planning=PlanParams(top=2))
    out = res.write(tmp_path / "p.json", keep=keep)
    doc = json.loads(out.read_text())
    F = float(res.gripper.grip_force)
    rows = [g for g in kept_grasps(doc) if g.get("quality")]
    assert rows
    for g in rows:
        q = g["quality"]
        assert q["hold_force_N"] == pytest.approx(F / q["gravity_margin"], abs=0.005 + 1e-9)
    text = load_result(out).export("csv", tmp_path / "p.csv").read_text()
    by_id = {int(r["id"]): r for r in csv.DictReader(io.StringIO(text))}
    for g in rows:
        assert float(by_id[g["id"]]["hold_force_N"]) == pytest.approx(F / g["quality"]["gravity_margin"], rel=1e-8)


def test_picks_carry_it(tmp_path):
    from grasplan.pick import Picker

    scene = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "pile.json"
    result = Picker().plan(scene, max_picks=2)
    picks = json.loads(result.to_json_text())["picks"]
    assert picks
    assert result.gripper is not None
    force = float(result.gripper.grip_force)
    for p in picks:
        q = p["quality"]
        assert q["hold_force_N"] == pytest.approx(force / q["gravity_margin"], abs=0.005 + 1e-9)


def test_pose_plans_give_the_least_hold_force_per_pose(tmp_path):
    from grasplan.motion.planning import plan_poses
    from grasplan.part.mesh import load_part
    from grasplan.results.pose_plans import write_pose_plans
    from plan_docs import kept_grasps

    runs = plan_poses(load_part(BRACKET, units="mm"), "ur5", planning=PlanParams(top=1))
    done = write_pose_plans(runs, tmp_path / "out.json", min_probability=0.02)
    assert len(done.poses) >= 2
    for p in done.poses:
        doc = json.loads((tmp_path / p["file"]).read_text())
        holds = [g["quality"]["hold_force_N"] for g in kept_grasps(doc) if g.get("quality")
                 and g["quality"]["hold_force_N"] is not None]
        # the pose file's own grasps, read independently (None: no grasp of the pose has a quality)
        assert p["hold_force_N"] == (min(holds) if holds else None)
        planned = [g for g in kept_grasps(doc) if g["status"] == "planned"]
        assert p["planned_holding"] == sum(g["quality"]["gravity_margin"] >= 1.0 for g in planned)
    assert all(len(r) == 7 for r in done.table_rows())
    # OUT.json is the pose with the most planned grasps that hold, then the most planned, the first of ties
    best = max(done.poses, key=lambda p: (p["planned_holding"], p["planned"], p["probability"]))
    assert done.chosen == best["pose_index"]


def test_the_chosen_pose_prefers_planned_grasps_that_hold():
    from grasplan.results.pose_plans import choice_key

    many_slipping = {"planned": 20, "planned_holding": 0}
    fewer_holding = {"planned": 5, "planned_holding": 3}
    assert choice_key(fewer_holding) > choice_key(many_slipping)
    assert choice_key({"planned": 6, "planned_holding": 3}) > choice_key(fewer_holding)


def test_hold_note_names_the_poses_that_hold():
    from grasplan.results.pose_plans import PosePlans

    poses = ({"pose_index": 0, "probability": 0.5, "hold_force_N": 150.0, "file": "o.pose0.json"},
             {"pose_index": 1, "probability": 0.3, "hold_force_N": 90.0, "file": "o.pose1.json"},
             {"pose_index": 2, "probability": 0.2, "hold_force_N": None, "file": "o.pose2.json"})
    done = PosePlans(chosen=0, result=None, planned=3, poses=poses)
    note = done.hold_note(140.0)
    assert "pose 0" in note and "150.0 N" in note and "pose 1 (30.0 %) holds from 90.0 N (o.pose1.json)" in note
    assert "pose 2" not in note
    assert done.hold_note(150.0) == ""  # the chosen pose holds
    assert done.hold_note(80.0) == ""  # no pose holds: nothing better to name


def test_plan_min_gravity_margin_plans_the_unfiltered_order_of_the_holding_grasps(tmp_path):
    """``min_gravity_margin``: the grasps tried are, in order, those of the plan without it whose
    margin reaches the bar; every grasp left out is below it and says so; at a bar no grasp reaches
    the command exits 4 saying how many were left out."""
    from click.testing import CliRunner

    from grasplan.cli import main
    from grasplan.motion.planning import WEAK_REASON, plan
    from grasplan.part.mesh import load_part

    part = load_part(BRACKET, units="mm")
    full = plan(part, "ur5", planning=PlanParams(top=100000, budget_s=None))
    bar = 15.0
    cut = plan(part, "ur5", planning=PlanParams(top=100000, budget_s=None, min_gravity_margin=bar))
    gm, rank_full = full.grasps.gravity_margin, np.asarray(full.grasps.rank, dtype=float)
    assert np.array_equal(cut.grasps.gravity_margin, gm, equal_nan=True)
    ranked = np.flatnonzero(np.isfinite(rank_full) & (rank_full >= 0))
    keep = ranked[gm[ranked] >= bar]
    expect = keep[np.argsort(rank_full[keep])]
    rank_cut = np.asarray(cut.grasps.rank, dtype=float)
    got = np.flatnonzero(np.isfinite(rank_cut) & (rank_cut >= 0))
    assert 0 < len(expect) < len(ranked)
    assert np.array_equal(got[np.argsort(rank_cut[got])], expect)
    reasons = np.asarray(cut.grasps.reason).astype(str)
    left = np.setdiff1d(ranked, keep)
    assert all(r.startswith(WEAK_REASON) for r in reasons[left])
    assert (gm[left] < bar).all() and (gm[got] >= bar).all()
    assert not np.char.startswith(reasons[got], WEAK_REASON).any()

    r = CliRunner().invoke(main, ["plan", str(BRACKET), "--units", "mm", "--robot", "ur5", "--min-gravity-margin",
                                  "100", "-o", str(tmp_path / "p.json")])
    assert r.exit_code == 4, r.output
    assert f"{len(ranked)} collision-free grasps predicted to slip were not tried (--min-gravity-margin 100" in r.output
