"""grasplan serve (issue 23 item 1): request reading, then the service over real HTTP on 127.0.0.1
(uvicorn in a thread): every endpoint, the token, 413, 400/422 naming the field, 500 and 503/504
keep the service serving, more than 100 malformed requests each a 4xx. /pick: test_serve_pick.py."""
from __future__ import annotations

import json
import logging
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fastapi")
pytest.importorskip("uvicorn")

from grasplan.errors import InputError  # noqa: E402
from grasplan.serve import ServeConfig, create_app  # noqa: E402
from grasplan.serve.loopback import Client, LoopbackServer  # noqa: E402
from grasplan.serve.bodies import BadRequest, parse_json, read_options  # noqa: E402
from grasplan.serve.state import Service, scan_parts  # noqa: E402
from serve_support import FAST_PLAN, TOKEN, malformed_requests, parts_folder, raw_request  # noqa: E402


# ----------------------------------------------------------------------------------- no server
@pytest.mark.parametrize("body, why", [
    (b"", "empty"), (b"  \n", "empty"), (b"\xff\xfe", "UTF-8"), (b"{", "not valid JSON"), (b"{'a': 1}", "not valid JSON"),
    (b'{"a": NaN}', "NaN"), (b'{"a": -Infinity}', "Infinity"), (b'{"a": 1e400}', "1e400"),
    (b'{"a": ' + b"1" * 40 + b"}", "digits"), (b"[" * 100 + b"]" * 100, "nested"),
])
def test_parse_json_refuses_what_is_not_json(body, why):
    with pytest.raises(BadRequest, match=why):
        parse_json(body)


def test_parse_json_reads_documents():
    assert parse_json(b'{"a": [1, 2.5, "x", null, true]}') == {"a": [1, 2.5, "x", None, True]}


def test_read_options_reads_like_the_cli():
    p = read_options({"top": 3, "thin": "2mm", "roll_step_deg": 30, "place": "0.3,0.2,0.05,0,0,90"})
    assert p["planning"].top == 3 and p["grasps"].thin_spacing == pytest.approx(0.002)
    assert p["grasps"].roll_step_deg == 30
    assert np.allclose(np.asarray(p["planning"].place)[:3, 3], [0.3, 0.2, 0.05])
    assert p["candidates"] == read_options({})["candidates"]
    capped = read_options({"budget": 500}, budget_cap_s=10.0)["planning"]
    assert capped.budget_s == 10.0
    assert read_options({"budget": 5}, budget_cap_s=10.0)["planning"].budget_s == 5


@pytest.mark.parametrize("options, field", [
    ({"top": 0}, "options.top"), ({"top": "x"}, "options.top"), ({"thin": "5parsecs"}, "options.thin"),
    ({"mu": float("nan")}, "options.mu"), ({"alpha": 1.0}, "options.alpha"), ({"nope": 1}, "options.nope"),
    ({"scoring": "w.yaml"}, "options.scoring"), ({"pose_index": "all"}, "options.pose_index"),
    ({"top": 2, "planning": 1}, "options.planning"), ({"thin": 0.001, "thin_spacing": 0.002}, "given twice"),
    ([1], "options"),
])
def test_read_options_names_the_field(options, field):
    with pytest.raises(InputError, match=field.replace(".", r"\.")):
        read_options(options)


def test_scan_parts_names_and_refusals(tmp_path):
    d = parts_folder(tmp_path / "p", ("box", "gear"))
    (d / "notes.txt").write_text("x")
    (d / "my part.stl").write_bytes((d / "box.stl").read_bytes())
    warnings: list[str] = []
    found = scan_parts(d, warnings.append)
    assert list(found) == ["box", "gear", "my_part"] and found["my_part"] == d / "my part.stl"
    assert any("my part.stl: part name 'my_part'" in w for w in warnings)
    (d / "box.obj").write_text("v 0 0 0\n")
    with pytest.raises(InputError, match="box.obj and box.stl|box.stl and box.obj"):
        scan_parts(d, warnings.append)
    with pytest.raises(InputError, match="no part meshes"):
        scan_parts(parts_folder(tmp_path / "empty", ()), warnings.append)


