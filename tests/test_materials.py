"""One default density story: steel (7850 kg/m^3) in every command, ``--material NAME`` wherever
``--density`` is (the two must agree), a scene part's own material driving the drop's physics
and the picker's grasp database, and the material recorded in the outputs."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from grasplan.cli import main
from grasplan.config.materials import CUSTOM, DEFAULT_DENSITY, DEFAULT_MATERIAL, MATERIALS, resolve_material
from grasplan.config.params import GraspParams
from grasplan.errors import InputError
from grasplan.part.mesh import load_part

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "parts"
BOX = EXAMPLES / "box.stl"


def _drop_params():
    from grasplan.sim.drop import DropParams

    return DropParams


# ---------------------------------------------------------------------------------------- names
@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_every_material_name_sets_its_density(name):
    for cls in (GraspParams, _drop_params()):
        p = cls(material=name)
        assert (p.material, p.density) == (name, MATERIALS[name])
        q = cls(density=MATERIALS[name])  # a density alone is named by the material that has it
        assert (q.material, q.density) == (name, MATERIALS[name])
        assert cls(material=name, density=MATERIALS[name]) == p  # both, agreeing


def test_no_two_materials_share_a_density_and_the_scene_schema_lists_them():
    import importlib.resources

    assert len(set(MATERIALS.values())) == len(MATERIALS)
    schema = json.loads(importlib.resources.files("grasplan.schemas").joinpath("scene.schema.json").read_text())
    part = schema["properties"]["parts"]["additionalProperties"]["properties"]
    assert part["material"]["enum"] == list(MATERIALS)


def test_a_density_of_no_material_is_custom_and_mass_is_custom():
    assert GraspParams(density=1234.0).material == CUSTOM
    assert GraspParams(mass=0.5).material == CUSTOM
    assert GraspParams(mass=0.5, material="brass").material == "brass"
    assert resolve_material(None, None) == (DEFAULT_MATERIAL, DEFAULT_DENSITY)


def test_unknown_names_and_conflicts_are_refused_naming_what_would_pass():
    with pytest.raises(InputError) as e:
        GraspParams(material="unobtainium")
    assert "unobtainium" in str(e.value) and all(n in str(e.value) for n in MATERIALS)
    for cls in (GraspParams, _drop_params()):
        with pytest.raises(InputError) as e:
            cls(material="plastic", density=7850.0)
        assert "--material plastic" in str(e.value) and "--density 7850" in str(e.value)


def test_the_cli_refuses_a_conflict_and_lists_names(tmp_path):
    out = tmp_path / "pile.yaml"
    r = CliRunner().invoke(main, ["scene", "drop", "--part", f"{BOX}:1", "--material", "plastic", "--density",
                                  "2700", "-o", str(out)])
    assert r.exit_code == 3 and "--material plastic" in r.output and "--density 2700" in r.output, r.output
    r = CliRunner().invoke(main, ["scene", "drop", "--part", f"{BOX}:1", "--material", "gold", "-o", str(out)])
    assert r.exit_code == 2 and "gold" in r.output and "aluminium" in r.output, r.output
    assert not out.exists()


# ------------------------------------------------------------------------- one default everywhere
def test_one_default_in_every_command():
    """Every command with --density also has --material; both print the one default, and the
    dataclasses, the mass properties and the simulation resolve to it."""
    import inspect

    from grasplan.part.mass import mass_properties
    from grasplan.sim.simulate import simulate_grasps

    from test_docs_help import click_commands, printed_default

    seen = []
    for name, cmd in click_commands().items():
        opts = {o: p for p in cmd.params for o in getattr(p, "opts", ())}
        if "--density" not in opts:
            continue
        seen.append(name)
        assert "--material" in opts, name
        assert printed_default(cmd, name, opts["--material"]) == DEFAULT_MATERIAL, name
        assert float(printed_default(cmd, name, opts["--density"]) or "nan") == DEFAULT_DENSITY, name
        assert opts["--density"].default is None and opts["--material"].default is None  # resolved by the dataclass
    assert {"plan", "grasps", "database", "simulate", "pick", "scene drop", "clutter", "batch"} <= set(seen), seen
    assert GraspParams().density == _drop_params()().density == DEFAULT_DENSITY
    assert GraspParams().material == _drop_params()().material == DEFAULT_MATERIAL
    assert inspect.signature(mass_properties).parameters["density"].default == DEFAULT_DENSITY
    assert inspect.signature(simulate_grasps).parameters["density"].default == DEFAULT_DENSITY


def test_the_mass_record_names_the_material():
    from grasplan.part.mass import mass_properties

    mesh = load_part(BOX).mesh
    assert mass_properties(mesh).record()["material"] == "steel"
    assert mass_properties(mesh, density=2700.0).record()["material"] == "aluminium"
    assert mass_properties(mesh, density=1234.0).record()["material"] == CUSTOM
    rec = mass_properties(mesh, mass=0.01, material="pom").record()
    assert rec["material"] == "pom" and np.isclose(rec["mass_kg"], 0.01)


def test_grasps_file_records_the_material(tmp_path):
    """``grasplan grasps --material aluminium``: the file's part has the material and its density."""
    out = tmp_path / "g.json"
    r = CliRunner().invoke(main, ["grasps", str(EXAMPLES / "bracket.stl"), "--units", "mm", "--material",
                                  "aluminium", "-o", str(out)])
    assert r.exit_code == 0, r.output
    part = json.loads(out.read_text())["part"]
    assert (part["density"], part["material"]) == (2700.0, "aluminium")
    assert np.isclose(part["mass_kg"], 2700.0 / DEFAULT_DENSITY * _steel_mass(EXAMPLES / "bracket.stl"), rtol=1e-9)


