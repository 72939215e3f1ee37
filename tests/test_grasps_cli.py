"""`grasplan grasps` end to end on an example part, its JSON, and bad-input handling."""
from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from grasplan.cell.model import load_cell
from grasplan.cell.resting import stable_pose
from grasplan.cli import main
from grasplan.errors import InputError
from grasplan.grasps.pipeline import compute_grasps
from grasplan.part.mesh import load_part
from grasplan.config.poses import parse_part_pose
from grasplan.config.params import GraspParams


@pytest.fixture(scope="module")
def box_json(tmp_path_factory, example_part):
    out = tmp_path_factory.mktemp("g") / "box.json"
    r = CliRunner().invoke(main, ["grasps", str(example_part("box.stl")), "-o", str(out), "--roll-step", "30"])
    assert r.exit_code == 0, r.output + str(r.exception)
    return out, r.output


def test_cli_writes_issue_schema(box_json):
    out, stdout = box_json
    doc = json.loads(out.read_text())
    assert doc["schema"] == "grasplan.grasps/1"
    assert {"path", "sha256", "scale_to_m", "triangles", "T_world_part"} <= set(doc["part"])
    assert set(doc["gripper"]) >= {"name", "max_opening", "T_flange_tcp", "definition"}
    assert doc["gripper"]["name"] == "schunk_egp_c_40"
    # the document is self-contained: the gripper's resolved shapes and the whole cell are embedded
    assert doc["gripper"]["definition"]["body"] and "finger" in doc["gripper"]["definition"]
    assert doc["cell"]["part_pose"] == "stable_pose"
    assert doc["cell"]["name"] == "table"
    assert doc["params"]["roll_step_deg"] == 30 and doc["params"]["max_opening"] == pytest.approx(0.042)
    assert doc["gripper"]["stroke"] == pytest.approx(0.012)  # jaws at 30-42 mm
    assert all(0.030 - 1e-9 <= g["width"] <= 0.042 + 1e-9 for g in doc["grasps"])
    n = doc["counts"]
    assert n["poses"] == len(doc["grasps"]) == n["ok"] + n["collision_part"] + n["collision_table"]
    assert n["ok"] > 0
    g = doc["grasps"][0]
    base = {"id", "candidate", "region", "contacts", "normals", "width", "T_part_tcp", "roll", "status", "quality"}
    assert set(g) == (base | {"score"} if g["status"] == "ok" else base)  # quality: docs/quality.md
    assert min(e["region"] for e in doc["grasps"]) >= 0  # the default method samples regions: every grasp has one
    assert [e["id"] for e in doc["grasps"]] == list(range(len(doc["grasps"])))
    for e in doc["grasps"][:50]:
        T = np.array(e["T_part_tcp"])
        c = np.array(e["contacts"])
        np.testing.assert_allclose(T[:3, 3], c.mean(axis=0), atol=1e-9)
        np.testing.assert_allclose(T[:3, 0], (c[1] - c[0]) / e["width"], atol=1e-8)
        assert e["width"] <= doc["gripper"]["max_opening"]
    T_wp = np.array(doc["part"]["T_world_part"])
    assert T_wp.shape == (4, 4)
    for word in ("candidates", "poses", "collision_part", "collision_table"):
        assert word in stdout


def test_ok_grasps_clear_the_table(box_json):
    out, _ = box_json
    doc = json.loads(out.read_text())
    T_wp = np.array(doc["part"]["T_world_part"])
    for e in doc["grasps"]:
        if e["status"] == "ok":
            T_wt = T_wp @ np.array(e["T_part_tcp"])
            # fingertips (z up to +0.008 in the TCP frame, +-(o/2+8mm) in x, +-8 mm in y) stay above z = 0
            o = min(0.05, e["width"] + 0.01) / 2 + 0.008
            corners = np.array([[sx * o, sy * 0.008, 0.008] for sx in (-1, 1) for sy in (-1, 1)])
            assert (corners @ T_wt[:3, :3].T + T_wt[:3, 3])[:, 2].min() >= -1e-6


def test_api_matches_cli_and_part_pose(example_part):
    part = load_part(example_part("box.stl"))
    T = parse_part_pose("0.45,0,0.5m,0,0,0")  # floating high above the table: no table collisions
    res = compute_grasps(part, T_world_part=T, grasps=GraspParams(roll_step_deg=90))
    n = res.counts()
    assert n["collision_table"] == 0 and n["ok"] > 0
    np.testing.assert_allclose(res.T_world_part, T)
    assert res.to_json()["cell"]["part_pose"] == "given"
    # default resting pose: the lowest point on z = 0
    T0 = stable_pose(part.mesh, load_cell())
    z = part.mesh.vertices @ T0[:3, :3].T + T0[:3, 3]
    assert z[:, 2].min() == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose((T0[:3, :3] @ part.mesh.center_mass + T0[:3, 3])[:2], [0.45, 0.0], atol=1e-12)


def test_part_pose_parsing(tmp_path):
    T = parse_part_pose("450mm, 0, 1cm, 0, 0, 90")
    np.testing.assert_allclose(T[:3, 3], [0.45, 0, 0.01])
    np.testing.assert_allclose(T[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    f = tmp_path / "pose.json"
    f.write_text(json.dumps({"T_world_part": T.tolist()}))
    np.testing.assert_allclose(parse_part_pose(f), T)
    for bad in ("1,2,3", "a,b,c,d,e,f"):
        with pytest.raises(InputError):
            parse_part_pose(bad)
    f.write_text(json.dumps([[1, 0], [0, 1]]))
    with pytest.raises(InputError):
        parse_part_pose(f)


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--gripper", "nope"], "available: long_stroke_50, long_stroke_50_shallow, onrobot_rg2, onrobot_rg6, "
                                "robotiq_2f_140, robotiq_2f_85, round_mesh_jaws, schunk_egp_25, schunk_egp_64, "
                                "schunk_egp_c_40"),
        (["--cell", "nope"], "available: bin, table, wall"),
        (["--part-pose", "1,2"], "--part-pose"),
    ],
)
def test_bad_input_exit_3_nothing_written(tmp_path, example_part, args, needle):
    out = tmp_path / "o.json"
    r = CliRunner().invoke(main, ["grasps", str(example_part("box.stl")), "-o", str(out), *args])
    assert r.exit_code == 3, r.output
    assert needle in r.output
    assert not out.exists()


