"""Grasp databases (issue 20 item 1): every grasp collision-free against the part (python-fcl),
the quality at a pose equal to the grasp stage's at that pose, rigid-motion invariance, the file
round trip, refusal for another part or gripper, the cache, and the CLI."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from grasplan.cell.model import NO_CELL, load_cell
from grasplan.cli import main
from grasplan.errors import InputError
from grasplan.grasps.graspdb import (
    DB_SUFFIX, GraspDatabase, build_database, cache_path, database_for, load_database, write_database
)
from grasplan.grasps.quality import grasp_quality
from grasplan.gripper.load import load_gripper
from grasplan.part.mesh import load_part
from grasplan.config.params import CandidateParams, GraspParams
from grasplan.geometry.transforms import rpy_matrix
from test_collision import FclPart  # noqa: E402  (independent python-fcl jaw boxes of the EGP-C 40)

ROOT = Path(__file__).resolve().parents[1]
BRACKET = ROOT / "examples" / "parts" / "bracket.stl"
GEAR = ROOT / "examples" / "parts" / "gear.stl"
FAST = GraspParams(roll_step_deg=45.0)


@pytest.fixture(scope="module")
def bracket():
    return load_part(BRACKET, units="mm")


@pytest.fixture(scope="module")
def db(bracket) -> GraspDatabase:
    return build_database(bracket, "schunk_egp_c_40", grasps=FAST)


def _pose(x: float, y: float, z: float, roll: float, pitch: float, yaw: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = rpy_matrix(*np.radians([roll, pitch, yaw]))
    T[:3, 3] = [x, y, z]
    return T


def test_every_grasp_is_free_of_the_part_in_python_fcl(db, bracket):
    assert len(db) >= 50
    ref = FclPart(bracket.mesh)
    hits = [i for i in range(len(db)) if ref.hits(db.T_part_tcp[i], float(db.width[i]))]
    assert not hits, f"{len(hits)} database grasps hit the part in python-fcl, e.g. row {hits[:5]}"


def test_rows_sorted_by_score_and_contacts_match_width(db):
    assert np.all(np.diff(db.score) <= 1e-12)
    d = np.linalg.norm(db.contacts[:, 1] - db.contacts[:, 0], axis=1)
    assert np.allclose(d, db.width, atol=1e-9)
    # the closing axis (TCP x) joins the contacts
    x = db.T_part_tcp[:, :3, 0]
    u = (db.contacts[:, 1] - db.contacts[:, 0]) / d[:, None]
    assert np.all(np.abs(np.einsum("ij,ij->i", x, u)) > 1 - 1e-6)


def test_quality_at_a_pose_equals_the_grasp_stage_at_that_pose(db, bracket):
    """The database's quality at a tilted pose (stored patches and epsilon, gravity margin for that
    pose) equals the grasp stage's quality function run from scratch on the same grasps at that pose."""
    T = _pose(0.0, 0.0, 0.5, 30.0, -50.0, 10.0)
    rows = np.arange(0, len(db), 3)
    q = db.quality_at(T, rows)
    assert q is not None and db.mass_props is not None
    ref = grasp_quality(bracket.mesh, db.mass_props, db.gripper, db.T_part_tcp[rows], db.contacts[rows],
                        db.normals[rows], db.width[rows], T_world_part=T, mu=db.mu)
    assert np.allclose(q.contact_area, ref.contact_area, rtol=1e-9, atol=1e-15)
    assert np.allclose(q.epsilon, ref.epsilon, rtol=1e-9, atol=1e-12)
    assert np.allclose(q.gravity_margin, ref.gravity_margin, rtol=1e-9, atol=1e-12)
    assert not np.allclose(q.gravity_margin, db.quality_at(np.eye(4), rows).gravity_margin)


@settings(max_examples=25, deadline=None)
@given(x=st.floats(-1, 1), y=st.floats(-1, 1), z=st.floats(0, 1), k=st.integers(-4, 4))
def test_score_invariant_under_motions_that_keep_gravity(db, bracket, x, y, z, k):
    """A translation and a turn about the world's vertical by a multiple of 45 deg keep gravity's
    direction in the part frame and map the load model's horizontal shake directions
    (grasplan.grasps.wrench.LOAD, every 45 deg) onto themselves: the score and the gravity margin stay
    the same (a tilt changes them)."""
    yaw = 45.0 * k
    T0 = _pose(0.1, 0.0, 0.1, 20.0, 35.0, 0.0)
    T1 = _pose(x, y, z, 0.0, 0.0, yaw) @ T0
    rows = np.arange(0, len(db), 7)
    assert np.allclose(db.score_at(bracket.mesh, T0, rows), db.score_at(bracket.mesh, T1, rows), atol=1e-9)


def test_score_in_the_part_frame_is_the_stored_score(db, bracket):
    assert np.allclose(db.score_at(bracket.mesh, np.eye(4)), db.score, atol=1e-12)
    tilted = db.score_at(bracket.mesh, _pose(0, 0, 0, 180.0, 0.0, 0.0))
    assert not np.allclose(tilted, db.score)  # upside down: top and gravity terms change


