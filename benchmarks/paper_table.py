"""Reproduce the paper's Table I (Vogt et al. 2021) on the real parts in ../shared/parts/paper/,
with the paper's candidate definition (``method="paper"``: one contact pair per face pair).

    .venv/bin/python benchmarks/paper_table.py                 # both modes: CLI defaults, per-part config
    .venv/bin/python benchmarks/paper_table.py --mode defaults
    .venv/bin/python benchmarks/paper_table.py --neighbourhood vertex   # convexity variant (see docs)

For every part: candidates without and with the BLM, triangles pre/post, gain, seconds per stage.
Mode ``defaults`` uses exactly the CLI's defaults (``grasplan candidates PART``); mode ``config``
takes alpha/gamma per part from configs/paper_parts.yaml (the paper's hand-picked values).
The headline (BLM gain >= 38 % on at least 5 of the 6 sharp-edged parts, i.e. all but the bunny)
is checked with the defaults; the script exits 1 if it does not hold.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from grasplan.candidates.blm import boundary_layer  # noqa: E402
from grasplan.candidates.pipeline import CandidateParams, compute_candidates, find_candidates  # noqa: E402
from grasplan.cli.common import table  # noqa: E402
from grasplan.candidates.convexity import classify_convexity  # noqa: E402
from grasplan.part.mesh import load_part  # noqa: E402
from grasplan.geometry.units import parse_length  # noqa: E402

PAPER_DIR = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
CONFIG = ROOT / "configs" / "paper_parts.yaml"
SUFFIXES = (".stl", ".obj", ".ply")
HEADLINE_GAIN = 0.38


def run(part, params: CandidateParams, neighbourhood: str):
    """compute_candidates, or the same stages with another convexity neighbourhood."""
    if neighbourhood == "edge":
        r = compute_candidates(part, params)
        return r.counts(), r.timing_s
    timing = {"load": 0.0}
    t = time.perf_counter()
    mesh = boundary_layer(part.mesh, alpha=params.alpha, gamma_deg=params.gamma_deg, tol=part.tol).mesh if params.blm else part.mesh
    timing["blm"] = time.perf_counter() - t if params.blm else 0.0
    t = time.perf_counter()
    convex = classify_convexity(mesh, d_shift=params.d_shift, tol=part.tol, neighbourhood=neighbourhood)
    timing["convexity"] = time.perf_counter() - t
    t = time.perf_counter()
    c = find_candidates(mesh, convex, max_opening=params.max_opening, beta_deg=params.beta_deg,
                        epsilon=params.epsilon, mu=params.mu, tol=part.tol, method=params.method)
    timing["antipodal"] = time.perf_counter() - t
    counts = {"triangles_in": part.triangles, "triangles_blm": len(mesh.faces) if params.blm else None,
              "convex_faces": int(convex.sum()), "candidates": len(c)}
    return counts, timing


def table_for(parts, mode: str, config: dict, neighbourhood: str):
    rows, gains = [], {}
    for path in parts:
        t0 = time.perf_counter()
        part = load_part(path)
        t_load = time.perf_counter() - t0
        if mode == "defaults":
            params, label, do_blm = CandidateParams(method="paper"), "0.1/135", True
        else:
            cfg = config.get(path.name, {})
            do_blm = bool(cfg.get("blm", True))
            alpha = parse_length(cfg["alpha"], name="alpha") if do_blm else 1e-4
            gamma = float(cfg.get("gamma_deg", 135.0)) if do_blm else 135.0
            params = CandidateParams(alpha=alpha, gamma_deg=gamma, method="paper")
            label = f"{alpha * 1e3:g}/{gamma:g}" if do_blm else "no BLM"
        pre, t_pre = run(part, CandidateParams(**{**params.to_json(), "blm": False}), neighbourhood)
        if do_blm:
            post, t_post = run(part, params, neighbourhood)
            gain = (post["candidates"] - pre["candidates"]) / max(pre["candidates"], 1)
            gains[path.name] = gain
            rows.append((path.name, label, pre["triangles_in"], post["triangles_blm"], pre["convex_faces"],
                         post["convex_faces"], pre["candidates"], post["candidates"], f"{100 * gain:+.0f} %",
                         t_load, t_pre["convexity"] + t_pre["antipodal"], t_post["blm"], t_post["convexity"],
                         t_post["antipodal"], t_load + t_post["blm"] + t_post["convexity"] + t_post["antipodal"]))
        else:
            rows.append((path.name, label, pre["triangles_in"], "-", pre["convex_faces"], "-", pre["candidates"], "-",
                         "-", t_load, t_pre["convexity"] + t_pre["antipodal"], "-", "-", "-", "-"))
    header = ("part", "alpha mm/gamma", "tri pre", "tri post", "convex pre", "convex post", "cand pre",
              "cand post", "gain", "load s", "pre s", "blm s", "convex s", "antipodal s", "total s")
    return table(rows, header), gains


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mode", choices=("both", "defaults", "config"), default="both")
    ap.add_argument("--neighbourhood", choices=("edge", "vertex"), default="edge",
                    help="convexity neighbourhood (edge = the library default)")
    args = ap.parse_args(argv)
    if not PAPER_DIR.is_dir():
        print(f"paper parts not found in {PAPER_DIR} (set GRASPLAN_PAPER_PARTS); nothing to do")
        return 0
    parts = sorted(p for p in PAPER_DIR.iterdir() if p.suffix.lower() in SUFFIXES)
    config = (yaml.safe_load(CONFIG.read_text()) or {}).get("parts", {})
    ok = True
    for mode in (("defaults", "config") if args.mode == "both" else (args.mode,)):
        title = ("CLI defaults (alpha 0.1 mm, gamma 135 deg)" if mode == "defaults"
                 else f"per-part alpha/gamma from {CONFIG.relative_to(ROOT)}")
        print(f"\nTable I, {title}; d_shift 0.01 mm, epsilon 5 mm, max opening 50 mm, beta 2 deg, mu 0.3, "
              f"convexity neighbourhood {args.neighbourhood}")
        text, gains = table_for(parts, mode, config, args.neighbourhood)
        print(text)
        sharp = {k: g for k, g in gains.items() if "Bunny" not in k}
        n_ok = sum(g >= HEADLINE_GAIN for g in sharp.values())
        print(f"BLM gain >= {HEADLINE_GAIN:.0%} on {n_ok} of {len(sharp)} sharp-edged parts"
              + (f" (min {min(sharp.values()):+.0%})" if sharp else ""))
        if mode == "defaults" and n_ok < min(5, len(sharp)):
            ok = False
    print("\nheadline (defaults): " + ("holds" if ok else "DOES NOT HOLD"))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
