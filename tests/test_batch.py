"""grasplan batch: discovery and manifests, isolated failures, summaries, resume, local vs Ray engine.

One batch of the example parts plus two malformed files is planned once per module (``--top 3``,
two workers) and shared by the tests that read its outputs."""
from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest

from grasplan.batch.run import run_batch
from grasplan.batch.layout import FINAL_STATUSES
from grasplan.batch.manifest import discover_parts, make_jobs, read_manifest
from grasplan.batch.options import BatchOptions
from grasplan.errors import InputError
from grasplan.config.params import GraspParams, PlanParams

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "parts"
GOOD = ("box.stl", "bracket.stl", "gear.stl")
BAD = {"empty.stl": b"", "garbage.stl": b"solid x\n this is not an STL facet list\nendsolid x\n"}
FAST = BatchOptions(planning=PlanParams(top=3))


def _plan_doc(path: Path) -> dict:
    doc = json.loads(path.read_text())
    doc.pop("timing_s")
    return doc


def _cli(args):
    from click.testing import CliRunner

    from grasplan.cli import main

    return CliRunner().invoke(main, args)


@pytest.fixture(scope="module")
def catalogue(tmp_path_factory):
    """A folder with the example parts (one in a sub-folder) and two malformed meshes."""
    root = tmp_path_factory.mktemp("catalogue")
    (root / "sub").mkdir()
    for name in GOOD:
        shutil.copy(EXAMPLES / name, root / ("sub" if name == "gear.stl" else "") / name)
    for name, data in BAD.items():
        (root / name).write_bytes(data)
    (root / "notes.txt").write_text("not a part")
    return root


@pytest.fixture(scope="module")
def batch(catalogue, tmp_path_factory):
    """``grasplan batch CATALOGUE -o OUT --top 3 --workers 2``: (out folder, CLI result)."""
    out = tmp_path_factory.mktemp("batch") / "out"
    r = _cli(["batch", str(catalogue), "-o", str(out), "--top", "3", "--workers", "2", "--export", "csv"])
    return out, r


# ------------------------------------------------------------------------------------------- inputs
def test_discovery_recurses_folders_sorted_and_skips_other_files(catalogue):
    found = [Path(e.path) for e in discover_parts([catalogue])]
    expected = sorted([catalogue / n for n in ("box.stl", "bracket.stl", *BAD)] + [catalogue / "sub" / "gear.stl"])
    assert found == expected


def test_manifest_csv_and_yaml_overrides_and_relative_paths(tmp_path):
    shutil.copy(EXAMPLES / "box.stl", tmp_path / "box.stl")
    (tmp_path / "m.csv").write_text("path,units,pose_index,thin,top\nbox.stl,mm,1,2mm,\nbox.stl,,,,5\n")
    rows = read_manifest(tmp_path / "m.csv")
    assert [r.path for r in rows] == [str(tmp_path / "box.stl")] * 2
    assert dict(rows[0].overrides) == {"units": "mm", "pose_index": 1, "thin_spacing": pytest.approx(0.002)}
    assert dict(rows[1].overrides) == {"top": 5}
    (tmp_path / "m.yaml").write_text("defaults: {top: 4}\nparts:\n  - box.stl\n  - {path: box.stl, gamma: 120}\n")
    rows = read_manifest(tmp_path / "m.yaml")
    assert dict(rows[0].overrides) == {"top": 4}
    assert dict(rows[1].overrides) == {"top": 4, "gamma_deg": 120.0}
    # the overrides land in the parameter objects; one file with two option sets gets two folders
    jobs = make_jobs(rows, FAST)
    assert jobs[1].options.candidates.gamma_deg == 120.0 and jobs[0].options.candidates.gamma_deg == 135.0
    assert jobs[0].options.planning.top == 4
    assert jobs[0].options_hash != jobs[1].options_hash
    assert jobs[0].dir_name != jobs[1].dir_name and all(j.dir_name.startswith("box-") for j in jobs)


@pytest.mark.parametrize("text, needle", [
    ("path,colour\nbox.stl,red\n", "unknown column 'colour'"),
    ("path\nmissing.stl\n", "not found"),
    ("units\nmm\n", "'path' column"),
    ("path,pose_index\nbox.stl,first\n", "whole number"),
    ("path,thin\nbox.stl,-1mm\n", "--thin"),
    ("path,units\nbox.stl,furlong\n", "units"),
])
def test_bad_manifest_is_input_error_naming_the_row(tmp_path, text, needle):
    shutil.copy(EXAMPLES / "box.stl", tmp_path / "box.stl")
    (tmp_path / "m.csv").write_text(text)
    with pytest.raises(InputError, match=needle):
        make_jobs(discover_parts([tmp_path / "m.csv"]), FAST)


