"""Shared pieces of the service tests (tests/test_serve*.py) and benchmarks/bench_serve.py: a parts
folder, a started service, seeded scenes of parts resting in the bin, malformed requests."""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path
from collections.abc import Iterator
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE_PARTS = ROOT / "examples" / "parts"
TOKEN = "test-token-0123456789"
#: fast plan options (a few hundred grasp poses, two planned)
FAST_PLAN = {"top": 2, "roll_step": 45, "spacing": "4mm"}


def parts_folder(dest: Path, names: tuple[str, ...] = ("box", "bracket", "gear")) -> Path:
    """``dest`` holding copies of the example parts ``names`` (STL, millimetres)."""
    dest.mkdir(parents=True, exist_ok=True)
    for n in names:
        shutil.copy(EXAMPLE_PARTS / f"{n}.stl", dest / f"{n}.stl")
    return dest


def picking_service(tmp_path_factory, tag: str, names: tuple[str, ...] = ("box", "bracket")) -> Iterator[Any]:
    """A module fixture's body: a picking :class:`grasplan.serve.state.Service` of the example parts
    ``names``, its grasp databases in a cache folder of its own (``GRASPLAN_CACHE_DIR``, restored after)."""
    import pytest

    from grasplan.serve.config import ServeConfig
    from grasplan.serve.state import Service

    mp = pytest.MonkeyPatch()
    mp.setenv("GRASPLAN_CACHE_DIR", str(tmp_path_factory.mktemp(f"{tag}_cache")))
    try:
        yield Service.start(ServeConfig(parts_dir=parts_folder(tmp_path_factory.mktemp(f"{tag}_parts"), names)))
    finally:
        mp.undo()


class GridScenes:
    """``grasplan.scene/1`` documents of ``n`` instances of one part resting in its most probable
    pose on the bin floor, on a grid (5 per row), each turned by a seeded yaw and moved by a seeded
    offset of at most ``jitter_m`` (pose-estimator noise, within the grid's clearance)."""

    def __init__(self, part_name: str, part_mesh: Any, cell: Any, n: int = 10, jitter_m: float = 0.002):
        from grasplan.part.stability import part_centre_of_mass, stable_poses

        self.name, self.mesh, self.cell, self.n, self.jitter = part_name, part_mesh, cell, n, jitter_m
        R, _ = stable_poses(part_mesh)
        self.R = R[0]
        v = (np.asarray(part_mesh.vertices) - part_centre_of_mass(part_mesh)) @ self.R.T  # resting, about its COM
        radius = float(np.linalg.norm(v[:, :2], axis=1).max()) + 0.004  # its footprint at any yaw, 4 mm spare
        self.cols = 5
        rows = math.ceil(n / self.cols)
        half = np.asarray(cell.bin.inner, dtype=float) / 2 if cell.bin is not None else np.array([0.3, 0.3])
        self.pitch = min(3.0 * radius, 2 * (half[0] - radius - jitter_m) / (self.cols - 1),
                         2 * (half[1] - radius - jitter_m) / max(rows - 1, 1))
        self.rows = rows
        assert self.pitch >= 2 * (radius + jitter_m), "the bin is too small for this grid"

    def scene(self, seed: int = 0) -> dict[str, Any]:
        from grasplan.cell.resting import place_on_table
        from grasplan.geometry.transforms import rpy_matrix

        rng = np.random.default_rng(seed)
        instances = []
        for k in range(self.n):
            T = place_on_table(self.mesh, rpy_matrix(0.0, 0.0, float(rng.uniform(0, 2 * np.pi))) @ self.R, self.cell)
            i, j = k % self.cols, k // self.cols
            T[0, 3] += (i - (self.cols - 1) / 2) * self.pitch + rng.uniform(-self.jitter, self.jitter)
            T[1, 3] += (j - (self.rows - 1) / 2) * self.pitch + rng.uniform(-self.jitter, self.jitter)
            instances.append({"id": f"{self.name}_{k}", "part": self.name, "T": T.tolist()})
        return {"schema": "grasplan.scene/1", "instances": instances}


