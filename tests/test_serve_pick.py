"""grasplan serve, POST /pick (issue 23): picks from a warm Picker over real HTTP on 127.0.0.1,
the same picks as the library, export of a pick, refusals naming the field, and the load test:
10-instance scenes with max_picks 1 from 4 concurrent clients, 0 errors, p50/p95 printed
(the issue's 500 requests; GRASPLAN_SERVE_LOAD=N sends N; timing targets are
benchmarks/bench_serve.py's)."""
from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fastapi")
pytest.importorskip("uvicorn")
pytest.importorskip("grasplan.pick")

from grasplan.serve import ServeConfig, create_app  # noqa: E402
from grasplan.serve.loopback import Client, LoopbackServer  # noqa: E402
from grasplan.serve.state import Service  # noqa: E402
from serve_support import (  # noqa: E402
    TOKEN,
    GridScenes,
    malformed_requests,
    parts_folder,
    percentile_ms,
    picking_service,
    run_load,
)

ROOT = Path(__file__).resolve().parents[1]
LOAD_REQUESTS = int(os.environ.get("GRASPLAN_SERVE_LOAD", "500"))
LOAD_CLIENTS = 4


@pytest.fixture(scope="module")
def service(tmp_path_factory) -> Iterator[Service]:
    yield from picking_service(tmp_path_factory, "serve_pick")


@pytest.fixture(scope="module")
def server(service):
    cfg = ServeConfig(parts_dir=service.config.parts_dir, token=TOKEN)
    with LoopbackServer(create_app(cfg, service=service)) as srv:
        yield srv


@pytest.fixture(scope="module")
def client(server) -> Client:
    c = Client(server.port, token=TOKEN)
    yield c
    c.close()


@pytest.fixture(scope="module")
def scenes(service) -> GridScenes:
    return GridScenes("box", service.parts["box"].part.mesh, service.cell, n=10)


def test_the_service_holds_a_warm_picker(client, service):
    status, h = client.json("GET", "/health")
    assert status == 200 and h["pick"] is True
    assert sorted(service.picker.parts()) == ["box", "bracket"]


def test_pick_matches_the_library(client, service, scenes):
    """The served picks are the library's: the same instance, grasp and joint path for the seed."""
    from grasplan.pick import Picker, PickParams
    from grasplan.piles.scene_file import scene_from_dict

    scene = scenes.scene(seed=1)
    status, doc = client.json("POST", "/pick", {**scene, "options": {"max_picks": 1, "seed": 5}})
    assert status == 200, doc
    assert doc["schema"] == "grasplan.picks/1" and len(doc["picks"]) == 1
    assert [r["id"] for r in doc["instances"]] == [i["id"] for i in scene["instances"]]
    assert {p["path"] for p in doc["parts"].values()} == {"box.stl"}
    assert str(service.config.parts_dir) not in json.dumps(doc)  # no path of the service's parts folder
    ref_picker = Picker(service.robot, gripper=service.gripper, cell=service.cell,
                        params=PickParams(budget_s=service.picker.params.budget_s))
    ref_picker.add_part("box", service.parts["box"].part)
    ref = ref_picker.plan(scene_from_dict({**scene, "cell": "bin"}), max_picks=1, seed=5)
    assert doc["picks"][0]["instance"] == ref.picks[0].instance
    assert np.allclose(doc["picks"][0]["T_part_tcp"], ref.picks[0].T_part_tcp)
    assert np.allclose(doc["picks"][0]["path"], ref.picks[0].motion.path)


def test_picks_text_is_the_documents_json(service, scenes):
    """The served serialisation (robot, gripper and cell serialised once per object) is byte for
    byte the JSON of the grasplan.picks/1 document, with the parts' paths reduced to file names."""
    from grasplan.io import to_json_text
    from grasplan.piles.scene_file import scene_from_dict
    from grasplan.serve.handlers import public_parts

    res = service.picker.plan(scene_from_dict({**scenes.scene(seed=11), "cell": "bin"}), max_picks=2, seed=1)
    assert res.picks and res.robot is not None and res.gripper is not None and res.cell is not None
    for _ in range(2):  # the first call serialises the robot, gripper and cell, the second reuses them
        assert res.to_json_text() == to_json_text(res.to_json())
    parts = public_parts(res.parts, service)
    assert parts["box"]["path"] == "box.stl" and res.parts["box"]["path"] != "box.stl"
    assert res.to_json_text(parts=parts) == to_json_text({**res.to_json(), "parts": parts})


