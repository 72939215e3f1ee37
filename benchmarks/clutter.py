"""Clutter removal in physics, VGN's and GIGA's protocols, measured in parallel and resumable.

    python benchmarks/clutter.py [--rounds 100] [--seed 0] [--protocol bin|pile|packed ...]
        [--noise 0,0 --noise 2mm,2deg ...] [--robust] [--jobs J] [--out out/clutter] [--gripper NAME]
        [--part PATH:COUNT[:MATERIAL] ...] [--material plastic | --density 1200] [--decomposition coacd|hull]
        [--max-occlusion 1.0]

Settings: every ``--protocol`` (default all three, :data:`grasplan.clutter.protocols.PROTOCOLS`:
``bin``, dropped anywhere into the walled bin and lifted above its rim; ``pile``, VGN's pile, dropped
over the bin floor's central third, the walls taken away; ``packed``, VGN's packed, placed upright
at free spots) times every ``--noise`` (pose error LENGTH,ANGLE, default ``0,0``: ground truth).
``--robust`` adds four settings on ``pile`` with ground truth unless said: friction mu 0.2, mu 0.5,
density 2700 kg/m^3 (aluminium; a part given its own material keeps it), and noise 2mm,2deg with
``--max-occlusion 0.8`` (parts an overhead camera sees 80 % or more hidden are left out of the
planner's scene). The "extra" column names what a setting changes against the run's options.

A round of a setting is one ``grasplan clutter`` round (:class:`grasplan.clutter.session.ClutterRun`):
round r drops its pile with seed ``--seed`` + r, whichever worker runs it, and is cleared until the
workspace is empty, two attempts in a row failed or nothing is feasible. The parts: ``--part``
(repeatable), by default the five paper parts one each (TLess20, TLess22, SileanePepper,
IPARingScrew, SileaneGear, from $GRASPLAN_PAPER_PARTS or ../shared/parts/paper; exit 2 when absent),
plastic 1200 kg/m^3 unless ``--material``/``--density`` say otherwise.

Parallel: each setting runs in a pool of ``--jobs`` worker processes (spawn: no fork after numba
and MuJoCo are loaded), after the parts' collision shapes are made and cached once in the parent
(CoACD takes minutes per part uncached); each worker builds one ClutterRun for the setting (its first planning call
is the cold one, left out of the planning times) and runs the rounds it is given. stderr gets one
line per finished round: the setting, the round, GSR and DR so far, elapsed time and an estimate of
the time left.

Resumable: each setting logs to ``DIR/<tag>.jsonl``: line 1 ``{"setting": {...}}`` (everything that
decides a round's result: protocol, pose noise, occlusion, seed, material, density, friction,
decomposition, drop gap, cell, robot, gripper, parts; not --rounds, --jobs or --out), then one
:func:`grasplan.clutter.report.round_json` document per finished round with ``worker_rss_mb`` (the
worker's peak RSS so far), appended, flushed and fsynced as it arrives. A rerun reads the logs
first: a header that differs from the setting is an error (exit 2 naming the file: delete it or use
another --out); logged rounds are not run again (a larger --rounds extends a log); a last line cut
short by a kill is dropped (the file rewritten without it) and its round run again. Ctrl-C keeps
every finished round (exit 130).

Output: one row per setting (the log's rounds 0..--rounds-1): rounds, parts, attempts, GSR and DR
with their 95 % intervals (:func:`grasplan.clutter.report.interval`: Wilson's interval with the
trials divided by the design effect of whole rounds, the rounds being the independent units), how rounds ended, the parts left by the planner's
status and by distance to the nearest wall, parts outside the workspace at the start, picks turned
in / dropped from the jaws, planning ms p50/p95, a round's CPU s (median), the workers' peak RSS,
and the target. Targets (checked and printed met/missed, not asserted; only settings without an
extra): pile ground truth GSR >= 95 % and DR >= 95 %; pile 2mm,2deg GSR >= 90 %, DR >= 90 %; bin
DR >= 90 % (with ``--push``). Then GIGA's published simulated figures beside our
ground-truth pile and packed rows. The same tables go to ``DIR/summary.md`` (written atomically,
after each setting, with the settings done so far; nothing in it depends on the time of the run).
"""
from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import os
import resource
import signal
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from grasplan.cli.common import table  # noqa: E402
from grasplan.config.params import DEFAULT_ROBOT, PAPER_GRIPPER  # noqa: E402