def grid_scene(part_name: str, part_mesh: Any, cell: Any, n: int = 10, seed: int = 0) -> dict[str, Any]:
    """One scene of :class:`GridScenes`."""
    return GridScenes(part_name, part_mesh, cell, n).scene(seed)


def percentile_ms(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values) * 1e3, q))


def malformed_requests(scene: dict[str, Any] | None, plan_doc: dict[str, Any] | None) -> list[tuple[str, str, bytes, dict[str, str]]]:
    """``(label, path, body, extra headers)`` of more than 100 requests that must each get a 4xx: bad
    JSON, wrong types, huge numbers, NaN, unknown parts, path traversal in names, a missing or wrong
    token (oversized bodies: :func:`raw_request`, which need not send them whole). GET for /parts. ``scene``/``plan_doc``: valid documents the cases are derived from
    (None: those cases are made from /plan requests instead)."""
    out: list[tuple[str, str, bytes, dict[str, str]]] = []

    def add(label: str, path: str, body: bytes | str | Any, headers: dict[str, str] | None = None) -> None:
        if not isinstance(body, (bytes, str)):
            body = json.dumps(body)
        out.append((label, path, body.encode() if isinstance(body, str) else body, headers or {}))

    bad_json = [b"", b" ", b"{", b"}", b"[", b'{"part": }', b"{'part': 'box'}", b'{"part": "box",}', b"nul",
                b'{"part": "box"} trailing', b"\xff\xfe\x00", "{\"part\": \"b\u00e4\"".encode(),
                b'{"part": NaN}', b'{"part": "box", "options": {"top": Infinity}}', b'{"options": -Infinity}',
                b'{"part": "box", "options": {"top": 1e400}}', b'{"part": "box", "options": {"top": ' + b"9" * 5000 + b"}}",
                b"[" * 5000 + b"]" * 5000, b'{"a":' * 200 + b"1" + b"}" * 200]
    for i, b in enumerate(bad_json):
        for path in ("/plan", "/pick", "/export"):
            add(f"bad json {i} {path}", path, b)
    wrong = [[], "box", 42, None, True, {"part": 42}, {"part": ["box"]}, {"part": {"name": "box"}}, {"part": None},
             {"part": "box", "options": []}, {"part": "box", "options": "top=2"}, {"part": "box", "part_pose": True},
             {"part": "box", "options": {"top": "many"}}, {"part": "box", "options": {"top": 2.5}},
             {"part": "box", "options": {"top": True}}, {"part": "box", "options": {"top": 10**18}},
             {"part": "box", "options": {"top": -1}}, {"part": "box", "options": {"alpha": 1e300}},
             {"part": "box", "options": {"alpha": "5parsecs"}}, {"part": "box", "options": {"mu": -1e308}},
             {"part": "box", "options": {"seed": 2**63}}, {"part": "box", "options": {"budget": 0}},
             {"part": "box", "options": {"nope": 1}}, {"part": "box", "options": {"scoring": "/etc/passwd"}},
             {"part": "box", "options": {"pose_index": "all"}}, {"part": "box", "part_pose": "1,2,3"},
             {"part": "box", "part_pose": [[1, 0], [0, 1]]}, {"part": "box", "part_pose": "1e9,0,0,0,0,0"},
             {"part": "box", "extra": 1}, {"options": {"top": 2}}]
    for i, d in enumerate(wrong):
        add(f"wrong plan {i}", "/plan", d)
    names = ["nosuch", "../box", "..", ".", "/etc/passwd", "box/../box", "C:\\box", "box.stl", "box\x00", "b" * 500,
             "~/box", "%2e%2e/box", "box\n", "", " box"]
    for n in names:
        add(f"plan name {n[:20]!r}", "/plan", {"part": n})
    if scene is not None:
        inst = scene["instances"][0]

        def sc(**changes: Any) -> dict[str, Any]:
            return {**scene, **changes}
        scenes = [sc(schema="grasplan.scene/2"), sc(instances=[]), sc(instances="a"), sc(instances=[{**inst, "part": "nosuch"}]),
                  sc(instances=[{**inst, "part": "../box"}]), sc(instances=[{**inst, "id": "../x"}]),
                  sc(instances=[{**inst, "T": [[1, 0, 0, 0]] * 4}]), sc(instances=[{**inst, "T": "up"}]),
                  sc(instances=[{**inst, "T": {"xyz": [1e300, 0, 0], "rpy_deg": [0, 0, 0]}}]),
                  sc(instances=[inst, inst]), sc(parts={"box": {"mesh": "/etc/passwd"}}),
                  sc(parts={"box": {"grasps": "../x.graspdb.npz"}}), sc(parts={"../box": {}}),
                  sc(cloud={"path": "/etc/passwd"}), sc(cell="/etc/cell.yaml"), sc(cell="obstacles"),
                  sc(options={"max_picks": 0}), sc(options={"max_picks": "all"}), sc(options={"max_picks": 1e18}),
                  sc(options={"seed": -1}), sc(options={"sequence": "yes"}), sc(options={"nope": 1}), sc(options=[]),
                  sc(extra=1), {"instances": scene["instances"]}]
        for i, d in enumerate(scenes):
            add(f"bad scene {i}", "/pick", d)
    if plan_doc is not None:
        exports = [{"document": plan_doc}, {"format": "urscript"}, {"document": plan_doc, "format": "nosuch"},
                   {"document": plan_doc, "format": 3}, {"document": "plan.json", "format": "urscript"},
                   {"document": plan_doc, "format": "urscript", "grasp": -1},
                   {"document": plan_doc, "format": "urscript", "grasp": 10**9},
                   {"document": plan_doc, "format": "urscript", "grasp": "best"},
                   {"document": plan_doc, "format": "joint-trajectory", "max_accel": 0},
                   {"document": plan_doc, "format": "krl", "program_name": "../../evil"},
                   {"document": {**plan_doc, "schema": "grasplan.plan/9"}, "format": "urscript"},
                   {"document": {**plan_doc, "part": {**plan_doc["part"], "sha256": "0" * 64}}, "format": "urscript"},
                   {"document": {**plan_doc, "robot": {**plan_doc["robot"], "source": {"yaml": "urdf: /etc/passwd"}}},
                    "format": "urscript"},
                   {"document": plan_doc, "format": "urscript", "path": "/tmp/out.script"}]
        for i, d in enumerate(exports):
            add(f"bad export {i}", "/export", d)
    add("no token", "/plan", {"part": "box"}, {"Authorization": ""})
    add("wrong token", "/plan", {"part": "box"}, {"Authorization": "Bearer wrong-token-000000"})
    add("no token, pick", "/pick", scene or {}, {"Authorization": ""})
    add("wrong token, pick", "/pick", scene or {}, {"Authorization": "Bearer " + TOKEN[::-1]})
    add("basic auth", "/parts", b"", {"Authorization": "Basic " + TOKEN})
    return out