def _steel_mass(path: Path) -> float:
    from grasplan.part.mass import mass_properties

    return mass_properties(load_part(path).mesh).mass


def test_the_holding_warning_says_which_density_would_hold():
    from grasplan.grasps.quality import Quality, holding_warning
    from grasplan.part.mass import mass_properties

    mp = mass_properties(load_part(BOX).mesh)  # steel
    q = Quality(contact_area=np.zeros((1, 2)), contact_type=np.zeros((1, 2), np.int8),
                contact_width=np.zeros((1, 2, 2)), gravity_margin=np.array([0.25]), epsilon=np.zeros(1),
                grip_force=140.0, mu=0.3)
    msg = holding_warning(q, mp, part="box.stl")
    limit = 0.25 * DEFAULT_DENSITY
    assert f"<= {limit:.4g} kg/m^3" in msg and "--material plastic" in msg and "steel" in msg
    assert all(n in msg for n, d in MATERIALS.items() if d <= limit) and "aluminium" not in msg
    q.gravity_margin[:] = 0.01  # lighter than any material of the table
    assert "lighter than any --material" in holding_warning(q, mp)


# ------------------------------------------------------------------------------ scene part materials
def test_scene_part_material_round_trips_and_is_checked(tmp_path):
    from grasplan.piles.scene_file import Instance, Scene, ScenePart, load_scene
    from grasplan.piles.scene_write import write_scene

    sha = load_part(BOX).sha256
    sc = Scene(instances=(Instance("a", "box", np.eye(4)),),
               parts=(ScenePart("box", mesh=str(BOX), units="mm", material="plastic", density=1200.0, sha256=sha),))
    for suffix in (".yaml", ".json"):
        back = load_scene(write_scene(tmp_path / f"s{suffix}", sc) and tmp_path / f"s{suffix}")
        p = back.part("box")
        assert p is not None and (p.material, p.density, p.sha256) == ("plastic", 1200.0, sha)
    doc = {"schema": "grasplan.scene/1", "instances": [{"id": "a", "part": "box", "T": np.eye(4).tolist()}]}
    from grasplan.piles.scene_file import scene_from_dict
    from grasplan.schemas.documents import validate

    assert scene_from_dict({**doc, "parts": {"box": {"density": 2700}}}).part("box").material == "aluminium"
    for spec, field in (({"material": "gold"}, "parts.box.material"), ({"density": -1}, "parts.box.density"),
                        ({"material": "steel", "density": 1200}, "parts.box: material steel"),
                        ({"sha256": "ABC"}, "parts.box.sha256")):
        with pytest.raises(InputError) as e:
            scene_from_dict({**doc, "parts": {"box": spec}})
        assert field in str(e.value), (spec, str(e.value))
    good = {**doc, "parts": {"box": {"material": "pom", "density": 1410.0, "sha256": sha}}}
    validate(good)  # the schema knows the fields
    with pytest.raises(Exception):
        validate({**doc, "parts": {"box": {"material": "gold"}}})