PAPER_DIR = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
PAPER_PARTS = ("TLess20.stl", "TLess22.stl", "SileanePepper.stl", "IPARingScrew.stl", "SileaneGear.stl")
PROTOCOL_NAMES = ("bin", "pile", "packed")
#: --robust: the friction coefficients, the density (kg/m^3), and the (noise, max occlusion) tried on pile
ROBUST_MU, ROBUST_DENSITY, ROBUST_NOISE, ROBUST_OCCLUSION = (0.2, 0.5), 2700.0, (0.002, 2.0), 0.8
#: GIGA (Jiang et al., RSS 2021), simulated clutter removal, 100 rounds of 5 objects, the box removed
#: before picking: (method, pile GSR %, pile DR %, packed GSR %, packed DR %)
PUBLISHED = (("VGN", 60.7, 44.0, 74.5, 79.2), ("GIGA", 69.3, 49.8, 83.5, 84.3))
PUBLISHED_SOURCE = "Jiang et al., RSS 2021 (GIGA), simulated, 100 rounds of 5 objects"
COMPARABLE = ("Comparable: the protocol (pile: dropped, bin removed; packed: placed upright; a round ends when "
              "empty, after two failures in a row or with nothing feasible) and the rates. Not comparable: "
              "their objects are unknown household objects seen through depth images; ours are known CAD "
              "parts whose poses the planner is given.")


class BenchError(Exception):
    """A problem with the options or the logs: the message is printed, exit 2."""


# ------------------------------------------------------------------------------------------------
# settings
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Setting:
    """One measured setting: ``protocol``, pose ``noise`` (m, deg), friction ``mu``, ``material``
    and ``density`` (kg/m^3), ``max_occlusion``, and ``extra``: what it changes against the run's
    options (empty for the base settings, the only ones with a target)."""

    protocol: str
    noise: tuple[float, float]
    mu: float
    material: str
    density: float
    max_occlusion: float
    extra: tuple[str, ...] = ()

    @property
    def tag(self) -> str:
        """The log's file stem, e.g. ``pile_gt``, ``pile_n2mm2deg_max_occlusion0.8``, ``pile_gt_mu0.2``."""
        m, deg = self.noise
        noise = "gt" if m == 0 and deg == 0 else f"n{m * 1e3:g}mm{deg:g}deg"
        return "_".join((self.protocol, noise, *(e.replace(" ", "") for e in self.extra)))


def noise_text(noise: tuple[float, float]) -> str:
    m, deg = noise
    return "0,0" if m == 0 and deg == 0 else f"{m * 1e3:g}mm,{deg:g}deg"


def make_settings(protocols: Sequence[str], noises: Sequence[tuple[float, float]], *, robust: bool, mu: float,
                  material: str, density: float, max_occlusion: float) -> list[Setting]:
    """Every protocol x every noise, then (``robust``) the pile variants; one per tag."""
    from grasplan.config.materials import resolve_material

    def base_extra(occ: float) -> tuple[str, ...]:
        return () if occ >= 1.0 else (f"max_occlusion {occ:g}",)

    out = [Setting(p, n, mu, material, density, max_occlusion, base_extra(max_occlusion))
           for p in protocols for n in noises]
    if robust:
        gt = (0.0, 0.0)
        out += [Setting("pile", gt, m, material, density, max_occlusion, (*base_extra(max_occlusion), f"mu {m:g}"))
                for m in ROBUST_MU]
        dense_material, _ = resolve_material(None, ROBUST_DENSITY)
        out.append(Setting("pile", gt, mu, dense_material, ROBUST_DENSITY, max_occlusion,
                           (*base_extra(max_occlusion), f"density {ROBUST_DENSITY:g}")))
        out.append(Setting("pile", ROBUST_NOISE, mu, material, density, ROBUST_OCCLUSION,
                           base_extra(ROBUST_OCCLUSION)))
    seen: dict[str, Setting] = {}
    for s in out:
        seen.setdefault(s.tag, s)
    return list(seen.values())


