"""`plan` on the part's grasp database: the cached road and the whole grasp stage computed in the
cell (`--grasp-db off`) give the same plan, the first plan of a part computes and stores the
database and later plans read it, grasp ids name the same grasp in every resting pose, and the
cache's failures cost a recomputation, never the plan."""
from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from grasplan.cli import main
from grasplan.config.params import GRASP_DB_OFF, GraspParams, PlanParams
from grasplan.errors import InputError
from grasplan.grasps.graspdb import cache_path, database_for, load_database
from grasplan.gripper.load import load_gripper
from grasplan.motion.planning import GraspDatabaseNote, plan
from grasplan.part.mesh import load_part
from grasplan.config.params import CandidateParams

ROOT = Path(__file__).resolve().parents[1]
BRACKET = ROOT / "examples" / "parts" / "bracket.stl"
FAST = GraspParams(roll_step_deg=30.0)
TOP = PlanParams(top=5)
#: what differs between the two roads' files: the seconds and the option that chose the road
ROAD_KEYS = {"timing_s", "plan_params"}


@pytest.fixture(scope="module")
def bracket():
    return load_part(BRACKET, units="mm")


@pytest.fixture
def own_cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("GRASPLAN_CACHE_DIR", str(folder))
    return folder


def _same_document(a, b):
    da, db = a.to_json(), b.to_json()
    assert set(da) == set(db)
    for k in set(da) - ROAD_KEYS:
        assert da[k] == db[k], k
    pa, pb = dict(da["plan_params"]), dict(db["plan_params"])
    assert pa.pop("grasp_db") != pb.pop("grasp_db") and pa == pb


@pytest.mark.parametrize("cell,pose_index", [("table", None), ("table", 1), ("bin", None)])
def test_database_road_gives_the_cell_computation(bracket, cell, pose_index, own_cache):
    """The database placed in the cell and the whole stage computed there: the same file (grasps,
    untried columns, rejected counts, counts, paths) but for the seconds and the road's option."""
    gp = replace(FAST, pose_index=pose_index)
    cached = plan(bracket, "ur5", cell=cell, grasps=gp, planning=TOP)
    full = plan(bracket, "ur5", cell=cell, grasps=gp, planning=replace(TOP, grasp_db=GRASP_DB_OFF))
    assert cached.rejected is not None and full.rejected is None
    assert len(cached.grasps) < len(full.grasps)  # the database holds the part-free poses only
    assert cached.counts() == full.counts() and cached.counts()["planned"] > 0
    _same_document(cached, full)
    # and row by row: every pose the database holds has the full computation's status and score
    rows = np.array([full.grasps.index_of(int(i)) for i in cached.grasps.ids])
    assert np.array_equal(full.grasps.status[rows].astype(str), cached.grasps.status.astype(str))
    np.testing.assert_array_equal(full.grasps.score[rows], cached.grasps.score)
    np.testing.assert_array_equal(full.grasps.T_part_tcp[rows], cached.grasps.T_part_tcp)
    hit_part = np.setdiff1d(full.grasps.ids, cached.grasps.ids)
    assert set(full.grasps.status[hit_part].astype(str)) == {"collision_part"}


def test_first_plan_computes_and_stores_later_plans_read(bracket, own_cache):
    notes: list[str] = []

    def progress(ev):
        if isinstance(ev, GraspDatabaseNote):
            notes.append(ev.message)

    first = plan(bracket, "ur5", grasps=FAST, planning=TOP, progress=progress)
    path = cache_path(bracket, load_gripper("schunk_egp_c_40"), CandidateParams(), FAST)
    assert path.is_file() and any("computing" in n for n in notes) and any("cached in" in n for n in notes)
    assert "candidates" in first.timing_s and "quality" in first.timing_s  # the database's own stages
    notes.clear()
    second = plan(bracket, "ur5", grasps=replace(FAST, pose_index=1), planning=TOP, progress=progress)
    assert notes == []  # read, not computed: another resting pose uses the same database
    assert "database" in second.timing_s and "candidates" not in second.timing_s
    db = load_database(path, part=bracket)
    assert db.counts["poses"] == first.counts()["grasps"] == second.counts()["grasps"]