def raw_request(port: int, head: bytes, body: bytes = b"", timeout_s: float = 30.0) -> tuple[int, bytes]:
    """Send ``head`` (request line and headers, no blank line) and ``body`` on a fresh socket; the
    status and the whole response (the server closes the connection or sends Content-Length)."""
    import socket

    with socket.create_connection(("127.0.0.1", port), timeout=timeout_s) as s:
        s.sendall(head + b"\r\n\r\n" + body)
        data = b""
        while b"\r\n\r\n" not in data:
            chunk = s.recv(65536)
            if not chunk:
                break
            data += chunk
        header, _, rest = data.partition(b"\r\n\r\n")
        length = next((int(line.split(b":", 1)[1]) for line in header.split(b"\r\n")
                       if line.lower().startswith(b"content-length:")), None)
        while length is not None and len(rest) < length:
            chunk = s.recv(65536)
            if not chunk:
                break
            rest += chunk
    status = int(header.split(b" ", 2)[1]) if header.startswith(b"HTTP/") else 0
    return status, rest
def run_load(port: int, bodies: list[bytes], n_requests: int, clients: int, token: str | None = TOKEN,
             path: str = "/pick") -> tuple[list[float], list[str], list[bytes]]:
    """``n_requests`` POSTs of ``bodies`` (cycled) from ``clients`` threads, each on its own
    keep-alive connection: ``(latencies s, errors, response bodies)``; an error is any status but 200."""
    import threading
    import time

    from grasplan.serve.loopback import Client

    lat: list[float] = []
    errors: list[str] = []
    responses: list[bytes] = []
    lock = threading.Lock()
    counter = iter(range(n_requests))

    def worker() -> None:
        c = Client(port, token=token)
        try:
            while True:
                with lock:
                    k = next(counter, None)
                if k is None:
                    return
                t = time.perf_counter()
                try:
                    status, data = c.request("POST", path, bodies[k % len(bodies)])
                except OSError as exc:
                    status, data = 0, str(exc).encode()
                dt = time.perf_counter() - t
                with lock:
                    lat.append(dt)
                    responses.append(data)
                    if status != 200:
                        errors.append(f"{status}: {data[:200]!r}")
        finally:
            c.close()

    threads = [threading.Thread(target=worker) for _ in range(clients)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return lat, errors, responses


# ------------------------------------------------------------------------------ raw connections
def connect(port: int, *, source: str = "127.0.0.1", timeout_s: float = 5.0) -> Any:
    """A TCP connection to the loopback service from ``source`` (any 127.x.y.z address: the server
    sees a different client address for each)."""
    import socket

    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.settimeout(timeout_s)
    if source != "127.0.0.1":
        s.bind((source, 0))
    s.connect(("127.0.0.1", port))
    return s


def read_answer(sock: Any, timeout_s: float = 5.0) -> tuple[int, dict[str, str], bytes]:
    """The next response on ``sock``: ``(status, headers lower-cased, body)``; status 0 when the
    server closed the connection without one. ``socket.timeout`` when nothing came in ``timeout_s``."""
    import time

    sock.settimeout(timeout_s)
    t_end = time.monotonic() + timeout_s
    data = b""
    while b"\r\n\r\n" not in data:
        if time.monotonic() > t_end:
            raise TimeoutError("no response")
        try:
            chunk = sock.recv(65536)
        except ConnectionResetError:
            chunk = b""
        if not chunk:
            return 0, {}, data
        data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    status = int(lines[0].split(" ", 2)[1])
    headers = {k.strip().lower(): v.strip() for k, _, v in (line.partition(":") for line in lines[1:])}
    length = int(headers.get("content-length", "0"))
    while len(body) < length:
        try:
            chunk = sock.recv(65536)
        except ConnectionResetError:
            break
        if not chunk:
            break
        body += chunk
    return status, headers, body[:length]


def closed_by_server(sock: Any, within_s: float) -> bool:
    """True when the server closes ``sock`` within ``within_s`` seconds (what it still sends is
    read and dropped)."""
    import socket
    import time

    t_end = time.monotonic() + within_s
    while True:
        left = t_end - time.monotonic()
        if left <= 0:
            return False
        sock.settimeout(left)
        try:
            if not sock.recv(65536):
                return True
        except (ConnectionResetError, BrokenPipeError):
            return True
        except socket.timeout:
            return False


def health_s(port: int, timeout_s: float = 5.0) -> float:
    """Seconds a ``GET /health`` takes on a fresh connection (AssertionError unless it is a 200)."""
    import time

    t = time.perf_counter()
    with connect(port, timeout_s=timeout_s) as s:
        s.sendall(b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
        status, _, body = read_answer(s, timeout_s)
    dt = time.perf_counter() - t
    assert status == 200 and json.loads(body)["status"] == "ok", (status, body[:200])
    return dt
