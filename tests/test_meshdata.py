"""MeshData (issue 10: loading and candidates without importing trimesh) against trimesh itself."""
from __future__ import annotations

import pickle
import subprocess
import sys

import numpy as np
import pytest
import trimesh

from grasplan.part.mesh import load_part
from grasplan.geometry.meshdata import MeshData, connected_components
from tests.conftest import EXAMPLE_PARTS


def _meshes():
    box = trimesh.creation.box((0.06, 0.045, 0.014))
    two = trimesh.util.concatenate([box, trimesh.creation.icosphere(2, 0.01).apply_translation([0.1, 0, 0])])
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-2], process=False)  # a hole: not watertight
    flipped = box.copy()
    flipped.faces = np.vstack([box.faces[:5], box.faces[5:6, ::-1], box.faces[6:]])  # one face wound backwards
    cyl = trimesh.creation.cylinder(0.01, 0.05, sections=33)
    return {"box": box, "two bodies": two, "open box": open_box, "one face flipped": flipped, "cylinder": cyl}


@pytest.mark.parametrize("name", list(_meshes()))
def test_arrays_and_flags_equal_trimesh(name):
    tm = _meshes()[name]
    md = MeshData(tm.vertices, tm.faces)
    assert np.array_equal(md.face_normals, tm.face_normals)  # same operations: same bits
    assert np.array_equal(md.area_faces, tm.area_faces)
    assert md.area == pytest.approx(tm.area, rel=1e-15)
    assert np.array_equal(md.triangles, tm.triangles)
    np.testing.assert_allclose(md.triangles_center, tm.triangles_center, rtol=0, atol=1e-18)
    np.testing.assert_array_equal(md.bounds, tm.bounds)
    np.testing.assert_array_equal(md.extents, tm.extents)
    assert md.is_watertight == tm.is_watertight
    assert md.is_winding_consistent == tm.is_winding_consistent
    assert md.body_count == tm.body_count
    # anything MeshData does not compute comes from an equal trimesh
    assert md.volume == pytest.approx(tm.volume) if tm.is_watertight else True
    assert np.array_equal(md.face_adjacency, tm.face_adjacency)


def test_connected_components_match_scipy():
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components as scipy_cc

    rng = np.random.default_rng(3)
    for n, k in [(1, 0), (10, 0), (50, 20), (400, 380), (2000, 1500)]:
        e = rng.integers(0, n, size=(k, 2))
        count, label = connected_components(n, e)
        c2, l2 = scipy_cc(coo_matrix((np.ones(k), (e[:, 0], e[:, 1])), shape=(n, n)), directed=False)
        assert count == c2
        # the same partition, labelled in order of each component's lowest node (as scipy)
        assert np.array_equal(label, l2)


def test_immutable_copy_and_pickle():
    tm = _meshes()["box"]
    md = MeshData(tm.vertices, tm.faces)
    for name in ("apply_transform", "apply_translation", "invert", "update_faces", "remove_unreferenced_vertices",
                 "merge_vertices", "fix_normals"):
        with pytest.raises(AttributeError, match="immutable"):
            getattr(md, name)
    c = md.copy()  # a mutable trimesh
    c.apply_translation([1.0, 0, 0])
    assert np.array_equal(md.vertices, tm.vertices) and not np.array_equal(c.vertices, tm.vertices)
    fn = -md.face_normals
    recorded = MeshData(tm.vertices, tm.faces, face_normals=fn)
    back = pickle.loads(pickle.dumps(recorded))
    assert np.array_equal(back.vertices, md.vertices) and np.array_equal(back.faces, md.faces)
    assert np.array_equal(back.face_normals, fn)  # recorded normals survive, caches do not matter
    with pytest.raises(ValueError, match="face normals"):
        MeshData(tm.vertices, tm.faces, face_normals=fn[:3])


def test_with_faces_drops_unreferenced_vertices_and_keeps_per_face_values():
    tm = _meshes()["two bodies"]
    md = MeshData(tm.vertices, tm.faces)
    _ = md.face_normals
    keep = np.zeros(len(tm.faces), dtype=bool)
    keep[:12] = True  # the box only
    sub = md.with_faces(keep)
    ref = tm.copy()
    ref.update_faces(keep)
    ref.remove_unreferenced_vertices()
    assert np.array_equal(sub.vertices, ref.vertices) and np.array_equal(sub.faces, ref.faces)
    assert np.array_equal(sub.face_normals, MeshData(sub.vertices, sub.faces).face_normals)
    assert sub.body_count == 1 and sub.is_watertight


