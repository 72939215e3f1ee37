"""Speed of ``grasplan scene drop``: mixed piles of the paper parts dropped into the packaged bin.

    python benchmarks/bench_drop.py [--seeds 5] [--sizes 5,10] [--density 1200]

Piles: 5 parts = one each of TLess20, TLess22, SileanePepper, IPARingScrew, SileaneGear (issue 21's
clutter rounds); 10 parts = two of each. Each pile is dropped for seeds 0..N-1 in this process
after one warm-up (the CoACD decompositions are computed once and cached: their first-time cost
is printed separately, it is not part of a drop). Per pile: wall and CPU seconds (the process's
user + system time; on a shared machine wall time grows with the load, CPU time does not),
simulated seconds, the slowest drop's settling time and the tries; medians over the seeds, and
the machine's 1-minute load average. Target (issue 21): a 5-part round, drop and picks, simulated
in < 60 s on 2 cores: the drop should be a small share of it.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from grasplan.cell.model import load_cell  # noqa: E402
from grasplan.cli.common import table  # noqa: E402
from grasplan.piles.scene_file import part_name  # noqa: E402
from grasplan.sim.drop import DropParams, PileItem, drop_pile  # noqa: E402
from grasplan.part.mesh import load_part  # noqa: E402
from grasplan.sim.simulate import convex_pieces  # noqa: E402

PAPER_DIR = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
PARTS = ["TLess20.stl", "TLess22.stl", "SileanePepper.stl", "IPARingScrew.stl", "SileaneGear.stl"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--sizes", default="5,10", help="pile sizes, multiples of 5")
    ap.add_argument("--density", type=float, default=1200.0)
    args = ap.parse_args()
    missing = [p for p in PARTS if not (PAPER_DIR / p).exists()]
    if missing:
        print(f"skipped: paper parts {', '.join(missing)} not found in {PAPER_DIR} (set GRASPLAN_PAPER_PARTS)")
        return 0
    parts = {p: load_part(PAPER_DIR / p) for p in PARTS}
    rows = []
    for p, part in parts.items():  # first-time decomposition (or the cache read) per part
        t = time.perf_counter()
        pieces = convex_pieces(part.mesh.trimesh)
        rows.append((p, len(part.faces), len(pieces), round(time.perf_counter() - t, 2)))
    print(table(rows, header=("part", "triangles", "pieces", "decomposition_s (0: cached)")))
    cell = load_cell("bin")
    out = []
    for size in (int(s) for s in args.sizes.split(",")):
        k = max(1, size // len(PARTS))
        items = [PileItem(part_name(p), parts[p], k) for p in PARTS]
        drop_pile(cell, items, params=DropParams(seed=10_000, density=args.density))  # warm-up
        wall, cpu, sim, slow, tries = [], [], [], [], []
        load0 = os.getloadavg()[0]
        for seed in range(args.seeds):
            t, c = time.perf_counter(), time.process_time()
            r = drop_pile(cell, items, params=DropParams(seed=seed, density=args.density))
            wall.append(time.perf_counter() - t)
            cpu.append(time.process_time() - c)
            sim.append(r.sim_s)
            slow.append(max(d.settle_s for d in r.drops))
            tries.append(sum(d.attempts for d in r.drops) - len(r.drops))
        med = statistics.median
        out.append((len(PARTS) * k, args.seeds, round(med(wall), 2), round(max(wall), 2), round(med(cpu), 2),
                    round(med(cpu) / (len(PARTS) * k), 2), round(med(sim), 2), round(max(slow), 2), sum(tries),
                    f"{load0:.1f}-{os.getloadavg()[0]:.1f}"))
    print(table(out, header=("parts", "seeds", "wall_s", "wall_max_s", "cpu_s", "cpu_s/part", "sim_s",
                             "slowest_drop_sim_s", "retries", "load")))
    return 0


if __name__ == "__main__":
    sys.exit(main())