def test_file_round_trip(db, bracket, tmp_path):
    p = write_database(db, tmp_path / f"b{DB_SUFFIX}")
    back = load_database(p, part=bracket, gripper=load_gripper("schunk_egp_c_40"))
    for name in ("T_part_tcp", "width", "contacts", "normals", "candidate", "region", "contact_area", "contact_type",
                 "epsilon", "score"):
        assert np.array_equal(getattr(back, name), getattr(db, name), equal_nan=name != "contact_type"), name
    assert back.params_key == db.params_key and back.gripper_key == db.gripper_key
    assert back.mass_props is not None and db.mass_props is not None
    assert np.allclose(back.mass_props.com, db.mass_props.com)
    assert back.gripper.max_opening == db.gripper.max_opening


def test_refused_for_another_part_scale_or_gripper(db, bracket, tmp_path):
    p = write_database(db, tmp_path / f"b{DB_SUFFIX}")
    gear = load_part(GEAR, units="mm")
    with pytest.raises(InputError, match="computed for part .*bracket.*not for .*gear"):
        load_database(p, part=gear)
    with pytest.raises(InputError, match="scale"):
        load_database(p, part=load_part(BRACKET, units="cm"))
    with pytest.raises(InputError, match="gripper 'schunk_egp_c_40', not for 'round_mesh_jaws'"):
        load_database(p, gripper=load_gripper("round_mesh_jaws"))


@pytest.mark.parametrize("content", [b"", b"not a zip", b"PK\x03\x04broken"])
def test_malformed_files_are_input_errors(tmp_path, content):
    p = tmp_path / f"x{DB_SUFFIX}"
    p.write_bytes(content)
    with pytest.raises(InputError, match="grasp database"):
        load_database(p)


def test_npz_without_the_arrays_or_a_fifo_is_refused(tmp_path):
    p = tmp_path / f"other{DB_SUFFIX}"
    with open(p, "wb") as f:
        np.savez(f, a=np.zeros(3))
    with pytest.raises(InputError, match="not a grasplan grasp database"):
        load_database(p)
    fifo = tmp_path / "fifo.npz"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="FIFO"):
        load_database(fifo)


def test_cache_reuses_and_recomputes_a_damaged_entry(bracket, tmp_path, monkeypatch):
    monkeypatch.setenv("GRASPLAN_CACHE_DIR", str(tmp_path / "cache"))
    lines: list[str] = []
    a = database_for(bracket, "schunk_egp_c_40", grasps=FAST, progress=lines.append)
    path = cache_path(bracket, load_gripper("schunk_egp_c_40"), CandidateParams(), FAST)
    assert path.is_file() and any("computing" in s for s in lines)
    lines.clear()
    b = database_for(bracket, "schunk_egp_c_40", grasps=FAST, progress=lines.append)
    assert not lines and np.array_equal(a.T_part_tcp, b.T_part_tcp)
    other = database_for(bracket, "schunk_egp_c_40", grasps=GraspParams(roll_step_deg=90.0))
    assert len(other) < len(a)  # other options, another entry
    path.write_bytes(b"damaged")
    c = database_for(bracket, "schunk_egp_c_40", grasps=FAST, progress=lines.append)
    assert any("unusable" in s for s in lines) and np.array_equal(c.T_part_tcp, a.T_part_tcp)
    assert load_database(path).params_key == a.params_key  # rewritten


def test_cli_database_and_grasps_in_cell_none(tmp_path):
    out = tmp_path / f"bracket{DB_SUFFIX}"
    r = CliRunner().invoke(main, ["database", str(BRACKET), "--units", "mm", "--roll-step", "45", "-o", str(out)])
    assert r.exit_code == 0, r.output
    db = load_database(out, part=load_part(BRACKET, units="mm"))
    assert len(db) > 0 and "grasps (collision-free)" in r.output
    g = tmp_path / "g.json"
    r = CliRunner().invoke(main, ["grasps", str(BRACKET), "--units", "mm", "--roll-step", "45", "--cell", "none",
                                  "-o", str(g)])
    assert r.exit_code == 0, r.output
    import json
    doc = json.loads(g.read_text())
    assert doc["cell"]["name"] == "none" and doc["cell"]["part_pose"] == "part_frame"
    assert sum(1 for x in doc["grasps"] if x["status"] == "ok") == len(db)


def test_plan_in_cell_none_is_refused(tmp_path):
    r = CliRunner().invoke(main, ["plan", str(BRACKET), "--units", "mm", "--cell", "none", "-o",
                                  str(tmp_path / "p.json")])
    assert r.exit_code == 3 and "cell 'none'" in r.output and not (tmp_path / "p.json").exists()
    assert load_cell("none") is NO_CELL


@pytest.mark.parametrize("spread", [1, 10**12])
def test_a_repeated_pose_id_is_refused(db, spread):
    """Two rows with one pose id (ids close together, counted in a table, or far apart, sorted):
    InputError; the ids as they are, spread as far, pass."""
    import dataclasses

    ids = np.asarray(db.pose, dtype=np.int64) * spread
    assert len(dataclasses.replace(db, pose=ids)) == len(db)
    twice = ids.copy()
    twice[-1] = twice[0]
    with pytest.raises(InputError, match="a pose id appears twice"):
        dataclasses.replace(db, pose=twice)
