"""The clutter report (``grasplan.clutter/1``): per round and in total, attempts, successes, GSR,
DR, planning milliseconds per pick and failures by reason (:func:`report_json`, :func:`write_report`).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..io import write_atomic_text
from .execute import OUTCOMES, SUCCESS
from .rounds import ENDS, NO_PLAN, RoundResult

CLUTTER_SCHEMA = "grasplan.clutter/1"
#: the failure reasons a report counts, in this order
FAILURES = (NO_PLAN, *[o for o in OUTCOMES if o != SUCCESS])


def _rate(n: int, d: int) -> float | None:
    return n / d if d else None


def plan_stats(ms: Sequence[float]) -> dict[str, Any]:
    """``{median, p95, n}`` of planning times (ms; None when there are none)."""
    a = np.asarray(ms, dtype=np.float64)
    if not len(a):
        return {"median": None, "p95": None, "n": 0}
    return {"median": float(np.median(a)), "p95": float(np.percentile(a, 95)), "n": int(len(a))}


#: the parts left at a round's end, counted by how far they keep from the nearest wall (m): below
#: each bound, then the rest
WALL_BINS = (0.005, 0.02)
#: resamples of the rounds for the 95 % intervals' design effect (seeded: the same report, the same
#: intervals) and the normal quantile of a two-sided 95 % interval
BOOTSTRAP, BOOTSTRAP_SEED = 2000, 0
Z95 = 1.959963984540054


def _failures(rounds: Sequence[dict[str, Any]]) -> dict[str, int]:
    out = dict.fromkeys(FAILURES, 0)
    for rj in rounds:
        for a in rj["picks"]:
            if a["outcome"] != SUCCESS and a.get("kind", "pick") == "pick":
                out[a["outcome"]] = out.get(a["outcome"], 0) + 1
    return out


def round_json(rr: RoundResult) -> dict[str, Any]:
    ex = rr.executed
    rj: dict[str, Any] = {"round": rr.r, "seed": rr.seed, "protocol": rr.protocol, "parts": rr.parts,
                          "attempts": len(ex), "successes": rr.successes, "removed": rr.removed,
                          "gsr": _rate(rr.successes, len(ex)), "dr": _rate(rr.removed, rr.parts), "ended": rr.ended,
                          "plan_ms": plan_stats([a.plan_ms for a in rr.attempts if not a.cold and a.plan_ms > 0]),
                          "fell_out": list(rr.fell_out), "outside": list(rr.outside),
                          "left": [p.to_json() for p in rr.left], "pushes": len(rr.pushes), "freed": rr.freed,
                          "seconds": rr.seconds, "drop_s": rr.drop_s,
                          "cpu_s": rr.cpu_s, "sim_s": rr.sim_s, "pile": [i.to_json() for i in rr.scene.instances],
                          "picks": [a.to_json() for a in rr.attempts]}
    rj["failures"] = _failures([rj])
    return rj


def interval(num: np.ndarray, den: np.ndarray) -> list[float] | None:
    """95 % interval of ``sum(num) / sum(den)`` over rounds (per-round counts, (n,) each): the
    Wilson score interval of the pooled rate with the trials divided by the design effect, the
    variance of the pooled rate over :data:`BOOTSTRAP` resamples of whole rounds over the
    binomial variance (at least 1): the rounds are the independent units, a round's attempts are
    not. Unlike a percentile bootstrap it does not shrink to a point at 0 or 100 %. None for fewer
    than two rounds or nothing counted."""
    num, den = np.asarray(num, dtype=np.float64), np.asarray(den, dtype=np.float64)
    n = float(den.sum())
    if len(num) < 2 or n <= 0:
        return None
    p = float(num.sum()) / n
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    idx = rng.integers(0, len(num), size=(BOOTSTRAP, len(num)))
    k, d = num[idx].sum(axis=1), den[idx].sum(axis=1)
    var_boot = float(np.var(k[d > 0] / d[d > 0]))
    var_bin = p * (1.0 - p) / n
    n_eff = n / (max(1.0, var_boot / var_bin) if var_bin > 0 else 1.0)
    z = Z95
    scale = 1.0 + z * z / n_eff
    centre = (p + z * z / (2.0 * n_eff)) / scale
    half = z * math.sqrt(p * (1.0 - p) / n_eff + z * z / (4.0 * n_eff * n_eff)) / scale
    return [max(0.0, centre - half), min(1.0, centre + half)]


def _wall_bin(wall_m: float) -> str:
    for bound in WALL_BINS:
        if wall_m < bound:
            return f"< {bound * 1e3:g} mm"
    return f">= {WALL_BINS[-1] * 1e3:g} mm"


def left_json(rounds: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The parts left at the rounds' ends: ``n``, counted ``by_status`` (the planner's last word on
    each) and ``by_wall`` (distance to the nearest wall, :data:`WALL_BINS`), and ``by_part``."""
    left = [p for rj in rounds for p in rj.get("left", [])]
    by_status: dict[str, int] = {}
    by_part: dict[str, int] = {}
    by_wall = {_wall_bin(b - 1e-12): 0 for b in (*WALL_BINS, np.inf)}
    for p in left:
        key = p["status"] or "unplanned"
        by_status[key] = by_status.get(key, 0) + 1
        by_part[p["part"]] = by_part.get(p["part"], 0) + 1
        by_wall[_wall_bin(p["wall_m"])] += 1
    return {"n": len(left), "by_status": dict(sorted(by_status.items())), "by_wall": by_wall,
            "by_part": dict(sorted(by_part.items()))}