def test_bad_batch_inputs_exit_3_and_write_nothing(tmp_path):
    (tmp_path / "empty_dir").mkdir()
    out = tmp_path / "out"
    r = _cli(["batch", str(tmp_path / "empty_dir"), "-o", str(out)])
    assert r.exit_code == 3 and "no parts found" in r.output
    assert not out.exists()
    r = _cli(["batch", str(EXAMPLES / "box.stl"), "-o", str(out), "--export", "nonsense"])
    assert r.exit_code == 3 and "nonsense" in r.output and "available" in r.output
    r = _cli(["batch", str(EXAMPLES / "box.stl"), "-o", str(out), "--robot", "ur6"])
    assert r.exit_code == 3 and "ur6" in r.output and "ur5" in r.output
    assert not out.exists()


# ------------------------------------------------------------------------------------ one batch run
def test_batch_summary_rows_and_exit_code(batch, catalogue):
    out, r = batch
    assert r.exit_code == 0, r.output
    with open(out / "summary.csv", newline="") as f:
        rows = {Path(row["part"]).name: row for row in csv.DictReader(f)}
    assert set(rows) == {*GOOD, *BAD}
    summary = json.loads((out / "summary.json").read_text())
    assert [Path(p["part"]).name for p in summary["parts"]] == [Path(e.path).name for e in discover_parts([catalogue])]
    for name in GOOD:
        row = rows[name]
        assert row["status"] == "planned" and row["exit_code"] == "0"
        plan = json.loads((out / row["dir"] / "plan.json").read_text())
        planned = [g for g in plan["grasps"] if g["status"] == "planned"]
        from plan_docs import REJECTED, kept_grasps

        # the row agrees with the plan it summarises
        assert int(row["planned"]) == len(planned) == 3
        kept, rejected = kept_grasps(plan), sum(sum(plan["rejected"][s]) for s in REJECTED)
        assert int(row["grasps"]) == len(kept) + rejected == plan["counts"]["poses"]  # every pose, counted or kept
        assert float(row["best_score"]) == pytest.approx(max(g["score"] for g in planned), rel=1e-5)
        assert row["dir"] == f"{Path(name).stem}-{plan['part']['sha256'][:8]}"
        assert float(row["s_plan"]) > 0 and float(row["seconds"]) >= float(row["s_plan"])
        for f in ("view.html", "log.txt", "done.json", "export-csv.csv"):
            assert (out / row["dir"] / f).is_file(), f
    for name in BAD:
        row = rows[name]
        assert row["status"] == "bad_input" and row["exit_code"] == "3"
        assert name in row["error"]  # the message names the file
        assert not (out / row["dir"] / "plan.json").exists()
        assert row["error"] in (out / row["dir"] / "log.txt").read_text()
    assert not (out / ".staging").exists()


def test_batch_plan_equals_single_part_plan(batch, catalogue):
    """The batch's plan.json is the one `grasplan.plan` writes for the same part and options."""
    import grasplan

    out, _ = batch
    path = catalogue / "bracket.stl"
    part = grasplan.load_part(path)
    grasplan.plan(part, robot="ur5", planning=PlanParams(top=3)).write(out.parent / "single.json")
    row = next(p for p in json.loads((out / "summary.json").read_text())["parts"] if p["part"] == str(path))
    assert _plan_doc(out / row["dir"] / "plan.json") == _plan_doc(out.parent / "single.json")


def test_batch_plan_equals_cli_plan(batch, catalogue):
    out, _ = batch
    path = catalogue / "box.stl"
    r = _cli(["plan", str(path), "--top", "3", "-o", str(out.parent / "cli.json")])
    assert r.exit_code == 0, r.output
    row = next(p for p in json.loads((out / "summary.json").read_text())["parts"] if p["part"] == str(path))
    assert _plan_doc(out / row["dir"] / "plan.json") == _plan_doc(out.parent / "cli.json")


def test_index_html_is_offline_and_links_every_viewer(batch):
    out, _ = batch
    page = (out / "index.html").read_text()
    rows = json.loads((out / "summary.json").read_text())["parts"]
    assert "<script>" in page and "http://" not in page and "https://" not in page
    for row in rows:
        has_view = row["status"] == "planned"
        assert (f'href="{row["dir"]}/view.html"' in page) == has_view
        assert row["status"] in page