@pytest.mark.parametrize("kw, field", [
    ({"token": "short"}, "--token"), ({"token": "has space in it"}, "--token"), ({"time_limit_s": 0}, "--time-limit"),
    ({"time_limit_s": float("inf")}, "--time-limit"), ({"workers": 0}, "--workers"), ({"max_queue": 0}, "--max-queue"),
    ({"port": 70000}, "--port"), ({"units": "parsec"}, "--units"), ({"max_body": 10}, "--max-body"),
])
def test_config_refuses(tmp_path, kw, field):
    with pytest.raises(InputError, match=field):
        ServeConfig(parts_dir=tmp_path, **kw)


def test_parse_size():
    from grasplan.serve.config import parse_size

    assert parse_size("10MB") == 10 << 20 and parse_size("512k") == 512 << 10 and parse_size(4096) == 4096
    for bad in ("lots", "10 parsecs", "1", "9" * 400, "3GB", True, -5):
        with pytest.raises(InputError, match="--max-body"):
            parse_size(bad)


def test_bind_warning(tmp_path):
    for host in ("127.0.0.1", "127.1.2.3", "::1", "localhost"):
        assert ServeConfig(parts_dir=tmp_path, host=host).bind_warning() is None
    warning = ServeConfig(parts_dir=tmp_path, host="0.0.0.0").bind_warning()
    assert warning is not None and "--token" in warning
    assert ServeConfig(parts_dir=tmp_path, host="0.0.0.0", token=TOKEN).bind_warning() is None


def test_config_travels_as_json(tmp_path):
    """``--workers N``: each planner process gets the settings as JSON."""
    from grasplan.serve.config import config_from_json, config_to_json

    cfg = ServeConfig(parts_dir=parts_folder(tmp_path, ("box",)), token=TOKEN, time_limit_s=12.5, databases=False,
                      config_dirs=(str(tmp_path),), workers=2)
    assert config_from_json(json.loads(json.dumps(config_to_json(cfg)))) == cfg


