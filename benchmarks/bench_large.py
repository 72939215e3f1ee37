"""Large parts: ``grasplan candidates`` and ``grasplan grasps`` on big spheres and triangle soups.

    .venv/bin/python benchmarks/bench_large.py [--repeat 1] [--spheres 100k,250k,...] [--soups 5k,20k,50k]
                                               [--radius 20mm] [--commands candidates,grasps] [--part PATH ...]

Parts are generated in a temporary folder (never in the repository): UV spheres (``--radius``,
default 20 mm so that a 50 mm gripper can hold them: every antipodal pair is a real candidate, the
hard case for the curved-surface search) of the given triangle counts up to
``grasplan.part.mesh.MAX_TRIANGLES``, and random triangle soups (vertices ~ N(0, 10 mm), seed 0, the
generator of the fuzz suite's soups). Each command runs as a whole process (``--units mm``), in a
fresh interpreter; per run: exit code, wall time, CPU time (user + system of the process, from
``wait4``) and peak RSS (VmHWM); and the stage seconds the command prints. The table shows the
medians over ``--repeat`` runs. Exit code 3 with a message is a refusal (a work limit saying what
would run), listed as such. The machine is shared: CPU time is the figure to compare.
"""
from __future__ import annotations

import argparse
import os
import re
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(ROOT / "tests"))

from fresh import _CLI  # noqa: E402
from fuzz_cases import uv_sphere  # noqa: E402

from grasplan.cli.common import table  # noqa: E402
from grasplan.part.mesh import MAX_TRIANGLES  # noqa: E402

STAGES = ("load", "blm", "convexity", "antipodal", "stable_pose", "frames", "collision", "quality")
_STAGE_ROW = re.compile(r"^(?:seconds: )?([a-z_]+)(?: \(s\))?\s+([0-9]+\.[0-9]+)\s*$")


def _count(text: str) -> int:
    t = text.strip().lower()
    mult = {"k": 1_000, "m": 1_000_000}.get(t[-1:], 1)
    return int(float(t[:-1] if mult > 1 else t) * mult)


def _stl(path: Path, tri: np.ndarray) -> None:
    rec = np.zeros(len(tri), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = tri
    path.write_bytes(b"grasplan bench_large".ljust(80, b" ") + struct.pack("<I", len(tri)) + rec.tobytes())


def sphere_triangles(n_target: int, radius_mm: float) -> np.ndarray:
    """(m, 3, 3) triangles of a UV sphere with about ``n_target`` triangles, wound outwards, millimetres."""
    v, f = uv_sphere(n_target, radius_mm)
    return v[f]


def soup(m: int, seed: int = 0) -> np.ndarray:
    """(m, 3, 3) random triangles, vertices ~ N(0, 10 mm) (the fuzz suite's soup generator)."""
    return (np.random.default_rng(seed).normal(size=(3 * m, 3)) * 10.0).reshape(m, 3, 3)


def run(args: list[str]) -> dict:
    """One ``grasplan *args`` in a fresh interpreter: exit code, wall, CPU, peak RSS, stage seconds, message."""
    with tempfile.TemporaryFile("w+") as fo, tempfile.TemporaryFile("w+") as fe:
        t = time.perf_counter()
        p = subprocess.Popen([sys.executable, "-c", _CLI, *args], stdout=fo, stderr=fe, text=True, cwd=ROOT)
        _, status, usage = os.wait4(p.pid, 0)     # the child's own rusage (CPU of this run alone)
        wall = time.perf_counter() - t
        p.returncode = os.waitstatus_to_exitcode(status)
        fo.seek(0)
        fe.seek(0)
        out, err = fo.read(), fe.read()
    rss = [ln for ln in err.splitlines() if ln.startswith("RSS_KIB ")]
    stages: dict[str, float] = {}
    for ln in out.splitlines():
        m = _STAGE_ROW.match(ln.strip())
        if m and m.group(1) in STAGES:
            stages[m.group(1)] = float(m.group(2))
    errors = [ln for ln in err.splitlines() if ln.startswith("grasplan: error:")]
    return {"rc": p.returncode, "wall": wall, "cpu": usage.ru_utime + usage.ru_stime,
            "rss": float(rss[-1].split()[1]) / 1024 if rss else float("nan"), "stages": stages,
            "error": errors[-1][len("grasplan: error: "):] if errors else ""}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=1, help="runs per part and command (medians)")
    ap.add_argument("--spheres", default="100k,250k,500k,750k,1m",
                    help="sphere triangle counts (capped at grasplan.part.mesh.MAX_TRIANGLES, duplicates dropped)")
    ap.add_argument("--soups", default="5k,20k,50k", help="soup triangle counts")
    ap.add_argument("--radius", default="20", help="sphere radius, mm")
    ap.add_argument("--commands", default="candidates,grasps")
    ap.add_argument("--extra", default="", help="extra options for every command, e.g. '--spacing 3mm'")
    ap.add_argument("--part", action="append", default=[], help="also this mesh file (millimetres), repeatable")
    a = ap.parse_args()
    radius = float(a.radius.removesuffix("mm"))
    parts: list[tuple[str, str, np.ndarray]] = []
    sizes = sorted({min(_count(s), MAX_TRIANGLES) for s in a.spheres.split(",") if s})
    for n in sizes:
        tri = sphere_triangles(n, radius)
        parts.append((f"sphere r{radius:g}mm", f"{len(tri):,}", tri))
    for n in (_count(s) for s in a.soups.split(",") if s):
        parts.append(("soup", f"{n:,}", soup(n)))
    for extra in a.part:
        parts.append((Path(extra).name, "", np.zeros((0, 3, 3))))
    rows = []
    with tempfile.TemporaryDirectory(prefix="grasplan-bench-large-") as tmp:
        for (name, tris, tri), given in zip(parts, [None] * (len(parts) - len(a.part)) + a.part):
            path = Path(given) if given else Path(tmp) / "part.stl"
            if not given:
                _stl(path, tri)
            for cmd in a.commands.split(","):
                runs = [run([cmd, str(path), "-o", str(Path(tmp) / "out.json"), "--units", "mm", *a.extra.split()])
                        for _ in range(max(1, a.repeat))]
                med = {k: statistics.median(r[k] for r in runs) for k in ("wall", "cpu", "rss")}
                st = {s: statistics.median(r["stages"].get(s, 0.0) for r in runs) for s in STAGES}
                rc = runs[-1]["rc"]
                rows.append((name, tris, cmd, rc, round(med["wall"], 1), round(med["cpu"], 1), round(med["rss"]),
                             " ".join(f"{s} {v:.1f}" for s, v in st.items() if v >= 0.05)))
                print(table([rows[-1]]), flush=True)
                if runs[-1]["error"]:
                    print(f"    exit {rc}: {runs[-1]['error']}", flush=True)
    load = os.getloadavg()
    print(f"\nmedians of {a.repeat} run(s); load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; "
          f"grasplan.part.mesh.MAX_TRIANGLES {MAX_TRIANGLES:,}")
    print(table(rows, header=("part", "triangles", "command", "exit", "wall s", "CPU s", "peak RSS MiB",
                              "stage seconds (as printed)")))
    return 0


if __name__ == "__main__":
    sys.exit(main())
