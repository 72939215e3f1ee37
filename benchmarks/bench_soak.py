"""A shift of ``grasplan serve``: memory and latency over thousands of ``/pick`` requests.

    python benchmarks/bench_soak.py [--workers 2] [--clients 2] [--warmup 500] [--requests 5000]
                                    [--fixed 1000] [--every 500] [--quick]

The service (``grasplan serve`` on 127.0.0.1, in a child process, ``--workers`` planners) knows one
part, TLess20, from a parts folder made in a temporary directory (a symbolic link to
../shared/parts/paper/TLess20.stl: the paper parts are never copied into the repository; without
them the benchmark says so and stops). Every request is ``POST /pick`` of a pile of 5 TLess20
dropped into the packaged bin by ``grasplan scene drop``'s physics (seed 0, cached in
``<cache folder>/bench_soak/``), with ``max_picks: 1`` and each instance moved by a seeded offset of
up to 1 mm per axis and turned by up to 1 degree (a camera's noise: every request's poses are new),
sent from ``--clients`` keep-alive connections:

1. ``--warmup`` requests with new instance ids every request (the service's caches filling);
2. ``--requests`` more, new ids every request (a tracker that numbers every detection anew);
3. ``--fixed`` more with the same five ids every request (a tracker that keeps its ids).

After every ``--every`` requests it prints the resident memory (VmRSS, from /proc) of every process
of the service (the HTTP process first, then the planners) and the p50/p99 latency of those
requests; at the end, each process's growth from the end of the warm-up to the end of the run
(the target: at most 10 %), the latency over each phase and the errors (any status but 200).
``--quick``: 100 + 300 + 100 requests, every 100.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "tests"))

from bench_serve import _child_server, _tree, jittered  # noqa: E402
from grasplan.cli.common import table  # noqa: E402
from serve_support import percentile_ms, run_load  # noqa: E402

PAPER_DIR = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
PART = "TLess20"
PILE = 5
TARGET_GROWTH = 0.10


def pile_doc(part_path: Path) -> dict:
    """The 5-instance pile (instances only: the service knows the part), dropped once and cached."""
    from grasplan.cache import cache_dir
    from grasplan.cell.model import load_cell
    from grasplan.sim.drop import DropParams, PileItem, drop_pile
    from grasplan.errors import GrasplanError
    from grasplan.part.mesh import load_part

    part = load_part(part_path)
    folder = cache_dir() / "bench_soak"
    folder.mkdir(parents=True, exist_ok=True)
    for seed in range(10):
        path = folder / f"{PART}_{part.sha256[:12]}_{PILE}_s{seed}.json"
        if path.exists():
            return json.loads(path.read_text())
        try:
            res = drop_pile(load_cell("bin"), [PileItem(PART, part, PILE)],
                            params=DropParams(seed=seed, material="plastic"))
        except GrasplanError:
            continue
        doc = {"schema": "grasplan.scene/1", "instances": [i.to_json() for i in res.scene.instances]}
        path.write_text(json.dumps(doc))
        return doc
    raise SystemExit(f"no pile of {PILE} {PART} fits the packaged bin")


def bodies(pile: dict, first: int, n: int, new_ids: bool) -> list[bytes]:
    """Requests ``first`` .. ``first + n - 1``: the pile jittered with each request's seed, its ids
    new per request (``r<k>_<j>``) or the pile's own."""
    out = []
    for k in range(first, first + n):
        doc = jittered(pile, k)
        if new_ids:
            doc["instances"] = [{**i, "id": f"r{k}_{j}"} for j, i in enumerate(doc["instances"])]
        out.append(json.dumps({**doc, "options": {"max_picks": 1}}).encode())
    return out