@dataclass(frozen=True)
class Common:
    """The options every setting shares."""

    parts: tuple[tuple[str, int, str | None], ...]
    seed: int
    gripper: str
    decomposition: str
    push: bool = False
    min_gravity_margin: float | None = None


def clutter_options(s: Setting, c: Common) -> Any:
    """The :class:`grasplan.clutter.session.ClutterOptions` of a setting (validates them)."""
    from grasplan.clutter.session import ClutterOptions
    from grasplan.sim.drop import DropParams

    drop = DropParams(seed=c.seed, material=s.material, density=s.density, mu=s.mu, decomposition=c.decomposition)
    pick = {} if c.min_gravity_margin is None else {"min_gravity_margin": c.min_gravity_margin}
    return ClutterOptions(parts=c.parts, protocol=s.protocol, pose_noise=s.noise, max_occlusion=s.max_occlusion,
                          gripper=c.gripper, drop=drop, push=c.push, pick=pick)


def setting_json(options: Any) -> dict[str, Any]:
    """A log's header setting: what decides a round's result (module docstring), as JSON reads it back."""
    o = options
    doc = {"protocol": o.protocol, "pose_noise_m": o.pose_noise[0], "pose_noise_deg": o.pose_noise[1],
           "max_occlusion": o.max_occlusion, "material": o.drop.material, **o.drop.to_json(), "cell": o.cell,
           "units": o.units, "robot": o.robot, "gripper": o.gripper, "parts": [list(p) for p in o.parts],
           "push": o.push, "pick": dict(o.pick)}
    loaded: dict[str, Any] = json.loads(json.dumps(doc))
    return loaded


# ------------------------------------------------------------------------------------------------
# the logs
# ------------------------------------------------------------------------------------------------
def read_log(path: Path, setting: dict[str, Any]) -> dict[int, dict[str, Any]]:
    """The rounds logged in ``path`` by round index, after making the file a clean log of
    ``setting``: created with its header when absent (or holding no whole line), a last line cut
    short dropped (the file rewritten without it). BenchError for another setting's header or a
    broken line before the last."""
    from grasplan.io import write_atomic_text

    header = json.dumps({"setting": setting}) + "\n"
    if not path.exists():
        write_atomic_text(path, header)
        return {}
    raw = path.read_text(encoding="utf-8")
    lines = raw.split("\n")
    tail = lines.pop()  # "" when the file ends with a newline, else a line cut short
    docs: list[dict[str, Any]] = []
    for k, line in enumerate(lines):
        try:
            d = json.loads(line)
        except json.JSONDecodeError:
            d = None
        if not isinstance(d, dict) or (k > 0 and not isinstance(d.get("round"), int)):
            if k == len(lines) - 1 and not tail:  # the last line, whole but unreadable: run its round again
                break
            raise BenchError(f"{path}: line {k + 1} is not a round of this benchmark; delete the file or use "
                             f"another --out")
        docs.append(d)
    if not docs:  # killed before the header was written
        write_atomic_text(path, header)
        return {}
    if docs[0].get("setting") != setting:
        old = docs[0].get("setting") or {}
        diff = ", ".join(f"{k}: {old.get(k)!r} -> {setting.get(k)!r}"
                         for k in sorted({*old, *setting}) if old.get(k) != setting.get(k))
        raise BenchError(f"{path} was logged with another setting ({diff}); delete it or use another --out")
    kept = len(docs)
    if tail or kept < len(lines):
        print(f"{path}: dropped a last line cut short; its round runs again", file=sys.stderr, flush=True)
        write_atomic_text(path, "".join(json.dumps(d) + "\n" for d in docs))
    rounds: dict[int, dict[str, Any]] = {}
    for d in docs[1:]:
        rounds.setdefault(int(d["round"]), d)
    return rounds


