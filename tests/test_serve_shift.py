"""``grasplan serve`` left running for a shift, as a process: SIGTERM finishes the request in
progress and exits 0; ``--time-limit`` holds with one planner process (a runaway plan is stopped,
the next request does not wait for it); the connection options on the command line; the open-file
limit. The HTTP layer's fuzz classes: tests/test_fuzz_http.py."""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("fastapi")
pytest.importorskip("uvicorn")

from grasplan.errors import InputError  # noqa: E402
from grasplan.serve import ServeConfig  # noqa: E402
from grasplan.serve.loopback import Client  # noqa: E402
from serve_support import FAST_PLAN, closed_by_server, connect, health_s, parts_folder  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: a /plan that runs far past a few seconds whatever the machine: the candidate and grasp stages of
#: a 250k-triangle sphere (about 20 s of CPU; the planning budget does not bound them)
SLOW_PLAN = {"part": "sphere"}


def _slow_parts(folder: Path) -> Path:
    """``folder`` holding the box and a 20 mm sphere of about 250k triangles (binary STL, mm)."""
    from fuzz_cases import binary_stl, uv_sphere

    parts_folder(folder, ("box",))
    v, f = uv_sphere(250_000, 20.0)
    (folder / "sphere.stl").write_bytes(binary_stl(v, f))
    return folder


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _start(folder: Path, *args: str) -> tuple[subprocess.Popen, int, Path]:
    """``grasplan serve --parts folder --no-pick ARGS`` as a process, once it answers /health; its
    log (stderr) goes to a file next to ``folder`` (a pipe nobody reads would block it)."""
    port = _free_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("GRASPLAN_TOKEN", None)
    log_path = folder.parent / f"serve-{port}.log"
    with open(log_path, "wb") as log:
        proc = subprocess.Popen([sys.executable, "-c", "from grasplan.cli import main; main()", "serve", "--parts",
                                 str(folder), "--port", str(port), "--no-pick", *args], env=env,
                                stdout=subprocess.DEVNULL, stderr=log)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            if Client(port).json("GET", "/health")[0] == 200:
                return proc, port, log_path
        except OSError:
            time.sleep(0.1)
    _stop(proc)
    raise AssertionError(f"grasplan serve did not start: {log_path.read_text()[-2000:]}")


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.kill()
        proc.wait(30)


def test_sigterm_finishes_the_request_and_exits_0(tmp_path):
    folder = parts_folder(tmp_path / "parts", ("box",))
    proc, port, log_path = _start(folder, "--workers", "1", "--time-limit", "60")
    try:
        status, h = Client(port).json("GET", "/health")
        assert h["planners"] == 1 and h["rss_mib"]["http"] > 0 and len(h["rss_mib"]["planners"]) == 1
        with connect(port) as s:  # a monitoring probe's HEAD
            s.sendall(b"HEAD /health HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
            head = s.recv(65536)
            assert head.startswith(b"HTTP/1.1 200") and head.endswith(b"\r\n\r\n") and closed_by_server(s, 5.0)
        idle = connect(port)
        got: dict[str, object] = {}

        def ask() -> None:
            got["answer"] = Client(port, timeout_s=120).json("POST", "/plan", {"part": "box", "options": FAST_PLAN})
            got["t"] = time.monotonic()
        t = threading.Thread(target=ask)
        t.start()
        while Client(port).json("GET", "/health")[1]["queued"] < 1:  # the plan is in progress
            assert t.is_alive(), got
            time.sleep(0.02)
        t_signal = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        assert closed_by_server(idle, 5.0)  # idle connections are closed at once
        t.join(120)
        status, doc = got["answer"]  # type: ignore[misc]
        assert status == 200 and doc["schema"] == "grasplan.plan/1", doc
        assert got["t"] > t_signal  # it was answered after the signal
        proc.wait(90)
        err = log_path.read_text()
        assert proc.returncode == 0, err[-2000:]
        assert "Traceback" not in err and "stopped" in err
    finally:
        _stop(proc)


def test_time_limit_holds_with_one_planner_process(tmp_path):
    """--workers 1: a plan past --time-limit is answered 504 at the limit and its planner process
    stopped; /health answers meanwhile, and the next request is planned by a fresh planner instead
    of waiting for the runaway."""
    folder = _slow_parts(tmp_path / "parts")
    limit = 5.0
    proc, port, log_path = _start(folder, "--workers", "1", "--time-limit", str(limit))
    try:
        lat: list[float] = []
        done = threading.Event()

        def watch() -> None:
            while not done.is_set():
                lat.append(health_s(port))
                time.sleep(0.1)
        w = threading.Thread(target=watch)
        w.start()
        t0 = time.monotonic()
        status, doc = Client(port, timeout_s=120).json("POST", "/plan", SLOW_PLAN)
        took = time.monotonic() - t0
        done.set()
        w.join()
        assert status == 504 and doc["error"] == "time_limit", (status, doc)
        assert limit - 0.2 < took < limit + 1.5, took
        assert lat and max(lat) < 1.0, max(lat)
        status, doc = Client(port, timeout_s=120).json("POST", "/plan", {"part": "nosuch"})
        assert status == 422 and "unknown part" in doc["detail"], (status, doc)  # a planner answered, in time
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(60)
        finally:
            _stop(proc)
    assert proc.returncode == 0 and "Traceback" not in log_path.read_text()


@pytest.mark.parametrize("args, field", [
    (["--header-timeout", "0"], "--header-timeout"), (["--body-timeout", "nan"], "--body-timeout"),
    (["--body-timeout", "1e9"], "--body-timeout"),
    (["--max-connections-per-client", "0"], "--max-connections-per-client"),
    (["--max-connections", "0"], "--max-connections"),
    (["--max-connections", "10", "--max-connections-per-client", "50"], "--max-connections-per-client"),
])
def test_cli_refuses_bad_connection_settings(tmp_path, args, field):
    from click.testing import CliRunner

    from grasplan.cli import main

    r = CliRunner().invoke(main, ["serve", "--parts", str(parts_folder(tmp_path, ("box",))), *args])
    assert r.exit_code in (2, 3) and field in r.output, r.output  # 2: click's reading, 3: the settings' check
    assert "Traceback" not in r.output


def test_cli_lists_the_connection_options():
    from click.testing import CliRunner

    from grasplan.cli import main

    out = CliRunner().invoke(main, ["serve", "--help"]).output
    for option in ("--header-timeout", "--body-timeout", "--max-connections-per-client", "--max-connections"):
        assert option in out


def test_config_connection_defaults(tmp_path):
    cfg = ServeConfig(parts_dir=tmp_path)
    assert 1 <= cfg.header_timeout_s <= 10 and 1 <= cfg.body_timeout_s <= 10
    assert cfg.max_connections_per_client < cfg.max_connections
    with pytest.raises(InputError, match="--header-timeout"):
        ServeConfig(parts_dir=tmp_path, header_timeout_s=True)


def test_open_file_limit_is_raised():
    resource = pytest.importorskip("resource")
    from grasplan.serve.run import RESERVED_FDS, raise_fd_limit

    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard != resource.RLIM_INFINITY and hard < 600:
        pytest.skip("the hard open-file limit is below 600")
    try:
        resource.setrlimit(resource.RLIMIT_NOFILE, (256, hard))
        assert raise_fd_limit(500) == 500
        assert resource.getrlimit(resource.RLIMIT_NOFILE)[0] >= 500 + RESERVED_FDS
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
