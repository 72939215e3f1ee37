"""Load test of ``grasplan serve`` over loopback HTTP (issue 23's figures).

    python benchmarks/bench_serve.py [--part TLess20] [--requests 500] [--clients 4] [--single 100]
                                     [--workers 1] [--scenes drop|grid] [--piles 10]

The service holds a warm picker for one part (TLess20 when ../shared/parts/paper has it, else
examples/parts/box.stl). Every request is ``POST /pick`` of a 10-instance scene with
``max_picks: 1``: one of ``--piles`` piles dropped into the packaged bin by ``grasplan scene
drop``'s physics (cached), each instance moved by a seeded 0.5 mm of camera noise, so every
request has poses of its own (``--scenes grid``: the tests' scenes, the part side by side on the
bin floor), from keep-alive HTTP/1.1 connections:
first one client alone (``--single`` requests), then ``--clients`` concurrent clients
(``--requests`` requests). Then more than 100 malformed requests (bad JSON, wrong types, huge
numbers, NaN, unknown parts, path traversal, missing token; plus an oversized body): each must
get a 4xx, and ``/health`` must answer afterwards. The service is ``grasplan serve --workers N``
(default 1) in a child process, as in a cell; its start (databases from the cache or computed)
is timed separately. Every request carries its own seeded poses (a camera never sends the same
pile twice), so no request profits from an earlier one's caches.

Printed: p50/p95 latency and throughput of each run against the targets (p50 < 100 ms alone,
p50 < 150 ms with 4 clients, 0 errors), the ratio p50/target, the picker's own ``plan`` time
(timing_s.total of the responses: the share of the latency that is planning, not HTTP and JSON),
peak RSS of the service, and the machine's load average (a shared machine's wall times grow
with its load).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from grasplan.cli.common import table  # noqa: E402
from serve_support import (  # noqa: E402
    TOKEN,
    GridScenes,
    malformed_requests,
    percentile_ms,
    raw_request,
    run_load,
)

PAPER_DIR = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
TARGET_SINGLE_MS = 100.0
TARGET_CONCURRENT_MS = 150.0


def _part(name: str | None) -> Path:
    if name:
        for folder in (PAPER_DIR, ROOT / "examples" / "parts"):
            hits = sorted(folder.glob(f"{name}.*")) if folder.is_dir() else []
            if hits:
                return hits[0]
        raise SystemExit(f"part {name!r} not found in {PAPER_DIR} or examples/parts")
    paper = PAPER_DIR / "TLess20.stl"
    return paper if paper.is_file() else ROOT / "examples" / "parts" / "box.stl"


def dropped_piles(name: str, part: Any, cell: Any, piles: int) -> list[dict]:
    """``piles`` scenes of 10 instances of ``part`` dropped into the bin by ``grasplan scene drop``'s
    physics (seeds 0, 1, ...; a seed whose pile does not fit is skipped), cached in
    ``<cache folder>/bench_serve/``; instances only (the service knows the part by name)."""
    from grasplan.cache import cache_dir
    from grasplan.drop import DropParams, PileItem, drop_pile
    from grasplan.errors import GrasplanError

    folder = cache_dir() / "bench_serve"
    folder.mkdir(parents=True, exist_ok=True)
    out: list[dict] = []
    seed = 0
    while len(out) < piles and seed < 5 * piles:
        path = folder / f"{name}_{part.sha256[:12]}_s{seed}.json"
        if path.exists():
            doc = json.loads(path.read_text())
        else:
            try:
                res = drop_pile(cell, [PileItem(name, part, 10)], params=DropParams(seed=seed))
                doc = {"schema": "grasplan.scene/1", "instances": [i.to_json() for i in res.scene.instances]}
            except GrasplanError:
                doc = None
            path.write_text(json.dumps(doc))
            print(f"  pile seed {seed}: {'dropped' if doc else 'did not fit'}", flush=True)
        if doc:
            out.append(doc)
        seed += 1
    return out


def jittered(pile: dict, seed: int, jitter_m: float = 0.0005) -> dict:
    """``pile`` with each instance moved by a seeded horizontal offset of at most ``jitter_m``
    (a camera's noise: every request has poses of its own, no planner cache helps)."""
    import numpy as np

    rng = np.random.default_rng(seed)
    inst = []
    for i in pile["instances"]:
        T = [list(r) for r in i["T"]]
        T[0][3] += float(rng.uniform(-jitter_m, jitter_m))
        T[1][3] += float(rng.uniform(-jitter_m, jitter_m))
        inst.append({**i, "T": T})
    return {**pile, "instances": inst}


def _child_server(parts: Path, workers: int, env: dict[str, str]) -> tuple[subprocess.Popen, int]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen([sys.executable, "-c", "from grasplan.cli import main; main()", "serve", "--parts",
                             str(parts), "--port", str(port), "--workers", str(workers)],
                            env={**env, "GRASPLAN_TOKEN": TOKEN, "PYTHONPATH": str(ROOT)},
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    from grasplan.serve.loopback import Client

    deadline = time.monotonic() + 600
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise SystemExit(f"grasplan serve exited: {proc.stderr.read().decode()[-2000:] if proc.stderr else ''}")
        try:
            if Client(port).json("GET", "/health")[0] == 200:
                return proc, port
        except OSError:
            time.sleep(0.5)
    raise SystemExit("grasplan serve did not start within 600 s")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default=None, help="part name (file stem) in the paper folder or examples/parts")
    ap.add_argument("--requests", type=int, default=500, help="requests of the concurrent run")
    ap.add_argument("--clients", type=int, default=4)
    ap.add_argument("--single", type=int, default=100, help="requests of the one-client run")
    ap.add_argument("--workers", type=int, default=1, help="service worker processes")
    ap.add_argument("--scenes", choices=("drop", "grid"), default="drop",
                    help="drop: physics-dropped piles (cached); grid: parts side by side on the bin floor (as the tests)")
    ap.add_argument("--piles", type=int, default=10, help="distinct dropped piles (each request jitters one)")
    a = ap.parse_args()

    from grasplan.serve import ServeConfig
    from grasplan.serve.loopback import Client
    from grasplan.serve.state import Service

    part_file = _part(a.part)
    tmp = Path(tempfile.mkdtemp(prefix="bench_serve_"))
    parts = tmp / "parts"
    parts.mkdir()
    shutil.copy(part_file, parts / part_file.name)
    name = part_file.stem
    local = Service.start(ServeConfig(parts_dir=parts, databases=False))  # the part and cell, for the scenes
    if a.scenes == "grid":
        gs = GridScenes(name, local.parts[name].part.mesh, local.cell, n=10)

        def scene(seed: int) -> dict:
            return gs.scene(seed=seed)
    else:
        piles = dropped_piles(name, local.parts[name].part, local.cell, a.piles)
        if not piles:
            raise SystemExit(f"no pile of 10 {name} fits the bin")

        def scene(seed: int) -> dict:
            return jittered(piles[seed % len(piles)], seed)

    def bodies(first_seed: int, n: int) -> list[bytes]:  # every request its own poses, as from a camera
        return [json.dumps({**scene(first_seed + k), "options": {"max_picks": 1}}).encode() for k in range(n)]

    t0 = time.perf_counter()
    proc, port = _child_server(parts, a.workers, dict(os.environ))
    start_s = time.perf_counter() - t0
    try:
        Client(port, token=TOKEN).request("POST", "/pick", bodies(10**6, 1)[0])  # first-request costs left out
        rows = []
        runs = {}
        for k, (label, n, clients, target) in enumerate((("1 client", a.single, 1, TARGET_SINGLE_MS),
                                                          (f"{a.clients} clients", a.requests, a.clients,
                                                           TARGET_CONCURRENT_MS))):
            load = bodies(k * 100000, n)
            t = time.perf_counter()
            lat, errors, responses = run_load(port, load, n, clients)
            wall = time.perf_counter() - t
            plan_ms = [json.loads(r)["timing_s"]["total"] * 1e3 for r in responses if r.startswith(b"{\"schema\"")]
            p50 = percentile_ms(lat, 50)
            runs[label] = (errors, p50)
            rows.append((label, n, len(errors), p50, percentile_ms(lat, 95), n / wall,
                         float(sorted(plan_ms)[len(plan_ms) // 2]) if plan_ms else float("nan"), target, p50 / target))
        cases = malformed_requests(scene(999), None)
        c = Client(port, token=TOKEN)
        not_4xx = [lab for lab, path, body, headers in cases
                   if not 400 <= c.request("GET" if path == "/parts" else "POST", path, body, headers=headers)[0] < 500]
        head = (f"POST /pick HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer {TOKEN}\r\n"
                f"Content-Length: {11 << 20}").encode()
        if raw_request(port, head)[0] != 413:
            not_4xx.append("oversized body")
        health = c.json("GET", "/health")[0]
        c.close()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=60)
        shutil.rmtree(tmp, ignore_errors=True)
    rss_child = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(f"\ngrasplan serve: POST /pick, 10 instances of {name}, max_picks 1, workers {a.workers}; "
          f"service start {start_s:.1f} s (to the first /health); load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(table(rows, header=("run", "requests", "errors", "p50 ms", "p95 ms", "req/s", "picker median ms",
                              "target p50 ms", "p50/target")))
    print(f"\nmalformed requests: {len(cases) + 1}, not answered 4xx: {len(not_4xx)} {not_4xx[:5]}; "
          f"/health afterwards: {health}")
    print(f"peak RSS of a service process: {rss_child:.0f} MiB")
    ok = all(not e for e, _ in runs.values()) and not not_4xx and health == 200
    print("targets: " + ", ".join(f"{k} p50 {'met' if p50 < tgt else 'MISSED'}" for (k, (_, p50)), tgt in
                                  zip(runs.items(), (TARGET_SINGLE_MS, TARGET_CONCURRENT_MS))))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