def test_grasp_ids_name_the_same_grasp_in_every_pose(bracket, own_cache):
    a = plan(bracket, "ur5", grasps=replace(FAST, pose_index=0), planning=TOP)
    b = plan(bracket, "ur5", grasps=replace(FAST, pose_index=1), planning=TOP)
    assert not np.allclose(a.T_world_part, b.T_world_part)
    common = np.intersect1d(a.grasps.ids, b.grasps.ids)
    assert len(common) > 100
    ra = [a.grasps.index_of(int(i)) for i in common]
    rb = [b.grasps.index_of(int(i)) for i in common]
    np.testing.assert_array_equal(a.grasps.T_part_tcp[ra], b.grasps.T_part_tcp[rb])
    np.testing.assert_array_equal(a.grasps.candidate[ra], b.grasps.candidate[rb])


def test_unwritable_cache_costs_the_next_run_not_this_one(bracket, tmp_path, monkeypatch):
    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    monkeypatch.setenv("GRASPLAN_CACHE_DIR", str(blocked / "cache"))
    notes: list[str] = []
    res = plan(bracket, "ur5", grasps=FAST, planning=TOP,
               progress=lambda ev: notes.append(ev.message) if isinstance(ev, GraspDatabaseNote) else None)
    assert res.counts()["planned"] > 0
    assert any("not cached" in n and "GRASPLAN_CACHE_DIR" in n for n in notes), notes


def test_a_database_of_other_options_is_refused(bracket, own_cache):
    db = database_for(bracket, "schunk_egp_c_40", grasps=GraspParams(roll_step_deg=90.0))
    with pytest.raises(InputError, match="other candidate or grasp options"):
        plan(bracket, "ur5", grasps=FAST, planning=TOP, database=db)
    ok = plan(bracket, "ur5", grasps=GraspParams(roll_step_deg=90.0), planning=TOP, database=db)
    assert ok.counts()["grasps"] == db.counts["poses"]


def test_cli_keep_all_writes_every_pose_and_default_reads_the_cache(tmp_path, own_cache):
    base = ["plan", str(BRACKET), "--units", "mm", "--robot", "ur5", "--roll-step", "30", "--top", "3"]
    r = CliRunner().invoke(main, [*base, "-o", str(tmp_path / "a.json")])
    assert r.exit_code == 0, r.output
    assert "grasp database for bracket.stl" in r.output and "computing" in r.output
    r = CliRunner().invoke(main, [*base, "--keep", "all", "-o", str(tmp_path / "b.json")])
    assert r.exit_code == 0, r.output
    a = json.loads((tmp_path / "a.json").read_text())
    b = json.loads((tmp_path / "b.json").read_text())
    assert b["keep"] == "all" and len(b["grasps"]) == b["counts"]["poses"] == a["counts"]["poses"]
    assert b["plan_params"]["grasp_db"] == GRASP_DB_OFF and a["plan_params"]["grasp_db"] == "cache"
    planned_a = [g["id"] for g in a["grasps"] if g["status"] == "planned"]
    planned_b = [g["id"] for g in b["grasps"] if g["status"] == "planned"]
    assert planned_a == planned_b
    r = CliRunner().invoke(main, [*base, "-o", str(tmp_path / "c.json")])
    assert r.exit_code == 0 and "computing" not in r.output
    assert os.listdir(own_cache / "graspdb")


def test_a_plan_from_the_cache_computes_no_hull_and_imports_no_scipy_spatial(tmp_path, own_cache):
    """The database keeps the part's resting poses: a plan that reads it places the part without
    the convex hull (SciPy's Qhull, scipy.spatial) and ranks without a k-d tree, in a fresh process
    as a cell runs it."""
    from test_startup import imported_heavy

    base = ["plan", str(BRACKET), "--units", "mm", "--robot", "ur5", "--roll-step", "30", "--top", "2"]
    code, heavy, _ = imported_heavy(*base, "-o", str(tmp_path / "a.json"))
    assert code == 0 and "scipy.spatial" in heavy  # computing the database needs the hull
    code, heavy, _ = imported_heavy(*base, "-o", str(tmp_path / "b.json"))
    assert code == 0 and not [m for m in heavy if m.startswith("scipy.spatial")], heavy
    a = json.loads((tmp_path / "a.json").read_text())
    b = json.loads((tmp_path / "b.json").read_text())
    assert a["part"]["T_world_part"] == b["part"]["T_world_part"] and a["counts"] == b["counts"]


