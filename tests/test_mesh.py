"""Stage 1: loading, units, repair and refusal."""
from __future__ import annotations

import struct

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings, strategies as st

from grasplan.errors import MeshError
from grasplan.mesh import AUTO_MM_THRESHOLD, decide_units, load_part, part_from_arrays
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
    from grasplan.mesh import load_recorded_part

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
