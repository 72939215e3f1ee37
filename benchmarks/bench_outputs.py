"""Plan file size and the time to write and read it, compact (``--keep collision_free``, the
default) against full (``--keep all``), per paper part; optionally the size of a ``grasplan batch``
of all of them.

    .venv/bin/python benchmarks/bench_outputs.py [--parts TLess20.stl,...] [--runs 3] [--batch]

Per part, in one process: ``plan(part, "ur5")`` once with the defaults, then medians over
``--runs`` of ``PlanResult.write`` and of ``load_result`` for each form, the file sizes and their
ratio, and whether both forms read back to the same planned grasps (ids, order, paths) and counts.
``--batch``: ``grasplan batch`` of the parts into a temporary folder with each ``--keep``, the
folder's total size (plans, views, logs). Targets: bracket <= 0.5 MB, every paper part <= 3 MB,
the batch of the 7 paper parts <= 20 MB.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

PAPER = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
ALL_PARTS = ("TLess20.stl", "TLess22.stl", "SileanePepper.stl", "SileaneGear.stl", "SileaneBunny.obj",
             "IPAGearShaft.stl", "IPARingScrew.stl")
FORMS = ("collision_free", "all")


def _median_time(fn, runs: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(runs):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def _same(a, b) -> bool:
    if a.counts() != b.counts() or a.planned_ids() != b.planned_ids():
        return False
    return all(np.array_equal(a.grasp(i).motion.path, b.grasp(i).motion.path) for i in a.planned_ids())


def part_rows(path: Path, runs: int, tmp: Path) -> dict:
    from grasplan import plan
    from grasplan.part.mesh import load_part
    from grasplan.results.reader import load_result

    res = plan(load_part(path), "ur5")
    row: dict = {"part": path.name, "poses": res.counts()["grasps"], "planned": len(res.planned_ids())}
    loaded = {}
    for keep in FORMS:
        out = tmp / f"{path.stem}.{keep}.json"
        row[f"write_{keep}"], _ = _median_time(lambda: res.write(out, keep=keep), runs)
        row[f"read_{keep}"], loaded[keep] = _median_time(lambda: load_result(out), runs)
        row[f"mb_{keep}"] = out.stat().st_size / 1e6
    row["same"] = _same(loaded["collision_free"], loaded["all"]) and _same(loaded["all"], res)
    return row


def batch_sizes(parts: list[Path], tmp: Path) -> dict[str, float]:
    out = {}
    for keep in FORMS:
        d = tmp / f"batch_{keep}"
        subprocess.run([str(Path(sys.executable).with_name("grasplan")), "batch", *map(str, parts), "-o", str(d),
                        "--keep", keep], check=False, capture_output=True)
        out[keep] = sum(f.stat().st_size for f in d.rglob("*") if f.is_file()) / 1e6
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--parts", default=",".join(ALL_PARTS))
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--batch", action="store_true", help="also the size of a grasplan batch of the parts")
    a = ap.parse_args()
    parts = [p if p.is_absolute() else PAPER / p for p in map(Path, a.parts.split(","))]
    missing = [str(p) for p in parts if not p.is_file()]
    if missing:
        sys.exit(f"bench_outputs: missing parts {missing} (set GRASPLAN_PAPER_PARTS)")
    parts = [ROOT / "examples" / "parts" / "bracket.stl", *parts]
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        print(f"{'part':<20} {'poses':>7} {'planned':>7} {'MB compact':>10} {'MB all':>8} {'ratio':>6} "
              f"{'write s':>15} {'read s':>15} same")
        for p in parts:
            r = part_rows(p, a.runs, tmp)
            print(f"{r['part']:<20} {r['poses']:>7} {r['planned']:>7} {r['mb_collision_free']:>10.2f} "
                  f"{r['mb_all']:>8.2f} {r['mb_all'] / r['mb_collision_free']:>6.1f} "
                  f"{r['write_collision_free']:>6.3f} / {r['write_all']:<6.3f} "
                  f"{r['read_collision_free']:>6.3f} / {r['read_all']:<6.3f} {r['same']}")
        if a.batch:
            sizes = batch_sizes(parts[1:], tmp)
            print(f"batch of {len(parts) - 1} parts: {sizes['collision_free']:.1f} MB compact, {sizes['all']:.1f} MB "
                  "with --keep all (plans, views, logs)")


if __name__ == "__main__":
    main()
