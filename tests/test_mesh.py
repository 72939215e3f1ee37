"""Stage 1: loading, units, repair and refusal."""
from __future__ import annotations

import struct

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings, strategies as st

from grasplan.errors import MeshError
from grasplan.part.mesh import AUTO_MM_THRESHOLD, decide_units, load_part, part_from_arrays
from conftest import PAPER_PARTS


def _write_stl(path, mesh, *, ascii=False):
    data = trimesh.exchange.stl.export_stl_ascii(mesh) if ascii else trimesh.exchange.stl.export_stl(mesh)
    (path.write_text if ascii else path.write_bytes)(data)
    return path


def test_binary_and_ascii_stl_agree(tmp_path):
    box = trimesh.creation.box(extents=(30, 20, 10))
    a = load_part(_write_stl(tmp_path / "b.stl", box))
    b = load_part(_write_stl(tmp_path / "a.stl", box, ascii=True))
    assert a.triangles == b.triangles == 12
    assert a.units == b.units == "mm" and a.scale_to_m == 1e-3
    assert np.allclose(np.sort(a.vertices, axis=0), np.sort(b.vertices, axis=0))
    assert a.mesh.is_watertight and a.mesh.volume == pytest.approx(30 * 20 * 10 * 1e-9)


@pytest.mark.parametrize("suffix", [".obj", ".ply"])
def test_obj_and_ply(tmp_path, suffix):
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.02)
    path = tmp_path / f"s{suffix}"
    mesh.export(path)
    part = load_part(path)
    assert part.units == "m" and part.triangles == len(mesh.faces)
    assert part.mesh.volume == pytest.approx(mesh.volume, rel=1e-6)


def test_merges_duplicate_vertices_and_reports(tmp_path):
    box = trimesh.creation.box(extents=(0.03, 0.02, 0.01))
    soup = trimesh.Trimesh(box.triangles.reshape(-1, 3), np.arange(36).reshape(-1, 3), process=False)
    part = part_from_arrays(soup.vertices, soup.faces, units="m")
    assert part.report.merged_vertices == 36 - 8
    assert part.mesh.is_watertight


def test_drops_degenerate_and_duplicate_faces():
    box = trimesh.creation.box(extents=(0.03, 0.02, 0.01))
    v = np.vstack([box.vertices, box.vertices[:1]])
    faces = np.vstack([box.faces, [[0, 0, 1]], box.faces[:1], [[0, 8, 1]]])  # repeated index, duplicate, zero-area
    part = part_from_arrays(v, faces, units="m")
    assert part.triangles == 12
    assert part.report.dropped_degenerate == 2 and part.report.dropped_duplicate == 1
    assert any("degenerate" in w for w in part.warnings)


def test_inverted_mesh_is_fixed():
    box = trimesh.creation.box(extents=(0.03, 0.02, 0.01))
    part = part_from_arrays(box.vertices, box.faces[:, ::-1], units="m")
    assert part.report.inverted_fixed and part.mesh.volume > 0


def test_open_mesh_and_several_bodies_warn():
    box = trimesh.creation.box(extents=(0.03, 0.02, 0.01))
    open_part = part_from_arrays(box.vertices, box.faces[:-1], units="m")
    assert not open_part.report.watertight and any("not watertight" in w for w in open_part.warnings)
    two = trimesh.util.concatenate([box, box.copy().apply_translation([0.1, 0, 0])])
    part = part_from_arrays(two.vertices, two.faces, units="m")
    assert part.report.bodies == 2 and any("2 separate bodies" in w for w in part.warnings)


@pytest.mark.parametrize(
    "content, message",
    [
        (b"", "empty"),
        (b"solid x\nendsolid x\n", "no triangles"),
        (b"this is not a mesh at all" * 10, "not a valid STL"),
    ],
)
def test_refuses_unusable_files(tmp_path, content, message):
    path = tmp_path / "bad.stl"
    path.write_bytes(content)
    with pytest.raises(MeshError, match=message) as err:
        load_part(path)
    assert str(path) in str(err.value) and err.value.exit_code == 3


def test_refuses_missing_folder_and_unknown_suffix(tmp_path):
    with pytest.raises(MeshError, match="no such file"):
        load_part(tmp_path / "nope.stl")
    with pytest.raises(MeshError, match="folder"):
        load_part(tmp_path)
    (tmp_path / "x.step").write_text("ISO-10303-21;")
    with pytest.raises(MeshError, match="unsupported file type"):
        load_part(tmp_path / "x.step")


