"""The output rule: no command writes over a file it reads, a file a document it reads names, or a
file among installed files (grasplan/setup/outputs.py, grasplan/io.py). Every command that writes, crossed
with every kind of named input: exit 3, a message naming the file, the file byte-identical.

The robot cases never touch the installed example-robot-data: a copy of its UR5 description is
installed in a folder put first on ``sys.path`` (a distribution record of its own), so the robot
YAML's ``package: example-robot-data`` resolves to the copy exactly as the robot loader resolves
it. The installed-file cases (grasplan's packaged data, a file of numpy) name an input that does
not exist, so that even a command whose guard failed would stop (exit 3) before writing anything;
their files are also hashed before and after.
"""
from __future__ import annotations

import hashlib
import importlib.metadata
import json
import shutil
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from grasplan.cli import main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples" / "parts"
DATA = ROOT / "grasplan" / "data"
UR = Path("example-robot-data") / "robots" / "ur_description"
ROBOT_KINDS = ("robot_yaml", "urdf", "srdf", "collision_mesh", "visual_mesh")


def _sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def _installed_dist_file(suffix: str) -> Path:
    """A harmless file of an installed distribution with the suffix a command's output needs."""
    want = {".txt": ("numpy", "LICENSE.txt"), ".json": ("jsonschema", "issue.json")}
    if suffix == ".stl":  # a mesh of a robot grasplan does not ship a description for
        from grasplan.robot.files import package_share_dir

        return package_share_dir() / "example-robot-data" / "robots" / "cassie_description" / "meshes" / "shin.stl"
    dist, name = want[suffix]
    f = next(f for f in importlib.metadata.files(dist) or [] if str(f).endswith(name))
    return Path(f.locate()).resolve()