def test_missing_part_exit_3(tmp_path):
    out = tmp_path / "o.json"
    r = CliRunner().invoke(main, ["grasps", str(tmp_path / "none.stl"), "-o", str(out)])
    assert r.exit_code == 3 and not out.exists()


def test_thinning_and_merge_reduce_posed_candidates(example_part):
    part = load_part(example_part("gear.stl"))
    full = compute_grasps(part, grasps=GraspParams(roll_step_deg=120, merge_distance=0.0, thin_spacing=0.0))
    merged = compute_grasps(part, grasps=GraspParams(roll_step_deg=120, merge_distance=1e-3, thin_spacing=0.0))
    thin = compute_grasps(part, grasps=GraspParams(roll_step_deg=120, merge_distance=1e-3, thin_spacing=0.005))
    a, b, c = (r.counts()["posed_candidates"] for r in (full, merged, thin))
    assert a >= b >= c and c < a
    assert thin.to_json()["params"]["thin_spacing"] == 0.005
    # thinning and merging only drop poses: every remaining pose exists in the full set with the same status
    key = {(int(ci), round(float(r), 6)): s for ci, r, s in zip(full.frames.candidate, full.frames.roll, full.status)}
    for ci, r, s in zip(thin.frames.candidate, thin.frames.roll, thin.status):
        assert key[(int(ci), round(float(r), 6))] == s


def test_candidate_search_follows_the_gripper_opening(tmp_path):
    """The Python API searches as far as the gripper opens (not a fixed 50 mm), and records it."""
    import trimesh

    from grasplan.candidates.pipeline import compute_candidates
    from grasplan.gripper.load import GRIPPER_DIR
    from grasplan.part.mesh import part_from_trimesh
    from grasplan.config.params import DEFAULT_MAX_OPENING, CandidateParams

    text = (GRIPPER_DIR / "long_stroke_50.yaml").read_text()
    assert "max_opening: 0.05" in text
    wide = tmp_path / "wide.yaml"
    wide.write_text(text.replace("max_opening: 0.05", "max_opening: 0.08"))
    part = part_from_trimesh(trimesh.creation.box(extents=(0.07, 0.02, 0.01)))
    res = compute_grasps(part, gripper=str(wide), grasps=GraspParams(roll_step_deg=90))
    assert res.cand.params.max_opening == 0.08 and res.to_json()["params"]["max_opening"] == 0.08
    assert res.cand.candidates.width.max() == pytest.approx(0.07)  # across the 70 mm length
    default = compute_candidates(part, CandidateParams())
    assert default.params.max_opening == DEFAULT_MAX_OPENING and default.candidates.width.max() < 0.05
    explicit = compute_grasps(part, candidates=CandidateParams(max_opening=0.03), gripper=str(wide),
                              grasps=GraspParams(roll_step_deg=90))
    assert explicit.cand.params.max_opening == 0.03  # an explicit value wins


def test_old_keywords_are_gone_and_params_name_the_cli_option(example_part):
    """The per-option keywords moved into GraspParams; its validation names the CLI spelling."""
    part = load_part(example_part("box.stl"))
    with pytest.raises(TypeError):
        compute_grasps(part, roll_step_deg=90)
    with pytest.raises(InputError, match=r"--roll-step \(roll_step_deg\).*got 0"):
        GraspParams(roll_step_deg=0)
    with pytest.raises(InputError, match=r"--thin \(thin_spacing\).*got -0.001"):
        GraspParams(thin_spacing=-0.001)


def test_nothing_collision_free_is_exit_4_and_file_still_written(tmp_path, example_part):
    """A gripper opening 5 mm cannot take the 10 x 20 x 30 mm box: no pose, exit 4, the file is written."""
    from grasplan.gripper.load import GRIPPER_DIR

    small = tmp_path / "small.yaml"
    small.write_text((GRIPPER_DIR / "long_stroke_50.yaml").read_text().replace("max_opening: 0.05",
                                                                                 "max_opening: 0.005"))
    out = tmp_path / "o.json"
    r = CliRunner().invoke(main, ["grasps", str(example_part("box.stl")), "--gripper", str(small), "-o", str(out)])
    assert r.exit_code == 4, r.output
    assert "no collision-free grasp" in r.output
    doc = json.loads(out.read_text())
    assert doc["counts"]["ok"] == 0 and doc["grasps"] == []
    # the file reads back (it once read as "'T_part_tcp' malformed": an empty list is no (0, 4, 4) array)
    from grasplan.results.reader import load_result

    assert len(load_result(out).grasps) == 0
    r = CliRunner().invoke(main, ["simulate", str(out), "-o", str(tmp_path / "sim.json")])
    assert r.exit_code == 3 and "has no grasp at all" in r.output and "malformed" not in r.output, r.output
    assert not (tmp_path / "sim.json").exists()
    r = CliRunner().invoke(main, ["view", str(out), "-o", str(tmp_path / "v.html")])
    assert r.exit_code == 0, r.output
