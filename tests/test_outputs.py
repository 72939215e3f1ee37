"""The output guard (grasplan/setup/outputs.py), all-or-nothing multi-file writes, the plan re-pointing
check and the guarded mesh resolver (issue 24)."""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from grasplan.errors import InputError, MeshError
from grasplan.io import write_files_atomic
from grasplan.setup.outputs import check_outputs, config_files

PARTS = Path(__file__).resolve().parents[1] / "examples" / "parts"


def test_companion_over_an_input_is_refused_naming_both(tmp_path):
    plan = tmp_path / "pick.dat"
    plan.write_text("{}")
    with pytest.raises(InputError, match=r"pick\.dat \(written with .*pick\.src\) is also an input"):
        check_outputs([tmp_path / "pick.src", tmp_path / "pick.dat"], inputs=[plan])
    assert plan.read_text() == "{}"


@pytest.mark.parametrize("spelling", ["dot", "symlink", "hardlink"])
def test_every_spelling_of_an_input_is_the_input(tmp_path, spelling):
    inp = tmp_path / "cell.yaml"
    inp.write_text("name: c\n")
    other = {"dot": tmp_path / "." / "cell.yaml", "symlink": tmp_path / "l.yaml", "hardlink": tmp_path / "h.yaml"}
    out = other[spelling]
    if spelling == "symlink":
        out.symlink_to(inp)
    elif spelling == "hardlink":
        os.link(inp, out)
    with pytest.raises(InputError, match="also an input"):
        check_outputs([out], inputs=[inp])


def test_family_of_later_names_is_checked(tmp_path):
    inp = tmp_path / "out.pose3.json"
    inp.write_text("x")
    fam = [(tmp_path, r"out\.pose\d+\.json")]
    with pytest.raises(InputError, match="writes files named like out.pose3.json"):
        check_outputs([tmp_path / "out.json"], inputs=[inp], families=fam)
    assert check_outputs([tmp_path / "other.json"], inputs=[inp], families=[(tmp_path, r"other\.pose\d+\.json")])


def test_group_write_is_all_or_nothing(tmp_path):
    src, dat = tmp_path / "pick.src", tmp_path / "pick.dat"
    src.write_text("old program")
    dat.mkdir()
    with pytest.raises(InputError, match="is a folder"):
        write_files_atomic([(src, "new program"), (dat, "data")])
    assert src.read_text() == "old program"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pick.dat", "pick.src"]  # no temporary file left
    dat.rmdir()
    write_files_atomic([(src, "new program"), (dat, b"data")])
    assert src.read_text() == "new program" and dat.read_bytes() == b"data"


def test_config_files_lists_the_meshes_a_yaml_names(tmp_path):
    (tmp_path / "ob.stl").write_bytes((PARTS / "box.stl").read_bytes())
    y = tmp_path / "c.yaml"
    y.write_text("name: c\nobstacles:\n  - {name: a, mesh: {path: ob.stl}, T: {xyz: [0, 0, 0]}}\n")
    assert config_files("cell", str(y)) == [y.resolve(), y.resolve().parent / "ob.stl"]
    assert config_files("cell", str(tmp_path / "missing.yaml")) == []


def _point_triangle_distance(p: np.ndarray, tri: np.ndarray) -> float:
    """Brute force, independent of coal: the closest point of a triangle by sampling its barycentric
    grid finely (enough for a tolerance test)."""
    u, v = np.meshgrid(np.linspace(0, 1, 201), np.linspace(0, 1, 201))
    keep = u + v <= 1
    pts = tri[0] + u[keep, None] * (tri[1] - tri[0]) + v[keep, None] * (tri[2] - tri[0])
    return float(np.min(np.linalg.norm(pts - p, axis=1)))


def test_repointed_plan_is_refused_and_the_distance_agrees_with_brute_force(tmp_path):
    import grasplan
    from grasplan.results.reader import check_contacts_on_part, load_result

    part = tmp_path / "box.stl"
    part.write_bytes((PARTS / "box.stl").read_bytes())
    res = grasplan.plan(grasplan.load_part(part, units="mm"), "ur5", grasps=grasplan.GraspParams(roll_step_deg=90),
                        planning=grasplan.PlanParams(top=1))
    res.write(tmp_path / "plan.json")
    loaded = load_result(tmp_path / "plan.json", load_mesh=True)  # the right part: accepted
    check_contacts_on_part(loaded, "plan")
    mesh = loaded.part_mesh
    tris = np.asarray(mesh.vertices)[np.asarray(mesh.faces)]
    c = np.asarray(loaded.grasps.contacts)[0, 0]
    assert min(_point_triangle_distance(c, t) for t in tris) < 1e-4  # on the surface by an independent check
    # the same plan pointing at the box moved by 5 mm along x: every contact is off by up to 5 mm
    moved = tmp_path / "moved.stl"
    data = bytearray(part.read_bytes())
    rec = np.frombuffer(bytes(data[84:]), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]).copy()
    rec["v"][..., 0] += 5.0
    moved.write_bytes(bytes(data[:84]) + rec.tobytes())
    doc = json.loads((tmp_path / "plan.json").read_text())
    import hashlib

    doc["part"].update(path=str(moved), sha256=hashlib.sha256(moved.read_bytes()).hexdigest())
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"contact lies .* mm from the part .*moved\.stl"):
        load_result(tmp_path / "bad.json", verify_part=True)
    # without the mesh at hand nothing can be checked: exports still work from the plan alone
    moved.unlink()
    assert load_result(tmp_path / "bad.json", verify_part=True).part_mesh is None


def test_gltf_buffer_fifo_is_refused_without_blocking(tmp_path):
    from grasplan.part.mesh import load_part

    os.mkfifo(tmp_path / "buf.bin")
    doc = {"asset": {"version": "2.0"}, "buffers": [{"uri": "buf.bin", "byteLength": 36}], "meshes": []}
    (tmp_path / "p.gltf").write_text(json.dumps(doc))
    with pytest.raises(MeshError, match="FIFO"):
        load_part(tmp_path / "p.gltf")


def test_obj_mtllib_through_the_guard_still_loads(tmp_path):
    from grasplan.part.mesh import load_part

    (tmp_path / "m.mtl").write_text("newmtl x\nKd 1 0 0\n")
    (tmp_path / "p.obj").write_text("mtllib m.mtl\nusemtl x\n" + "".join(
        f"v {x} {y} {z}\n" for x in (0, 0.02) for y in (0, 0.02) for z in (0, 0.02))
        + "f 1 3 4\nf 1 4 2\nf 5 6 8\nf 5 8 7\nf 1 2 6\nf 1 6 5\nf 3 7 8\nf 3 8 4\nf 1 5 7\nf 1 7 3\nf 2 4 8\nf 2 8 6\n")
    p = load_part(tmp_path / "p.obj", units="m")
    assert p.triangles == 12