def append_line(f: Any, doc: dict[str, Any]) -> None:
    """One JSON line appended, flushed and fsynced (a kill leaves at most the last line cut short)."""
    f.write(json.dumps(doc) + "\n")
    f.flush()
    os.fsync(f.fileno())


# ------------------------------------------------------------------------------------------------
# workers
# ------------------------------------------------------------------------------------------------
_RUN: Any = None
_INIT_ERROR: str | None = None
_COLD = True


def peak_rss_mb() -> float:
    """This process's peak resident set size (MB; ru_maxrss is KiB on Linux, bytes on macOS)."""
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / (1024.0 * 1024.0) if sys.platform == "darwin" else rss / 1024.0


def _init_worker(options: Any) -> None:
    """Pool initializer: one ClutterRun for the worker's setting. Ctrl-C is left to the parent. A
    failure is kept for the first task to report (a pool restarts a worker whose initializer
    raises, forever)."""
    global _RUN, _INIT_ERROR
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from grasplan.clutter.session import ClutterRun
    from grasplan.errors import InputError

    try:
        _RUN = ClutterRun(options)
    except InputError as exc:
        _INIT_ERROR = str(exc)
    except Exception as exc:  # noqa: BLE001 (reported by the first task, with its traceback)
        import traceback

        _INIT_ERROR = f"building the run failed: {type(exc).__name__}: {exc}\n{traceback.format_exc()}"


def _run_round(r: int) -> dict[str, Any]:
    """Round ``r`` in this worker: its round_json document with ``worker_rss_mb``, or ``{"error": ...}``."""
    global _COLD
    if _INIT_ERROR is not None:
        return {"error": _INIT_ERROR}
    from grasplan.clutter.report import round_json

    rr = _RUN.round(r, cold=_COLD)
    _COLD = False
    rj = round_json(rr)
    rj["worker_rss_mb"] = peak_rss_mb()
    return rj


def _rates(rounds: Sequence[dict[str, Any]]) -> tuple[float | None, float | None]:
    att, suc = sum(d["attempts"] for d in rounds), sum(d["successes"] for d in rounds)
    parts, rem = sum(d["parts"] for d in rounds), sum(d["removed"] for d in rounds)
    return (suc / att if att else None), (rem / parts if parts else None)


def warm_shapes(s: Setting, options: Any) -> None:
    """The parts' collision shapes made (and cached) here once, before the workers each need them:
    CoACD takes minutes per part when not cached, and every worker would compute it at once."""
    from grasplan.errors import InputError
    from grasplan.sim.drop import load_items, pile_bodies

    try:
        pile_bodies(load_items(list(options.parts), units=options.units), options.drop, cache=True,
                    log=lambda line: print(f"[{s.tag}] {line}", file=sys.stderr, flush=True))
    except InputError as exc:
        raise BenchError(f"[{s.tag}] {exc}") from None


def run_setting(s: Setting, options: Any, path: Path, rounds: int, jobs: int) -> list[dict[str, Any]]:
    """The setting's rounds ``0..rounds-1`` in round order: those logged in ``path``, the others run
    in a pool of up to ``jobs`` workers and logged as they finish."""
    done = read_log(path, setting_json(options))
    todo = [r for r in range(rounds) if r not in done]
    print(f"[{s.tag}] {rounds - len(todo)} of {rounds} rounds logged in {path}; {len(todo)} rounds to run",
          file=sys.stderr, flush=True)
    if todo:
        t0 = time.perf_counter()
        warm_shapes(s, options)
        ctx = mp.get_context("spawn")
        with ctx.Pool(min(jobs, len(todo)), initializer=_init_worker, initargs=(options,)) as pool, \
                open(path, "a", encoding="utf-8") as f:
            for k, rj in enumerate(pool.imap_unordered(_run_round, todo, chunksize=1), 1):
                if "error" in rj:
                    raise BenchError(f"[{s.tag}] {rj['error']}")
                append_line(f, rj)
                done[int(rj["round"])] = rj
                gsr, dr = _rates([done[r] for r in done if r < rounds])
                el = time.perf_counter() - t0
                print(f"[{s.tag}] round {rj['round']} (seed {rj['seed']}) done, {k}/{len(todo)}: "
                      f"{rj['successes']}/{rj['attempts']} held, {rj['removed']}/{rj['parts']} removed, "
                      f"ended {rj['ended']}; so far GSR {pct(gsr)} %, DR {pct(dr)} %; {el:.0f} s elapsed, "
                      f"ETA {el / k * (len(todo) - k):.0f} s", file=sys.stderr, flush=True)
    return [done[r] for r in range(rounds)]


