"""A newcomer's first hour: a light `make demo`, a word while the kernels compile, a quiet `pip
install`, and help, docs and messages that say what the code does (formats, defaults, robots, hints,
the pick table and the pick viewer's colours)."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

ROOT = Path(__file__).resolve().parents[1]


def _toml(path: Path) -> dict:
    tomllib = pytest.importorskip("tomllib")
    return tomllib.loads(path.read_text())


def _dry_run(target: str) -> list[str]:
    """The commands ``make -n -B target`` would run (nothing is run)."""
    if shutil.which("make") is None:
        pytest.skip("make is not installed")
    r = subprocess.run(["make", "-n", "-B", target], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    return r.stdout.splitlines()


def _extras(lines: list[str]) -> set[str]:
    """Every extra named by a ``pip install ... -e '.[a,b]'`` line."""
    out: set[str] = set()
    for line in lines:
        if "pip install" in line:
            for group in re.findall(r"\.\[([\w,-]+)\]", line):
                out |= set(group.split(","))
    return out


# ----------------------------------------------------------------------------------- installing
def test_make_demo_installs_the_runtime_only_and_make_test_the_test_tools():
    project = _toml(ROOT / "pyproject.toml")["project"]
    test_extra = " ".join(project["optional-dependencies"]["test"])
    for tool in ("pytest", "hypothesis", "mypy", "ray"):  # the heavy test tools live in the test extra
        assert tool in test_extra
        assert not any(d.startswith(tool) for d in project["dependencies"]), tool
    demo, test = _dry_run("demo"), _dry_run("test")
    assert any("pip install" in line for line in demo)
    assert "test" not in _extras(demo), [line for line in demo if "pip install" in line]
    assert "test" in _extras(test)
    assert any("mypy" in line for line in test) and any("pytest" in line for line in test)


def test_make_install_compiles_the_numba_kernels_after_pip_and_never_fails_on_them():
    lines = _dry_run("install")
    pip = max(i for i, line in enumerate(lines) if "pip install" in line and " -e " in line)
    warm = [i for i, line in enumerate(lines) if "grasplan.cli.warmup" in line]
    assert warm and warm[0] > pip, lines
    assert "||" in lines[warm[0]], lines[warm[0]]  # a failed warm-up prints a line; the install goes on


def test_pyproject_license_is_an_spdx_string_without_deprecation_warnings():
    doc = _toml(ROOT / "pyproject.toml")
    assert doc["project"]["license"] == "BSD-3-Clause"
    assert not any(c.startswith("License ::") for c in doc["project"].get("classifiers", []))
    setuptools_req = [r for r in doc["build-system"]["requires"] if r.startswith("setuptools")]
    assert setuptools_req and int(re.search(r">=(\d+)", setuptools_req[0]).group(1)) >= 77
    # what `pip install` prints: setuptools reading pyproject.toml warns on deprecated fields
    import setuptools

    if int(setuptools.__version__.split(".")[0]) < 77:
        pytest.skip("setuptools < 77 reads no SPDX license string")
    from setuptools.config.pyprojecttoml import apply_configuration
    from setuptools.dist import Distribution

    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            dist = apply_configuration(Distribution(), ROOT / "pyproject.toml")
    finally:
        os.chdir(cwd)
    assert [str(w.message) for w in caught if "deprecat" in str(w.message).lower()] == []
    assert dist.metadata.license_expression == "BSD-3-Clause"


# ----------------------------------------------------------------------------------- compiling
def test_numba_kernels_say_once_that_they_compile_and_nothing_when_cached(tmp_path):
    from grasplan.compiled.jit import COMPILE_MESSAGE

    code = ("import numpy as np\n"
            "from grasplan.motion import pathboxes\n"  # a second kernel module: still one line
            "from grasplan.robot.ik import ur_batch\n"
            "ur_batch.unwrap_rows(np.zeros((3, 6)))\n"
            "ur_batch.fk_many(ur_batch.make_chain(0.1, -0.4, -0.4, 0.1, 0.1, 0.1, np.eye(4), np.eye(4)),"
            " np.zeros((2, 6)))\n")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba"), "GRASPLAN_AOT": "0"}  # numba's own cache
    runs = [subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                           timeout=600) for _ in range(2)]
    for r in runs:
        assert r.returncode == 0, r.stderr
    assert runs[0].stderr.count(COMPILE_MESSAGE) == 1, runs[0].stderr  # cold cache: one line
    assert COMPILE_MESSAGE not in runs[1].stderr                       # warm cache: silent


# ----------------------------------------------------------------------------------- help and docs
def test_grasplan_help_lists_every_export_format():
    from grasplan.cli import main
    from grasplan.cli.group import export_help
    from grasplan.results.export_registry import load_builtin_formats

    formats = list(load_builtin_formats())
    assert len(formats) >= 7
    line = export_help()
    assert all(f in line for f in formats) and str(len(formats)) in line
    out = CliRunner().invoke(main, ["--help"]).output
    text = re.sub(r"-\s+", "-", " ".join(out.split()))  # undo click's wrapping (it breaks after hyphens)
    assert re.sub(r"-\s+", "-", line) in text


def _option_row(page: str, option: str) -> str:
    rows = [r for r in (ROOT / "docs" / page).read_text().splitlines() if r.startswith(f"| `{option}")]
    assert len(rows) == 1, rows
    return rows[0]


def test_docs_export_format_row_names_every_format():
    from grasplan.results.export_registry import load_builtin_formats

    row = _option_row("export.md", "--format")
    assert set(re.findall(r"`([\w-]+)`", row)) >= set(load_builtin_formats())


def test_docs_plan_thin_default_and_robots_match_the_cli():
    from grasplan.cli.plan import command

    thin = next(p for p in command.params if p.name == "thin_spacing")
    assert thin.default == 0
    assert "`0` (off)" in _option_row("plan.md", "--thin")
    shipped = sorted(p.stem for p in (ROOT / "grasplan" / "data" / "robots").glob("*.yaml"))
    assert len(shipped) >= 5
    row = _option_row("plan.md", "--robot")
    assert set(re.findall(r"`(\w+)`", row)) >= set(shipped), row


# ----------------------------------------------------------------------------------- batch hint
def test_batch_reason_of_a_part_with_nothing_planned_suggests_other_poses():
    from grasplan.batch.manifest import PartJob
    from grasplan.batch.options import BatchOptions
    from grasplan.batch.report import summary_row
    from grasplan.config.params import GraspParams

    def row(options: BatchOptions, status: str = "nothing_planned") -> str:
        job = PartJob(path="p.stl", sha256="0" * 64, dir_name="p-00000000", options=options, options_hash="h")
        return summary_row(job, {"status": status, "exit_code": 4, "planned": 0, "grasps": 5, "best_score": None,
                                 "timing_s": {}, "error": "no grasp could be planned for ur5"})["error"]

    plain = row(BatchOptions())
    assert plain.startswith("no grasp could be planned for ur5")
    assert "--pose-index 1" in plain and "--pose-index all" in plain
    assert "--pose-index 0" in row(BatchOptions(grasps=GraspParams(pose_index=2)))
    # every pose planned already, or the part's pose given: no pose to suggest
    assert "--pose-index" not in row(BatchOptions(grasps=GraspParams(pose_index="all")))
    assert "--pose-index" not in row(BatchOptions(T_world_part=tuple(map(tuple, np.eye(4).tolist()))))
    assert "--pose-index" not in row(BatchOptions(), status="planned")


# ----------------------------------------------------------------------------------- pick table, viewer
def test_pick_table_explains_blocked_by():
    from grasplan.cli.pick import instance_table
    from grasplan.pick.result import InstanceReport

    reps = [InstanceReport("a", "p", "picked", "planned", ("b",)), InstanceReport("b", "p", "blocked", "hit", ("a",)),
            InstanceReport("c", "p", "picked", "planned")]
    text = instance_table(reps)
    assert text.splitlines()[0].split() == ["instance", "part", "status", "blocked_by"]
    footer = text.splitlines()[-1]
    assert footer.startswith("blocked_by:") and "picked" in footer and "better-ranked" in footer
    assert "blocked_by:" not in instance_table(reps[2:])  # nothing to explain


def test_viewer_draws_neighbours_neutral_and_blockers_red_with_a_legend():
    from grasplan.cell.model import Cell, Obstacle
    from grasplan.viewer.page import OBSTACLE_ROLES, cell_data, read_asset

    box = dict(kind="box", T_world_obstacle=np.eye(4), size=(0.1, 0.1, 0.1))
    cell = Cell(name="pile", obstacles=(Obstacle("instance_a", **box), Obstacle("instance_b", **box),
                                        Obstacle("instance_c", **box), Obstacle("post", **box)))
    data = cell_data(cell, [], blockers={"b"})
    roles = {o["name"]: o["role"] for o in data["obstacles"]}
    assert roles == {"instance_a": "neighbour", "instance_b": "blocker", "instance_c": "neighbour", "post": "obstacle"}
    legend = {r["role"]: r for r in data["roles"]}
    assert legend["blocker"]["n"] == 1 and legend["neighbour"]["n"] == 2 and "bin" not in legend
    red = OBSTACLE_ROLES["blocker"][0]
    assert all(OBSTACLE_ROLES[r][0] != red for r in OBSTACLE_ROLES if r != "blocker")  # red means blocked
    assert {r["role"] for r in cell_data(cell, [])["roles"]} == {"neighbour", "obstacle"}  # no pick: no red
    # the page colours bodies from these roles and shows their legend
    js, page = read_asset("viewer.js"), read_asset("template.html")
    assert "0xc62828" not in js and "roleOf.get(ob.role)" in js
    assert 'id="bodies"' in page


def test_docs_plan_status_table_lists_every_plan_status():
    from grasplan.status import Status

    rows = [r for r in (ROOT / "docs" / "plan.md").read_text().splitlines() if r.startswith("| `")]
    named = {s for r in rows for s in re.findall(r"`(\w+)`", r.split("|")[1])}
    assert {s.value for s in Status} - {Status.OK.value} <= named  # ok: the grasp stage's, split by the plan
