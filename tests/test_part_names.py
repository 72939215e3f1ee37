"""One name per part: a part is named by its mesh file's stem as written in ``scene drop``,
``clutter`` and ``serve --parts``; two files that give one name are refused naming both; a pile
written by ``scene drop`` posts to ``/pick`` of a service started on the same parts folder."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from grasplan.cli import main
from grasplan.errors import InputError
from grasplan.piles.scene_file import MAX_PART_NAME, NAME_RE, name_parts, part_name
from grasplan.serve.state import scan_parts
from grasplan.sim.drop import load_items

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples" / "parts"


@pytest.mark.parametrize("path, name", [
    ("parts/TLess20.stl", "TLess20"), ("IPAGearShaft.PLY", "IPAGearShaft"), ("box.stl", "box"),
    ("a b(1).STL", "a_b_1_"), ("-x.stl", "_-x"), ("v1.2.obj", "v1.2"), ("caf\u00e9.stl", "caf_"),
])
def test_a_part_is_named_by_its_stem_as_written(path, name):
    assert part_name(path) == name
    assert NAME_RE.match(name) and NAME_RE.match(f"{name}_499")


def test_a_long_stem_leaves_room_for_instance_ids():
    name = part_name("p" * 100 + ".stl")
    assert len(name) == MAX_PART_NAME and NAME_RE.match(f"{name}_499")


def test_two_files_with_one_name_are_refused_naming_both():
    assert list(name_parts(["a/Box.stl", "b/box.stl"], where="--part")) == ["Box", "box"]
    with pytest.raises(InputError, match=r"--part: a/Box.stl and b/Box.obj both give part name 'Box'.*rename one"):
        name_parts(["a/Box.stl", "b/Box.obj"], where="--part")


def test_scene_drop_and_serve_name_parts_alike(tmp_path):
    """The names ``load_items`` (scene drop, clutter) and ``scan_parts`` (serve) give one folder agree."""
    shutil.copy(EXAMPLES / "box.stl", tmp_path / "TLess20.stl")
    shutil.copy(EXAMPLES / "gear.stl", tmp_path / "my gear.stl")
    warnings: list[str] = []
    served = scan_parts(tmp_path, warnings.append)
    dropped = [it.name for it in load_items([(str(tmp_path / "TLess20.stl"), 1), (str(tmp_path / "my gear.stl"), 1)])]
    assert list(served) == dropped == ["TLess20", "my_gear"]
    assert warnings == ["my gear.stl: part name 'my_gear' (a part's name is the mesh file's stem as written "
                        "(characters other than letters, digits, '_', '.', '+', '-' made '_'))"]
    shutil.copy(EXAMPLES / "box.stl", tmp_path / "my_gear.stl")
    with pytest.raises(InputError, match="my gear.stl and my_gear.stl both give part name 'my_gear'"):
        scan_parts(tmp_path, warnings.append)


def test_a_scene_drop_pile_posts_to_pick(tmp_path, monkeypatch):
    """``scene drop`` of examples/parts, posted as written to a service on ``--parts examples/parts``:
    planned; a lower-cased name is matched by its mesh; an unknown mesh is a 422 naming the field
    and the service's parts."""
    pytest.importorskip("fastapi")
    pytest.importorskip("uvicorn")
    pytest.importorskip("grasplan.pick")
    from grasplan.serve import ServeConfig, create_app
    from grasplan.serve.loopback import Client, LoopbackServer
    from grasplan.serve.state import Service

    monkeypatch.setenv("GRASPLAN_CACHE_DIR", str(tmp_path / "cache"))
    pile = tmp_path / "pile.yaml"
    r = CliRunner().invoke(main, ["scene", "drop", "--part", f"{EXAMPLES / 'box.stl'}:2", "--part",
                                  f"{EXAMPLES / 'gear.stl'}:1", "--seed", "3", "-o", str(pile)])
    assert r.exit_code == 0, r.output
    doc = yaml.safe_load(pile.read_text())
    assert set(doc["parts"]) == {"box", "gear"} and all("mesh" in p for p in doc["parts"].values())
    before = sorted(p.name for p in EXAMPLES.iterdir())
    service = Service.start(ServeConfig(parts_dir=EXAMPLES))
    with LoopbackServer(create_app(ServeConfig(parts_dir=EXAMPLES, token="t" * 20), service=service)) as srv:
        client = Client(srv.port, token="t" * 20)
        try:
            status, out = client.json("POST", "/pick", {**doc, "options": {"max_picks": 1, "seed": 0}})
            assert status == 200, out
            assert {i["id"] for i in out["scene"]["instances"]} == {"box_0", "box_1", "gear_0"}
            assert len(out["picks"]) == 1 and out["picks"][0]["instance"] in {"box_0", "box_1", "gear_0"}

            old = {**doc, "parts": {"Box_old" if k == "box" else k: v for k, v in doc["parts"].items()},
                   "instances": [{**i, "part": "Box_old" if i["part"] == "box" else i["part"]}
                                 for i in doc["instances"]]}
            status, again = client.json("POST", "/pick", {**old, "options": {"max_picks": 1, "seed": 0}})
            assert status == 200, again
            assert again["picks"][0]["instance"] == out["picks"][0]["instance"]
            assert {i["part"] for i in again["scene"]["instances"]} == {"box", "gear"}

            foreign = {**doc, "parts": {**doc["parts"], "gear": {"mesh": "elsewhere/Sprocket.stl"}}}
            status, bad = client.json("POST", "/pick", foreign)
            assert status == 422, bad
            assert "parts.gear.mesh" in bad["detail"] and "'Sprocket'" in bad["detail"]
            assert "box, bracket, gear" in bad["detail"]
        finally:
            client.close()
    assert sorted(p.name for p in EXAMPLES.iterdir()) == before
