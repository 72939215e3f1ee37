"""The clutter report (``grasplan.clutter/1``): per round and in total, attempts, successes, GSR,
DR, planning milliseconds per pick and failures by reason (:func:`report_json`, :func:`write_report`).
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..io import write_atomic_text
from .execute import OUTCOMES, SUCCESS
from .rounds import NO_PLAN, RoundResult

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


def _failures(rounds: Sequence[RoundResult]) -> dict[str, int]:
    out = dict.fromkeys(FAILURES, 0)
    for rr in rounds:
        for a in rr.attempts:
            if a.outcome != SUCCESS:
                out[a.outcome] += 1
    return out


def round_json(rr: RoundResult) -> dict[str, Any]:
    ex = rr.executed
    return {"round": rr.r, "seed": rr.seed, "parts": rr.parts, "attempts": len(ex), "successes": rr.successes,
            "removed": rr.removed, "gsr": _rate(rr.successes, len(ex)), "dr": _rate(rr.removed, rr.parts),
            "ended": rr.ended, "plan_ms": plan_stats([a.plan_ms for a in rr.attempts if not a.cold]),
            "failures": _failures([rr]), "fell_out": list(rr.fell_out), "seconds": rr.seconds, "drop_s": rr.drop_s,
            "cpu_s": rr.cpu_s, "sim_s": rr.sim_s, "pile": [i.to_json() for i in rr.scene.instances],
            "picks": [a.to_json() for a in rr.attempts]}


def total_json(rounds: Sequence[RoundResult]) -> dict[str, Any]:
    attempts = sum(len(rr.executed) for rr in rounds)
    successes = sum(rr.successes for rr in rounds)
    parts = sum(rr.parts for rr in rounds)
    removed = sum(rr.removed for rr in rounds)
    calls = [a for rr in rounds for a in rr.attempts]
    plan = plan_stats([a.plan_ms for a in calls if not a.cold])
    cold = [a.plan_ms for a in calls if a.cold]
    plan["cold_ms"] = cold[0] if cold else None
    secs = np.asarray([rr.seconds for rr in rounds], dtype=np.float64)
    cpu = np.asarray([rr.cpu_s for rr in rounds], dtype=np.float64)
    return {"rounds": len(rounds), "attempts": attempts, "successes": successes, "parts": parts, "removed": removed,
            "gsr": _rate(successes, attempts), "dr": _rate(removed, parts), "plan_ms": plan,
            "failures": _failures(rounds),
            "ended": {e: sum(rr.ended == e for rr in rounds) for e in ("empty", "two_failures", "nothing_feasible")},
            "round_seconds": {"median": float(np.median(secs)) if len(secs) else None,
                              "max": float(secs.max()) if len(secs) else None},
            "round_cpu_s": {"median": float(np.median(cpu)) if len(cpu) else None,
                            "max": float(cpu.max()) if len(cpu) else None},
            "seconds": float(secs.sum())}


def report_json(rounds: Sequence[RoundResult], *, params: dict[str, Any], parts: dict[str, Any], cell: str,
                gripper: dict[str, Any], robot: str | None = None) -> dict[str, Any]:
    """The whole ``grasplan.clutter/1`` document::

        {"schema": "grasplan.clutter/1",
         "params": {...}, "parts": {name: {path, sha256, scale_to_m, units, count}}, "cell": ..., "gripper": ...,
         "rounds": [{round, seed, parts, attempts, successes, removed, gsr, dr, ended, plan_ms: {median, p95, n},
                     failures: {reason: n}, fell_out, seconds, drop_s, cpu_s, sim_s, pile, picks: [...]}],
         "total": {rounds, attempts, successes, parts, removed, gsr, dr, plan_ms: {median, p95, n, cold_ms},
                   failures: {...}, ended: {why: n}, round_seconds: {median, max}, round_cpu_s: {median, max},
                   seconds}}

    Rates are fractions (0..1; ``null`` when nothing was attempted). Planning times leave out the
    run's first planning call (``cold``: it loads the databases and builds the caches), recorded as
    ``cold_ms``. Failures count every failed execution by outcome and every planning call that found
    nothing (``no_plan``), which ends a round without being an attempt (as in VGN)."""
    return {"schema": CLUTTER_SCHEMA, "params": params, "parts": parts, "cell": cell, "gripper": gripper,
            "robot": robot, "rounds": [round_json(rr) for rr in rounds], "total": total_json(rounds)}


def write_report(path: str | Path, doc: dict[str, Any]) -> None:
    """Write the report atomically (a temp file, then a rename)."""
    import json

    write_atomic_text(Path(path), json.dumps(doc, indent=1, allow_nan=False) + "\n")