def test_planner_processes(tmp_path):
    """``--workers 2``: two planner processes behind the HTTP process, a request to a free one; a
    planner that died while idle is replaced before a request reaches it; one killed mid-request
    costs that request a one-line 500; a stuck one is answered 504 at the time limit and replaced;
    beyond the queue 503 at once; /health answers throughout and the service plans again after."""
    import os
    import signal

    cfg = ServeConfig(parts_dir=parts_folder(tmp_path / "parts", ("box",)), token=TOKEN, databases=False, workers=2,
                      time_limit_s=8.0, max_queue=1)
    app = create_app(cfg)
    pool = app.state.pool
    with LoopbackServer(app) as srv:
        def ask(body: dict | None = None) -> tuple[int, dict]:
            return Client(srv.port, token=TOKEN).json("POST", "/plan", body or {"part": "box", "options": FAST_PLAN})

        def asked_together(n: int, body: dict | None = None) -> list[tuple[int, dict]]:
            out: dict[int, tuple[int, dict]] = {}
            threads = [threading.Thread(target=lambda k=k: out.__setitem__(k, ask(body))) for k in range(n)]
            for t in threads:
                t.start()
                time.sleep(0.05)
            for t in threads:
                t.join()
            return [out[k] for k in range(n)]

        def until_replaced(gone: list[int], timeout_s: float = 120.0) -> None:
            """Until two planners, none of ``gone``, plan again."""
            t_end = time.monotonic() + timeout_s
            while time.monotonic() < t_end:
                # answered by the planners (a refusal: quick); a dead idle planner is found by a request
                ok = [s for s, _ in asked_together(2, {"part": "nosuch"})] == [422, 422]
                pids = pool.pids()
                if ok and len(pids) == 2 and not set(gone) & set(pids):
                    return
                time.sleep(0.5)
            raise AssertionError(f"the planners {gone} were not replaced: {pool.pids()}")

        status, h = Client(srv.port).json("GET", "/health")
        assert status == 200 and h["planners"] == 2 and h["pick"] is False
        for pid in pool.pids():  # single-threaded BLAS in each planner (the planners are the parallelism)
            env = dict(kv.split("=", 1) for kv in open(f"/proc/{pid}/environ").read().split("\0") if "=" in kv)
            for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
                assert env.get(name) == os.environ.get(name, "1"), (name, env.get(name))
        assert [s for s, _ in asked_together(2)] == [200, 200]
        status, doc = ask({"part": "nosuch"})  # refusals come back from the planner as 422
        assert status == 422 and "unknown part" in doc["detail"]
        first = pool.pids()
        os.kill(first[0], signal.SIGKILL)  # dies while idle: replaced, the request goes to a live one
        time.sleep(0.3)
        assert ask({"part": "nosuch"})[0] == 422 and ask({"part": "nosuch"})[0] == 422
        until_replaced(first[:1])
        for pid in pool.pids():  # both stuck
            os.kill(pid, signal.SIGSTOP)
        stuck = pool.pids()
        got = asked_together(4, {"part": "nosuch"})
        assert Client(srv.port).json("GET", "/health")[0] == 200
        kinds = sorted((s, d["error"]) for s, d in got)
        assert kinds == [(503, "busy"), (503, "busy"), (504, "time_limit"), (504, "time_limit")], kinds
        assert any("queued" in d["detail"] for _, d in got) and any("waited" in d["detail"] for _, d in got)
        until_replaced(stuck)
        busy: dict[str, tuple[int, dict]] = {}

        def cpu_s(pid: int) -> float:  # user + system CPU seconds of a planner
            fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
            return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

        before = {pid: cpu_s(pid) for pid in pool.pids()}
        # a plan of ~1.5 s in a planner (fine spacing, 1 deg rolls), killed once a planner works on it
        slow = threading.Thread(target=lambda: busy.__setitem__(
            "r", ask({"part": "box", "options": {"spacing": "0.2mm", "roll_step": 1}})))
        slow.start()
        t_end = time.monotonic() + 30.0
        while time.monotonic() < t_end and not any(cpu_s(pid) > c + 0.1 for pid, c in before.items()):
            time.sleep(0.02)
        killed = pool.pids()
        for pid in killed:  # killed while planning (a crash, the OOM killer)
            os.kill(pid, signal.SIGKILL)
        slow.join()
        status, doc = busy["r"]
        assert status == 500 and doc["error"] == "internal" and "\n" not in doc["detail"], doc
        until_replaced(killed)
        assert ask()[0] == 200  # the fresh planners plan
        status, h = Client(srv.port).json("GET", "/health")
        assert status == 200 and h["queued"] == 0
    assert all(p.proc.poll() is not None for p in pool._planners)  # stopped with the service


def test_config_needs_a_parts_folder(tmp_path):
    for bad in (tmp_path / "missing", "9" * 5000, tmp_path / "box.stl"):
        with pytest.raises(InputError, match="--parts"):
            ServeConfig(parts_dir=bad)


# --------------------------------------------------------------------------------- the server
@pytest.fixture(scope="module")
def service(tmp_path_factory) -> Service:
    folder = parts_folder(tmp_path_factory.mktemp("serve_parts"))
    return Service.start(ServeConfig(parts_dir=folder, databases=False))


@pytest.fixture(scope="module")
def server(service):
    cfg = ServeConfig(parts_dir=service.config.parts_dir, token=TOKEN, max_body=1 << 20, databases=False)
    with LoopbackServer(create_app(cfg, service=service)) as srv:
        yield srv


@pytest.fixture(scope="module")
def client(server) -> Client:
    c = Client(server.port, token=TOKEN)
    yield c
    c.close()


@pytest.fixture(scope="module")
def box_plan(client) -> dict:
    status, doc = client.json("POST", "/plan", {"part": "box", "options": FAST_PLAN})
    assert status == 200, doc
    return doc