def test_resting_poses_stored_in_the_database_are_the_computed_ones(bracket, own_cache):
    from grasplan.part.stability import stable_poses

    db = database_for(bracket, "schunk_egp_c_40", grasps=FAST)
    R, p = stable_poses(load_part(BRACKET, units="mm").mesh)  # a fresh mesh: computed
    np.testing.assert_array_equal(db.rest_R, R)
    np.testing.assert_array_equal(db.rest_prob, p)
    fresh = load_part(BRACKET, units="mm")
    loaded = load_database(cache_path(fresh, load_gripper("schunk_egp_c_40"), CandidateParams(), FAST), part=fresh)
    loaded.prime_resting_poses(fresh)
    R2, p2 = stable_poses(fresh.mesh)  # primed: the stored ones
    np.testing.assert_array_equal(R2, R)
    np.testing.assert_array_equal(p2, p)


def test_hold_by_pose_counts_what_the_cell_computation_predicts(bracket, own_cache):
    """Per resting pose, the grasps predicted to hold (the database placed in each pose) are those
    the whole grasp stage computed in that pose predicts, at a density where some poses hold."""
    from grasplan.cell.model import load_cell
    from grasplan.grasps.pipeline import compute_grasps
    from grasplan.grasps.placed import hold_by_pose
    from grasplan.motion.planning import stable_pose_indices

    heavy = GraspParams(roll_step_deg=30.0, density=60000.0)
    g, cell = load_gripper("schunk_egp_c_40"), load_cell("table")
    poses = stable_pose_indices(bracket.mesh)[:3]
    rows = hold_by_pose(bracket, g, cell, candidates=CandidateParams(), grasps=heavy, poses=poses)
    assert [r[:2] for r in rows] == poses and sum(r[2] for r in rows) > 0
    for k, _, n, force in rows:
        gr = compute_grasps(bracket, gripper=g, cell=cell, grasps=replace(heavy, pose_index=k))
        gm = gr.quality.gravity_margin
        assert n == int(np.count_nonzero(gm >= 1.0))
        assert force == pytest.approx(g.grip_force / gm.max(), rel=1e-12)


def test_hold_by_pose_rows_are_kept_beside_the_database_and_read_back(bracket, own_cache, monkeypatch):
    """The second call reads the rows the first kept (no database is opened), a damaged file or
    another cell is computed again, and the kept rows equal the computed ones."""
    from grasplan.cell.model import load_cell
    from grasplan.grasps import placed
    from grasplan.motion.planning import stable_pose_indices

    heavy = GraspParams(roll_step_deg=30.0, density=60000.0)
    g, cell = load_gripper("schunk_egp_c_40"), load_cell("table")
    poses = stable_pose_indices(bracket.mesh)[:3]
    kw = dict(candidates=CandidateParams(), grasps=heavy, poses=poses)
    first = placed.hold_by_pose(bracket, g, cell, **kw)
    path = placed.hold_cache_path(bracket, g, cell, **kw)
    assert path.is_file() and path.parent.name == "graspdb"
    computed = placed.hold_by_pose(bracket, g, cell, cache=False, **kw)
    opened = []
    real = placed.database_for
    monkeypatch.setattr(placed, "database_for", lambda *a, **k: opened.append(1) or real(*a, **k))
    assert placed.hold_by_pose(bracket, g, cell, **kw) == first == computed and opened == []
    path.write_text('[[0, 0.5, "many", null]]')
    assert placed.hold_by_pose(bracket, g, cell, **kw) == first and opened == [1]
    other = replace(cell, table_z=cell.table_z + 0.01)
    assert placed.hold_cache_path(bracket, g, other, **kw) != path


@pytest.mark.paper
def test_a_pose_that_holds_none_names_the_poses_that_do(tmp_path, own_cache):
    from conftest import paper_part

    part = paper_part("TLess20.stl")
    r = CliRunner().invoke(main, ["plan", str(part), "--robot", "ur5", "--top", "2", "-o", str(tmp_path / "t.json")])
    assert r.exit_code == 0, r.output
    line = next(ln for ln in r.output.splitlines() if "predicted to hold; poses that have" in ln)
    assert "--pose-index" in line
    k = int(line.split("--pose-index ")[1].split(",")[0])
    r = CliRunner().invoke(main, ["plan", str(part), "--robot", "ur5", "--top", "2", "--pose-index", str(k),
                                  "-o", str(tmp_path / "k.json")])
    assert r.exit_code == 0 and "no collision-free grasp is predicted to hold" not in r.output, r.output
