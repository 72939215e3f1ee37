"""Gripper-vs-part pose checks per second (target >= 20 000 /s on this 2-core machine).

Runs the full collision check (body + both swept jaws vs the part BVH, table half-space) of the
poses ``grasplan grasps`` builds for a part with the default ``CandidateParams`` / ``GraspParams``
(``--thin 0`` poses every candidate, as before thinning), several times, and prints the median
rate, its ratio to the target and the process's peak RSS.

    python benchmarks/bench_collision.py [PART ...] [--runs 5] [--poses 100000] [--thin 3mm]
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from grasplan.candidates.pipeline import compute_candidates
from grasplan.cell.model import load_cell
from grasplan.grasps.collision import GripperCollider
from grasplan.grasps.frames import grasp_frames
from grasplan.gripper.load import load_gripper
from grasplan.part.mesh import load_part
from grasplan.config.params import PAPER_GRIPPER, CandidateParams, GraspParams
from grasplan.cell.resting import stable_pose
from grasplan.candidates.thinning import thin_candidates
from grasplan.geometry.units import parse_length

PAPER = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
TARGET_PER_S = 20_000


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("parts", nargs="*", default=[str(PAPER / "TLess20.stl"), str(PAPER / "SileanePepper.stl")])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--poses", type=int, default=100_000, help="poses per run (at most)")
    ap.add_argument("--thin", default=f"{GraspParams.default('thin_spacing')}",
                    help="thinning spacing (length; 0 = pose every candidate)")
    args = ap.parse_args()
    gp = GraspParams(thin_spacing=parse_length(args.thin, name="--thin", allow_zero=True))
    g = load_gripper(PAPER_GRIPPER)
    cell = load_cell()
    rows = []
    for path in args.parts:
        if not Path(path).exists():
            print(f"skip {path}: not found", file=sys.stderr)
            continue
        part = load_part(path)
        T = stable_pose(part.mesh, cell)
        # the poses of grasplan.grasps.pipeline.compute_grasps: search up to the gripper's opening, thinning,
        # swapped duplicates posed once for a symmetric gripper
        c = compute_candidates(part, CandidateParams(max_opening=g.max_opening)).candidates
        select = (thin_candidates(c, spacing=gp.thin_spacing, axis_step_deg=gp.thin_axis_deg)
                  if gp.thin_spacing > 0 else None)
        fr = grasp_frames(c, roll_step_deg=gp.roll_step_deg, max_width=g.max_opening, dedupe_swapped=g.symmetric,
                          merge_distance=gp.merge_distance, select=select, reference=T[:3, :3].T @ [0, 0, -1.0])
        sel = np.random.default_rng(0).permutation(len(fr))[: args.poses]
        Tp, w = fr.T_part_tcp[sel], c.width[fr.candidate[sel]]
        col = GripperCollider(part.mesh, g, cell, T)  # part BVH built once
        rates, calls = [], 0
        for _ in range(args.runs):
            col.coal_calls = 0
            t = time.perf_counter()
            st = col.check(Tp, w)
            rates.append(len(w) / (time.perf_counter() - t))
            calls = col.coal_calls
        ok = int(np.count_nonzero(st == "ok"))
        rows.append((Path(path).name, len(part.mesh.faces), len(w), ok, calls / len(w), statistics.median(rates), min(rates), max(rates)))
    print(f"poses of `grasplan grasps` (roll step {gp.roll_step_deg:g} deg, thin {gp.thin_spacing * 1e3:g} mm), "
          f"median of {args.runs} runs")
    print(f"{'part':<20}{'faces':>8}{'poses':>9}{'ok':>7}{'coal/pose':>11}{'median/s':>11}{'min/s':>10}{'max/s':>10}"
          f"{'median/target':>15}")
    for r in rows:
        print(f"{r[0]:<20}{r[1]:>8}{r[2]:>9}{r[3]:>7}{r[4]:>11.2f}{r[5]:>11.0f}{r[6]:>10.0f}{r[7]:>10.0f}"
              f"{r[5] / TARGET_PER_S:>15.2f}")
    print(f"target: >= {TARGET_PER_S} poses/s; peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()
