"""Resolve once, at the edge: the one name-or-path rule (:func:`grasplan.config.lookup.is_path_like`),
the frozen :class:`grasplan.setup.resolved.Setup` built by :func:`build_setup` (models, the
references they came from, every file they were read from), the output guard reading a setup's
files, and the service and a batch handing the files they resolved to their worker processes."""
from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import pytest

from grasplan.config.lookup import document_ref, is_path_like, use_config_dirs
from grasplan.errors import ConfigError, InputError
from grasplan.setup.resolved import Setup, build_setup, load_description

DATA = Path(__file__).resolve().parents[1] / "grasplan" / "data"
EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "parts"


@pytest.mark.parametrize(("ref", "path_like"), [
    ("bin", False), ("schunk_egp_c_40", False), ("ur5", False), ("my.cell", False),
    ("bin.yaml", True), ("bin.yml", True), ("BIN.YAML", True), ("Bin.Yml", True),
    ("cells/bin", True), ("/abs/bin", True), ("./bin", True), ("~/bin.yaml", True),
])
def test_one_rule_tells_a_name_from_a_path(ref, path_like, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no file of these names here
    assert is_path_like(ref) is path_like


def test_an_existing_file_is_a_path_where_the_document_lies(tmp_path, monkeypatch):
    (tmp_path / "doc").mkdir()
    (tmp_path / "doc" / "mycell").write_text("name: c\n")
    monkeypatch.chdir(tmp_path)
    assert not is_path_like("mycell")  # not in the current folder
    assert is_path_like("mycell", tmp_path / "doc")  # but next to the document naming it
    assert document_ref("mycell", tmp_path / "doc") == str(tmp_path / "doc" / "mycell")
    assert document_ref("bin", tmp_path / "doc") == "bin"
    assert document_ref("cells/x.yaml", tmp_path / "doc") == str(tmp_path / "doc" / "cells" / "x.yaml")
    assert document_ref("/abs/x.yaml", tmp_path / "doc") == "/abs/x.yaml"
    assert document_ref("cells/x.yaml", None) == "cells/x.yaml"
    (tmp_path / "doc" / "mycell").unlink()
    (tmp_path / "mycell").write_text("name: c\n")
    assert is_path_like("mycell") and not is_path_like("mycell", tmp_path / "doc")


def test_a_name_with_a_yaml_suffix_in_capitals_is_a_missing_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError, match=r"cell file BIN\.YAML not found; give an existing YAML file or a name"):
        build_setup(cell="BIN.YAML")


def test_build_setup_by_name_path_and_model_gives_the_same_setup(tmp_path):
    by_name = build_setup(robot="ur5", gripper="schunk_egp_c_40", cell="bin")
    assert isinstance(by_name, Setup) and dataclasses.is_dataclass(by_name)
    with pytest.raises(dataclasses.FrozenInstanceError):
        by_name.robot = None  # type: ignore[misc]
    assert (by_name.robot.name, by_name.gripper.name, by_name.cell.name) == ("ur5", "schunk_egp_c_40", "bin")
    assert [s.kind for s in by_name.sources] == ["gripper", "cell", "robot"]  # the order errors are reported in
    assert by_name.ref("robot") == "ur5" and by_name.source("robot").path == (DATA / "robots" / "ur5.yaml").resolve()
    files = set(by_name.files)
    assert len(files) == len(by_name.files)  # each once
    robot = by_name.robot
    assert {Path(robot.config_path), Path(robot.urdf_path), Path(robot.srdf_path)} <= files
    assert (DATA / "configs" / "cells" / "bin.yaml").resolve() in files
    refs = by_name.resolved_refs()
    assert all(Path(v).is_absolute() and Path(v).is_file() for v in refs.values())
    by_path = build_setup(**refs)
    assert by_path.robot is robot and by_path.gripper == by_name.gripper and by_path.cell == by_name.cell
    assert set(by_path.files) == files and by_path.resolved_refs() == refs
    given = build_setup(robot=robot, gripper=by_name.gripper, cell=by_name.cell)
    assert given.robot is robot and given.ref("gripper") == "schunk_egp_c_40"
    assert set(given.files) == files  # a model's files are those it was read from
    only = build_setup(cell="none")
    assert only.robot is None and only.gripper is None and only.cell.name == "none" and only.files == ()
    assert only.resolved_refs() == {"cell": "none"}


