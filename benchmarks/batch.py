"""Benchmark of ``grasplan batch``: throughput on 1 and 2 workers, speed-up, peak RSS per worker.

    python benchmarks/batch.py [--parts 100] [--top 5] [--workers 1,2] [--engine local|ray]

The catalogue: the paper's parts (``../shared/parts/paper`` or ``$GRASPLAN_PAPER_PARTS``, when
present) and the example parts, each written again under random rigid transforms and scalings
(0.8-1.25, so a millimetre file stays millimetres) until ``--parts`` files exist, in a temporary
folder. Each worker count runs the same catalogue into a fresh output folder in its own process;
the peak RSS of the workers is that process's ``RUSAGE_CHILDREN`` high-water mark (the largest
worker), the driver's is ``RUSAGE_SELF``; CPU s/part is the workers' user + system time per part
and the machine's 1-minute load average is printed at the start and end of each run (the speed-up
is only meaningful when nothing else competes for the cores). Target: speed-up >= 1.8x from 1 to 2 workers.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAPER = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
EXAMPLES = ROOT / "examples" / "parts"


def make_catalogue(folder: Path, n: int, seed: int = 0) -> list[Path]:
    """``n`` mesh files: the source parts, then copies under random rigid motions and scalings."""
    import numpy as np
    import trimesh
    from scipy.spatial.transform import Rotation

    sources = []
    if PAPER.is_dir():
        sources = sorted(p for p in PAPER.glob("*") if p.suffix.lower() in (".stl", ".obj", ".ply"))
    sources += sorted(EXAMPLES.glob("*.stl"))
    rng = np.random.default_rng(seed)
    meshes = [trimesh.load(str(p), force="mesh", process=False) for p in sources]
    out = []
    for i in range(n):
        k = i % len(sources)
        m = meshes[k].copy()
        if i >= len(sources):
            T = np.eye(4)
            T[:3, :3] = Rotation.random(random_state=int(rng.integers(2**31))).as_matrix() * rng.uniform(0.8, 1.25)
            T[:3, 3] = rng.uniform(-50, 50, 3)
            m.apply_transform(T)
        path = folder / f"{sources[k].stem}_{i:03d}.stl"
        m.export(str(path))
        out.append(path)
    return out


def run_one(catalogue: Path, out: Path, workers: int, top: int, engine: str) -> dict:
    """One batch in this process; returns seconds, rows and peak RSS (MiB)."""
    from grasplan.batch import run_batch
    from grasplan.batch.options import BatchOptions
    from grasplan.params import PlanParams

    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    s = run_batch([catalogue], out, options=BatchOptions(planning=PlanParams(top=top)), engine=engine,
                  workers=workers)
    wall = time.perf_counter() - t0
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return {"wall_s": wall, "rows": s.rows, "worker_cpu_s": ru.ru_utime + ru.ru_stime,
            "load": (load0, os.getloadavg()[0]),
            # Linux reports ru_maxrss in KiB
            "worker_rss_mib": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
            "driver_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--parts", type=int, default=100)
    ap.add_argument("--top", type=int, default=5, help="grasps planned per part (plan's --top)")
    ap.add_argument("--workers", default="1,2", help="comma-separated worker counts")
    ap.add_argument("--engine", default="local", choices=("local", "ray"))
    ap.add_argument("--_child", nargs=3, metavar=("CATALOGUE", "OUT", "WORKERS"), help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a._child:
        res = run_one(Path(a._child[0]), Path(a._child[1]), int(a._child[2]), a.top, a.engine)
        print(json.dumps(res))
        return 0

    from grasplan.cli.common import table

    counts = [int(w) for w in a.workers.split(",")]
    with tempfile.TemporaryDirectory(prefix="grasplan-bench-batch-") as tmp:
        cat = Path(tmp) / "parts"
        cat.mkdir()
        t = time.perf_counter()
        files = make_catalogue(cat, a.parts)
        print(f"{len(files)} parts written in {time.perf_counter() - t:.1f} s "
              f"({'paper parts + ' if PAPER.is_dir() else 'no paper parts found; '}examples, rigid motions, scalings)",
              flush=True)
        results = {}
        for w in counts:
            proc = subprocess.run([sys.executable, __file__, "--_child", str(cat), str(Path(tmp) / f"out{w}"), str(w),
                                   "--top", str(a.top), "--engine", a.engine],
                                  capture_output=True, text=True, cwd=ROOT)
            if proc.returncode != 0:
                print(proc.stderr, file=sys.stderr)
                return 1
            results[w] = json.loads(proc.stdout.strip().splitlines()[-1])
            print(f"  {w} worker(s): {results[w]['wall_s']:.1f} s", flush=True)
        base = results[counts[0]]["wall_s"]
        rows = []
        for w in counts:
            r = results[w]
            per_part = [x["seconds"] for x in r["rows"] if x.get("seconds") is not None]
            statuses = [x["status"] for x in r["rows"]]
            n = len(r["rows"])
            rows.append((w, a.engine, n, statuses.count("planned"), r["wall_s"], 60.0 * n / r["wall_s"],
                         statistics.median(per_part), r["worker_cpu_s"] / n, base / r["wall_s"],
                         r["worker_rss_mib"], r["driver_rss_mib"], f"{r['load'][0]:.1f} / {r['load'][1]:.1f}"))
        print(table(rows, header=("workers", "engine", "parts", "planned", "wall s", "parts/min",
                                  "median s/part", "CPU s/part", "speed-up", "peak RSS/worker MiB",
                                  "driver RSS MiB", "load avg start/end")))
        print(f"{os.cpu_count()} cores; a load average above the core count means other processes shared them "
              "(the speed-up is then a lower bound; CPU s/part shows the work itself)")
        # the same plans whatever the worker count (timing aside)
        same = all(_plans(Path(tmp) / f"out{counts[0]}", results[counts[0]]["rows"])
                   == _plans(Path(tmp) / f"out{w}", results[w]["rows"]) for w in counts[1:])
        print(f"plans identical across worker counts: {same}; target speed-up 1 -> 2 workers >= 1.8x")
    return 0 if same else 1


def _plans(out: Path, rows: list[dict]) -> dict:
    """part -> sha256 of its plan.json without timing_s (None when the part failed)."""
    import hashlib

    got = {}
    for r in rows:
        p = out / r["dir"] / "plan.json"
        if p.is_file():
            doc = json.loads(p.read_text())
            doc.pop("timing_s", None)
            got[r["part"]] = hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()
        else:
            got[r["part"]] = None
    return got


if __name__ == "__main__":
    sys.exit(main())
