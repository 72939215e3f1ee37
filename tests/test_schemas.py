"""JSON Schemas: every JSON the CLI writes validates; broken documents do not."""
from __future__ import annotations

import copy
import json

import jsonschema
import pytest
from click.testing import CliRunner

from grasplan.errors import InputError
from grasplan.schemas.documents import SCHEMA_FILES, available_schemas, errors, load_schema, validate


def _run(args):
    from grasplan.cli import main

    return CliRunner().invoke(main, args, catch_exceptions=False)


@pytest.fixture(scope="module")
def synthetic_plan():
    pytest.importorskip("pinocchio")
    from test_export import mini_ur5, synthetic_plan

    robot = mini_ur5()
    return synthetic_plan(robot), robot


@pytest.fixture(scope="module")
def candidates_doc(tmp_path_factory, example_part):
    out = tmp_path_factory.mktemp("cand") / "c.json"
    r = _run(["candidates", str(example_part("bracket.stl")), "-o", str(out)])
    assert r.exit_code == 0, r.output
    return json.loads(out.read_text())


def test_schemas_are_valid_draft_2020_12():
    assert set(available_schemas()) == {"grasplan.candidates/1", "grasplan.grasps/1", "grasplan.plan/1",
                                        "grasplan.joint_trajectory/1", "grasplan.picks/1", "grasplan.scene/1"}
    for name in SCHEMA_FILES:
        schema = load_schema(name)
        assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
        assert schema["title"] == name
        jsonschema.Draft202012Validator.check_schema(schema)


def test_candidates_cli_output_validates(candidates_doc):
    assert candidates_doc["counts"]["candidates"] > 0
    assert validate(candidates_doc) == "grasplan.candidates/1"


@pytest.mark.parametrize("path, why", [
    (("candidates",), "'candidates' is a required property"),
    (("part", "sha256"), "'sha256' is a required property"),
    (("counts", "convex_faces"), "'convex_faces' is a required property"),
])
def test_candidates_missing_field_fails(candidates_doc, path, why):
    doc = copy.deepcopy(candidates_doc)
    d = doc
    for k in path[:-1]:
        d = d[k]
    del d[path[-1]]
    assert any(why in e for e in errors(doc))
    with pytest.raises(InputError, match="invalid grasplan.candidates/1"):
        validate(doc)


def test_candidates_wrong_shapes_fail(candidates_doc):
    doc = copy.deepcopy(candidates_doc)
    doc["candidates"]["contacts"][0] = doc["candidates"]["contacts"][0][:1]   # one contact instead of two
    assert errors(doc)
    doc = copy.deepcopy(candidates_doc)
    doc["candidates"]["width"][0] = -1.0
    assert errors(doc)


def test_plan_validates_and_negatives(synthetic_plan):
    plan, _ = synthetic_plan
    assert errors(plan) == []
    # a planned grasp without its path
    bad = copy.deepcopy(plan)
    del bad["grasps"][0]["path"]
    assert any("'path' is a required property" in e and "$.grasps[0]" in e for e in errors(bad))
    # unknown status
    bad = copy.deepcopy(plan)
    bad["grasps"][1]["status"] = "maybe"
    assert any("$.grasps[1].status" in e for e in errors(bad))
    # missing robot block; 3x4 matrix
    bad = copy.deepcopy(plan)
    del bad["robot"]
    assert any("'robot' is a required property" in e for e in errors(bad))
    bad = copy.deepcopy(plan)
    bad["part"]["T_world_part"] = bad["part"]["T_world_part"][:3]
    assert any("$.part.T_world_part" in e for e in errors(bad))
    # the self-contained blocks: the gripper's definition and the robot's source
    bad = copy.deepcopy(plan)
    del bad["gripper"]["definition"]
    assert any("'definition' is a required property" in e for e in errors(bad))
    # a not-planned grasp needs no joint data
    ok = copy.deepcopy(plan)
    assert ok["grasps"][2]["status"] == "not_tried" and "path" not in ok["grasps"][2]
    assert errors(ok) == []


def test_grasps_schema_hand_built(synthetic_plan):
    from test_export import grasps_doc

    plan, _ = synthetic_plan
    doc = grasps_doc(plan)
    assert doc["schema"] == "grasplan.grasps/1" and "robot" not in doc
    assert all(set(g) == {"id", "candidate", "region", "contacts", "normals", "width", "T_part_tcp", "roll", "status"}
               for g in doc["grasps"])
    assert errors(doc) == []
    doc["grasps"][0]["status"] = "planned"          # a plan status is not a grasps status
    assert any("$.grasps[0].status" in e for e in errors(doc))
    del doc["gripper"]["T_flange_tcp"]
    assert any("T_flange_tcp" in e for e in errors(doc))


def test_joint_trajectory_output_validates(synthetic_plan, tmp_path):
    from test_export import RecordingScene

    from grasplan.export import trajectory, write

    plan, robot = synthetic_plan
    scene = RecordingScene()
    with pytest.MonkeyPatch.context() as mp:   # the written file, without the part's mesh (not in this plan)
        mp.setattr(trajectory, "build_scene", lambda res: scene)
        out = write(plan, "joint-trajectory", tmp_path / "t.json")
    assert len(scene.calls) == 1
    doc = json.loads(out.read_text())
    assert validate(doc) == "grasplan.joint_trajectory/1"
    bad = copy.deepcopy(doc)
    del bad["points"][3]["time_from_start"]["nanosec"]
    assert any("nanosec" in e for e in errors(bad))
    bad = copy.deepcopy(doc)
    bad["points"][0]["time_from_start"]["nanosec"] = 10 ** 9
    assert errors(bad)


def test_not_a_grasplan_document():
    assert errors([1, 2]) and errors({"schema": "other/1"}) and errors({})
    with pytest.raises(InputError, match="unknown schema"):
        validate({"schema": "grasplan.nothing/1"})


@pytest.mark.slow
def test_grasps_and_plan_cli_outputs_validate(tmp_path, example_part):
    """`grasplan grasps` and `grasplan plan` on the example bracket: both files validate."""
    part = str(example_part("bracket.stl"))
    g_out, p_out = tmp_path / "g.json", tmp_path / "p.json"
    r = _run(["grasps", part, "-o", str(g_out)])
    assert r.exit_code == 0, r.output
    assert validate(json.loads(g_out.read_text())) == "grasplan.grasps/1"
    r = _run(["plan", part, "--robot", "ur5", "--top", "2", "-o", str(p_out)])
    assert r.exit_code in (0, 4), r.output
    assert validate(json.loads(p_out.read_text())) == "grasplan.plan/1"
    # and both read back through the full loader (schema, grasps, robot, FK of the planned grasps)
    from grasplan.results.reader import load_result

    assert load_result(g_out).schema == "grasplan.grasps/1" and load_result(p_out).robot.name == "ur5"
