"""Grasp quality vs MuJoCo lift-and-shake (issue 11), on the paper parts and the examples.

Per part: the collision-free grasps of ``compute_grasps`` are scored with the weights of
``configs/scoring.yaml`` (reachability terms of ``grasplan.scoring`` + ``gravity_margin`` and
``epsilon`` of ``grasplan.quality``), ranked with the diversity rule (``distinct_order``); the top
20 and 20 random collision-free grasps (seeded) are simulated. Prints a table: hold rate of the
top 20 (target >= 90 %), of the random 20, Spearman correlation of gravity_margin with simulated
slip (expected negative), and seconds per 20 simulations (median of the two batches; target < 10 s,
CoACD decomposition cached, its first computation reported separately), then peak RSS.

    .venv/bin/python benchmarks/quality.py [--parts DIR] [--top 20] [--decomposition coacd|hull]
"""
from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from grasplan.grasps import compute_grasps
from grasplan.mass import mass_properties
from grasplan.mesh import load_part
from grasplan.params import CandidateParams
from grasplan.quality import grasp_quality, load_scoring, score_quality_terms
from grasplan.scoring import TERMS, ScoreContext, distinct_order
from grasplan.simulate import convex_pieces, simulate_grasps

PAPER = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
PAPER_PARTS = ["IPAGearShaft.stl", "IPARingScrew.stl", "SileaneBunny.obj", "SileaneGear.stl",
               "SileanePepper.stl", "TLess20.stl", "TLess22.stl"]


def score(res, q, cfg) -> np.ndarray:
    """Weighted score of the grasps ``res`` restricted to ``ok`` rows (the quality ``q`` is for those)."""
    ctx = ScoreContext(res["mesh"], res["T_world_part"], res["T"], res["width"], res["max_opening"])
    phys = score_quality_terms(q, cfg)
    total = np.zeros(len(res["width"]))
    wsum = 0.0
    for name, w in cfg.weights:
        if w == 0:
            continue
        term = phys[name] if name in phys else TERMS[name](ctx)
        total += w * term
        wsum += w
    return total / wsum


def run_part(path: Path, args, cfg) -> dict:
    part = load_part(path)
    mu = float(CandidateParams.default("mu"))
    gr = compute_grasps(part, gripper="schunk_egp_c_40", cell="table")
    ok = np.flatnonzero(np.asarray(gr.status) == "ok")
    c = gr.cand.candidates
    ci = gr.frames.candidate[ok]
    T = gr.frames.T_part_tcp[ok]
    width = c.width[ci]
    mp = mass_properties(part.mesh)
    t = time.perf_counter()
    q = grasp_quality(part.mesh, mp, gr.gripper, T, c.contacts[ci], c.normals[ci], width,
                      T_world_part=gr.T_world_part, mu=mu)
    t_quality = time.perf_counter() - t
    res = {"mesh": part.mesh, "T_world_part": gr.T_world_part, "T": T, "width": width,
           "max_opening": gr.gripper.max_opening}
    s = score(res, q, cfg)
    order = distinct_order(T, np.argsort(-s, kind="stable"))
    top = order[: args.top]
    rng = np.random.default_rng(args.seed)
    rand = rng.choice(len(ok), size=min(args.top, len(ok)), replace=False)
    t = time.perf_counter()
    convex_pieces(part.mesh, decomposition=args.decomposition)
    t_decomp = time.perf_counter() - t
    sims, secs = [], []
    for sel in (top, rand):
        r = simulate_grasps(part.mesh, gr.gripper, gr.T_world_part, T[sel], width[sel], table_z=gr.cell.table_z,
                            mass_props=mp, mu=mu, decomposition=args.decomposition)
        sims.append(r)
        secs.append(r.seconds * 20.0 / max(len(sel), 1))
    gm = np.concatenate([q.gravity_margin[top], q.gravity_margin[rand]])
    slip = np.concatenate([sims[0].slip_m, sims[1].slip_m])
    rho = spearmanr(gm, slip).statistic if np.ptp(gm) > 0 and np.ptp(slip) > 0 else float("nan")
    return {"part": path.name, "ok": len(ok), "mass_kg": mp.mass, "top_hold": sims[0].success.mean(),
            "rand_hold": sims[1].success.mean(), "spearman": rho, "s_per_20": float(np.median(secs)),
            "decomp_s": t_decomp, "pieces": sims[0].pieces, "quality_s": t_quality}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--parts", type=Path, default=PAPER)
    ap.add_argument("--top", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--decomposition", choices=("coacd", "hull"), default="coacd")
    ap.add_argument("--only", nargs="*", default=None, help="part file names to run (default: all)")
    args = ap.parse_args()
    cfg = load_scoring()
    paths = [args.parts / p for p in PAPER_PARTS if (args.parts / p).exists()]
    paths += sorted((ROOT / "examples" / "parts").glob("*.stl"))
    if args.only:
        paths = [p for p in paths if p.name in args.only]
    if not (args.parts / PAPER_PARTS[0]).exists():
        print(f"(paper parts not found in {args.parts}; examples only)")
    rows = []
    for p in paths:
        row = run_part(p, args, cfg)
        rows.append(row)
        print(f"{row['part']:<20} ok {row['ok']:>6}  top {100 * row['top_hold']:5.1f} %  random "
              f"{100 * row['rand_hold']:5.1f} %  spearman {row['spearman']:+.2f}  {row['s_per_20']:.2f} s/20", flush=True)
    hdr = f"{'part':<20} {'ok':>6} {'kg':>6} {'top20 hold':>10} {'rand20 hold':>11} {'spearman(gm,slip)':>17} " \
          f"{'s/20 sims':>9} {'pieces':>6} {'coacd s':>7} {'quality s':>9}"
    print()
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        print(f"{r['part']:<20} {r['ok']:>6} {r['mass_kg']:>6.3f} {100 * r['top_hold']:>9.0f}% {100 * r['rand_hold']:>10.0f}% "
              f"{r['spearman']:>17.2f} {r['s_per_20']:>9.2f} {r['pieces']:>6} {r['decomp_s']:>7.1f} {r['quality_s']:>9.2f}")
    top = np.array([r["top_hold"] for r in rows])
    print("-" * len(hdr))
    print(f"{'median':<20} {'':>6} {'':>6} {100 * np.median(top):>9.0f}% "
          f"{100 * np.median([r['rand_hold'] for r in rows]):>10.0f}% {np.nanmedian([r['spearman'] for r in rows]):>17.2f} "
          f"{np.median([r['s_per_20'] for r in rows]):>9.2f}")
    print(f"parts with top-20 hold rate >= 90 %: {int((top >= 0.9).sum())}/{len(rows)} (target: all); "
          f"s per 20 sims: max {max(r['s_per_20'] for r in rows):.2f} (target < 10)")
    print(f"peak RSS: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
