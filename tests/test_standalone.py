"""Plans stand alone (issue 9): custom gripper, cell and robot YAMLs from a folder that is deleted
before export and view; config lookup order; typed results round-trip through their files."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import grasplan
from grasplan.cli import main
from grasplan.config.lookup import PACKAGED_DIR, search_path
from grasplan.errors import ConfigError, InputError

ROOT = Path(__file__).resolve().parents[1]
BRACKET = ROOT / "examples" / "parts" / "bracket.stl"


def _run(args, **kw):
    r = CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False, **kw)
    return r


def _custom_configs(folder: Path) -> dict[str, Path]:
    """A gripper with a 45 mm opening and a mesh body, a raised table cell and a UR5 moved in x."""
    (folder / "grippers").mkdir(parents=True)
    (folder / "cells").mkdir()
    (folder / "robots").mkdir()
    g = yaml.safe_load((PACKAGED_DIR / "configs" / "grippers" / "schunk_egp_c_40.yaml").read_text())
    g["name"] = "custom_jaws"
    g["max_opening"] = 0.045
    g["grip_force"] = 90
    shutil.copy(PACKAGED_DIR / "configs" / "grippers" / "round_body.stl", folder / "grippers" / "body.stl")
    g["body"].append({"mesh": {"path": "body.stl", "scale": 0.0005, "T": {"xyz": [0, 0, -0.14], "rpy_deg": [0, 0, 0]}}})
    (folder / "grippers" / "custom_jaws.yaml").write_text(yaml.safe_dump(g))
    (folder / "cells" / "raised.yaml").write_text("name: raised\ntable_z: 0.02\npart_xy: [0.42, 0.05]\npose_index: 0\n")
    r = (PACKAGED_DIR / "robots" / "ur5.yaml").read_text().replace("name: ur5", "name: ur5_shifted")
    r = r.replace("T_world_base: identity",
                  "T_world_base: [[1, 0, 0, -0.03], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]")
    (folder / "robots" / "ur5_shifted.yaml").write_text(r)
    return {"gripper": folder / "grippers" / "custom_jaws.yaml", "cell": folder / "cells" / "raised.yaml",
            "robot": folder / "robots" / "ur5_shifted.yaml"}


@pytest.fixture(scope="module")
def standalone_plan(tmp_path_factory):
    """A plan made with YAMLs given by path from a folder that no longer exists."""
    tmp = tmp_path_factory.mktemp("standalone")
    cfg = _custom_configs(tmp / "cfg")
    part = tmp / "bracket.stl"
    shutil.copy(BRACKET, part)
    out = tmp / "plan.json"
    r = _run(["plan", part, "--units", "mm", "--robot", cfg["robot"], "--gripper", cfg["gripper"],
              "--cell", cfg["cell"], "--top", "2", "-o", out])
    assert r.exit_code == 0, r.output
    shutil.rmtree(tmp / "cfg")
    return tmp, out


def test_plan_embeds_its_models(standalone_plan):
    _, out = standalone_plan
    doc = json.loads(out.read_text())
    assert doc["gripper"]["name"] == "custom_jaws" and "definition" in doc["gripper"]
    assert doc["robot"]["source"]["package"] == "example-robot-data"
    assert "ur5_shifted" in doc["robot"]["source"]["yaml"]
    assert doc["cell"]["table"]["z"] == pytest.approx(0.02)
    res = grasplan.load_result(out)
    assert res.gripper.max_opening == pytest.approx(0.045)
    assert res.gripper.grip_force == pytest.approx(90.0)
    assert len(res.gripper.body) == 2  # the box and the embedded mesh
    assert res.robot.name == "ur5_shifted"
    np.testing.assert_allclose(res.robot.T_world_base[:3, 3], [-0.03, 0, 0])
    assert res.cell.table_z == pytest.approx(0.02)


def test_export_every_format_and_view_without_yamls(standalone_plan):
    tmp, out = standalone_plan
    formats = grasplan.export.load_builtin_formats()
    assert {"urscript", "joint-trajectory", "csv", "krl", "rapid", "moveit-grasp"} <= set(formats)
    for name, fmt in formats.items():
        target = tmp / f"out_{name}{fmt.extension}"
        r = _run(["export", out, "--format", name, "-o", target])
        assert r.exit_code == 0, (name, r.output)
        assert target.stat().st_size > 0
    r = _run(["view", out, "-o", tmp / "view.html"])
    assert r.exit_code == 0, r.output
    assert "custom_jaws" in (tmp / "view.html").read_text()


def test_result_round_trip_is_exact(tmp_path):
    res = grasplan.plan(grasplan.load_part(BRACKET, units="mm"), "ur5", planning=grasplan.PlanParams(top=2))
    path = res.write(tmp_path / "plan.json")
    back = grasplan.load_result(path)
    assert back.to_json() == json.loads(path.read_text())
    assert back.planned_ids() == res.planned_ids()
    # the in-memory result and the file export the same program
    a = grasplan.export.render(res, "urscript")
    b = grasplan.export.render(back, "urscript")
    assert a == b


def test_in_memory_part_plan_is_valid_and_exports(tmp_path):
    import trimesh

    from grasplan.part.mesh import part_from_trimesh

    box = trimesh.creation.box(extents=(0.04, 0.03, 0.02))
    part = part_from_trimesh(box)
    assert len(part.sha256) == 64  # a sha256 of the vertex and face arrays
    res = grasplan.plan(part, "ur5", planning=grasplan.PlanParams(top=1))
    path = res.write(tmp_path / "plan.json")
    grasplan.schemas.validate(json.loads(path.read_text()))
    res.export("csv", tmp_path / "g.csv")
    assert len((tmp_path / "g.csv").read_text().splitlines()) == len(res.grasps) + 1


def test_lookup_order(tmp_path, monkeypatch):
    explicit, env, cwd = tmp_path / "explicit", tmp_path / "env", tmp_path / "cwd"
    for root, z in ((explicit / "cells", 0.3), (env / "cells", 0.2), (cwd / "configs" / "cells", 0.1)):
        root.mkdir(parents=True)
        (root / "table.yaml").write_text(f"name: table\ntable_z: {z}\n")
    monkeypatch.chdir(cwd)
    from grasplan.cell.model import load_cell

    assert load_cell("table").table_z == pytest.approx(0.1)           # ./configs beats the package
    monkeypatch.setenv("GRASPLAN_CONFIG_PATH", str(env))
    assert load_cell("table").table_z == pytest.approx(0.2)           # $GRASPLAN_CONFIG_PATH beats ./configs
    with grasplan.use_config_dirs(explicit):
        assert load_cell("table").table_z == pytest.approx(0.3)       # --config-dir beats everything
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("GRASPLAN_CONFIG_PATH")
    assert load_cell("table").table_z == pytest.approx(0.0)           # the packaged table
    assert search_path("cell")[-1] == PACKAGED_DIR / "configs" / "cells"


def test_unknown_name_lists_where_it_looked(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    from grasplan.gripper.load import load_gripper

    with pytest.raises(ConfigError) as e:
        load_gripper("no_such_gripper")
    msg = str(e.value)
    assert "schunk_egp_c_40" in msg and "Looked in" in msg and str(PACKAGED_DIR) in msg


def test_config_dir_option(tmp_path):
    cfg = _custom_configs(tmp_path / "cfg")
    out = tmp_path / "g.json"
    r = _run(["grasps", BRACKET, "--units", "mm", "--config-dir", tmp_path / "cfg", "--gripper", "custom_jaws",
              "--cell", "raised", "-o", out])
    assert r.exit_code in (0, 4), r.output
    doc = json.loads(out.read_text())
    assert doc["gripper"]["name"] == "custom_jaws" and doc["cell"]["name"] == "raised"
    assert cfg["gripper"].is_file()
    r = _run(["grasps", BRACKET, "--config-dir", tmp_path / "missing", "-o", tmp_path / "x.json"])
    assert r.exit_code == 3 and "no such folder" in r.output


def test_params_validate_themselves():
    with pytest.raises(InputError, match="--roll-step"):
        grasplan.GraspParams(roll_step_deg=1e-9)
    with pytest.raises(InputError, match="--alpha"):
        grasplan.CandidateParams(alpha=float("nan"))
    with pytest.raises(InputError, match="--budget"):
        grasplan.PlanParams(budget_s=float("inf"))
    with pytest.raises(InputError, match="score_weights"):
        grasplan.PlanParams(score_weights=(("nope", 1.0),))
    p = grasplan.PlanParams(top=3, backoff=0.08, max_ik_solutions=2, path_attempts=1)
    assert grasplan.PlanParams.from_json(p.to_json()) == p


def test_plan_passes_every_plan_param(tmp_path):
    """backoff, max_dev, max_ik_solutions and path_attempts reach the planner (issue 9)."""
    part = grasplan.load_part(BRACKET, units="mm")
    res = grasplan.plan(part, "ur5", planning=grasplan.PlanParams(top=1, backoff=0.08))
    gid = res.planned_ids()[0]
    m = res.motions[gid]
    T_pre = res.robot.fk(m.q_pregrasp) @ res.gripper.T_flange_tcp
    T_grasp = res.T_world_part @ res.grasps.T_part_tcp[res.grasps.index_of(gid)]
    assert np.linalg.norm(T_pre[:3, 3] - T_grasp[:3, 3]) == pytest.approx(0.08, abs=2e-3)
    assert res.params.planning.backoff == 0.08