def test_a_gripper_yaml_names_its_meshes_and_a_config_dir_is_looked_in_first(tmp_path):
    cfg = tmp_path / "cfg" / "grippers"
    cfg.mkdir(parents=True)
    for f in ("round_mesh_jaws.yaml", "round_body.stl", "tapered_jaw.stl"):
        shutil.copy(DATA / "configs" / "grippers" / f, cfg / f)
    (cfg / "round_mesh_jaws.yaml").rename(cfg / "mine.yaml")
    with pytest.raises(ConfigError, match="unknown gripper 'mine'"):
        build_setup(gripper="mine")
    setup = build_setup(gripper="mine", config_dirs=(tmp_path / "cfg",))
    assert setup.source("gripper").path == (cfg / "mine.yaml").resolve()
    assert {cfg / "round_body.stl", cfg / "tapered_jaw.stl"} <= set(setup.files)
    with use_config_dirs(tmp_path / "cfg"):  # the lookup in force is used without config_dirs
        assert build_setup(gripper="mine").source("gripper").path == (cfg / "mine.yaml").resolve()


def test_each_description_is_loaded_once_with_a_cache(monkeypatch):
    import grasplan.setup.resolved as resolved

    calls: list[tuple[str, str]] = []
    real = resolved._loader

    def counting(kind):
        load = real(kind)
        return lambda ref: calls.append((kind, str(ref))) or load(ref)

    monkeypatch.setattr(resolved, "_loader", counting)
    cache: dict = {}
    a = build_setup(robot="ur5", gripper="schunk_egp_c_40", cell="bin", cache=cache)
    b = build_setup(robot="ur5", gripper="schunk_egp_c_40", cell="table", cache=cache)
    assert a.robot is b.robot and a.cell.name == "bin" and b.cell.name == "table"
    assert sorted(k for k, _ in calls) == ["cell", "cell", "gripper", "robot"]
    assert load_description("robot", "ur5", cache)[0] is a.robot and len(calls) == 4


@pytest.mark.parametrize(("kw", "match"), [
    ({"gripper": "nosuch", "cell": "nosuchcell", "robot": "nosuchrobot"}, "unknown gripper 'nosuch'; available: "),
    ({"cell": "nosuchcell", "robot": "nosuchrobot"}, "unknown cell 'nosuchcell'; available: "),
    ({"robot": "nosuchrobot"}, "unknown robot 'nosuchrobot'; available: .*ur5"),
    ({"cell": "missing/c.yaml"}, r"cell file missing/c\.yaml not found"),
])
def test_bad_references_are_refused_as_the_loaders_refuse_them(kw, match):
    with pytest.raises(ConfigError, match=match):
        build_setup(**kw)


def test_the_output_guard_reads_the_setups_files(tmp_path):
    from grasplan.cli.common import check_output

    cell = tmp_path / "c.yaml"
    cell.write_text("name: c\nobstacles:\n  - {name: a, mesh: {path: ob.stl, scale: 0.001}, T: {xyz: [0.3, 0.4, 0.6]}}\n")
    shutil.copy(DATA / "configs" / "grippers" / "tapered_jaw.stl", tmp_path / "ob.stl")
    setup = build_setup(cell=str(cell))
    assert (tmp_path / "ob.stl") in setup.files and cell.resolve() in setup.files
    for target in (cell, tmp_path / "ob.stl"):
        before = target.read_bytes()
        with pytest.raises(InputError, match="is also an input"):
            check_output(str(target), setup=setup)
        assert target.read_bytes() == before
    assert check_output(str(tmp_path / "out.json"), setup=setup) == tmp_path / "out.json"