def test_health_and_the_lists(client, server, service):
    anon = Client(server.port)
    status, h = anon.json("GET", "/health")
    assert status == 200 and h["status"] == "ok"
    assert (h["robot"], h["gripper"], h["cell"], h["parts"]) == ("ur5", "schunk_egp_c_40", "bin", 3)
    status, parts = client.json("GET", "/parts")
    assert status == 200
    assert [p["name"] for p in parts["parts"]] == ["box", "bracket", "gear"]
    assert {p["sha256"] for p in parts["parts"]} == {e.part.sha256 for e in service.parts.values()}
    status, robots = client.json("GET", "/robots")
    assert status == 200 and robots["robot"]["name"] == "ur5" and "ur5" in robots["available"]
    assert robots["robot"]["joint_names"] == list(service.robot.joint_names)
    status, grippers = client.json("GET", "/grippers")
    assert status == 200 and grippers["gripper"]["max_opening"] == pytest.approx(service.gripper.max_opening)
    folder = str(service.config.parts_dir)
    for path in ("/parts", "/robots", "/grippers", "/health"):  # no server path in any answer
        assert folder not in client.request("GET", path)[1].decode()


def test_unknown_paths_and_methods_answer_json(client):
    status, doc = client.json("GET", "/nosuch")
    assert status == 404 and doc["error"] == "not_found" and "/nosuch" in doc["detail"]
    status, doc = client.json("GET", "/plan")
    assert status == 405 and doc["error"] == "method_not_allowed"


def test_docs_and_openapi_are_open(server):
    anon = Client(server.port)
    status, spec = anon.json("GET", "/openapi.json")
    assert status == 200 and {"/pick", "/plan", "/export", "/health", "/parts"} <= set(spec["paths"])
    plan_opts = spec["paths"]["/plan"]["post"]["requestBody"]["content"]["application/json"]["schema"]
    assert "top" in plan_opts["properties"]["options"]["properties"]
    status, html = anon.request("GET", "/docs")
    assert status == 200 and b"swagger" in html.lower()


@pytest.mark.parametrize("header", [None, "", "Bearer", "Bearer wrong-token-000000", f"Basic {TOKEN}",
                                    f"Bearer {TOKEN}x", f"Bearer {TOKEN[:-1]}"])
def test_token_is_required(server, header):
    c = Client(server.port)
    status, body = c.json("GET", "/parts", headers={} if header is None else {"Authorization": header})
    assert status == 401 and "Bearer" in body["detail"]
    assert c.json("GET", "/parts", headers={"Authorization": f"bearer {TOKEN}"})[0] == 200


def test_plan_matches_the_library(client, box_plan, service):
    """The service builds its options exactly as the library does: same seed, same plan."""
    import grasplan
    from grasplan.results.reader import result_from_document
    from grasplan.schemas.documents import validate

    validate(box_plan, "grasplan.plan/1")
    assert box_plan["part"]["path"] == "box.stl"
    res = result_from_document(box_plan, where="served plan")  # FK re-checked for every planned grasp
    assert len(res.planned_ids()) >= 1
    ref = grasplan.plan(service.parts["box"].part, "ur5", cell="bin", **read_options(FAST_PLAN, budget_cap_s=48.0))
    assert res.planned_ids() == ref.planned_ids()
    for i in res.planned_ids():
        assert np.allclose(res.motions[i].q_grasp, ref.motions[i].q_grasp)


def test_plan_keep_chooses_the_document_form(client):
    body = {"part": "bracket", "options": {**FAST_PLAN, "top": 1, "seed": 3}}
    status, compact = client.json("POST", "/plan", body)
    assert status == 200 and compact["keep"] == "collision_free" and "rejected" in compact
    status, full = client.json("POST", "/plan", {**body, "keep": "all"})
    assert status == 200 and full["keep"] == "all" and "rejected" not in full
    assert compact["counts"] == full["counts"]
    assert [g["id"] for g in compact["grasps"] if g["status"] == "planned"] == \
        [g["id"] for g in full["grasps"] if g["status"] == "planned"]
    status, err = client.json("POST", "/plan", {**body, "keep": "some"})
    assert status == 422 and "keep" in err["detail"] and "collision_free" in err["detail"]


def test_plan_options_reach_the_planner(client):
    status, doc = client.json("POST", "/plan", {"part": "bracket", "options": {**FAST_PLAN, "top": 1, "seed": 3}})
    assert status == 200
    assert doc["plan_params"]["top"] == 1 and doc["plan_params"]["seed"] == 3
    assert doc["params"]["roll_step_deg"] == 45 and doc["params"]["spacing"] == pytest.approx(0.004)
    assert doc["counts"]["planned"] <= 1


