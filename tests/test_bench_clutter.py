"""benchmarks/clutter.py: its log (header, one line per round, seeds), resuming (nothing recomputed;
a last line cut short recomputed alone), a header of another setting refused, and its table helpers."""
from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "clutter.py"
SEED = 3
ARGS = ["--rounds", "2", "--jobs", "2", "--protocol", "pile", "--part", "examples/parts/box.stl:2",
        "--decomposition", "hull", "--seed", str(SEED)]
#: the results table's columns measured in time or memory (they differ between runs of the same rounds)
TIMING = ("plan_ms p50/p95", "round_cpu_s", "peak_rss_MB")


def _bench() -> Any:
    spec = importlib.util.spec_from_file_location("bench_clutter", SCRIPT)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # its dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


def _run(out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *ARGS, "--out", str(out), *extra], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)


def _log(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "pile_gt.jsonl").read_text().splitlines()]


def _pile_row(out: Path) -> dict[str, str]:
    """The summary's results row of pile by column name."""
    lines = (out / "summary.md").read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("| protocol |"))
    names = [c.strip() for c in lines[head].strip("|").split("|")]
    row = next(line for line in lines[head + 2:] if line.startswith("| pile |"))
    return dict(zip(names, [c.strip() for c in row.strip("|").split("|")]))


@pytest.fixture(scope="module")
def first(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, subprocess.CompletedProcess]:
    out = tmp_path_factory.mktemp("clutter") / "out"
    r = _run(out)
    assert r.returncode == 0, r.stderr[-3000:]
    return out, r


def test_first_run_logs_a_header_and_one_line_per_round(first: tuple[Path, Any]) -> None:
    out, r = first
    log = _log(out)
    assert len(log) == 3
    setting = log[0]["setting"]
    assert setting["protocol"] == "pile" and setting["seed"] == SEED and setting["decomposition"] == "hull"
    assert setting["parts"] == [[str((ROOT / "examples/parts/box.stl").resolve()), 2, None]]
    rounds = sorted(log[1:], key=lambda d: d["round"])
    assert [d["round"] for d in rounds] == [0, 1]
    assert [d["seed"] for d in rounds] == [SEED, SEED + 1]
    assert all(d["parts"] == 2 and d["worker_rss_mb"] > 0 for d in rounds)
    row = _pile_row(out)
    assert row["rounds"] == "2" and row["parts"] == "4"
    assert row["attempts"] == str(sum(d["attempts"] for d in rounds))
    assert "2 rounds to run" in r.stderr
    assert r.stdout.count("pile") >= 2  # the results row and the published table's row of ours