def test_a_part_material_drives_the_drop_and_is_written(tmp_path):
    """A pile item's own material sets its body's mass; the scene, the drop's part records and the
    scene file record each part's material, density and sha256."""
    from grasplan.cell.model import load_cell
    from grasplan.piles.scene_file import load_scene
    from grasplan.piles.scene_write import write_scene
    from grasplan.sim.drop import PileItem, drop_pile

    DropParams = _drop_params()
    box = load_part(BOX)
    res = drop_pile(load_cell("bin"), [PileItem("light", box, 1, material="plastic"), PileItem("heavy", box, 1)],
                    params=DropParams(seed=0, decomposition="hull"))
    rec = res.parts
    assert (rec["light"]["material"], rec["light"]["density"]) == ("plastic", 1200.0)
    assert (rec["heavy"]["material"], rec["heavy"]["density"]) == ("steel", DEFAULT_DENSITY)
    assert np.isclose(rec["light"]["mass_kg"], 1200.0 * rec["light"]["volume_m3"], rtol=1e-9)
    assert np.isclose(rec["heavy"]["mass_kg"] / rec["light"]["mass_kg"], DEFAULT_DENSITY / 1200.0, rtol=1e-9)
    world = res.world
    assert world is not None
    masses = {b.name: b.mass.mass for b in world.bodies}
    assert np.isclose(masses["heavy_0"] / masses["light_0"], DEFAULT_DENSITY / 1200.0, rtol=1e-9)
    back = load_scene(write_scene(tmp_path / "pile.json", res.scene) and tmp_path / "pile.json")
    assert {p.name: (p.material, p.density, p.sha256) for p in back.parts} == {
        "light": ("plastic", 1200.0, box.sha256), "heavy": ("steel", DEFAULT_DENSITY, box.sha256)}
    from grasplan.sim.drop import parts_record

    assert parts_record([PileItem("b", box, 1)], DropParams(material="wood"))["b"]["density"] == 600.0


def test_picks_record_and_use_a_scene_parts_material(tmp_path, monkeypatch):
    """``grasplan pick`` of a scene whose part says plastic: that part's grasp database is computed
    at 1200 kg/m^3 (not the default steel) and the picks file records material and density."""
    import yaml

    from grasplan.grasps.graspdb import load_database

    monkeypatch.setenv("GRASPLAN_CACHE_DIR", str(tmp_path / "cache"))
    doc = {"schema": "grasplan.scene/1", "cell": "table",
           "parts": {"box": {"mesh": str(BOX), "material": "plastic", "sha256": load_part(BOX).sha256}},
           "instances": [{"id": "a", "part": "box", "T": {"xyz": [0.45, 0.0, 0.05], "rpy_deg": [0, 0, 0]}}]}
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(doc))
    out = tmp_path / "p.json"
    r = CliRunner().invoke(main, ["pick", str(tmp_path / "s.yaml"), "-o", str(out), "--max-picks", "1"])
    assert r.exit_code in (0, 4), r.output
    picks = json.loads(out.read_text())
    assert (picks["parts"]["box"]["material"], picks["parts"]["box"]["density"]) == ("plastic", 1200.0)
    from grasplan.schemas.documents import validate

    validate(picks)
    (db,) = [load_database(p) for p in (tmp_path / "cache").rglob("*.graspdb.npz")]
    assert db.mass_props is not None and np.isclose(db.mass_props.density, 1200.0)


def test_pick_refuses_a_mesh_that_changed_since_the_scene(tmp_path):
    import yaml

    doc = {"schema": "grasplan.scene/1", "cell": "table", "parts": {"box": {"mesh": str(BOX), "sha256": "0" * 64}},
           "instances": [{"id": "a", "part": "box", "T": {"xyz": [0.45, 0.0, 0.05], "rpy_deg": [0, 0, 0]}}]}
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(doc))
    out = tmp_path / "p.json"
    r = CliRunner().invoke(main, ["pick", str(tmp_path / "s.yaml"), "-o", str(out)])
    assert r.exit_code == 3 and "parts.box.sha256" in r.output and "changed since the scene was written" in r.output
    assert "Traceback" not in r.output and not out.exists()


def test_scene_drop_takes_a_material_per_part(tmp_path):
    """``--part PATH:COUNT:MATERIAL``: that part's material, the others --material's; all written."""
    import yaml

    out = tmp_path / "pile.yaml"
    r = CliRunner().invoke(main, ["scene", "drop", "--part", f"{BOX}:1:pom", "--part", f"{EXAMPLES / 'bracket.stl'}:1",
                                  "--material", "aluminium", "--decomposition", "hull", "-o", str(out)])
    assert r.exit_code == 0, r.output
    text = out.read_text()
    parts = yaml.safe_load(text)["parts"]
    assert (parts["box"]["material"], parts["box"]["density"]) == ("pom", 1410.0)
    assert (parts["bracket"]["material"], parts["bracket"]["density"]) == ("aluminium", 2700.0)
    assert parts["box"]["sha256"] == load_part(BOX).sha256 and "aluminium 2700 kg/m^3" in text.splitlines()[0]
    bad = CliRunner().invoke(main, ["scene", "drop", "--part", f"{BOX}:1:gold", "-o", str(tmp_path / "b.yaml")])
    assert bad.exit_code == 3 and "gold" in bad.output and "plastic" in bad.output and "Traceback" not in bad.output
