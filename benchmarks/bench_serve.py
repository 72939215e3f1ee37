"""Load test of ``grasplan serve`` over loopback HTTP (issue 23's figures).

    python benchmarks/bench_serve.py [--part TLess20] [--requests 500] [--clients 4] [--single 100]
                                     [--workers N] [--poses repeat,jitter] [--scenes drop|grid] [--piles 10]

The service (``grasplan serve``, in a child process, as in a cell; ``--workers`` as given, else
its default: one planner process per core, at most 4) holds a warm picker for one part (TLess20
when ../shared/parts/paper has it, else examples/parts/box.stl). Every request is ``POST /pick`` of
a 10-instance scene with ``max_picks: 1``, from keep-alive HTTP/1.1 connections: first one client
alone (``--single`` requests), then ``--clients`` concurrent clients (``--requests``). The scenes
are ``--piles`` piles of 10 dropped into the packaged bin by ``grasplan scene drop``'s physics
(cached; ``--scenes grid``: the tests' scenes, the part side by side on the bin floor), in two
variants (``--poses``):

- ``repeat``: the piles as dropped, cycled: the issue's "500 requests on a 10-instance scene"
  (10 distinct scenes, each sent 50 times: the picker's caches of an arrangement it has seen, the
  collision scene of each instance with its neighbours, can help a repeated scene; nothing caches
  responses);
- ``jitter``: a vision loop: every request's poses are new, each instance moved by a seeded
  uniform offset of up to 1 mm per axis and turned by up to 1 degree about a random axis, so no
  cache of an earlier request helps.

Then more than 100 malformed requests (bad JSON, wrong types, huge numbers, NaN, unknown parts,
path traversal, missing token; plus an oversized body): each must get a 4xx, and ``/health`` must
answer afterwards.

Printed per run: p50/p95 latency and throughput against the targets (p50 < 100 ms alone, p50 <
150 ms with 4 clients, 0 errors), the ratio p50/target; the picker's own medians from the responses'
``timing_s`` (``total``: ``Picker.plan``; ``checks``: the scene's geometric checks; ``first_pick``:
from the checked scene to the first feasible pick): the rest of the latency is HTTP, JSON and
waiting for a planner; the service's CPU time per request (every process of the service, from
/proc: wall times on a shared machine grow with its load, CPU time much less). Then the peak RSS
of each service process and the machine's load average.
"""
from __future__ import annotations

import argparse
import json
import os
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
    from grasplan.sim.drop import DropParams, PileItem, drop_pile
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
                res = drop_pile(cell, [PileItem(name, part, 10)], params=DropParams(seed=seed, material="plastic"))
                doc = {"schema": "grasplan.scene/1", "instances": [i.to_json() for i in res.scene.instances]}
            except GrasplanError:
                doc = None
            path.write_text(json.dumps(doc))
            print(f"  pile seed {seed}: {'dropped' if doc else 'did not fit'}", flush=True)
        if doc:
            out.append(doc)
        seed += 1
    return out


def jittered(pile: dict, seed: int, jitter_m: float = 0.001, jitter_deg: float = 1.0) -> dict:
    """``pile`` with each instance moved by a seeded uniform offset of at most ``jitter_m`` per axis
    (within the scene checks' 2 mm tolerance of the floor) and turned about its origin by at most
    ``jitter_deg`` about a random axis (a camera's noise: every request has poses of its own)."""
    import numpy as np

    rng = np.random.default_rng(seed)
    inst = []
    for i in pile["instances"]:
        T = np.asarray(i["T"], dtype=np.float64)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        a = np.radians(rng.uniform(0.0, jitter_deg))
        K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
        T[:3, :3] = (np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * (K @ K)) @ T[:3, :3]
        T[:3, 3] += rng.uniform(-jitter_m, jitter_m, 3)
        inst.append({**i, "T": T.tolist()})
    return {**pile, "instances": inst}


def _tree(pid: int) -> list[int]:
    """``pid`` and every process below it (from /proc)."""
    children: dict[int, list[int]] = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(d.name))
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        todo.extend(children.get(p, []))
    return out


def cpu_s(pid: int) -> float:
    """CPU seconds (user + system) of ``pid`` and the processes below it, so far."""
    tick = os.sysconf("SC_CLK_TCK")
    total = 0
    for p in _tree(pid):
        try:
            f = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()
            total += int(f[11]) + int(f[12])
        except (OSError, IndexError, ValueError):
            pass
    return total / tick


def peak_rss_mib(pid: int) -> list[float]:
    """Peak RSS (VmHWM, MiB) of ``pid`` and of each process below it."""
    out = []
    for p in _tree(pid):
        try:
            line = next(x for x in Path(f"/proc/{p}/status").read_text().splitlines() if x.startswith("VmHWM:"))
            out.append(int(line.split()[1]) / 1024)
        except (OSError, StopIteration, ValueError):
            pass
    return out