def test_rerun_runs_nothing_and_a_cut_line_runs_again(first: tuple[Path, Any], tmp_path: Path) -> None:
    out = tmp_path / "out"
    shutil.copytree(first[0], out)
    before = (out / "summary.md").read_text()
    lines = (out / "pile_gt.jsonl").read_text().splitlines()
    r = _run(out)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "0 rounds to run" in r.stderr
    assert (out / "pile_gt.jsonl").read_text().splitlines() == lines
    assert (out / "summary.md").read_text() == before

    cut = json.loads(lines[-1])
    (out / "pile_gt.jsonl").write_text("\n".join(lines[:-1]) + "\n" + lines[-1][:len(lines[-1]) // 2])
    r = _run(out)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "1 rounds to run" in r.stderr and "cut short" in r.stderr
    log = _log(out)  # every line parses
    assert len(log) == 3 and log[:2] == [json.loads(x) for x in lines[:2]]
    again = log[2]
    assert again["round"] == cut["round"] and again["seed"] == cut["seed"]
    # the same pile (made before any planning: the same seed gives the same bits in any worker)
    assert again["pile"] == cut["pile"]
    row, first_row = _pile_row(out), _pile_row(first[0])
    assert {k: v for k, v in row.items() if k not in TIMING} == {k: v for k, v in first_row.items() if k not in TIMING}


def test_another_setting_on_the_same_log_exits_2(first: tuple[Path, Any], tmp_path: Path) -> None:
    out = tmp_path / "out"
    shutil.copytree(first[0], out)
    lines = (out / "pile_gt.jsonl").read_text()
    r = _run(out, "--density", "2700")
    assert r.returncode == 2
    assert str(out / "pile_gt.jsonl") in r.stderr and "density" in r.stderr and "another --out" in r.stderr
    assert (out / "pile_gt.jsonl").read_text() == lines


def test_missing_paper_parts_exit_2_naming_the_folder(tmp_path: Path) -> None:
    env = {**os.environ, "GRASPLAN_PAPER_PARTS": str(tmp_path / "nowhere")}
    r = subprocess.run([sys.executable, str(SCRIPT), "--rounds", "1", "--out", str(tmp_path / "out")], cwd=ROOT,
                       capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 2 and str(tmp_path / "nowhere") in r.stderr


def test_formatting_helpers() -> None:
    b = _bench()
    assert b.pct_ci(0.973, [0.9312, 0.9921]) == "97.3 [93.1-99.2]"
    assert b.pct_ci(0.5, None) == "50.0" and b.pct_ci(None, None) == "-"
    assert b.counts({"blocked": 3, "no_grasp": 0, "< 5 mm": 2}) == "blocked 3, <5mm 2"
    assert b.counts({"a": 0}) == "-"
    md = b.md_table([("pile", 1.5, "a|b")], ("protocol", "x", "y")).splitlines()
    assert md == ["| protocol | x | y |", "|---|---|---|", "| pile | 1.500 | a\\|b |"]


def test_settings_targets_and_tags() -> None:
    from grasplan.clutter.protocols import PROTOCOLS

    b = _bench()
    assert b.PROTOCOL_NAMES == tuple(PROTOCOLS)
    s = b.make_settings(["bin", "pile"], [(0.0, 0.0), (0.002, 2.0)], robust=True, mu=0.3, material="plastic",
                        density=1200.0, max_occlusion=1.0)
    tags = [x.tag for x in s]
    assert len(tags) == len(set(tags)) == 8
    assert tags[:4] == ["bin_gt", "bin_n2mm2deg", "pile_gt", "pile_n2mm2deg"]
    robust = {x.tag: x for x in s[4:]}
    assert robust["pile_gt_mu0.2"].mu == 0.2 and robust["pile_gt_mu0.5"].mu == 0.5
    assert robust["pile_gt_density2700"].density == 2700.0
    occ = robust["pile_n2mm2deg_max_occlusion0.8"]
    assert occ.max_occlusion == 0.8 and occ.noise == (0.002, 2.0)
    by = {x.tag: x for x in s}
    assert b.target(by["pile_gt"]) == (0.95, 0.95) and b.target(by["pile_n2mm2deg"]) == (0.90, 0.90)
    assert b.target(by["bin_gt"]) == (None, 0.90) and b.target(occ) is None
    tot = {"gsr": 0.96, "dr": 0.94}
    assert b.target_cells(by["pile_gt"], tot) == ("GSR>=95 DR>=95", "missed")
    assert b.target_cells(by["bin_gt"], tot) == ("DR>=90", "met")
    assert b.target_cells(occ, tot) == ("-", "-")


def test_read_log_drops_only_a_cut_last_line(tmp_path: Path) -> None:
    b = _bench()
    setting = {"protocol": "pile", "seed": 0}
    p = tmp_path / "x.jsonl"
    assert b.read_log(p, setting) == {} and json.loads(p.read_text()) == {"setting": setting}
    with open(p, "a") as f:
        b.append_line(f, {"round": 1, "seed": 1})
        f.write('{"round": 0, "se')
    assert list(b.read_log(p, setting)) == [1]
    assert p.read_text().endswith('"seed": 1}\n')
    p.write_text(p.read_text() + "not json\n" + json.dumps({"round": 2}) + "\n")
    with pytest.raises(b.BenchError, match="line 3"):
        b.read_log(p, setting)
    y = tmp_path / "y.jsonl"
    b.read_log(y, setting)
    with pytest.raises(b.BenchError, match="another setting"):
        b.read_log(y, {**setting, "seed": 1})