def _copy_ur5(site: Path) -> None:
    """The UR5 of example-robot-data (URDF, SRDF, meshes) under ``site`` as an installed package."""
    from grasplan.robot.files import package_share_dir

    src = package_share_dir() / UR
    dst = site / "cmeel.prefix" / "share" / UR
    shutil.copytree(src / "meshes" / "ur5", dst / "meshes" / "ur5")
    (dst / "urdf").mkdir()
    (dst / "srdf").mkdir()
    shutil.copy(src / "urdf" / "ur5_robot.urdf", dst / "urdf")
    shutil.copy(src / "srdf" / "ur5.srdf", dst / "srdf")
    info = site / "example_robot_data-0.0.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: example-robot-data\nVersion: 0.0.0\n")
    files = sorted(p.relative_to(site).as_posix() for p in (site / "cmeel.prefix").rglob("*") if p.is_file())
    (info / "RECORD").write_text("".join(f"{f},,\n" for f in files))


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """Every input kind in one folder: part, cell and gripper YAMLs with meshes, a config folder,
    a robot YAML over a copied UR5, a plan (part recorded relative to it), a picks file, scenes."""
    import grasplan
    from grasplan.cell.model import load_cell
    from grasplan.part.mesh import load_part
    from grasplan.cell.resting import stable_pose

    w = tmp_path_factory.mktemp("rule")
    (w / "elsewhere").mkdir()
    shutil.copy(EXAMPLES / "box.stl", w / "box.stl")
    shutil.copy(EXAMPLES / "box.stl", w / "ob.stl")
    (w / "tcell.yaml").write_text("name: tcell\ntable_z: 0.0\npart_xy: [0.45, 0.0]\npose_index: 0\nobstacles:\n"
                                  "  - {name: post, mesh: {path: ob.stl, scale: 0.001}, T: {xyz: [0.8, 0.5, 0.0]}}\n")
    (w / "grip").mkdir()
    for f in ("round_mesh_jaws.yaml", "round_body.stl", "tapered_jaw.stl"):
        shutil.copy(DATA / "configs" / "grippers" / f, w / "grip" / f)
    (w / "grip" / "round_mesh_jaws.yaml").rename(w / "grip" / "mgrip.yaml")
    for sub, f, new in (("cells", "table.yaml", "cdcell.yaml"), ("grippers", "schunk_egp_c_40.yaml", "cdgrip.yaml")):
        (w / "cfg" / sub).mkdir(parents=True, exist_ok=True)
        shutil.copy(DATA / "configs" / sub / f, w / "cfg" / sub / new)
    _copy_ur5(w / "fakesite")
    (w / "rob").mkdir()
    shutil.copy(DATA / "robots" / "ur5.yaml", w / "rob" / "myur5.yaml")

    # a plan recording its part relative to its own folder (the reader looks there too)
    res = grasplan.plan(load_part(w / "box.stl", units="mm"), "ur5", grasps=grasplan.GraspParams(roll_step_deg=90),
                        planning=grasplan.PlanParams(top=1))
    res.write(w / "plan.json")
    doc = json.loads((w / "plan.json").read_text())
    doc["part"]["path"] = "box.stl"
    (w / "plan.json").write_text(json.dumps(doc))
    # the same plan made with the copied robot: its YAML is myur5.yaml (the text differs, so the
    # reader's cache of embedded robots does not hand back the installed one)
    src = doc["robot"]["source"]
    src.update(yaml=src["yaml"] + "\n# the copy in tests/test_output_rule.py\n", yaml_path=str(w / "rob" / "myur5.yaml"))
    (w / "planc.json").write_text(json.dumps(doc))

    # a picks file, and scenes for grasplan pick
    pk = w / "pk"
    (pk / "parts").mkdir(parents=True)
    shutil.copy(EXAMPLES / "bracket.stl", pk / "parts" / "bracket.stl")
    shutil.copy(EXAMPLES / "box.stl", pk / "parts" / "other.stl")
    rest = stable_pose(load_part(pk / "parts" / "bracket.stl").mesh, load_cell("bin"))
    scene = {"schema": "grasplan.scene/1", "cell": "bin",
             "parts": {"bracket": {"mesh": "parts/bracket.stl", "units": "auto"}},
             "instances": [{"id": "a", "part": "bracket", "T": rest.tolist()}]}
    (pk / "s.yaml").write_text(yaml.safe_dump(scene))
    r = CliRunner().invoke(main, ["pick", str(pk / "s.yaml"), "-o", str(pk / "picks.json")])
    assert r.exit_code == 0, r.output
    picks = json.loads((pk / "picks.json").read_text())
    picks["scene"]["parts"]["bracket"]["mesh"] = "parts/other.stl"  # its scene names another mesh than its part
    (pk / "picks.json").write_text(json.dumps(picks))
    (pk / "db.npz").write_bytes(b"not a database")
    (pk / "scan.ply").write_text("not a cloud\n")
    scene["parts"]["bracket"]["grasps"] = "db.npz"
    scene["cloud"] = {"path": "scan.ply", "resolution": 0.005}
    (pk / "s2.yaml").write_text(yaml.safe_dump(scene))
    return w


@pytest.fixture
def fake_erd(world, monkeypatch):
    """``package: example-robot-data`` resolves to the copy under ``world/fakesite`` (then back)."""
    from grasplan.robot import files as robot

    monkeypatch.syspath_prepend(str(world / "fakesite"))
    robot.package_share_dir.cache_clear()
    assert robot.package_share_dir() == (world / "fakesite" / "cmeel.prefix" / "share").resolve()
    yield
    robot.package_share_dir.cache_clear()


def target(kind: str, cmd: str, w: Path) -> Path:
    erd = w / "fakesite" / "cmeel.prefix" / "share" / UR
    if kind == "installed_data":
        return DATA / "configs" / {"blm": "grippers/round_body.stl"}.get(cmd, "cells/table.yaml")
    if kind == "installed_dist":
        return _installed_dist_file({"blm": ".stl", "scene": ".json"}.get(cmd, ".txt"))
    return {"part": w / "box.stl", "plan": w / "plan.json", "plan_part": w / "box.stl",
            "picks": w / "pk" / "picks.json", "picks_part": w / "pk" / "parts" / "bracket.stl",
            "picks_scene_mesh": w / "pk" / "parts" / "other.stl", "scene": w / "pk" / "s.yaml",
            "scene_mesh": w / "pk" / "parts" / "bracket.stl", "scene_grasps": w / "pk" / "db.npz",
            "scene_cloud": w / "pk" / "scan.ply", "cell_yaml": w / "tcell.yaml", "cell_mesh": w / "ob.stl",
            "gripper_yaml": w / "grip" / "mgrip.yaml", "gripper_mesh": w / "grip" / "round_body.stl",
            "robot_yaml": w / "rob" / "myur5.yaml", "urdf": erd / "urdf" / "ur5_robot.urdf",
            "srdf": erd / "srdf" / "ur5.srdf", "collision_mesh": erd / "meshes" / "ur5" / "collision" / "base.stl",
            "visual_mesh": erd / "meshes" / "ur5" / "visual" / "base.dae",
            "config_dir": w / "cfg" / ("grippers/cdgrip.yaml" if cmd == "database" else "cells/cdcell.yaml")}[kind]


