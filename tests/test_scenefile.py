"""Scene files (grasplan.scene/1): structure and value checks name the field; edits make new scenes."""
from __future__ import annotations

import json

import numpy as np
import pytest

from grasplan.errors import InputError
from grasplan.piles.scene_file import Instance, Scene, load_scene, scene_from_dict
from grasplan.geometry.transforms import rpy_matrix

DOC = {
    "schema": "grasplan.scene/1",
    "cell": "bin",
    "parts": {"tless20": {"mesh": "parts/TLess20.stl", "units": "mm"}},
    "instances": [
        {"id": "a", "part": "tless20", "T": {"xyz": [0.40, 0.03, 0.03], "rpy_deg": [0, 0, 30]}},
        {"id": "b", "part": "tless20", "T": [[1, 0, 0, 0.5], [0, 1, 0, 0], [0, 0, 1, 0.03], [0, 0, 0, 1]]},
    ],
    "cloud": {"path": "scan.ply", "resolution": 0.005},
}


def test_yaml_and_json_read_the_same(tmp_path):
    import yaml

    (tmp_path / "s.yaml").write_text(yaml.safe_dump(DOC))
    (tmp_path / "s.json").write_text(json.dumps(DOC))
    a, b = load_scene(tmp_path / "s.yaml"), load_scene(tmp_path / "s.json")
    assert a.ids == b.ids == ["a", "b"] and a.cell == "bin"
    for x, y in zip(a.instances, b.instances):
        assert x == y
    Ta = a.instance("a").T_world_part
    np.testing.assert_allclose(Ta[:3, :3], rpy_matrix(0, 0, np.radians(30)))
    np.testing.assert_allclose(Ta[:3, 3], [0.40, 0.03, 0.03])
    assert a.resolve(a.part("tless20").mesh) == tmp_path / "parts" / "TLess20.stl"
    assert a.cloud.resolution == 0.005 and a.resolve(a.cloud.path) == tmp_path / "scan.ply"
    # the embedded form reads back to the same scene
    c = scene_from_dict(a.to_json())
    assert [i == j for i, j in zip(a.instances, c.instances)] == [True, True]


def _with(path, value):
    d = json.loads(json.dumps(DOC))
    node = d
    for k in path[:-1]:
        node = node[k]
    if value is KeyError:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return d


@pytest.mark.parametrize("path, value, match", [
    (("colour",), "red", r"unknown keys \['colour'\]"),
    (("schema",), "grasplan.scene/2", "schema must be"),
    (("instances", 0, "part"), "gear", r"instances\[0\]\.part: unknown part 'gear'"),
    (("instances", 1, "id"), "a", r"instances\[1\]\.id: 'a' is used"),
    (("instances", 1, "T"), [[1, 0, 0, 0], [0, 2, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], r"instances\[1\]\.T: not a rigid"),
    (("instances", 0, "T"), {"xyz": [0.4, float("nan"), 0.0]}, r"instances\[0\]\.T\.xyz\[1\]: must be finite"),
    (("instances", 0, "T"), {"xyz": [0.4, 0.0, 0.0], "rpy_deg": [1e308, 0, 0]}, r"rpy_deg"),
    (("instances", 0, "T"), {"pos": [0, 0, 0]}, r"unknown keys \['pos'\]"),
    (("instances", 0, "id"), "../etc", "not a valid name"),
    (("instances", 0, "size"), 3, r"instances\[0\]: unknown keys \['size'\]"),
    (("instances",), [], "non-empty list"),
    (("parts", "tless20", "units"), "furlong", "units"),
    (("cloud", "resolution"), 1e-9, "resolution"),
    (("cloud", "path"), KeyError, "missing 'path'"),
])
def test_bad_scenes_name_the_field(path, value, match):
    with pytest.raises(InputError, match=match):
        scene_from_dict(_with(path, value))


def test_duplicate_yaml_keys_and_fifo_refused(tmp_path):
    import os

    (tmp_path / "s.yaml").write_text("schema: grasplan.scene/1\ncell: bin\ncell: table\ninstances: []\n")
    with pytest.raises(InputError, match="duplicate key 'cell'"):
        load_scene(tmp_path / "s.yaml")
    os.mkfifo(tmp_path / "f.yaml")
    with pytest.raises(InputError, match="FIFO"):
        load_scene(tmp_path / "f.yaml")


def test_edits_make_new_scenes():
    s = scene_from_dict(DOC)
    t = s.without("a")
    assert t.ids == ["b"] and s.ids == ["a", "b"]
    T = np.eye(4)
    T[:3, 3] = [0.3, 0.0, 0.05]
    u = s.with_poses({"b": T})
    np.testing.assert_array_equal(u.instance("b").T_world_part, T)
    np.testing.assert_array_equal(s.instance("b").T_world_part[:3, 3], [0.5, 0, 0.03])
    with pytest.raises(InputError, match="unknown instance 'z'; the scene has a, b"):
        s.without("z")
    with pytest.raises(InputError, match="unique"):
        Scene(instances=(Instance("a", "p", np.eye(4)), Instance("a", "p", np.eye(4))))
    assert not s.instance("a").T_world_part.flags.writeable


# the JSON Schema (grasplan/schemas/scene.schema.json) and the reader agree ----------------------
STRUCTURAL = [
    (("colour",), "red"),
    (("schema",), "grasplan.scene/2"),
    (("instances", 0, "T"), {"pos": [0, 0, 0]}),
    (("instances", 0, "T"), {"rpy_deg": [0, 0, 0]}),
    (("instances", 0, "T"), [[1, 0, 0], [0, 1, 0], [0, 0, 1]]),
    (("instances", 0, "id"), "../etc"),
    (("instances", 0, "size"), 3),
    (("instances", 1, "part"), KeyError),
    (("instances",), []),
    (("parts", "tless20", "units"), "furlong"),
    (("parts", "tless20", "colour"), "red"),
    (("cloud", "path"), KeyError),
    (("cloud", "resolution"), "fine"),
]


def test_schema_accepts_what_the_reader_writes_and_accepts():
    from grasplan.schemas.documents import errors

    assert errors(DOC) == []
    assert errors(scene_from_dict(DOC).to_json()) == []


@pytest.mark.parametrize("path, value", STRUCTURAL)
def test_schema_and_reader_refuse_the_same_structural_errors(path, value):
    from grasplan.schemas.documents import errors

    doc = _with(path, value)
    assert errors(doc, "grasplan.scene/1"), f"the schema accepts {path} = {value!r}"
    with pytest.raises(InputError):
        scene_from_dict(doc)
