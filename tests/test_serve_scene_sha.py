"""grasplan serve, POST /pick with a scene's part records (loopback only): a part with a ``sha256``
is matched to the service's part of that mesh whatever the scene calls it; a sha256 of no served
part, or one that differs from the mesh of the served part of that name, is a 422 naming the field;
a part's material lighter than the service's databases is ranked with them (a warning says so), a
heavier one is a 422."""
from __future__ import annotations

from collections.abc import Iterator

import pytest

pytest.importorskip("fastapi")
pytest.importorskip("uvicorn")
pytest.importorskip("grasplan.pick")

from grasplan.serve import ServeConfig, create_app  # noqa: E402
from grasplan.serve.loopback import Client, LoopbackServer  # noqa: E402
from grasplan.serve.state import Service  # noqa: E402
from serve_support import TOKEN, GridScenes, picking_service  # noqa: E402


@pytest.fixture(scope="module")
def service(tmp_path_factory) -> Iterator[Service]:
    yield from picking_service(tmp_path_factory, "serve_sha")


@pytest.fixture(scope="module")
def client(service):
    cfg = ServeConfig(parts_dir=service.config.parts_dir, token=TOKEN)
    with LoopbackServer(create_app(cfg, service=service)) as srv:
        c = Client(srv.port, token=TOKEN)
        yield c
        c.close()


@pytest.fixture(scope="module")
def scene(service) -> dict:
    return GridScenes("box", service.parts["box"].part.mesh, service.cell, n=2).scene(0)


def _named(scene: dict, name: str, spec: dict) -> dict:
    """``scene`` with its part called ``name`` and given ``spec``."""
    return {**scene, "parts": {name: spec}, "instances": [{**i, "part": name} for i in scene["instances"]],
            "options": {"max_picks": 1, "seed": 0}}


def test_a_part_is_matched_by_its_meshs_sha256(client, service, scene):
    sha = service.parts["box"].part.sha256
    status, out = client.json("POST", "/pick", _named(scene, "crate", {"sha256": sha, "mesh": "x/crate.stl"}))
    assert status == 200, out
    assert {i["part"] for i in out["scene"]["instances"]} == {"box"} and set(out["parts"]) == {"box"}
    assert out["parts"]["box"]["sha256"] == sha and out["parts"]["box"]["material"] == "steel"


def test_a_sha256_of_no_served_part_lists_the_parts(client, service, scene):
    status, bad = client.json("POST", "/pick", _named(scene, "crate", {"sha256": "0" * 64}))
    assert status == 422 and "parts.crate.sha256" in bad["detail"], bad
    for name, e in service.parts.items():
        assert f"{name} ({e.part.sha256[:12]})" in bad["detail"]


def test_a_name_with_another_mesh_is_refused(client, service, scene):
    other = service.parts["bracket"].part.sha256
    status, bad = client.json("POST", "/pick", _named(scene, "box", {"sha256": other}))
    assert status == 422 and "parts.box.sha256" in bad["detail"] and "meshes differ" in bad["detail"], bad
    status, bad = client.json("POST", "/pick", _named(scene, "box", {"sha256": "ABC"}))
    assert status == 422 and "parts.box.sha256" in bad["detail"], bad


def test_a_lighter_material_is_ranked_as_the_services_and_a_heavier_refused(client, service, scene):
    sha = service.parts["box"].part.sha256
    status, plain = client.json("POST", "/pick", _named(scene, "box", {"sha256": sha}))
    status2, light = client.json("POST", "/pick", _named(scene, "box", {"sha256": sha, "material": "plastic"}))
    assert status == status2 == 200, light
    assert any("plastic" in w and "steel" in w for w in light["warnings"]), light["warnings"]
    assert not any("plastic" in w for w in plain["warnings"])
    assert [p["T_part_tcp"] for p in light["picks"]] == [p["T_part_tcp"] for p in plain["picks"]]
    status, bad = client.json("POST", "/pick", _named(scene, "box", {"material": "brass"}))
    assert status == 422 and "parts.box.material" in bad["detail"] and "steel" in bad["detail"], bad
    status, bad = client.json("POST", "/pick", _named(scene, "box", {"material": "plastic", "density": 2700}))
    assert status == 422 and "disagree" in bad["detail"], bad