def argv(cmd: str, kind: str, w: Path, out: Path) -> list[str]:
    """The command line of ``cmd`` that reads the input of ``kind`` and writes ``out``."""
    installed = kind.startswith("installed")
    part = str(w / ("missing.stl" if installed else "box.stl"))  # a missing input: nothing could be written
    robot = ["--robot", str(w / "rob" / "myur5.yaml")] if kind in ROBOT_KINDS else []
    cell = (["--cell", str(w / "tcell.yaml")] if kind in ("cell_yaml", "cell_mesh")
            else ["--config-dir", str(w / "cfg"), "--cell", "cdcell"] if kind == "config_dir" else [])
    grip = (["--gripper", str(w / "grip" / "mgrip.yaml")] if kind in ("gripper_yaml", "gripper_mesh")
            else ["--config-dir", str(w / "cfg"), "--gripper", "cdgrip"] if kind == "config_dir" and cmd == "database"
            else [])
    doc = str(w / ("missing.json" if installed else "planc.json" if kind in ROBOT_KINDS
                   else "pk/picks.json" if kind.startswith("picks") else "plan.json"))
    o = ["-o", str(out)]
    if cmd == "plan":
        return ["plan", part, *robot, *cell, *grip, "--top", "1", "--roll-step", "90", *o]
    if cmd == "pick":
        scene = str(w / ("missing.yaml" if installed else "pk/s2.yaml" if kind in ("scene_grasps", "scene_cloud")
                         else "pk/s.yaml"))
        return ["pick", scene, *robot, *cell, *grip, *o]
    if cmd == "export":
        return ["export", doc, "--format", "csv", *o]
    if cmd == "view":
        return ["view", doc, *o]
    if cmd == "simulate":
        return ["simulate", doc, "--top", "1", "--decomposition", "hull", *o]
    if cmd in ("database", "grasps"):
        return [cmd, part, *(cell if cmd == "grasps" else []), *grip, "--roll-step", "90", *o]
    if cmd in ("candidates", "blm"):
        return [cmd, part, *o]
    # scene drop and clutter: a cell without a bin, so that nothing runs past the checks
    bin_less = cell or ["--cell", str(w / "tcell.yaml")]
    if cmd == "scene":
        return ["scene", "drop", *bin_less, "--part", f"{part}:1", *o]
    if cmd == "clutter":
        return ["clutter", *bin_less, "--part", f"{part}:1", "--rounds", "1", *robot, *grip, *o]
    if cmd == "clutter-view":
        return ["clutter", *bin_less, "--part", f"{part}:1", "--rounds", "1", *robot, *grip, "-o",
                str(w / "elsewhere" / "report.json"), "--view", str(out)]
    raise ValueError(cmd)


