"""Boundary layer mesher speed on the paper parts: median seconds over 5 runs at the defaults.

    python benchmarks/bench_blm.py [--runs 5] [--alpha 0.1mm] [--gamma 135]

Target (issue 2): BLM + convexity + antipodal for the 21k-triangle TLess22 in < 1 s on 2 cores,
so the BLM's share should stay around 0.2-0.3 s there.
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from grasplan.candidates.blm import boundary_layer
from grasplan.cli.common import table
from grasplan.part.mesh import load_part
from grasplan.geometry.units import parse_length

PAPER_DIR = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
PARTS = ["IPAGearShaft.stl", "IPARingScrew.stl", "SileaneBunny.obj", "SileaneGear.stl",
         "SileanePepper.stl", "TLess20.stl", "TLess22.stl"]
TARGET_S = {"TLess22.stl": 0.3}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--alpha", default="0.1mm")
    ap.add_argument("--gamma", type=float, default=135.0)
    args = ap.parse_args()
    alpha = parse_length(args.alpha, name="--alpha")

    paths = [ROOT / "examples" / "parts" / n for n in ("box.stl", "bracket.stl", "gear.stl")]
    paths += [PAPER_DIR / n for n in PARTS if (PAPER_DIR / n).exists()]
    if len(paths) == 3:
        print(f"(paper parts not found in {PAPER_DIR}; set GRASPLAN_PAPER_PARTS)", file=sys.stderr)
    rows, slow = [], []
    for path in paths:
        part = load_part(path)
        times = []
        for _ in range(args.runs):
            # a fresh copy each run: trimesh caches adjacency on the mesh, a real run starts cold
            mesh = part.mesh.copy()
            t0 = time.perf_counter()
            r = boundary_layer(mesh, alpha=alpha, gamma_deg=args.gamma, tol=part.tol)
            times.append(time.perf_counter() - t0)
        med = statistics.median(times)
        target = TARGET_S.get(path.name)
        if target is not None and med > target:
            slow.append(f"{path.name}: {med:.3f} s > {target} s")
        rows.append((path.name, part.triangles, int(len(r.mesh.faces)), round(len(r.mesh.faces) / part.triangles, 2),
                     r.facets, r.surfaces, r.boundary_edges, r.shifted_vertices, r.clamped, med,
                     f"{med / target:.2f}" if target is not None else "-"))
    print(f"BLM at alpha = {alpha * 1e3:g} mm, gamma = {args.gamma:g} deg, median of {args.runs} runs (cold mesh caches)")
    print(table(rows, header=("part", "tri in", "tri out", "ratio", "facets", "surfaces", "bnd edges",
                              "new verts", "clamped", "median s", "median / target")))
    print(f"peak RSS: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")
    for s in slow:
        print(f"SLOW: {s}")
    return 1 if slow else 0


if __name__ == "__main__":
    sys.exit(main())
