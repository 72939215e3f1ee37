"""The wheel works anywhere (issue 9): build it, install it into a fresh venv outside the repository,
and in an empty folder plan a part for the UR5, export every format and write the viewer.

The fresh venv gets the wheel itself (``pip install --no-deps``: its files, entry point and package
data, nothing from the repository) and reaches the already installed dependencies through a
``.pth`` line naming the test venv's site-packages (a plain path line: the editable install's
finder there is *not* activated, which the test checks by asserting where ``grasplan`` is imported
from). ``make install`` checks that the dependencies install from PyPI by name.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BRACKET = ROOT / "examples" / "parts" / "bracket.stl"

pytestmark = pytest.mark.slow


def _run(cmd, cwd, env=None, timeout=600):
    r = subprocess.run([str(c) for c in cmd], cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env)
    return r


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    pytest.importorskip("build", reason="the 'build' package (in .[test]) builds the wheel")
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    # build from a copy of the tracked sources: no stale build/ folder, no editable leftovers
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(".venv", ".git", "build", "dist", "out", "*.egg-info",
                                                                "__pycache__", ".pytest_cache", ".hypothesis"),
                    symlinks=True)
    r = _run([sys.executable, "-m", "build", "--wheel", "--no-isolation", "--outdir", tmp / "dist", src], cwd=tmp)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    wheel = next((tmp / "dist").glob("grasplan-*.whl"))
    env_dir = tmp / "venv"
    venv.create(env_dir, with_pip=True)
    py = env_dir / "bin" / "python"
    r = _run([py, "-m", "pip", "install", "--quiet", "--no-deps", "--no-index", wheel], cwd=tmp)
    assert r.returncode == 0, r.stderr[-3000:]
    site = Path(_run([py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=tmp).stdout.strip())
    deps = Path(sysconfig.get_paths()["purelib"])
    lines = [str(deps)]
    if (deps / "cmeel_pth").exists() or (deps / "cmeel_pth.py").exists():
        lines.append("import cmeel_pth")  # Pinocchio/coal wheels put their modules under cmeel.prefix
    (site / "zz_test_dependencies.pth").write_text("\n".join(lines) + "\n")
    work = tmp / "empty"
    work.mkdir()
    shutil.copy(BRACKET, work / "bracket.stl")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "GRASPLAN_CONFIG_PATH")}
    return {"py": py, "bin": env_dir / "bin", "work": work, "env": env}


def test_imports_from_the_wheel_not_the_repository(installed):
    r = _run([installed["py"], "-c", "import grasplan; print(grasplan.__file__)"], cwd=installed["work"],
             env=installed["env"])
    assert r.returncode == 0, r.stderr
    where = Path(r.stdout.strip())
    assert ROOT not in where.parents, f"grasplan imported from the repository: {where}"
    assert installed["bin"].parent in where.parents


def test_plan_export_view_in_an_empty_folder(installed):
    gp, work, env = installed["bin"] / "grasplan", installed["work"], installed["env"]
    r = _run([gp, "plan", "bracket.stl", "--robot", "ur5", "--units", "mm", "--top", "2", "-o", "plan.json"],
             cwd=work, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    doc = json.loads((work / "plan.json").read_text())
    assert doc["counts"]["planned"] >= 1
    r = _run([gp, "export", "--help"], cwd=work, env=env)
    formats = ["urscript", "joint-trajectory", "csv", "krl", "rapid", "moveit-grasp"]
    for f in formats:
        assert f in r.stdout, f"export --help does not list {f}"
    for f in formats:
        r = _run([gp, "export", "plan.json", "--format", f, "-o", f"out_{f}"], cwd=work, env=env)
        assert r.returncode == 0, (f, r.stderr[-2000:])
        assert (work / f"out_{f}").stat().st_size > 0
    r = _run([gp, "view", "plan.json", "-o", "view.html"], cwd=work, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    assert (work / "view.html").stat().st_size > 100_000
    r = _run([gp, "grasps", "bracket.stl", "--gripper", "nope", "-o", "g.json"], cwd=work, env=env)
    assert r.returncode == 3 and "schunk_egp_c_40" in r.stderr  # packaged grippers are found and listed
