"""Benchmark of ``grasplan batch``: throughput on 1 and 2 workers, speed-up, peak RSS per worker;
with ``--scaling``, the batch's bookkeeping against the manifest's length.

    python benchmarks/batch.py [--parts 100] [--top 5] [--workers 1,2] [--engine local|ray]
    python benchmarks/batch.py --scaling [--rows 1000,2000,8000,30000] [--formats csv,yaml,csv-seed]

The catalogue: the paper's parts (``../shared/parts/paper`` or ``$GRASPLAN_PAPER_PARTS``, when
present) and the example parts, each written again under random rigid transforms and scalings
(0.8-1.25, so a millimetre file stays millimetres) until ``--parts`` files exist, in a temporary
folder. Each worker count runs the same catalogue into a fresh output folder in its own process;
the peak RSS of the workers is that process's ``RUSAGE_CHILDREN`` high-water mark (the largest
worker), the driver's is ``RUSAGE_SELF``; CPU s/part is the workers' user + system time per part
and the machine's 1-minute load average is printed at the start and end of each run (the speed-up
is only meaningful when nothing else competes for the cores). Target: speed-up >= 1.8x from 1 to 2 workers.

``--scaling``: manifests of 1,000 to 30,000 rows, each naming its own small part file (a
distinct tetrahedron, so no row is a duplicate of another), as CSV (``path,top``), YAML
(``- {path: ..., top: ...}``) and CSV with a per-row ``seed`` (every row its own option set).
Nothing is planned: an engine that answers every part at once stands in for the workers, so the
table shows what the driver itself costs per row. Columns: ``setup s`` from ``run_batch`` to the
engine's start (manifest read and validated, parts hashed, options hashed, output folders named,
the output folder checked, the resume scan), ``finish s`` the engine's answers filed (each part's
``done.json`` and ``log.txt``, then ``summary.csv``/``summary.json``/``index.html``), ``resume s`` the
same command again (every part already done: the whole run), CPU seconds of the setup, and the
setup per 1,000 rows (flat when linear). fsync is off in these runs (``--fsync`` keeps it): the
table measures the bookkeeping, not the disk. Each size runs in its own process with a time
limit (``--limit``, a row shows ``>limit`` when it is reached). Target: 30,000 rows set up in
under 5 s, in CSV and in YAML.
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
    from grasplan.batch.run import run_batch
    from grasplan.batch.options import BatchOptions
    from grasplan.config.params import PlanParams

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
    ap.add_argument("--scaling", action="store_true", help="time the bookkeeping against the manifest's rows")
    ap.add_argument("--rows", default="1000,2000,8000,30000", help="--scaling: comma-separated row counts")
    ap.add_argument("--formats", default="csv,yaml,csv-seed", help="--scaling: csv, yaml, csv-seed")
    ap.add_argument("--limit", type=float, default=300.0, help="--scaling: seconds allowed per size")
    ap.add_argument("--fsync", action="store_true", help="--scaling: keep fsync on (measures the disk too)")
    ap.add_argument("--_scaling_child", nargs=3, metavar=("ROWS", "FORMAT", "FOLDER"), help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a._scaling_child:
        rows, fmt, folder = a._scaling_child
        print(json.dumps(scaling_one(int(rows), fmt, Path(folder), fsync=a.fsync)))
        return 0
    if a.scaling:
        return scaling_main(a)
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

    got: dict[str, str | None] = {}
    for r in rows:
        p = out / r["dir"] / "plan.json"
        if p.is_file():
            doc = json.loads(p.read_text())
            doc.pop("timing_s", None)
            got[r["part"]] = hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()
        else:
            got[r["part"]] = None
    return got


# ------------------------------------------------------------------------------------ --scaling
#: an ASCII STL tetrahedron (1 cm); ``{name}`` makes every file's bytes (and sha256) its own
_TETRA = """solid {name}
facet normal 0 0 -1
outer loop
vertex 0 0 0
vertex 10 0 0
vertex 0 10 0
endloop
endfacet
facet normal 0 -1 0
outer loop
vertex 0 0 0
vertex 0 0 10
vertex 10 0 0
endloop
endfacet
facet normal -1 0 0
outer loop
vertex 0 0 0
vertex 0 10 0
vertex 0 0 10
endloop
endfacet
facet normal 0.577 0.577 0.577
outer loop
vertex 10 0 0
vertex 0 0 10
vertex 0 10 0
endloop
endfacet
endsolid {name}
"""


def scaling_manifest(folder: Path, rows: int, fmt: str) -> Path:
    """``rows`` part files under ``folder/parts`` and the manifest naming them (see the module doc)."""
    parts = folder / "parts"
    parts.mkdir()
    names = [f"p{i:05d}.stl" for i in range(rows)]
    for n in names:
        (parts / n).write_text(_TETRA.format(name=n[:-4]))
    if fmt == "yaml":
        m = folder / "parts.yaml"
        m.write_text("defaults: {units: mm}\nparts:\n"
                     + "".join(f"  - {{path: parts/{n}, top: {1 + i % 5}}}\n" for i, n in enumerate(names)))
    elif fmt == "csv-seed":
        m = folder / "parts.csv"
        m.write_text("path,units,top,seed\n" + "".join(f"parts/{n},mm,{1 + i % 5},{i}\n" for i, n in enumerate(names)))
    elif fmt == "csv":
        m = folder / "parts.csv"
        m.write_text("path,units,top\n" + "".join(f"parts/{n},mm,{1 + i % 5}\n" for i, n in enumerate(names)))
    else:
        raise SystemExit(f"--formats: unknown {fmt!r}; use csv, yaml or csv-seed")
    return m


def scaling_one(rows: int, fmt: str, folder: Path, *, fsync: bool = False) -> dict:
    """Setup, finish and resume seconds of a ``rows``-row manifest written in the empty ``folder``,
    in this process (see the module doc)."""
    import zlib

    from grasplan.batch.run import run_batch
    from grasplan.batch.engines import ENGINES

    marks: dict[str, float] = {}

    def answer_all(jobs, **_kw):
        """An engine that plans nothing: every part 'planned' at once, with a one-line log."""
        marks["engine"], marks["engine_cpu"] = time.perf_counter(), time.process_time()
        for job in jobs:
            row = {"status": "planned", "exit_code": 0, "planned": 1, "grasps": 1, "best_score": 0.5,
                   "timing_s": {"load": 0.001, "total": 0.01}, "error": ""}
            yield job, {"row": row, "files": {"log.txt": zlib.compress(f"part: {job.path}\n".encode())}}, None

    ENGINES["bench-answer-all"] = answer_all
    if not fsync:
        os.fsync = lambda fd: None  # the bookkeeping, not the disk
    m = scaling_manifest(folder, rows, fmt)
    out = folder / "out"
    t0, c0 = time.perf_counter(), time.process_time()
    s = run_batch([m], out, engine="bench-answer-all", workers=1)
    t1 = time.perf_counter()
    assert len(s.rows) == rows and s.counts["planned"] == rows, s.counts
    t2 = time.perf_counter()
    s = run_batch([m], out, engine="bench-answer-all", workers=1)
    t3 = time.perf_counter()
    assert s.counts["resumed"] == rows, s.counts
    return {"setup_s": marks["engine"] - t0, "setup_cpu_s": marks["engine_cpu"] - c0, "finish_s": t1 - marks["engine"],
            "resume_s": t3 - t2}


def scaling_main(a: argparse.Namespace) -> int:
    from grasplan.cli.common import table

    rows_list = [int(r) for r in a.rows.split(",")]
    out = []
    print(f"load average at start: {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores)", flush=True)
    for fmt in a.formats.split(","):
        for n in rows_list:
            with tempfile.TemporaryDirectory(prefix="grasplan-bench-scaling-") as tmp:  # removed whatever happens
                cmd = [sys.executable, __file__, "--_scaling_child", str(n), fmt, tmp, *(["--fsync"] if a.fsync else [])]
                try:
                    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=a.limit)
                except subprocess.TimeoutExpired:
                    proc = None
            if proc is None:
                out.append((n, fmt, f">{a.limit:.0f}", "", "", "", ""))
                print(f"  {fmt} {n} rows: more than {a.limit:.0f} s", flush=True)
                continue
            if proc.returncode != 0:
                msg = (proc.stderr.strip().splitlines() or ["?"])[-1]
                out.append((n, fmt, "refused", "", "", "", msg[:100]))
                print(f"  {fmt} {n} rows: {msg[:200]}", flush=True)
                continue
            r = json.loads(proc.stdout.strip().splitlines()[-1])
            out.append((n, fmt, round(r["setup_s"], 2), round(r["setup_cpu_s"], 2), round(r["finish_s"], 2),
                        round(r["resume_s"], 2), round(1000 * r["setup_s"] / n, 3)))
            print(f"  {fmt} {n} rows: setup {r['setup_s']:.2f} s", flush=True)
    print(table(out, header=("rows", "format", "setup s", "setup CPU s", "finish s", "resume s",
                             "setup s per 1k rows")))
    print(f"load average at end: {os.getloadavg()[0]:.2f}; target: 30,000 rows set up in under 5 s "
          f"(fsync {'on' if a.fsync else 'off'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
