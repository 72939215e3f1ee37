"""Every script in examples/ runs (in a subprocess, outputs to a temporary folder)."""
from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
KNOWN = {"make_parts.py", "api_example.py"}


def _run(args, **kw):
    return subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True, cwd=ROOT,
                          timeout=600, **kw)


def test_every_example_is_tested():
    scripts = {p.name for p in EXAMPLES.glob("*.py")}
    assert scripts == KNOWN, f"examples without a test: {sorted(scripts - KNOWN)}"


def test_make_parts(tmp_path):
    r = _run([EXAMPLES / "make_parts.py", "-o", tmp_path])
    assert r.returncode == 0, r.stderr
    for name in ("bracket.stl", "gear.stl", "box.stl"):
        made = tmp_path / name
        assert made.stat().st_size > 84
        # deterministic: byte-identical to the shipped part
        assert made.read_bytes() == (EXAMPLES / "parts" / name).read_bytes()


@pytest.mark.slow
def test_api_example(tmp_path):
    r = _run([EXAMPLES / "api_example.py", "-o", tmp_path, "--top", "3"])
    if r.returncode == 4:
        pytest.fail(f"no planned grasp on the example part:\n{r.stdout}\n{r.stderr}")
    assert r.returncode == 0, r.stderr
    from grasplan.schemas.documents import validate

    doc = json.loads((tmp_path / "plan.json").read_text())
    validate(doc)
    traj = json.loads((tmp_path / "trajectory.json").read_text())
    validate(traj)
    script = (tmp_path / "pick.script").read_text()
    assert "movel(p[" in script and "def grasplan_close_gripper" in script
    rows = list(csv.DictReader((tmp_path / "grasps.csv").open()))
    from plan_docs import kept_grasps

    assert [int(r["id"]) for r in rows] == [g["id"] for g in kept_grasps(doc)]  # the grasps the plan keeps
    assert len(list(tmp_path.glob("pick_grasp*.script"))) == 1
    # every other registered format was written, with all its files (KRL: .src and .dat)
    from grasplan.export import load_builtin_formats, output_paths

    for name, fmt in load_builtin_formats().items():
        if name in ("urscript", "joint-trajectory", "csv"):
            continue
        for f in output_paths(name, tmp_path / f"pick_{name.replace('-', '_')}{fmt.extension}"):
            assert f.exists() and f.stat().st_size > 0, f"{name}: {f.name} not written"