# ------------------------------------------------------------------------------------------------
# tables
# ------------------------------------------------------------------------------------------------
def pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.1f}"


def pct_ci(rate: float | None, ci: Sequence[float] | None) -> str:
    """A rate and its 95 % interval in percent: ``97.3 [93.1-99.2]`` (``-`` for no rate; no
    interval below two rounds)."""
    if rate is None:
        return "-"
    return pct(rate) if ci is None else f"{pct(rate)} [{pct(ci[0])}-{pct(ci[1])}]"


def counts(d: dict[str, int]) -> str:
    """``{"blocked": 3, "no_grasp": 1, "x": 0}`` -> ``blocked 3, no_grasp 1`` (``-`` when all are 0)."""
    return ", ".join(f"{k.replace(' ', '')} {v}" for k, v in d.items() if v) or "-"


def md_table(rows: Sequence[Sequence[object]], header: Sequence[str]) -> str:
    """A Markdown table (cells as :func:`grasplan.cli.common.table` shows them, ``|`` escaped)."""
    def cell(c: object) -> str:
        return (f"{c:.3f}" if isinstance(c, float) else str(c)).replace("|", "\\|")

    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(cell(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def target(s: Setting) -> tuple[float | None, float | None] | None:
    """(GSR, DR) target of a setting (None: no target; a None rate: not targeted)."""
    if s.extra:
        return None
    if s.protocol == "pile" and s.noise == (0.0, 0.0):
        return 0.95, 0.95
    if s.protocol == "pile" and all(math.isclose(a, b) for a, b in zip(s.noise, ROBUST_NOISE)):
        return 0.90, 0.90
    if s.protocol == "bin":
        return None, 0.90
    return None


def target_cells(s: Setting, total: dict[str, Any]) -> tuple[str, str]:
    """(the target as text, ``met`` / ``missed`` / ``-``)."""
    t = target(s)
    if t is None:
        return "-", "-"
    text = " ".join(f"{name}>={100 * v:g}" for name, v in zip(("GSR", "DR"), t) if v is not None)
    ok = all(v is None or (total[k] is not None and total[k] >= v) for k, v in zip(("gsr", "dr"), t))
    return text, "met" if ok else "missed"


HEADER = ("protocol", "noise", "extra", "rounds", "parts", "attempts", "GSR_% [95% CI]", "DR_% [95% CI]",
          "ends empty/2fail/none", "left by status", "left by wall", "outside", "turned/dropped",
          "plan_ms p50/p95", "round_cpu_s", "peak_rss_MB", "target_%", "met")


def result_row(s: Setting, logged: Sequence[dict[str, Any]]) -> tuple[object, ...]:
    """One setting's row of the results table (:data:`HEADER`) from its logged rounds."""
    from grasplan.clutter.report import total_json

    t = total_json(logged)
    e, pm, out = t["ended"], t["plan_ms"], t["outcomes"]
    cpu = t["round_cpu_s"]["median"]
    rss = [d["worker_rss_mb"] for d in logged if "worker_rss_mb" in d]
    ms = "-" if pm["median"] is None else f"{pm['median']:.0f}/{pm['p95']:.0f}"
    return (s.protocol, noise_text(s.noise), " ".join(s.extra) or "-", t["rounds"], t["parts"], t["attempts"],
            pct_ci(t["gsr"], t["gsr_ci95"]), pct_ci(t["dr"], t["dr_ci95"]),
            f"{e['empty']}/{e['two_failures']}/{e['nothing_feasible']}", counts(t["left"]["by_status"]),
            counts(t["left"]["by_wall"]), t["outside"], f"{out.get('turned', 0)}/{out.get('dropped', 0)}", ms,
            "-" if cpu is None else f"{cpu:.1f}", f"{max(rss):.0f}" if rss else "-", *target_cells(s, t))


PUBLISHED_HEADER = ("method", "source", "pile GSR_%", "pile DR_%", "packed GSR_%", "packed DR_%")


def published_rows(ours: dict[str, Sequence[dict[str, Any]]]) -> list[tuple[object, ...]]:
    """GIGA's published rows, then ours (``ours``: the logged rounds of the ground-truth base pile
    and packed settings, by protocol; ``-`` for one not run)."""
    rows: list[tuple[object, ...]] = [(m, PUBLISHED_SOURCE, f"{a:.1f}", f"{b:.1f}", f"{c:.1f}", f"{d:.1f}")
                                      for m, a, b, c, d in PUBLISHED]
    cells: list[str] = []
    n = []
    for proto in ("pile", "packed"):
        logged = ours.get(proto) or []
        gsr, dr = _rates(logged) if logged else (None, None)
        cells += [pct(gsr), pct(dr)]
        if logged:
            n.append(f"{proto} {len(logged)} rounds")
    rows.append(("grasplan, ground truth", "this run (" + (", ".join(n) or "not run") + ")", *cells))
    return rows


def summary(results: Sequence[tuple[Setting, Sequence[dict[str, Any]]]], common_line: str) -> tuple[str, str]:
    """(plain-text tables, Markdown) of the settings' results."""
    rows = [result_row(s, logged) for s, logged in results]
    ours = {s.protocol: logged for s, logged in results
            if s.protocol in ("pile", "packed") and not s.extra and s.noise == (0.0, 0.0)}
    pub = published_rows(ours)
    text = "\n".join((common_line, "", table(rows, header=HEADER), "", table(pub, header=PUBLISHED_HEADER),
                      COMPARABLE))
    md = "\n".join(("# Clutter removal benchmark (benchmarks/clutter.py)", "", common_line, "",
                    md_table(rows, HEADER), "", "## Published figures", "", md_table(pub, PUBLISHED_HEADER), "",
                    COMPARABLE, ""))
    return text, md


# ------------------------------------------------------------------------------------------------
# main
# ------------------------------------------------------------------------------------------------
def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=100, help="rounds per setting (default 100)")
    ap.add_argument("--seed", type=int, default=0, help="round r drops its pile with seed SEED + r (default 0)")
    ap.add_argument("--protocol", action="append", choices=PROTOCOL_NAMES,
                    help="repeatable (default: bin, pile and packed)")
    ap.add_argument("--noise", action="append", metavar="LENGTH,ANGLE",
                    help="pose noise, repeatable (default 0,0: ground truth), e.g. 2mm,2deg")
    ap.add_argument("--robust", action="store_true", help="add the pile settings mu 0.2, mu 0.5, density 2700 "
                    "and noise 2mm,2deg with --max-occlusion 0.8")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="worker processes (default: the CPUs)")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "clutter", help="folder of the logs and summary.md")
    ap.add_argument("--gripper", default=PAPER_GRIPPER, help=f"gripper name or YAML (default {PAPER_GRIPPER})")
    ap.add_argument("--part", action="append", metavar="PATH:COUNT[:MATERIAL]",
                    help="repeatable (default: the five paper parts, one each, from $GRASPLAN_PAPER_PARTS)")
    ap.add_argument("--material", default=None, help="part material (default plastic)")
    ap.add_argument("--density", type=float, default=None, help="part density, kg/m^3 (default: the material's)")
    ap.add_argument("--decomposition", choices=("coacd", "hull"), default="coacd",
                    help="parts' collision shapes (default coacd)")
    ap.add_argument("--push", action="store_true", help="plan and execute pushes when no pick is planned "
                    "(grasplan clutter --push)")
    ap.add_argument("--min-gravity-margin", type=float, default=None,
                    help="the planner's --min-gravity-margin (default: grasplan clutter's, 1)")
    ap.add_argument("--max-occlusion", type=float, default=1.0,
                    help="parts hidden at least this share are not planned (default 1: every part)")
    args = ap.parse_args(argv)
    if args.rounds < 1 or args.jobs < 1:
        ap.error("--rounds and --jobs must be at least 1")
    return args