def rss_mib(pids: list[int]) -> list[float]:
    """VmRSS (MiB) of each of ``pids`` (0 for a process gone)."""
    out = []
    for p in pids:
        try:
            line = next(x for x in Path(f"/proc/{p}/status").read_text().splitlines() if x.startswith("VmRSS:"))
            out.append(int(line.split()[1]) / 1024)
        except (OSError, StopIteration, ValueError):
            out.append(0.0)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2, help="planner processes of the service")
    ap.add_argument("--clients", type=int, default=2, help="concurrent keep-alive connections")
    ap.add_argument("--warmup", type=int, default=500, help="requests before the memory baseline")
    ap.add_argument("--requests", type=int, default=5000, help="measured requests, new instance ids each")
    ap.add_argument("--fixed", type=int, default=1000, help="then requests with the same instance ids")
    ap.add_argument("--every", type=int, default=500, help="print memory and latency every this many requests")
    ap.add_argument("--quick", action="store_true", help="100 + 300 + 100 requests, every 100")
    a = ap.parse_args()
    if a.quick:
        a.warmup, a.requests, a.fixed, a.every = 100, 300, 100, 100
    src = PAPER_DIR / f"{PART}.stl"
    if not src.is_file():
        print(f"skipped: {src} not found (the paper parts live outside the repository; set GRASPLAN_PAPER_PARTS)")
        return 0
    pile = pile_doc(src)
    tmp = Path(tempfile.mkdtemp(prefix="bench_soak_"))
    parts = tmp / "parts"
    parts.mkdir()
    (parts / src.name).symlink_to(src)
    t0 = time.perf_counter()
    proc, port = _child_server(parts, a.workers, dict(os.environ))
    start_s = time.perf_counter() - t0
    phases = [("warm-up, new ids", a.warmup, True), ("new ids", a.requests, True), ("fixed ids", a.fixed, False)]
    rows, lat_by_phase, errors = [], {}, []
    base: list[float] | None = None
    end: list[float] = []
    pids: list[int] = []
    done = 0
    t_run = time.perf_counter()
    try:
        time.sleep(1.0)  # the planners started with the service
        pids = _tree(proc.pid)  # the HTTP process first, then the planners
        for phase, n, new_ids in phases:
            lat_by_phase[phase] = []
            for b0 in range(0, n, a.every):
                m = min(a.every, n - b0)
                lat, errs, _ = run_load(port, bodies(pile, done, m, new_ids), m, a.clients)
                done += m
                errors += errs
                lat_by_phase[phase] += lat
                now = _tree(proc.pid)
                pids += [p for p in now if p not in pids]  # a planner replaced (killed past the limit)
                rss = rss_mib(pids)
                rows.append((done, phase, rss, percentile_ms(lat, 50), percentile_ms(lat, 99), len(errs)))
                print(f"  {done} requests: RSS {', '.join(f'{r:.0f}' for r in rss)} MiB; p50 "
                      f"{percentile_ms(lat, 50):.0f} ms, p99 {percentile_ms(lat, 99):.0f} ms", flush=True)
            if phase.startswith("warm-up"):
                base = rss_mib(pids)
        end = rss_mib(pids)
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=60)
        except Exception:
            proc.kill()
        shutil.rmtree(tmp, ignore_errors=True)
    wall = time.perf_counter() - t_run
    names = ["http"] + [f"pid {p}" for p in pids[1:]]
    print(f"\ngrasplan serve --workers {a.workers}: POST /pick, {PILE} instances of {PART} jittered every request, "
          f"max_picks 1, {a.clients} clients; start {start_s:.1f} s; {done} requests in {wall:.0f} s; load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (processes: the HTTP one, then its children)")
    print(table([(n, ph, *(round(x) for x in rss + [0.0] * (len(pids) - len(rss))), round(sum(rss)), round(p50),
                  round(p99), ne) for n, ph, rss, p50, p99, ne in rows],
                header=("requests", "phase", *(f"{x} MiB" for x in names), "total MiB", "p50 ms", "p99 ms",
                        "errors")))
    growth = []
    if base is not None:
        growth = [(e - b) / b if b > 0 else 0.0 for b, e in zip(base, end)]
        print(table([(x, round(b), round(e), f"{100 * g:+.1f} %", "met" if g <= TARGET_GROWTH else "MISSED")
                     for x, b, e, g in zip(names, base, end, growth)],
                    header=("process", "after warm-up MiB", "at the end MiB", "growth",
                            f"<= {100 * TARGET_GROWTH:g} %")))
    print(table([(ph, len(v), round(percentile_ms(v, 50)), round(percentile_ms(v, 99)))
                 for ph, v in lat_by_phase.items() if v], header=("phase", "requests", "p50 ms", "p99 ms")))
    print(f"errors: {len(errors)} {errors[:3]}")
    return 0 if not errors and all(g <= TARGET_GROWTH for g in growth) else 1


if __name__ == "__main__":
    sys.exit(main())