@pytest.mark.parametrize("body, status, field", [
    ({"part": "nosuch"}, 422, "unknown part 'nosuch'; the service's parts: box, bracket, gear"),
    ({"part": "../box"}, 422, "never a path"), ({"part": "box", "options": {"top": 0}}, 422, "options.top"),
    ({"part": "box", "options": {"thin": "1parsec"}}, 422, "options.thin"), ({}, 422, "part: missing"),
    ({"part": "box", "part_pose": "1,2"}, 422, "part_pose"), ({"part": "box", "part_pose": [1, 2, 3]}, 422, "part_pose"),
    ({"part": "box", "options": {"scoring": "/etc/passwd"}}, 422, "options.scoring"),
    ({"part": "box", "part_pose": "20,0,0,0,0,0"}, 422, "part_pose"),
])
def test_plan_refusals_name_the_field(client, body, status, field):
    got, doc = client.json("POST", "/plan", body)
    assert got == status and field in doc["detail"] and doc["error"] == "invalid"


def test_export_renders_the_program(client, box_plan):
    from grasplan.results.export_registry import render_export
    from grasplan.results.reader import result_from_document

    status, out = client.json("POST", "/export", {"document": box_plan, "format": "urscript"})
    assert status == 200 and out["extension"] == ".script"
    ref = render_export(result_from_document(box_plan), "urscript")[".script"]
    assert out["text"] == ref and out["files"] == {".script": ref}
    best = min(box_plan["grasps"], key=lambda g: g["rank"] if g.get("rank") is not None and g["rank"] >= 0 else 1e9)
    assert f"grasp {best['id']}" in out["text"]
    status, text = client.request("POST", "/export", json.dumps({"document": box_plan, "format": "urscript"}).encode(),
                                  headers={"Accept": "text/plain"})
    assert status == 200 and text.decode() == ref
    status, out = client.json("POST", "/export", {"document": box_plan, "format": "krl", "program_name": "pick_box"})
    assert status == 200 and set(out["files"]) == {".src", ".dat"} and "DEF pick_box" in out["files"][".src"]
    status, out = client.json("POST", "/export", {"document": box_plan, "format": "joint-trajectory",
                                                  "max_accel": 2.0})
    assert status == 200 and json.loads(out["text"])["schema"] == "grasplan.joint_trajectory/1"


def test_export_refuses_foreign_documents(client, box_plan):
    other_part = {**box_plan, "part": {**box_plan["part"], "sha256": "0" * 64}}
    other_robot = {**box_plan, "robot": {**box_plan["robot"], "source": {**box_plan["robot"]["source"],
                                                                        "yaml": "urdf: /etc/passwd\n"}}}
    cases = [({"document": other_part, "format": "urscript"}, "document.part.sha256"),
             ({"document": other_robot, "format": "urscript"}, "document.robot"),
             ({"document": box_plan, "format": "nosuch"}, "format: unknown export format 'nosuch'; available:"),
             ({"document": box_plan, "format": "urscript", "grasp": 10**9}, "grasp"),
             ({"document": box_plan, "format": "urscript", "grasp": -2}, "grasp"),
             ({"document": {**box_plan, "schema": "grasplan.grasps/1"}, "format": "urscript"}, "document.schema"),
             ({"document": box_plan, "format": "urscript", "out": "/tmp/x"}, "unknown keys"),
             ({"document": box_plan, "format": "urscript", "instance": "a"}, "instance")]
    for body, field in cases:
        status, doc = client.json("POST", "/export", body)
        assert status == 422 and field in doc["detail"], (body.get("format"), doc)