def prepare(args: argparse.Namespace) -> tuple[list[tuple[Setting, Any]], Common]:
    """The settings and their ClutterOptions from the command line (BenchError for bad ones)."""
    from grasplan.cli.scene import parse_part_count
    from grasplan.clutter.perception import parse_pose_noise
    from grasplan.config.materials import resolve_material
    from grasplan.errors import InputError
    from grasplan.sim.drop import DropParams

    try:
        if args.part:
            specs = [parse_part_count(p) for p in args.part]
        else:
            missing = [p for p in PAPER_PARTS if not (PAPER_DIR / p).exists()]
            if missing:
                raise BenchError(f"the paper parts {', '.join(missing)} are not in {PAPER_DIR}; set "
                                 f"GRASPLAN_PAPER_PARTS to their folder or give --part PATH:COUNT")
            specs = [(str(PAPER_DIR / p), 1, None) for p in PAPER_PARTS]
        for path, _, _ in specs:
            if not Path(path).is_file():
                raise BenchError(f"--part {path}: no such file")
        parts = tuple((str(Path(p).resolve()), n, m) for p, n, m in specs)
        noises = list(dict.fromkeys(parse_pose_noise(n) for n in (args.noise or ["0,0"])))
        material, density = resolve_material("plastic" if args.material is None and args.density is None
                                             else args.material, args.density)
        common = Common(parts=parts, seed=args.seed, gripper=args.gripper, decomposition=args.decomposition,
                        push=args.push, min_gravity_margin=args.min_gravity_margin)
        settings = make_settings(list(dict.fromkeys(args.protocol or PROTOCOL_NAMES)), noises, robust=args.robust,
                                 mu=float(DropParams().mu), material=material, density=float(density),
                                 max_occlusion=args.max_occlusion)
        return [(s, clutter_options(s, common)) for s in settings], common
    except InputError as exc:
        raise BenchError(str(exc)) from None


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        prepared, common = prepare(args)
        args.out.mkdir(parents=True, exist_ok=True)
        for s, options in prepared:  # every log's header checked before any round runs
            read_log(args.out / f"{s.tag}.jsonl", setting_json(options))
    except BenchError as exc:
        print(f"clutter.py: error: {exc}", file=sys.stderr)
        return 2
    s0 = prepared[0][0]
    common_line = (f"{args.rounds} rounds per setting from seed {common.seed}; parts "
                   f"{', '.join(f'{Path(p).stem} x{n}' + (f' ({m})' if m else '') for p, n, m in common.parts)}; "
                   f"{s0.material} {s0.density:g} kg/m^3, mu {s0.mu:g}, {common.decomposition} collision shapes; "
                   f"robot {DEFAULT_ROBOT}, gripper {common.gripper}")
    print(f"{len(prepared)} settings: {', '.join(s.tag for s, _ in prepared)}; {args.jobs} jobs", file=sys.stderr,
          flush=True)
    from grasplan.io import write_atomic_text

    results: list[tuple[Setting, Sequence[dict[str, Any]]]] = []
    try:
        for s, options in prepared:
            results.append((s, run_setting(s, options, args.out / f"{s.tag}.jsonl", args.rounds, args.jobs)))
            write_atomic_text(args.out / "summary.md", summary(results, common_line)[1])
    except KeyboardInterrupt:
        print("interrupted: the logs keep every finished round; run the same command to resume", file=sys.stderr)
        return 130
    except BenchError as exc:
        print(f"clutter.py: error: {exc}", file=sys.stderr)
        return 2
    print(summary(results, common_line)[0])
    print(f"logs (<setting>.jsonl) and summary.md in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