def test_refuses_nan_and_no_area(tmp_path):
    # binary STL with one NaN vertex
    tri = struct.pack("<12f", 0, 0, 1, float("nan"), 0, 0, 1, 0, 0, 0, 1, 0) + b"\0\0"
    path = tmp_path / "nan.stl"
    path.write_bytes(b"\0" * 80 + struct.pack("<I", 1) + tri)
    with pytest.raises(MeshError, match="NaN"):
        load_part(path)
    flat = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]])
    with pytest.raises(MeshError, match="no area"):
        part_from_arrays(flat, [[0, 1, 2]], units="m")


@given(extent=st.floats(min_value=1e-3, max_value=1e4, allow_nan=False))
def test_auto_units_rule(extent):
    scale, unit, note = decide_units(extent, "auto")
    assert (unit == "mm") == (extent >= AUTO_MM_THRESHOLD)
    assert scale == (1e-3 if unit == "mm" else 1.0)
    assert "auto" in note


@pytest.mark.parametrize("name", PAPER_PARTS)
def test_paper_parts_load_with_documented_units(paper, name):
    part = load_part(paper(name))
    expected = {"SileaneGear.stl": "mm", "SileanePepper.stl": "mm", "TLess20.stl": "mm", "TLess22.stl": "mm"}
    assert part.units == expected.get(name, "m")
    assert part.report.watertight and part.mesh.volume > 0
    size = np.ptp(part.vertices, axis=0).max()
    assert 0.03 < size < 0.5  # every paper part is a hand-sized object in metres


@settings(max_examples=20, deadline=None)
@given(st.integers(min_value=0, max_value=2**31 - 1))
def test_rigid_motion_keeps_volume_and_counts(seed):
    rng = np.random.default_rng(seed)
    box = trimesh.creation.box(extents=(0.03, 0.02, 0.01))
    T = trimesh.transformations.random_rotation_matrix(rng.random(3))
    T[:3, 3] = rng.uniform(-1, 1, 3)
    moved = box.copy().apply_transform(T)
    part = part_from_arrays(moved.vertices, moved.faces, units="m")
    assert part.triangles == 12 and part.mesh.volume == pytest.approx(6e-6, rel=1e-9)


@pytest.mark.parametrize("units", ["cm", "in", "mm", "m"])
def test_load_recorded_part_uses_the_recorded_scale(tmp_path, units):
    """Export and viewer reload a result's part: at the recorded scale, not by guessing (a 3 cm
    box written in cm numbers would read as 3 mm with units=auto)."""
    from grasplan.part.mesh import load_recorded_part

    box = trimesh.creation.box(extents=(3.0, 2.0, 1.0))
    path = _write_stl(tmp_path / "box.stl", box)
    original = load_part(path, units=units)
    again = load_recorded_part(original.to_json() | {"path": "box.stl"}, search_dirs=(tmp_path,))
    assert again.scale_to_m == original.scale_to_m
    assert np.allclose(np.ptp(again.vertices, axis=0), np.ptp(original.vertices, axis=0))
    with pytest.raises(MeshError, match="--part"):
        load_recorded_part(original.to_json() | {"path": "elsewhere/box.stl"})
    with pytest.raises(MeshError, match="corrupt"):
        load_recorded_part(original.to_json() | {"scale_to_m": 0.37})


# -- every parse failure is one MeshError; flat parts rest; huge parts are refused ----

def test_truncated_binary_stl_names_the_sizes(tmp_path):
    data = trimesh.exchange.stl.export_stl(trimesh.creation.box(extents=(30, 20, 10)))
    path = tmp_path / "t.stl"
    path.write_bytes(data[:300])
    with pytest.raises(MeshError, match=r"declares 12 triangles \(684 bytes\) but the file has 300 bytes \(truncated\)"):
        load_part(path)


def test_ascii_stl_bad_number_names_the_line(tmp_path):
    text = trimesh.exchange.stl.export_stl_ascii(trimesh.creation.box(extents=(30, 20, 10))).splitlines()
    i = next(k for k, line in enumerate(text) if "vertex" in line)
    text[i] = "vertex 1 2 abc"
    path = tmp_path / "a.stl"
    path.write_text("\n".join(text))
    with pytest.raises(MeshError, match=f"line {i + 1}: cannot read 'vertex 1 2 abc'"):
        load_part(path)


