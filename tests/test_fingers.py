"""``grasplan fingers``: the finger windows of a short-stroke gripper ranked by the part's distinct
holdable grasps over its resting poses; the count checked against the whole grasp stage computed
in each pose with the written gripper, and the refusals."""
from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from grasplan.cell.model import load_cell
from grasplan.cli import main
from grasplan.config.params import GraspParams, PlanParams
from grasplan.errors import InputError
from grasplan.grasps.fingers import FingerWindow, gripper_yaml, window_offsets
from grasplan.grasps.pipeline import compute_grasps
from grasplan.grasps.ranking import distinct_order
from grasplan.gripper.load import load_gripper
from grasplan.motion.planning import stable_pose_indices
from grasplan.part.mesh import load_part

BRACKET = Path(__file__).resolve().parents[1] / "examples" / "parts" / "bracket.stl"


@pytest.fixture
def own_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("GRASPLAN_CACHE_DIR", str(tmp_path / "cache"))


def test_window_offsets_hold_the_most_widths():
    w = np.array([0.010, 0.011, 0.0115, 0.012, 0.030, 0.031])
    got = window_offsets(w, stroke=0.002, step=0.001, evaluate=2)
    assert got[0] == pytest.approx(0.010)  # 10-12 mm holds four widths
    assert all(o >= 0 for o in got) and len(got) == 2
    assert window_offsets(np.zeros(0), 0.002, 0.001, 3) == []


def test_cli_ranks_windows_and_writes_a_gripper_whose_count_the_cell_computation_confirms(tmp_path, own_cache):
    out = tmp_path / "egp25_bracket.yaml"
    r = CliRunner().invoke(main, ["fingers", str(BRACKET), "--units", "mm", "--gripper", "schunk_egp_25",
                                  "--roll-step", "30", "--windows", "4", "-o", str(out)])
    assert r.exit_code == 0, r.output
    rows = [ln.split() for ln in r.output.splitlines() if re.match(r"^\d+\.\d-\d+\.\d ", ln)]
    assert len(rows) == 4
    weighted = [float(x[2]) for x in rows]
    assert weighted == sorted(weighted, reverse=True) and weighted[0] > 0
    g = load_gripper(out)
    lo, hi = (float(v) / 1e3 for v in rows[0][0].split("-"))
    assert g.max_opening == pytest.approx(hi) and g.min_opening == pytest.approx(lo) and g.stroke == 0.006
    assert g.name == "schunk_egp_25_bracket" and out.read_text().startswith("# fingers for ")
    # independently: the whole grasp stage in each resting pose with the written gripper
    part = load_part(BRACKET, units="mm")
    pp, total = PlanParams(), 0.0
    for k, prob in stable_pose_indices(part.mesh):
        gr = compute_grasps(part, gripper=g, cell=load_cell("table"), grasps=GraspParams(roll_step_deg=30.0, pose_index=k))
        ok = np.flatnonzero(gr.status.astype(str) == "ok")
        hold = ok[gr.quality.gravity_margin >= 1.0] if gr.quality is not None else ok[:0]
        hold = hold[np.lexsort((hold, -gr.score[hold]))]
        _, n = distinct_order(gr.frames.T_part_tcp, hold, min_distance=pp.distinct_distance,
                              min_angle_deg=pp.distinct_angle_deg)
        total += prob * n
    assert total == pytest.approx(weighted[0], abs=0.01)


def test_the_output_must_be_a_yaml_file(tmp_path, own_cache):
    r = CliRunner().invoke(main, ["fingers", str(BRACKET), "--units", "mm", "-o", str(tmp_path / "g.json")])
    assert r.exit_code == 2 and ".yaml" in r.output and not (tmp_path / "g.json").exists(), r.output


def test_a_long_stroke_gripper_is_refused_naming_short_ones(tmp_path, own_cache):
    r = CliRunner().invoke(main, ["fingers", str(BRACKET), "--units", "mm", "--gripper", "long_stroke_50"])
    assert r.exit_code == 3 and "no stroke" in r.output and "schunk_egp_c_40" in r.output, r.output
    assert "Traceback" not in r.output


def test_the_default_grippers_fingers_are_the_best_window_for_the_demo_bracket(tmp_path, own_cache):
    """The shipped schunk_egp_c_40's 30-42 mm jaws are the window ``grasplan fingers`` ranks first
    for examples/parts/bracket.stl (the YAML's claim), and its -o file keeps stroke and shapes."""
    from grasplan.gripper.load import load_gripper

    out = tmp_path / "egp.yaml"
    r = CliRunner().invoke(main, ["fingers", str(BRACKET), "--units", "mm", "-o", str(out)])
    assert r.exit_code == 0, r.output
    shipped, best = load_gripper(), load_gripper(str(out))
    assert shipped.name == "schunk_egp_c_40" and best.name == "schunk_egp_c_40_bracket"
    assert best.max_opening == pytest.approx(shipped.max_opening, abs=1e-9)
    assert best.stroke == shipped.stroke and best.grip_force == shipped.grip_force
    np.testing.assert_allclose(best.T_flange_tcp, shipped.T_flange_tcp)


def test_gripper_yaml_without_max_opening_is_refused(tmp_path):
    src = tmp_path / "g.yaml"
    src.write_text("name: g\nstroke: 0.006\n")
    with pytest.raises(InputError, match="max_opening"):
        gripper_yaml(src, FingerWindow(0.01, 0.016, (), 1.0, 3), name="h", note="n")


def test_a_part_narrower_than_the_jaws_close_is_told_to_choose_fingers(tmp_path):
    """A 20 x 25 x 60 mm block: the default EGP-C 40's jaws close to 30 mm, so nothing is posed;
    `grasps` and `plan` exit 4 naming the window and `grasplan fingers`; long_stroke_50 grasps it."""
    import trimesh

    pin = tmp_path / "block.stl"
    trimesh.creation.box(extents=(0.020, 0.025, 0.060)).export(pin)
    for cmd in (["grasps", str(pin), "--units", "m"], ["plan", str(pin), "--units", "m", "--robot", "ur5"]):
        out = tmp_path / f"{cmd[0]}.json"
        r = CliRunner().invoke(main, [*cmd, "-o", str(out)])
        assert r.exit_code == 4, r.output
        assert "narrower than schunk_egp_c_40's jaws close (30.0 mm" in r.output and "grasplan fingers" in r.output
        assert "Traceback" not in r.output
    r = CliRunner().invoke(main, ["grasps", str(pin), "--units", "m", "--gripper", "long_stroke_50",
                                  "-o", str(tmp_path / "long.json")])
    assert r.exit_code == 0, r.output