def _child_server(parts: Path, workers: int | None, env: dict[str, str]) -> tuple[subprocess.Popen, int]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen([sys.executable, "-c", "from grasplan.cli import main; main()", "serve", "--parts",
                             str(parts), "--port", str(port), *(["--workers", str(workers)] if workers else [])],
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


def _median(values: list[float]) -> float:
    return float(sorted(values)[len(values) // 2]) if values else float("nan")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default=None, help="part name (file stem) in the paper folder or examples/parts")
    ap.add_argument("--requests", type=int, default=500, help="requests of the concurrent run")
    ap.add_argument("--clients", type=int, default=4)
    ap.add_argument("--single", type=int, default=100, help="requests of the one-client run")
    ap.add_argument("--workers", type=int, default=None,
                    help="planners of the service (default: grasplan serve's, one per core, at most 4)")
    ap.add_argument("--poses", default="repeat,jitter",
                    help="comma-separated variants: repeat (the dropped piles as they are, cycled), jitter (every "
                         "request's poses moved by up to 1 mm and 1 deg)")
    ap.add_argument("--scenes", choices=("drop", "grid"), default="drop",
                    help="drop: physics-dropped piles (cached); grid: parts side by side on the bin floor (as the tests)")
    ap.add_argument("--piles", type=int, default=10, help="distinct piles (the scenes cycled through)")
    a = ap.parse_args()
    variants = [v.strip() for v in a.poses.split(",") if v.strip()]
    if not variants or any(v not in ("repeat", "jitter") for v in variants):
        raise SystemExit(f"--poses: expected repeat, jitter or both, got {a.poses!r}")

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
        piles = [gs.scene(seed=k) for k in range(a.piles)]
    else:
        piles = dropped_piles(name, local.parts[name].part, local.cell, a.piles)
        if not piles:
            raise SystemExit(f"no pile of 10 {name} fits the bin")

    def bodies(kind: str, first_seed: int, n: int) -> list[bytes]:
        def scene(k: int) -> dict:
            pile = piles[k % len(piles)]
            return pile if kind == "repeat" else jittered(pile, first_seed + k)
        return [json.dumps({**scene(k), "options": {"max_picks": 1}}).encode() for k in range(n)]

    t0 = time.perf_counter()
    proc, port = _child_server(parts, a.workers, dict(os.environ))
    start_s = time.perf_counter() - t0
    try:
        planners = int(Client(port).json("GET", "/health")[1].get("planners", 1))
        # first-request costs (each planner's collision scenes) left out
        run_load(port, bodies("jitter", 10**6, 2 * planners), 2 * planners, planners)
        rows = []
        runs = {}
        for kind in variants:
            for k, (label, n, clients, target) in enumerate((("1 client", a.single, 1, TARGET_SINGLE_MS),
                                                              (f"{a.clients} clients", a.requests, a.clients,
                                                               TARGET_CONCURRENT_MS))):
                load = bodies(kind, k * 100000, n)
                c0 = cpu_s(proc.pid)
                t = time.perf_counter()
                lat, errors, responses = run_load(port, load, n, clients)
                wall = time.perf_counter() - t
                cpu_ms = (cpu_s(proc.pid) - c0) / n * 1e3
                timing = [json.loads(r)["timing_s"] for r in responses if r.startswith(b"{\"schema\"")]
                med = {key: _median([1e3 * tm[key] for tm in timing if key in tm])
                       for key in ("total", "checks", "first_pick")}
                p50 = percentile_ms(lat, 50)
                runs[f"{kind}, {label}"] = (errors, p50, target)
                rows.append((f"{kind}, {label}", n, len(errors), p50, percentile_ms(lat, 95), n / wall, cpu_ms,
                             med["total"], med["checks"], med["first_pick"], target, p50 / target))
        cases = malformed_requests(piles[0], None)
        c = Client(port, token=TOKEN)
        not_4xx = [lab for lab, path, body, headers in cases
                   if not 400 <= c.request("GET" if path == "/parts" else "POST", path, body, headers=headers)[0] < 500]
        head = (f"POST /pick HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer {TOKEN}\r\n"
                f"Content-Length: {11 << 20}").encode()
        if raw_request(port, head)[0] != 413:
            not_4xx.append("oversized body")
        health = c.json("GET", "/health")[0]
        c.close()
        rss = peak_rss_mib(proc.pid)
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=60)
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"\ngrasplan serve: POST /pick, 10 instances of {name} ({a.scenes}, {len(piles)} piles), max_picks 1, "
          f"{planners} planner{'s' if planners > 1 else ''}; service start {start_s:.1f} s (to the first /health); "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(table(rows, header=("run", "requests", "errors", "p50 ms", "p95 ms", "req/s", "service CPU ms/req",
                              "plan ms", "checks ms", "first_pick ms", "target p50 ms", "p50/target")))
    print("(plan, checks, first_pick: medians of the responses' timing_s: Picker.plan, its scene checks, from "
          "the checked scene to the first pick)")
    print(f"\nmalformed requests: {len(cases) + 1}, not answered 4xx: {len(not_4xx)} {not_4xx[:5]}; "
          f"/health afterwards: {health}")
    print("peak RSS of the service's processes (MiB): " + ", ".join(f"{r:.0f}" for r in rss)
          + " (the HTTP process first, then the planners)")
    ok = all(not e for e, _, _ in runs.values()) and not not_4xx and health == 200
    print("targets: " + ", ".join(f"{k} p50 {'met' if p50 < tgt else 'MISSED'}" for k, (_, p50, tgt) in runs.items()))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