def test_oversized_bodies_get_413_before_they_are_read(server):
    head = (f"POST /plan HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer {TOKEN}\r\n"
            f"Content-Type: application/json\r\nContent-Length: {50 << 20}").encode()
    status, body = raw_request(server.port, head)  # 50 MB announced, none sent: answered at once
    assert status == 413 and b"--max-body" in body
    chunk = b"x" * 65536
    chunked = b"".join(b"%x\r\n" % len(chunk) + chunk + b"\r\n" for _ in range(20)) + b"0\r\n\r\n"
    head = (f"POST /plan HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer {TOKEN}\r\n"
            "Content-Type: application/json\r\nTransfer-Encoding: chunked").encode()
    status, body = raw_request(server.port, head, chunked)  # 1.25 MB without a length: counted
    assert status == 413 and b"--max-body" in body
    head = (f"POST /plan HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer {TOKEN}\r\nContent-Length: -5").encode()
    assert raw_request(server.port, head)[0] == 400


def test_gzip_bodies(client, box_plan, server):
    """A gzip body counts its compressed size against --max-body; it may inflate to 8 x the
    limit, no further; other encodings are 415."""
    import gzip

    doc = {"document": box_plan, "format": "urscript"}
    status, plain = client.json("POST", "/export", doc)
    assert status == 200
    status, data = client.request("POST", "/export", gzip.compress(json.dumps(doc).encode()),
                                  headers={"Content-Encoding": "gzip"})
    assert status == 200 and json.loads(data) == plain
    big = {"part": "box", "pad": "x" * (9 << 20)}  # inflates past 8 x the 1 MB limit
    packed = gzip.compress(json.dumps(big).encode())
    assert len(packed) < (1 << 20)
    status, data = client.request("POST", "/plan", packed, headers={"Content-Encoding": "gzip"})
    assert status == 413 and b"inflates" in data
    status, data = client.request("POST", "/plan", b"not gzip", headers={"Content-Encoding": "gzip"})
    assert status == 400 and b"gzip" in data
    status, data = client.request("POST", "/plan", gzip.compress(b'{"part": "box"}')[:-8],
                                  headers={"Content-Encoding": "gzip"})
    assert status == 400 and b"truncated" in data
    status, data = client.request("POST", "/plan", b'{"part": "box"}', headers={"Content-Encoding": "br"})
    assert status == 415


def test_internal_error_is_one_line_and_the_service_keeps_serving(client, monkeypatch, caplog):
    import grasplan.motion.planning

    def broken(*a, **k):
        raise RuntimeError("simulated bug")
    monkeypatch.setattr(grasplan.motion.planning, "plan", broken)
    with caplog.at_level(logging.ERROR, logger="grasplan.serve"):
        status, doc = client.json("POST", "/plan", {"part": "box", "options": FAST_PLAN})
    assert status == 500 and doc["error"] == "internal" and "RuntimeError" in doc["detail"]
    assert "\n" not in doc["detail"] and "simulated bug" not in doc["detail"]  # no internals to the client
    assert any("internal error" in r.getMessage() and r.exc_info for r in caplog.records)
    monkeypatch.undo()
    assert client.json("GET", "/health")[0] == 200
    status, doc = client.json("POST", "/plan", {"part": "gear", "options": FAST_PLAN})
    assert status == 200 and doc["schema"] == "grasplan.plan/1"


def test_one_request_at_a_time_with_a_time_limit(service, monkeypatch):
    """A slow plan is answered 504; the one queued behind it 503 (it could not start in time); a
    third, past the queue's bound, 503 at once; the service answers /health throughout and plans
    again afterwards."""
    import grasplan.motion.planning

    running = {"now": 0, "most": 0}
    lock = threading.Lock()

    def slow(*a, **k):
        with lock:
            running["now"] += 1
            running["most"] = max(running["most"], running["now"])
        time.sleep(2.0)
        with lock:
            running["now"] -= 1
        raise RuntimeError("not reached by a client")
    monkeypatch.setattr(grasplan.motion.planning, "plan", slow)
    cfg = ServeConfig(parts_dir=service.config.parts_dir, time_limit_s=0.8, max_queue=1, databases=False)
    with LoopbackServer(create_app(cfg, service=service)) as srv:
        results: dict[int, tuple[int, dict]] = {}

        def ask(k: int) -> None:
            results[k] = Client(srv.port).json("POST", "/plan", {"part": "box"})
        threads = [threading.Thread(target=ask, args=(k,)) for k in range(3)]
        for k, t in enumerate(threads):
            t.start()
            time.sleep(0.3)  # arrivals 0.3 s apart
        status, h = Client(srv.port).json("GET", "/health")
        assert status == 200 and h["queued"] >= 1
        for t in threads:
            t.join()
        got = sorted((status, doc["error"]) for status, doc in results.values())
        assert got == [(503, "busy"), (503, "busy"), (504, "time_limit")], got
        assert any("queued" in doc["detail"] for _, doc in results.values())  # refused at once: queue full
        assert any("waited" in doc["detail"] for _, doc in results.values())  # could not start in time
        assert running["most"] == 1
        time.sleep(2.1)  # the abandoned plan finishes in the background
        monkeypatch.undo()
        status, doc = Client(srv.port).json("POST", "/plan", {"part": "box", "options": FAST_PLAN})
        assert status == 200