def test_pick_defaults_to_every_instance_that_has_one(client, scenes):
    scene = scenes.scene(seed=2)
    status, doc = client.json("POST", "/pick", {**scene, "instances": scene["instances"][:3]})
    assert status == 200
    picked = [r["id"] for r in doc["instances"] if r["status"] == "picked"]
    assert sorted(p["instance"] for p in doc["picks"]) == sorted(picked) and len(picked) >= 1
    assert all(r["status"] != "not_tried" for r in doc["instances"])


def test_export_a_pick(client, scenes, service):
    """A served picks document exports like the library exports it (the meshes read from the
    service's folder, never from the document's paths)."""
    from grasplan.results.export_registry import render_export
    from grasplan.pick.reader import pick_as_plan, result_from_picks

    status, doc = client.json("POST", "/pick", {**scenes.scene(seed=3), "options": {"max_picks": 1}})
    assert status == 200 and doc["picks"]
    iid = doc["picks"][0]["instance"]
    status, out = client.json("POST", "/export", {"document": doc, "format": "urscript", "instance": iid})
    assert status == 200, out
    folder = service.config.parts_dir
    local = {**doc, "parts": {k: {**v, "path": str(folder / v["path"])} for k, v in doc["parts"].items()}}
    ref = render_export(pick_as_plan(result_from_picks(local), iid), "urscript")[".script"]
    assert out["text"] == ref
    status, bad = client.json("POST", "/export", {"document": doc, "format": "urscript", "instance": "nosuch"})
    assert status == 422 and "nosuch" in bad["detail"] and iid in bad["detail"]
    moved = {**doc, "parts": {k: {**v, "path": "/etc/passwd"} for k, v in doc["parts"].items()}}
    status, again = client.json("POST", "/export", {"document": moved, "format": "urscript", "instance": iid})
    assert status == 200 and again["text"] == ref  # the recorded path is not what is read
    foreign = {**doc, "parts": {k: {**v, "sha256": "0" * 64} for k, v in doc["parts"].items()}}
    status, bad = client.json("POST", "/export", {"document": foreign, "format": "urscript"})
    assert status == 422 and "sha256" in bad["detail"]


def test_pick_with_push_carries_the_push_entry(client, scenes):
    """``options.push``: the document carries ``push`` (null: something was picked, no push needed)
    and ``push_tried``; without it, neither key."""
    status, doc = client.json("POST", "/pick", {**scenes.scene(seed=3), "options": {"max_picks": 1, "push": True}})
    assert status == 200 and doc["picks"] and doc["push"] is None and doc["push_tried"] == []
    status, plain = client.json("POST", "/pick", {**scenes.scene(seed=3), "options": {"max_picks": 1}})
    assert status == 200 and "push" not in plain and "push_tried" not in plain