@pytest.mark.parametrize("value, message", [(1e308, "overflow|across"), (float("inf"), "NaN or infinite"),
                                            (1e200, "across")])
def test_huge_coordinates_never_reach_the_tolerance(tmp_path, value, message):
    box = trimesh.creation.box(extents=(30, 20, 10))
    v = box.vertices.copy()
    v[0, 0] = value
    path = tmp_path / "h.stl"
    path.write_text(trimesh.exchange.stl.export_stl_ascii(trimesh.Trimesh(v, box.faces, process=False)))
    with pytest.raises(MeshError, match=message):
        load_part(path)


def test_huge_part_refused_before_reading(tmp_path, monkeypatch):
    import grasplan.part.mesh as gm

    box = trimesh.creation.box(extents=(30, 20, 10))
    path = _write_stl(tmp_path / "b.stl", box)
    monkeypatch.setattr(gm, "MAX_TRIANGLES", 11)
    with pytest.raises(MeshError, match=r"12 triangles is more than grasplan handles \(limit 11 triangles"):
        load_part(path)
    monkeypatch.setattr(gm, "MAX_TRIANGLES", 12)
    assert load_part(path).triangles == 12


def test_special_files_are_refused_without_blocking(tmp_path):
    import os

    fifo = tmp_path / "p.stl"
    os.mkfifo(fifo)
    with pytest.raises(MeshError, match="named pipe"):
        load_part(fifo)  # would block forever if opened
    with pytest.raises(MeshError, match="device"):
        load_part("/dev/null")
    with pytest.raises(MeshError, match="at most 255"):
        load_part(tmp_path / ("x" * 300 + ".stl"))


def test_library_text_never_reaches_the_message(tmp_path):
    for name, data in [("a.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n"),
                       ("b.obj", b"v 0 0 0\nv 1 0 0\nf 1 2 7\n"), ("c.off", b"OFF\n3 1 0\n0 0 0\n")]:
        (tmp_path / name).write_bytes(data)
        with pytest.raises(MeshError) as err:
            load_part(tmp_path / name)
        assert name in str(err.value)
        assert not any(w in str(err.value) for w in ("Error", "index", "KeyError", "reshape"))


def test_units_hint_names_inches_for_a_40mm_part_saved_in_inches(tmp_path):
    box = trimesh.creation.box(extents=(40 / 25.4, 30 / 25.4, 20 / 25.4))
    part = load_part(_write_stl(tmp_path / "inch.stl", box))
    assert part.units == "m"  # the auto rule, unchanged
    assert "--units in (40 mm)" in part.units_note
    assert any("--units in (40 mm)" in w for w in part.warnings)


def test_metre_part_read_as_mm_is_refused_with_the_right_units(tmp_path):
    path = _write_stl(tmp_path / "m.stl", trimesh.creation.box(extents=(0.04, 0.03, 0.02)))
    with pytest.raises(MeshError, match=r"--units m \(40 mm\)"):
        load_part(path, units="mm")


def _flat_meshes():
    n = 9
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ngon = np.vstack([np.c_[0.02 * np.cos(a), 0.02 * np.sin(a), np.zeros(n)], [[0, 0, 0]]])
    flat_box = trimesh.creation.box(extents=(0.03, 0.02, 1.0))
    flat_box.vertices[:, 2] = 0.0
    return {
        "triangle": (np.array([[0, 0, 0], [0.03, 0, 0], [0, 0.02, 0.0]]), np.array([[0, 1, 2]])),
        "plane": (np.array([[0, 0, 0], [0.05, 0, 0], [0.05, 0.03, 0], [0, 0.03, 0.0]]), np.array([[0, 1, 2], [0, 2, 3]])),
        "bow-tie": (np.array([[0, 0, 0], [0.05, 0, 0], [0.025, 0.0125, 0], [0, 0.025, 0], [0.05, 0.025, 0.0]]),
                    np.array([[0, 1, 2], [2, 4, 3]])),
        "n-gon": (ngon, np.array([[i, (i + 1) % n, n] for i in range(n)])),
        "flattened-box": (flat_box.vertices, flat_box.faces),
    }