def total_json(rounds: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Totals over rounds given as :func:`round_json` documents (a report's, or lines of a
    benchmark's log): counts, GSR and DR pooled over the rounds with their 95 % intervals
    (:func:`interval`), planning times, failures, ends, the parts left (:func:`left_json`)."""
    att = np.array([rj["attempts"] for rj in rounds], dtype=np.float64)
    suc = np.array([rj["successes"] for rj in rounds], dtype=np.float64)
    parts = np.array([rj["parts"] for rj in rounds], dtype=np.float64)
    rem = np.array([rj["removed"] for rj in rounds], dtype=np.float64)
    calls = [a for rj in rounds for a in rj["picks"]]
    plan = plan_stats([a["plan_ms"] for a in calls if not a["cold"] and a["plan_ms"] > 0])
    cold = [a["plan_ms"] for a in calls if a["cold"]]
    plan["cold_ms"] = cold[0] if cold else None
    secs = np.asarray([rj["seconds"] for rj in rounds], dtype=np.float64)
    cpu = np.asarray([rj["cpu_s"] for rj in rounds], dtype=np.float64)
    outcomes = dict.fromkeys((SUCCESS, *FAILURES), 0)
    pushes: dict[str, int] = {}
    for a in calls:
        tally = pushes if a.get("kind", "pick") == "push" else outcomes
        tally[a["outcome"]] = tally.get(a["outcome"], 0) + 1
    return {"rounds": len(rounds), "attempts": int(att.sum()), "successes": int(suc.sum()), "parts": int(parts.sum()),
            "removed": int(rem.sum()), "gsr": _rate(int(suc.sum()), int(att.sum())),
            "dr": _rate(int(rem.sum()), int(parts.sum())), "gsr_ci95": interval(suc, att),
            "dr_ci95": interval(rem, parts), "plan_ms": plan, "failures": _failures(rounds), "outcomes": outcomes,
            "ended": {e: sum(rj["ended"] == e for rj in rounds) for e in ENDS},
            "outside": sum(len(rj.get("outside", [])) for rj in rounds),
            "fell_out": sum(len(rj["fell_out"]) for rj in rounds), "left": left_json(rounds),
            "pushes": {"n": sum(pushes.values()), "outcomes": dict(sorted(pushes.items())),
                       "freed": sum(len(rj.get("freed", [])) for rj in rounds)},
            "round_seconds": {"median": float(np.median(secs)) if len(secs) else None,
                              "max": float(secs.max()) if len(secs) else None},
            "round_cpu_s": {"median": float(np.median(cpu)) if len(cpu) else None,
                            "max": float(cpu.max()) if len(cpu) else None},
            "seconds": float(secs.sum())}


def report_json(rounds: Sequence[RoundResult], *, params: dict[str, Any], parts: dict[str, Any], cell: str,
                gripper: dict[str, Any], robot: str | None = None) -> dict[str, Any]:
    """The whole ``grasplan.clutter/1`` document::

        {"schema": "grasplan.clutter/1",
         "params": {..., "protocol": "bin|pile|packed", "execution": {...}},
         "parts": {name: {path, sha256, scale_to_m, units, count}}, "cell": ..., "gripper": ...,
         "rounds": [{round, seed, protocol, parts, attempts, successes, removed, gsr, dr, ended,
                     plan_ms: {median, p95, n}, failures: {reason: n}, fell_out, outside, left: [...],
                     pushes, freed, seconds, drop_s, cpu_s, sim_s, pile, picks: [...]}],
         "total": {rounds, attempts, successes, parts, removed, gsr, dr, gsr_ci95, dr_ci95,
                   plan_ms: {median, p95, n, cold_ms}, failures: {...}, outcomes: {...}, ended: {why: n},
                   outside, fell_out, left: {n, by_status, by_wall, by_part}, pushes: {n, outcomes, freed},
                   round_seconds: {median, max},
                   round_cpu_s: {median, max}, seconds}}

    Rates are fractions (0..1; ``null`` when nothing was attempted); their ``_ci95`` are 95 %
    intervals from resampling whole rounds (``null`` below two rounds). ``parts`` counts the parts
    in the workspace when each round starts (``outside``: those that were not, left out). Planning
    times leave out the run's first planning call (``cold``: it loads the databases and builds the
    caches), recorded as ``cold_ms``. Failures count every failed pick by outcome and every
    planning call that found nothing (``no_plan``), which ends a round without being an attempt
    (as in VGN). Pushes (``kind`` "push" in ``picks``) are not grasp attempts: GSR leaves them out;
    ``pushes`` counts them by outcome and the parts they ``freed`` (picked after their last push)."""
    rj = [round_json(rr) for rr in rounds]
    return {"schema": CLUTTER_SCHEMA, "params": params, "parts": parts, "cell": cell, "gripper": gripper,
            "robot": robot, "rounds": rj, "total": total_json(rj)}


def write_report(path: str | Path, doc: dict[str, Any]) -> None:
    """Write the report atomically (a temp file, then a rename)."""
    import json

    write_atomic_text(Path(path), json.dumps(doc, indent=1, allow_nan=False) + "\n")