@pytest.mark.parametrize("change, field", [
    ({"parts": {"box": {"mesh": "/etc/passwd"}}}, "parts.box.mesh"),
    ({"parts": {"box": {"grasps": "x.graspdb.npz"}}}, "parts.box.grasps"),
    ({"cloud": {"path": "scan.ply"}}, "cloud"), ({"cell": "table"}, "cell"),
    ({"options": {"max_picks": 0}}, "options.max_picks"), ({"options": {"seed": "x"}}, "options.seed"),
    ({"options": {"sequence": 1}}, "options.sequence"), ({"options": {"top": 1}}, "options: unknown keys"),
    ({"options": {"push": "yes"}}, "options.push"),
    ({"instances": [{"id": "a", "part": "nosuch", "T": np.eye(4).tolist()}]}, "unknown part 'nosuch'"),
    ({"instances": [{"id": "a", "part": "box", "T": [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}]},
     "instances[0].T"),
])
def test_pick_refusals_name_the_field(client, scenes, change, field):
    status, doc = client.json("POST", "/pick", {**scenes.scene(), **change})
    assert status == 422 and field in doc["detail"], doc


def test_load_and_malformed_requests(server, client, scenes, record_property):
    """The issue's load test (bounded: GRASPLAN_SERVE_LOAD requests): 10-instance scenes (each
    request its own seeded poses), max_picks 1, 4 concurrent clients: 0 errors, one pick each;
    then malformed /pick requests each get a 4xx and the service still answers."""
    bodies = [json.dumps({**scenes.scene(seed=100 + k), "options": {"max_picks": 1}}).encode()
              for k in range(min(LOAD_REQUESTS, 50))]
    lat, errors, responses = run_load(server.port, bodies, LOAD_REQUESTS, LOAD_CLIENTS)
    assert errors == []
    assert len(lat) == LOAD_REQUESTS
    assert all(len(json.loads(r)["picks"]) == 1 for r in responses)
    record_property("summary", f"grasplan serve /pick load: {LOAD_REQUESTS} requests, {LOAD_CLIENTS} clients, "
                               f"10 instances, max_picks 1: p50 {percentile_ms(lat, 50):.0f} ms, "
                               f"p95 {percentile_ms(lat, 95):.0f} ms, 0 errors")
    cases = malformed_requests(scenes.scene(), None)
    assert len(cases) >= 100 and sum(c[1] == "/pick" for c in cases) >= 40
    bad = [(label, s) for label, path, body, headers in cases
           if not 400 <= (s := client.request("GET" if path == "/parts" else "POST", path, body,
                                              headers=headers)[0]) < 500]
    assert bad == []
    status, h = client.json("GET", "/health")
    assert status == 200 and h["queued"] == 0


def test_the_documented_node_client_works(server, scenes, tmp_path):
    """docs/serve.md's 20-line Node.js client, run as written against the loopback service."""
    import re
    import shutil
    import subprocess

    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed")
    doc = (ROOT / "docs" / "serve.md").read_text()
    code = re.search(r"```js\n(.*?)```", doc, re.S).group(1)
    assert len(code.strip().splitlines()) <= 22
    (tmp_path / "pick.mjs").write_text(code)
    (tmp_path / "scene.json").write_text(json.dumps(scenes.scene(seed=7)))
    env = {"PATH": os.environ.get("PATH", ""), "GRASPLAN_URL": f"http://127.0.0.1:{server.port}",
           "GRASPLAN_TOKEN": TOKEN}
    r = subprocess.run([node, "pick.mjs", "scene.json"], cwd=tmp_path, env=env, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert sum(": picked" in line for line in lines) == 1
    assert any(line.startswith("pick box_") and "q_grasp" in line for line in lines)
    assert "movej(" in r.stdout and "movel(" in r.stdout  # the URScript program
    env["GRASPLAN_TOKEN"] = "wrong-token-0000"
    r = subprocess.run([node, "pick.mjs", "scene.json"], cwd=tmp_path, env=env, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode != 0 and "HTTP 401" in r.stderr


def test_a_database_next_to_the_mesh_is_used_and_checked(service, tmp_path):
    """``NAME.graspdb.npz`` next to a mesh is the part's database; one of another part stops the start."""
    from grasplan.errors import InputError
    from grasplan.grasps.graspdb import database_for, write_database

    folder = parts_folder(tmp_path / "parts", ("box", "bracket"))
    write_database(database_for(service.parts["box"].part, service.gripper), folder / "box.graspdb.npz")
    lines: list[str] = []
    Service.start(ServeConfig(parts_dir=folder), lines.append)
    assert any("part box: grasp database ready (from box.graspdb.npz" in line for line in lines), lines
    assert any("part bracket: grasp database ready (from the cache" in line for line in lines), lines
    write_database(database_for(service.parts["bracket"].part, service.gripper), folder / "box.graspdb.npz")
    with pytest.raises(InputError, match="box.graspdb.npz"):
        Service.start(ServeConfig(parts_dir=folder))
