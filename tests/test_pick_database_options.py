"""``Picker(database=GraspParams(...))``: the grasp databases it computes use those options (the
clutter benchmark plans plastic parts with the density it simulates, not the default steel)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from grasplan.part.mesh import load_part
from grasplan.config.params import DEFAULT_DENSITY, GraspParams
from grasplan.pick import Picker

BOX = Path(__file__).resolve().parents[1] / "examples" / "parts" / "box.stl"


def test_database_density_reaches_the_margin(tmp_path, monkeypatch):
    monkeypatch.setenv("GRASPLAN_CACHE_DIR", str(tmp_path))
    part = load_part(BOX)
    steel = Picker("ur5", database=GraspParams())
    plastic = Picker("ur5", database=GraspParams(density=1200.0))
    steel.add_part("box", part)
    plastic.add_part("box", part)
    a, b = steel._grasps["box"], plastic._grasps["box"]
    assert a.mass_props is not None and b.mass_props is not None
    assert np.isclose(a.mass_props.mass / b.mass_props.mass, DEFAULT_DENSITY / 1200.0, rtol=1e-9)
    assert a.params_key != b.params_key  # cached apart
    assert len(list(tmp_path.rglob("*.graspdb.npz"))) == 2
    up = np.eye(4)
    ga, gb = a.quality_at(up).gravity_margin, b.quality_at(up).gravity_margin
    assert np.all(gb >= ga - 1e-12) and np.any(gb > ga * 1.5)  # lighter part, larger margins


def test_cli_pick_density(tmp_path, monkeypatch):
    """``grasplan pick --density``: the database it computes and caches is for that density."""
    import yaml
    from click.testing import CliRunner

    from grasplan.cli import main
    from grasplan.grasps.graspdb import load_database

    monkeypatch.setenv("GRASPLAN_CACHE_DIR", str(tmp_path / "cache"))
    doc = {"schema": "grasplan.scene/1", "cell": "table", "parts": {"box": {"mesh": str(BOX)}},
           "instances": [{"id": "a", "part": "box", "T": {"xyz": [0.45, 0.0, 0.05], "rpy_deg": [0, 0, 0]}}]}
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(doc))
    r = CliRunner().invoke(main, ["pick", str(tmp_path / "s.yaml"), "-o", str(tmp_path / "p.json"),
                                  "--density", "1200", "--max-picks", "1"])
    assert r.exit_code in (0, 4), r.output
    dbs = list((tmp_path / "cache").rglob("*.graspdb.npz"))
    assert len(dbs) == 1
    db = load_database(dbs[0])
    assert db.mass_props is not None and np.isclose(db.mass_props.mass, 1200.0 * db.mass_props.volume, rtol=1e-9)
    bad = CliRunner().invoke(main, ["pick", str(tmp_path / "s.yaml"), "-o", str(tmp_path / "q.json"),
                                    "--density", "-5"])
    assert bad.exit_code == 3 and "--density" in bad.output and not (tmp_path / "q.json").exists()  # as grasps


def test_an_empty_database_is_named_as_such(tmp_path, monkeypatch):
    """A gripper whose stroke takes no contact pair of the part (the EGP 25: 34-40 mm, the box is
    10 x 20 x 30 mm): an empty database, the instance's reason says so (not "none of 0 grasps")."""
    from grasplan.piles.scene_file import Instance, Scene

    monkeypatch.setenv("GRASPLAN_CACHE_DIR", str(tmp_path))
    pk = Picker("ur5", gripper="schunk_egp_25", cell="bin")
    pk.add_part("box", load_part(BOX))
    assert len(pk._grasps["box"]) == 0
    T = np.eye(4)
    T[:3, 3] = [0.45, 0.0, 0.03]
    res = pk.plan(Scene(instances=(Instance("a", "box", T),), cell="bin"))
    assert not res.picks and res.instances[0].status == "no_grasp"
    assert res.instances[0].reason == "its grasp database is empty: no contact pair fits the gripper schunk_egp_25"