@pytest.mark.parametrize("name", list(_flat_meshes()))
def test_flat_parts_lie_on_their_plane(name):
    from grasplan.cell.model import Cell
    from grasplan.cell.resting import stable_pose
    from grasplan.part.stability import stable_poses

    v, f = _flat_meshes()[name]
    R0 = trimesh.transformations.rotation_matrix(0.7, [1, 2, 3])[:3, :3]  # tilted in the file
    part = part_from_arrays(v @ R0.T, f, units="m")
    R, prob = stable_poses(part.mesh)
    assert len(R) == 2 and np.allclose(prob, 0.5)
    for k in range(2):
        T = stable_pose(part.mesh, Cell("t", table_z=0.1, pose_index=k))
        z = (part.vertices @ T[:3, :3].T + T[:3, 3])[:, 2]
        assert np.allclose(z, 0.1, atol=1e-12)  # every vertex on the table: lying on its face


def test_collinear_part_is_refused():
    from grasplan.errors import InputError
    from grasplan.part.stability import stable_poses

    mesh = trimesh.Trimesh([[0, 0, 0], [0.01, 0, 0], [0.02, 0, 0]], [[0, 1, 2]], process=False)
    with pytest.raises(InputError, match="collinear"):
        stable_poses(mesh)


def _trimesh_poses(mesh):
    from grasplan.part.stability import part_centre_of_mass

    T, p = trimesh.poses.compute_stable_poses(mesh, center_mass=part_centre_of_mass(mesh), sigma=0.0, n_samples=1,
                                              threshold=0.0)
    down = np.round(np.einsum("kji,j->ki", T[:, :3, :3], [0, 0, -1.0]), 6) + 0.0
    o = np.lexsort((down[:, 2], down[:, 1], down[:, 0], -np.round(p, 9)))
    return T[o, :3, :3], p[o] / p.sum()


@settings(max_examples=15, deadline=None)
@given(st.integers(min_value=0, max_value=2**31 - 1))
def test_stable_poses_match_trimesh_on_random_convex_parts(seed):
    """Cross-check of the vectorised toppling model against trimesh's reference implementation."""
    from grasplan.part.stability import stable_poses

    rng = np.random.default_rng(seed)
    mesh = trimesh.convex.convex_hull(rng.normal(size=(int(rng.integers(8, 60)), 3)) * rng.uniform(0.005, 0.05, 3))
    R, p = stable_poses(mesh)
    R2, p2 = _trimesh_poses(mesh)
    assert len(R) == len(R2)
    assert np.allclose(R, R2, atol=1e-6) and np.allclose(p, p2, atol=1e-9)


@pytest.mark.parametrize("name", ["box.stl", "bracket.stl", "gear.stl"])
def test_stable_poses_match_trimesh_on_example_parts(example_part, name):
    from grasplan.part.stability import stable_poses

    mesh = load_part(example_part(name)).mesh
    R, p = stable_poses(mesh)
    R2, p2 = _trimesh_poses(mesh)
    assert len(R) == len(R2) and np.allclose(R, R2, atol=1e-6) and np.allclose(p, p2, atol=1e-9)


def test_cell_round_trips_and_is_range_checked():
    from grasplan.cell.model import Cell, cell_from_dict
    from grasplan.errors import ConfigError

    c = Cell("bench", table_z=0.75, part_xy=(0.4, -0.2), pose_index=2)
    again = Cell.from_json(c.to_json())
    assert (again.name, again.table_z, again.part_xy, again.pose_index) == (c.name, c.table_z, c.part_xy, c.pose_index)
    assert set(Cell("t").to_json()) >= {"name", "up", "table", "part_xy", "pose_index"}
    for bad in ({"table_z": 1e300}, {"part_xy": [11, 0]}, {"part_xy": ["nan", 0]}, {"name": "a\nb"},
                {"name": "x\u2028popup"}, {"pose_index": -1}, {"table_z": "'x'*2000"}):
        with pytest.raises(ConfigError):
            cell_from_dict(bad, name="t", source="t.yaml")
    doc = c.to_json()
    for tamper in ({**doc, "table": {**doc["table"], "z": float("nan")}}, {**doc, "up": [1, 0, 0]},
                   {**doc, "part_xy": [1e9, 0]}, [], {**doc, "evil": 1}):
        with pytest.raises(ConfigError):
            Cell.from_json(tamper)
