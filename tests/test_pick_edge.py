"""``grasplan pick`` resolves at the edge: the scene file is read once, its cell (a name, or a path
relative to the scene's folder) is loaded with the robot and gripper before planning and passed to
the Picker as a model, and the output guard reads the files that setup came from. The Picker
itself still takes names and paths (its API), with the one default robot."""
from __future__ import annotations

import inspect
import json
import shutil
from pathlib import Path

import yaml
from click.testing import CliRunner

from grasplan.cli import main
from grasplan.config.params import DEFAULT_ROBOT
from grasplan.pick import Picker

ROOT = Path(__file__).resolve().parents[1]
BOX = ROOT / "examples" / "parts" / "box.stl"
TABLE = ROOT / "grasplan" / "data" / "configs" / "cells" / "table.yaml"


def _scene(tmp_path: Path) -> Path:
    """A scene in ``tmp_path/sub`` whose cell is ``../cells/mytable.yaml`` (a copy of the table)."""
    (tmp_path / "cells").mkdir()
    shutil.copy(TABLE, tmp_path / "cells" / "mytable.yaml")
    (tmp_path / "sub").mkdir()
    doc = {"schema": "grasplan.scene/1", "cell": "../cells/mytable.yaml", "parts": {"box": {"mesh": str(BOX)}},
           "instances": [{"id": "a", "part": "box", "T": {"xyz": [0.45, 0.0, 0.05], "rpy_deg": [0, 0, 0]}}]}
    (tmp_path / "sub" / "s.yaml").write_text(yaml.safe_dump(doc))
    return tmp_path / "sub" / "s.yaml"


def test_cli_reads_the_scene_once_and_passes_models(tmp_path, monkeypatch):
    import grasplan.pick.picker as picker_mod
    import grasplan.piles.scene_file as scene_file

    scene = _scene(tmp_path)
    parsed, given = [], []
    parse = scene_file.scene_from_dict
    monkeypatch.setattr(scene_file, "scene_from_dict", lambda *a, **k: parsed.append(1) or parse(*a, **k))
    init = picker_mod.Picker.__init__

    def spy(self, robot, **kw):
        given.append((robot, kw["gripper"], kw["cell"]))
        init(self, robot, **kw)

    monkeypatch.setattr(picker_mod.Picker, "__init__", spy)
    monkeypatch.chdir(tmp_path)  # the cell path is the scene folder's, not the current one's
    out = tmp_path / "p.json"
    r = CliRunner().invoke(main, ["pick", str(scene), "-o", str(out), "--max-picks", "1"])
    assert r.exit_code in (0, 4), r.output
    assert len(parsed) == 1
    (robot, gripper, cell), = given
    assert not isinstance(robot, str) and not isinstance(gripper, str) and not isinstance(cell, str)
    assert Path(cell.source).resolve() == (tmp_path / "cells" / "mytable.yaml").resolve()
    assert json.loads(out.read_text())["cell"] == json.loads(json.dumps(cell.to_json()))


def test_cli_refuses_an_output_over_the_scenes_cell(tmp_path):
    scene = _scene(tmp_path)
    cell = tmp_path / "cells" / "mytable.yaml"
    before = cell.read_bytes()
    r = CliRunner().invoke(main, ["pick", str(scene), "-o", str(cell)])
    assert r.exit_code == 3 and "is also an input" in r.output and "mytable.yaml" in r.output, r.output
    assert cell.read_bytes() == before


def test_picker_takes_names_and_resolves_a_scene_cell_next_to_the_scene(tmp_path, monkeypatch):
    assert inspect.signature(Picker).parameters["robot"].default == DEFAULT_ROBOT
    scene = _scene(tmp_path)
    monkeypatch.chdir(tmp_path)
    res = Picker(gripper="schunk_egp_c_40").plan(str(scene), max_picks=0)
    assert res.robot is not None and res.robot.name == DEFAULT_ROBOT
    assert res.cell is not None and Path(res.cell.source).resolve() == (tmp_path / "cells" / "mytable.yaml").resolve()
    assert [r.status for r in res.instances] == ["not_tried"]