EVERYWHERE = ("installed_data", "installed_dist")
PLAN_KINDS = ("part", "cell_yaml", "cell_mesh", "gripper_yaml", "gripper_mesh", *ROBOT_KINDS, "config_dir")
MATRIX = {
    "plan": PLAN_KINDS,
    "pick": ("scene", "scene_mesh", "scene_grasps", "scene_cloud", "cell_yaml", "cell_mesh", "gripper_yaml",
             "gripper_mesh", *ROBOT_KINDS, "config_dir"),
    "export": ("plan", "plan_part", "picks", "picks_part", "picks_scene_mesh", *ROBOT_KINDS),
    "view": ("plan", "plan_part", "picks", "picks_part", "picks_scene_mesh", *ROBOT_KINDS),
    "simulate": ("plan", "plan_part", *ROBOT_KINDS),
    "database": ("part", "gripper_yaml", "gripper_mesh", "config_dir"),
    "grasps": ("part", "cell_yaml", "cell_mesh", "gripper_yaml", "gripper_mesh", "config_dir"),
    "candidates": ("part",),
    "blm": ("part",),
    "scene": ("cell_yaml", "config_dir"),
    "clutter": PLAN_KINDS,
    "clutter-view": ("part", "cell_mesh", "gripper_yaml", "urdf", "collision_mesh"),
}
CASES = [(cmd, kind) for cmd, kinds in MATRIX.items() for kind in (*kinds, *EVERYWHERE)]


@pytest.mark.parametrize(("cmd", "kind"), CASES, ids=[f"{c}-{k}" for c, k in CASES])
def test_no_command_writes_over_what_it_reads(world, cmd, kind, request, monkeypatch):
    if kind in ROBOT_KINDS:
        request.getfixturevalue("fake_erd")
    out = target(kind, cmd, world)
    assert out.is_file(), out
    before = _sha(out)
    monkeypatch.chdir(world / "elsewhere")  # relative paths recorded in documents are not found by accident
    r = CliRunner().invoke(main, argv(cmd, kind, world, out))
    assert _sha(out) == before, f"{out} was changed\n{r.output}"
    assert r.exit_code == 3, r.output
    msg = r.output.strip().splitlines()[-1]
    assert msg.startswith("grasplan: error: ") and out.name in msg, msg
    if kind.startswith("installed"):
        assert "is an installed file" in msg and "grasplan never writes there" in msg, msg
    else:
        assert "is also an input" in msg, msg


def test_installed_folders_refuse_new_files_and_allow_the_usual_places(tmp_path, monkeypatch):
    """A new file among installed files is refused like a replaced one; the project folder, the
    temporary folder and the home stay writable."""
    import site
    import sysconfig

    from grasplan.errors import InputError
    from grasplan.io import check_output_path, installed_root

    purelib = Path(sysconfig.get_paths()["purelib"])
    for folder in (purelib / "numpy", purelib / "a-new-folder", DATA / "robots", Path(site.getsitepackages()[0])):
        with pytest.raises(InputError, match="would be written among installed files"):
            check_output_path(folder / "new-output.json", create_parents=True)
        assert not (folder / "new-output.json").exists()
    for ok in (tmp_path / "out.json", ROOT / "out.json", Path.home() / "out.json", ROOT / "venv" / "x.json"):
        assert installed_root(ok.resolve()) is None, ok
    monkeypatch.chdir(tmp_path)
    assert check_output_path("out.json") == Path("out.json")


def test_symlinked_spelling_of_an_installed_file_is_refused(tmp_path):
    """A symbolic link in the user's folder pointing into the installation is refused too."""
    from grasplan.errors import InputError
    from grasplan.io import check_output_path

    real = DATA / "robots" / "ur5.yaml"
    link = tmp_path / "ur5.yaml"
    link.symlink_to(real)
    before = _sha(real)
    with pytest.raises(InputError, match="is an installed file"):
        check_output_path(link)
    assert _sha(real) == before


def test_urdf_meshes_resolve_like_pinocchio(world, fake_erd):
    """The guard's list of a robot's files is what pinocchio loads: every collision and visual mesh
    of the robot model built from the copy is in it (and only files that exist)."""
    from grasplan.setup.outputs import config_files
    from grasplan.robot.description import load_robot

    files = config_files("robot", str(world / "rob" / "myur5.yaml"))
    assert all(f.is_file() for f in files)
    robot = load_robot(world / "rob" / "myur5.yaml")
    loaded = {Path(g.meshPath).resolve() for gm in (robot.collision_model, robot.visual_model)
              for g in gm.geometryObjects if Path(str(g.meshPath)).is_file()}
    assert loaded and loaded <= {f.resolve() for f in files}
    assert robot.urdf_path.resolve() in {f.resolve() for f in files}