def test_a_scene_names_its_cell_by_the_same_rule(tmp_path):
    from grasplan.piles.scene_file import load_scene
    from grasplan.piles.scene_write import write_scene
    from grasplan.setup.outputs import scene_files

    (tmp_path / "in").mkdir()
    shutil.copy(DATA / "configs" / "cells" / "bin.yaml", tmp_path / "in" / "MyBin.YAML")
    doc = {"schema": "grasplan.scene/1", "cell": "MyBin.YAML",
           "instances": [{"id": "a", "part": "p", "T": [[1, 0, 0, 0.4], [0, 1, 0, 0], [0, 0, 1, 0.1], [0, 0, 0, 1]]}]}
    (tmp_path / "in" / "s.json").write_text(__import__("json").dumps(doc))
    scene = load_scene(tmp_path / "in" / "s.json")
    assert tmp_path / "in" / "MyBin.YAML" in scene_files(scene)  # a path (any-case suffix): an input
    out = write_scene(tmp_path / "out" / "s.yaml", scene)
    assert out.cell == "../in/MyBin.YAML"  # rebased next to the new file
    named = write_scene(tmp_path / "out" / "n.yaml", load_scene({**doc, "cell": "bin"}))
    assert named.cell == "bin" and scene_files(named) == []


def test_the_service_hands_its_planners_the_files_it_resolved(tmp_path):
    from grasplan.serve.config import ServeConfig
    from grasplan.serve.state import Service

    shutil.copy(EXAMPLES / "box.stl", tmp_path / "box.stl")
    service = Service.start(ServeConfig(parts_dir=tmp_path, databases=False))
    assert service.robot is service.setup.robot and service.cell.name == "bin"
    cfg = service.resolved_config(service.config)
    assert cfg.robot == str((DATA / "robots" / "ur5.yaml").resolve()) and Path(cfg.gripper).is_file()
    assert Path(cfg.cell).name == "bin.yaml" and cfg.parts_dir == service.config.parts_dir
    assert service.with_config(cfg).setup is service.setup


def test_a_batch_resolves_once_and_sends_its_workers_the_files(tmp_path):
    from grasplan.batch.manifest import discover_parts, make_jobs
    from grasplan.batch.options import BatchOptions, options_hash
    from grasplan.batch.outdir import config_inputs
    from grasplan.batch.worker import job_payload

    (tmp_path / "m.csv").write_text(f"path,cell\n{EXAMPLES / 'box.stl'},bin\n{EXAMPLES / 'gear.stl'},table\n"
                                    f"{EXAMPLES / 'bracket.stl'},bin\n")
    jobs = make_jobs(discover_parts([tmp_path / "m.csv"]), BatchOptions())
    assert jobs[0].setup is jobs[2].setup and jobs[1].setup is not jobs[0].setup
    assert jobs[0].setup.robot is jobs[1].setup.robot  # one robot loaded for every job
    assert jobs[1].setup.cell.name == "table"
    assert jobs[0].options_hash == options_hash(jobs[0].options)  # hashed from the files it resolved
    local = job_payload(jobs[1], ship_bytes=False, config_dirs=[])
    assert local["refs"] == jobs[1].setup.resolved_refs() and Path(local["refs"]["cell"]).name == "table.yaml"
    shipped = job_payload(jobs[1], ship_bytes=True, config_dirs=[])
    assert shipped["refs"] == {"robot": "ur5", "gripper": "schunk_egp_c_40", "cell": "table"}
    ins = set(config_inputs(jobs))
    assert set(jobs[0].setup.files) | set(jobs[1].setup.files) <= ins
    bare = [dataclasses.replace(j, setup=None) for j in jobs]  # jobs made without a setup: looked up
    assert set(config_inputs(bare)) == ins