# ------------------------------------------------------------------------------------------- resume
def test_rerun_skips_finished_parts_and_redoes_unfinished(batch, catalogue, tmp_path):
    out, _ = batch
    work = tmp_path / "out"
    shutil.copytree(out, work)
    rows = json.loads((work / "summary.json").read_text())["parts"]
    box = next(r for r in rows if Path(r["part"]).name == "box.stl")
    # an unfinished part (no done.json: killed before the rename) and a leftover staging folder
    (work / box["dir"] / "done.json").unlink()
    (work / ".staging" / "gear-x").mkdir(parents=True)
    before = {r["dir"]: (work / r["dir"] / "done.json").stat().st_mtime_ns
              for r in rows if r["dir"] != box["dir"]}
    seen = []
    s = run_batch([catalogue], work, options=BatchOptions(planning=PlanParams(top=3), exports=("csv",)),
                  workers=1, progress=lambda ev: seen.append(Path(ev["row"]["part"]).name))
    assert seen == ["box.stl"]  # only the unfinished part was planned again
    assert {Path(r["part"]).name: r["resumed"] for r in s.rows} == {n: n != "box.stl" for n in (*GOOD, *BAD)}
    assert all(r["status"] in FINAL_STATUSES for r in s.rows)
    assert {r["dir"]: (work / r["dir"] / "done.json").stat().st_mtime_ns for r in rows if r["dir"] != box["dir"]} \
        == before
    assert _plan_doc(work / box["dir"] / "plan.json") == _plan_doc(out / box["dir"] / "plan.json")
    assert not (work / ".staging").exists()


def test_nothing_planned_anywhere_exits_4(tmp_path):
    """A part whose only stable pose leaves nothing the gripper can reach: exit 4, row says so."""
    (tmp_path / "m.yaml").write_text(f"- {{path: {EXAMPLES / 'box.stl'}, max_opening: 1mm}}\n")
    r = _cli(["batch", str(tmp_path / "m.yaml"), "-o", str(tmp_path / "out"), "--top", "1", "--workers", "1",
              "--no-view"])
    assert r.exit_code == 4, r.output
    row = json.loads((tmp_path / "out" / "summary.json").read_text())["parts"][0]
    assert row["status"] == "nothing_planned" and row["planned"] == 0 and row["exit_code"] == 4


# ---------------------------------------------------------------------------------------------- ray
@pytest.mark.slow
def test_ray_engine_gives_the_local_engines_plans(batch, catalogue, tmp_path):
    """`--engine ray --workers 2`: a private local Ray runtime (ray.init(address="local", num_cpus=2));
    the parts travel as bytes, the plans and exports come back identical to the local engine's."""
    pytest.importorskip("ray", reason="Ray is an optional extra: pip install 'grasplan[ray]'")
    out, _ = batch
    parts = [catalogue / "box.stl", catalogue / "bracket.stl", catalogue / "garbage.stl"]
    r = _cli(["batch", *map(str, parts), "-o", str(tmp_path / "ray"), "--top", "3", "--export", "csv",
              "--engine", "ray", "--workers", "2"])
    assert r.exit_code == 0, r.output
    rows = json.loads((tmp_path / "ray" / "summary.json").read_text())["parts"]
    local = {row["part"]: row for row in json.loads((out / "summary.json").read_text())["parts"]}
    assert [row["status"] for row in rows] == ["planned", "planned", "bad_input"]
    for row in rows:
        assert row["dir"] == local[row["part"]]["dir"] and row["error"] == local[row["part"]]["error"]
        if row["status"] == "planned":
            got, ref = tmp_path / "ray" / row["dir"], out / row["dir"]
            assert _plan_doc(got / "plan.json") == _plan_doc(ref / "plan.json")
            assert (got / "export-csv.csv").read_bytes() == (ref / "export-csv.csv").read_bytes()
            assert (got / "view.html").is_file()