def _modules_after(command: str, tmp_path) -> tuple[bool, bool]:
    """Run ``grasplan COMMAND bracket.stl --units mm -o OUT`` in a fresh interpreter: were trimesh
    and scipy imported?"""
    code = ("import sys\nfrom grasplan.cli import main\nsys.argv = ['grasplan', sys.argv[1], sys.argv[2], '--units', "
            "'mm', '-o', sys.argv[3]]\ntry:\n    main()\nexcept SystemExit as e:\n    assert e.code in (0, None), e.code\n"
            "print('trimesh' in sys.modules, 'scipy' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code, command, str(EXAMPLE_PARTS / "bracket.stl"),
                          str(tmp_path / f"{command}.json")], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / f"{command}.json").is_file()
    trimesh_used, scipy_used = out.stdout.strip().splitlines()[-1].split()
    return trimesh_used == "True", scipy_used == "True"


def test_loading_a_part_and_candidates_do_not_import_trimesh_or_scipy(tmp_path):
    """The point of MeshData and grasplan.geometry.gridsearch: a fresh ``grasplan candidates`` imports
    neither trimesh nor scipy (0.5-0.9 s and 0.3 s of a command that must take < 1 s)."""
    assert _modules_after("candidates", tmp_path) == (False, False)


def test_loaded_part_equals_trimesh_processing():
    """An independent reference for the cleaning: trimesh's own merge, degenerate and duplicate
    removal, winding fix give the same triangles as the NumPy loader."""
    part = load_part(EXAMPLE_PARTS / "gear.stl", units="mm")
    raw = trimesh.load(EXAMPLE_PARTS / "gear.stl", force="mesh", process=False)
    raw.apply_scale(part.scale_to_m)
    raw.merge_vertices(digits_vertex=int(max(0, np.floor(-np.log10(part.tol.merge)))))
    raw.update_faces(raw.nondegenerate_faces(height=None) & (raw.area_faces > part.tol.area))
    raw.update_faces(raw.unique_faces())
    raw.remove_unreferenced_vertices()
    trimesh.repair.fix_winding(raw)
    a = {tuple(sorted(map(tuple, np.round(t, 12)))) for t in part.mesh.triangles}
    b = {tuple(sorted(map(tuple, np.round(t, 12)))) for t in raw.triangles}
    assert a == b
    assert part.mesh.is_watertight == raw.is_watertight and part.mesh.body_count == raw.body_count


@pytest.mark.parametrize("name", ["box", "cylinder", "two bodies"])
def test_convex_hull_and_mass_integrals_equal_trimesh(name):
    """The NumPy/scipy hull and the polyhedron integrals reproduce trimesh's, bit for bit."""
    from grasplan.geometry.meshdata import convex_hull, polyhedron_integrals

    tm = _meshes()[name]
    h, ref = convex_hull(tm.vertices), tm.convex_hull
    assert np.array_equal(h.vertices, ref.vertices) and np.array_equal(h.faces, ref.faces)
    assert np.array_equal(h.face_normals, ref.face_normals) and h.is_watertight and h.is_winding_consistent
    mp = trimesh.triangles.mass_properties(tm.triangles, density=1.0)
    v, c, inertia = polyhedron_integrals(tm.triangles)
    assert v == mp["volume"] and np.array_equal(c, mp["center_mass"]) and np.array_equal(inertia, mp["inertia"])
    md = MeshData(tm.vertices, tm.faces)
    assert md.volume == tm.volume and np.array_equal(md.center_mass, tm.center_mass)
    assert md.convex_hull.volume == pytest.approx(ref.volume, rel=1e-14)


def test_grasps_do_not_import_trimesh(tmp_path):
    """Stable pose, collision filter, quality and score run on MeshData: ``grasplan grasps``
    (whose steps ``plan`` repeats) never imports trimesh (0.5 s of every command)."""
    assert _modules_after("grasps", tmp_path)[0] is False