def test_malformed_requests_each_get_a_4xx(server, client, box_plan, service):
    """More than 100 malformed requests (bad JSON, wrong types, huge numbers, NaN, unknown parts,
    path traversal, missing token, oversized): each a 4xx; the service answers /health after."""
    from serve_support import grid_scene

    scene = grid_scene("box", service.parts["box"].part.mesh, service.cell, n=3) if service.picker else None
    cases = [c for c in malformed_requests(scene, box_plan) if service.picker is not None or c[1] != "/pick"]
    assert len(cases) >= 100
    bad = []
    for label, path, body, headers in cases:
        status, _ = client.request("GET" if path == "/parts" else "POST", path, body, headers=headers)
        if not 400 <= status < 500:
            bad.append((label, status))
    head = (f"POST /pick HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer {TOKEN}\r\n"
            f"Content-Length: {(1 << 20) + 1}").encode()
    status, _ = raw_request(server.port, head, b"{" * 1000)
    if status != 413:
        bad.append(("oversized", status))
    assert bad == []
    status, h = client.json("GET", "/health")
    assert status == 200 and h["queued"] == 0


def test_pick_without_a_picker_is_503(client, service):
    if service.picker is not None:
        pytest.skip("this service has a picker")
    status, doc = client.json("POST", "/pick", {"schema": "grasplan.scene/1", "instances": []})
    assert status == 503 and "picker" in doc["detail"]


# ------------------------------------------------------------------------------------- the CLI
def test_cli_without_the_extra_names_it(tmp_path, monkeypatch):
    import sys

    from click.testing import CliRunner

    from grasplan.cli import main

    monkeypatch.setitem(sys.modules, "uvicorn", None)
    r = CliRunner().invoke(main, ["serve", "--parts", str(parts_folder(tmp_path, ("box",)))])
    assert r.exit_code == 3 and "grasplan[serve]" in r.output


def test_cli_refuses_bad_settings(tmp_path):
    from click.testing import CliRunner

    from grasplan.cli import main

    for args, field in ([["--parts", str(tmp_path / "none")], "--parts"],
                        [["--parts", str(tmp_path), "--max-body", "lots"], "--max-body"],
                        [["--parts", str(tmp_path), "--token", "x"], "--token"]):
        r = CliRunner().invoke(main, ["serve", *args])
        assert r.exit_code == 3 and field in r.output, r.output
    assert "--max-body" in CliRunner().invoke(main, ["serve", "--help"]).output


def test_cli_serves_until_interrupted(tmp_path):
    """``grasplan serve`` as a process: it answers on the port it was given, then stops on SIGINT."""
    import os
    import signal
    import socket
    import subprocess
    import sys

    folder = parts_folder(tmp_path / "parts", ("box",))
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {**os.environ, "GRASPLAN_TOKEN": TOKEN, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    proc = subprocess.Popen([sys.executable, "-c", "from grasplan.cli import main; main()", "serve", "--parts",
                             str(folder), "--port", str(port), "--no-pick"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60
        status = 0
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                status, h = Client(port, token=TOKEN).json("GET", "/parts")
                break
            except OSError:
                time.sleep(0.2)
        assert status == 200 and [p["name"] for p in h["parts"]] == ["box"]
        assert Client(port).json("GET", "/parts")[0] == 401  # the token came from $GRASPLAN_TOKEN
    finally:
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err.decode()[-2000:]
    assert b"listening on http://127.0.0.1" in err