def test_per_part_pose_index_reaches_the_plan_and_other_options_replan(tmp_path):
    manifest = tmp_path / "m.csv"
    manifest.write_text(f"path,pose_index\n{EXAMPLES / 'bracket.stl'},1\n")
    options = BatchOptions(planning=PlanParams(top=1), view=False)
    s = run_batch([manifest], tmp_path / "out", options=options, workers=1)
    folder = tmp_path / "out" / s.rows[0]["dir"]
    plan = json.loads((folder / "plan.json").read_text())
    assert plan["params"]["pose_index"] == 1 != GraspParams().pose_index
    assert plan["part"]["path"] == str(EXAMPLES / "bracket.stl")
    # another per-part option: the finished result does not match, the part is planned again in place
    manifest.write_text(f"path,pose_index\n{EXAMPLES / 'bracket.stl'},0\n")
    s2 = run_batch([manifest], tmp_path / "out", options=options, workers=1)
    assert s2.rows[0]["dir"] == s.rows[0]["dir"] and not s2.rows[0]["resumed"]
    assert s2.rows[0]["options_hash"] != s.rows[0]["options_hash"]
    assert json.loads((folder / "plan.json").read_text())["params"]["pose_index"] == 0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(
        [".grasplan-batch.lock", s.rows[0]["dir"], "index.html", "summary.csv", "summary.json"])


# ------------------------------------------------------------------ place, scoring file, every pose
@pytest.mark.slow
def test_place_scoring_file_and_every_pose_give_the_files_plan_gives(tmp_path):
    """``place``, ``scoring`` and ``pose_index: all`` are plan options a manifest row (and the batch's
    command line) sets too: each part's files are those `grasplan plan` writes with the same options
    (with ``all``: plan.json plus one plan.pose<k>.json per resting pose), timing aside."""
    import trimesh

    plate = tmp_path / "plate.stl"  # lying flat nothing fits the jaws; on its long edge (poses 2, 3) it does
    trimesh.creation.box(extents=[0.1, 0.06, 0.012]).export(plate)
    (tmp_path / "s.yaml").write_text("weights: {top: 1, center: 1}\n")
    place = "0.45,0.3,5mm,0,0,180"
    (tmp_path / "m.yaml").write_text(f"- {{path: plate.stl, units: m, pose_index: all, scoring: s.yaml}}\n"
                                     f"- {{path: {EXAMPLES / 'box.stl'}, place: '{place}'}}\n")
    out = tmp_path / "out"
    r = _cli(["batch", str(tmp_path / "m.yaml"), "-o", str(out), "--top", "1", "--workers", "2", "--no-view", "--gripper", "long_stroke_50"])
    assert r.exit_code == 0, r.output
    rows = json.loads((out / "summary.json").read_text())["parts"]
    assert [row["status"] for row in rows] == ["planned", "planned"]
    r = _cli(["plan", str(plate), "--units", "m", "--gripper", "long_stroke_50", "--top", "1", "--pose-index", "all", "--scoring",
              str(tmp_path / "s.yaml"), "-o", str(tmp_path / "plate.json")])
    assert r.exit_code == 0, r.output
    r = _cli(["plan", str(EXAMPLES / "box.stl"), "--gripper", "long_stroke_50", "--top", "1", "--place", place,
              "-o", str(tmp_path / "box.json")])
    assert r.exit_code == 0, r.output

    folder = out / rows[0]["dir"]
    batch_all, plan_all = _plan_doc(folder / "plan.json"), _plan_doc(tmp_path / "plate.json")
    for p in plan_all["poses"]["poses"]:  # the per-pose files are named after OUT
        p["file"] = p["file"] and p["file"].replace("plate.", "plan.", 1)
    assert batch_all == plan_all
    assert batch_all["params"]["score_weights"] == [["top", 1.0], ["center", 1.0]]
    files = sorted(p.name for p in folder.glob("plan.pose*.json"))
    assert files == sorted(p["file"] for p in plan_all["poses"]["poses"] if p["file"]) and len(files) >= 2
    for name in files:
        assert _plan_doc(folder / name) == _plan_doc(tmp_path / name.replace("plan.", "plate.", 1))
    assert rows[0]["planned"] == batch_all["counts"]["planned"] == 1

    batch_box = _plan_doc(out / rows[1]["dir"] / "plan.json")
    assert batch_box == _plan_doc(tmp_path / "box.json")
    assert batch_box["cell"]["place"]["T_world_part"][2][3] == pytest.approx(0.005)
    # the options hash covers the new options: the same part without them is another option set
    plain = make_jobs(discover_parts([EXAMPLES / "box.stl"]), BatchOptions())[0]
    assert rows[1]["options_hash"] != plain.options_hash
    done = json.loads((out / rows[1]["dir"] / "done.json").read_text())
    assert done["options"]["planning"]["place"][2][3] == pytest.approx(0.005)
    assert "scoring" not in json.loads((folder / "done.json").read_text())["options"]["grasps"]
