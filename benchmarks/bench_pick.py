"""Speed and memory of ``grasplan pick`` / ``grasplan.Picker`` on piles of the paper parts (issue 20).

    python benchmarks/bench_pick.py [--scenes 20] [--no-cold] [--no-lift-carry] [--recheck]

Scenes: piles of 10 instances of one part (TLess20, SileanePepper, IPARingScrew in turn) dropped
into the packaged bin by ``grasplan scene drop``'s physics (:func:`grasplan.sim.drop.drop_pile`, seeds
0, 1, ...; a seed whose pile does not fit or settle is skipped), and one pile of 30 (10 of each)
in a bin twice as long and wide (the packaged bin holds about 20 such parts). The scenes are made
once and cached in ``<cache folder>/bench_pick/`` (:func:`grasplan.cache.cache_dir`), as are the
grasp databases (``graspdb/``).

Measured, with a warm :class:`grasplan.Picker` (robot, databases and collision objects loaded; one
warm-up plan on another scene): per scene ``timing_s["first_pick"]`` (seconds from the ready
scene to the first feasible pick), the whole ``plan`` (the best pick of every instance), and per
grasp tried (IK + approach + lift + transit + their collision checks, divided by the grasps
tried; its CPU column is the process's CPU seconds inside the per-grasp motion planning,
``plan_pick_motion``, which also holds the lift's gripper pre-check); wall and CPU seconds (on a
shared machine wall time grows with the load, CPU time does not). Then ``grasplan pick`` cold in a fresh process (databases cached) on a 10-instance scene,
and on the 30-instance scene with its peak RSS. Targets (issue 20): first_pick median < 100 ms and
p95 < 300 ms; every instance < 1 s median; <= 5 ms per grasp; cold < 5 s; 30 instances < 1 GB.
Also printed: how many picks raise a neighbour lying on the part (``lift_carries``, docs/pick.md).
``--recheck`` then re-checks every pick of the measured plans independently (tests/pick_recheck.py:
python-fcl, an independent depth, the raised neighbours' freedom to rise), outside the timings.
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

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from grasplan.cache import cache_dir  # noqa: E402
from grasplan.config.params import PAPER_GRIPPER  # noqa: E402
from grasplan.cell.model import load_cell  # noqa: E402
from grasplan.cli.common import table  # noqa: E402
from grasplan.errors import GrasplanError  # noqa: E402
from grasplan.part.mesh import load_part  # noqa: E402

PAPER_DIR = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
PARTS = ["TLess20.stl", "SileanePepper.stl", "IPARingScrew.stl"]
MOTION_KEYS = ("ik", "collision", "approach", "lift", "transit")
BIG_BIN = """# bench_pick: a bin 0.60 m x 0.40 m (the packaged one is 0.30 x 0.20) for the 30-instance pile
name: bin_large
table_z: 0.0
pose_index: 0
bin: {inner: [0.60, 0.40], wall: 0.01, height: 0.15, T: {xyz: [0.45, 0.0, 0.01], rpy_deg: [0, 0, 0]}}
"""


def _drop(folder: Path, name: str, cell_ref: str, items: list[tuple[str, int]], seed: int) -> Path | None:
    """The cached scene ``name``, dropped now when missing (None: that seed's pile fails)."""
    from dataclasses import replace

    from grasplan.piles.scene_file import part_name
    from grasplan.sim.drop import DropParams, PileItem, drop_pile
    from grasplan.piles.scene_write import write_scene

    path, fail = folder / f"{name}.yaml", folder / f"{name}.failed"
    if path.exists():
        return path
    if fail.exists():
        return None
    if cell_ref.endswith(".yaml"):  # a cell file next to the scenes (written relative to them)
        cell_ref = str(folder / cell_ref)
    cell = load_cell(cell_ref)
    its = [PileItem(part_name(p), load_part(PAPER_DIR / p), n) for p, n in items]
    try:
        res = drop_pile(cell, its, params=DropParams(seed=seed, material="plastic"), cell_ref=cell_ref)
    except GrasplanError as exc:
        fail.write_text(str(exc))
        return None
    # the bench picks its plastic piles with the default (steel) grasp databases: the scene leaves the
    # parts' material out
    plain = replace(res.scene, parts=tuple(replace(p, material=None, density=None) for p in res.scene.parts))
    write_scene(path, plain, header=[f"bench_pick: seed {seed}"])
    print(f"  dropped {path.name}", flush=True)
    return path


def scenes(n: int) -> tuple[list[Path], Path | None]:
    folder = cache_dir() / "bench_pick"
    folder.mkdir(parents=True, exist_ok=True)
    out: list[Path] = []
    seed = 0
    while len(out) < n and seed < 5 * n:
        for p in PARTS:
            s = _drop(folder, f"{Path(p).stem}_s{seed}", "bin", [(p, 10)], seed)
            if s is not None and len(out) < n:
                out.append(s)
        seed += 1
    (folder / "bin_large.yaml").write_text(BIG_BIN)
    big = _drop(folder, "mix30_s0", "bin_large.yaml", [(p, 10) for p in PARTS], 0)
    return out, big


#: runs the command in a child of this small process, so that the child's peak RSS does not count
#: the bench's own memory (a forked child's high-water mark starts at its parent's size)
_WRAP = ("import resource, subprocess, sys\nrc = subprocess.call(sys.argv[1:])\n"
         "print('PEAK_RSS_KB', resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\nsys.exit(rc)\n")


def _cli(scene: Path) -> tuple[float, float, int, str]:
    """(wall s, peak RSS MB, exit code, summary line) of ``grasplan pick SCENE`` in a fresh process."""
    with tempfile.TemporaryDirectory() as d:
        t = time.perf_counter()
        r = subprocess.run([sys.executable, "-c", _WRAP, sys.executable, "-c", "from grasplan.cli import main; main()",
                            "pick", str(scene), "--gripper", PAPER_GRIPPER, "-o", str(Path(d) / "picks.json")],
                           capture_output=True, text=True,
                           env={**os.environ, "PYTHONPATH": str(ROOT)})
        wall = time.perf_counter() - t
    rss = next((int(ln.split()[1]) for ln in r.stdout.splitlines() if ln.startswith("PEAK_RSS_KB")), 0)
    lines = [ln for ln in r.stdout.splitlines() if "instances picked" in ln]
    return wall, rss / 1024, r.returncode, (lines[-1] if lines else r.stderr.strip()[-200:])


def pct(xs: list[float], q: float) -> float:
    s = sorted(xs)
    return s[min(len(s) - 1, int(round(q * (len(s) - 1))))]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=20)
    ap.add_argument("--no-cold", action="store_true", help="skip the fresh-process runs")
    ap.add_argument("--lift-depth", type=float, default=None,
                    help="PickParams.lift_depth in m (default the picker's; 0: the strict lift rule)")
    ap.add_argument("--profile", metavar="FILE", help="write a cProfile of the measured plans to FILE")
    ap.add_argument("--no-lift-carry", action="store_true", help="PickParams.lift_carry off (no lift raises a neighbour)")
    ap.add_argument("--recheck", action="store_true", help="re-check every pick independently (tests/pick_recheck.py)")
    args = ap.parse_args()
    missing = [p for p in PARTS if not (PAPER_DIR / p).exists()]
    if missing:
        print(f"skipped: paper parts {', '.join(missing)} not found in {PAPER_DIR} (set GRASPLAN_PAPER_PARTS)")
        return 0
    print("scenes (dropped once, cached) ...", flush=True)
    paths, big = scenes(args.scenes + 1)
    from grasplan.pick import Picker

    from grasplan.pick.params import PickParams

    params = PickParams(**({} if args.lift_depth is None else {"lift_depth": args.lift_depth}),
                        lift_carry=not args.no_lift_carry)
    picker = Picker("ur5", gripper=PAPER_GRIPPER, params=params, progress=lambda s: print(" ", s, flush=True))
    loaded = {Path(p).stem.lower(): load_part(PAPER_DIR / p) for p in PARTS}
    for name, part in loaded.items():
        picker.add_part(name, part)
    picker.warm()  # every part's probes and voxel grid, as the pick service does at start
    import grasplan.pick.picker as picker_mod

    motion_cpu = [0.0]  # CPU seconds inside plan_pick_motion (IK, approach, lift, transit, their checks)
    plan_motion = picker_mod.plan_pick_motion

    def timed_motion(*a: object, **k: object) -> object:
        c0 = time.process_time()
        try:
            return plan_motion(*a, **k)  # type: ignore[arg-type]
        finally:
            motion_cpu[0] += time.process_time() - c0

    picker_mod.plan_pick_motion = timed_motion  # type: ignore[assignment]
    load0 = os.getloadavg()[0]
    picker.plan(paths[-1])  # warm-up on a scene not measured
    rows, first, first_cpu, whole, per_grasp, per_grasp_cpu, cpu = [], [], [], [], [], [], []
    n_inst = n_picked = n_raising = 0
    results = []
    prof = None
    if args.profile:
        import cProfile

        prof = cProfile.Profile()
    for path in paths[:-1]:
        c, motion_cpu[0] = time.process_time(), 0.0
        if prof is not None:
            prof.enable()
        res = picker.plan(path)
        if prof is not None:
            prof.disable()
        c = time.process_time() - c
        n_inst += len(res.instances)
        n_picked += len(res.picks)
        n_raising += sum(bool(q.carries) for q in res.picks)
        if args.recheck:
            results.append(res)
        t = res.timing_s
        tried = res.stats.get("grasps_tried", 0)
        motion = sum(t.get(k, 0.0) for k in MOTION_KEYS)
        fp = t.get("first_pick", float("nan"))
        if fp == fp:
            first.append(fp)
            first_cpu.append(t["first_pick_cpu"])
        whole.append(t["plan"])
        cpu.append(c)
        if tried:
            per_grasp.append(motion / tried)
            per_grasp_cpu.append(motion_cpu[0] / tried)
        rows.append((path.stem, len(res.instances), len(res.picks), round(1e3 * fp, 1), round(t["plan"], 3),
                     round(c, 3), tried, round(1e3 * motion / max(tried, 1), 2),
                     round(1e3 * motion_cpu[0] / max(tried, 1), 2), round(1e3 * t["gripper_check"], 1)))
    print(table(rows, header=("scene", "instances", "picked", "first_pick_ms", "plan_s", "cpu_s", "grasps_tried",
                              "ms/grasp", "cpu_ms/grasp", "gripper_check_ms")))
    print(f"picked {n_picked} of {n_inst} instances (lift_depth {1e3 * picker.params.lift_depth:g} mm, lift_carry "
          f"{'on' if picker.params.lift_carry else 'off'}); {n_raising} of the picks raise a neighbour lying on the part")
    if prof is not None:
        prof.dump_stats(args.profile)
    med = statistics.median
    summary = [
        ("first_pick median (ms)", round(1e3 * med(first), 1), 100, round(1e3 * med(first) / 100, 2)),
        ("first_pick p95 (ms)", round(1e3 * pct(first, 0.95), 1), 300, round(1e3 * pct(first, 0.95) / 300, 2)),
        ("first_pick CPU median (ms)", round(1e3 * med(first_cpu), 1), 100, round(1e3 * med(first_cpu) / 100, 2)),
        ("first_pick CPU p95 (ms)", round(1e3 * pct(first_cpu, 0.95), 1), 300,
         round(1e3 * pct(first_cpu, 0.95) / 300, 2)),
        ("every instance median (s)", round(med(whole), 3), 1.0, round(med(whole) / 1.0, 2)),
        ("every instance CPU median (s)", round(med(cpu), 3), 1.0, round(med(cpu) / 1.0, 2)),
        ("per grasp tried median (ms)", round(1e3 * med(per_grasp), 2), 5, round(1e3 * med(per_grasp) / 5, 2)),
        ("per grasp tried CPU median (ms)", round(1e3 * med(per_grasp_cpu), 2), 5,
         round(1e3 * med(per_grasp_cpu) / 5, 2)),
    ]
    if not args.no_cold:
        wall, rss, rc, line = _cli(paths[0])
        print(line)
        summary.append((f"cold grasplan pick {paths[0].stem} (s)", round(wall, 2), 5, round(wall / 5, 2)))
        summary.append((f"  its peak RSS (MB), exit {rc}", round(rss), 1024, round(rss / 1024, 2)))
        if big is not None:
            wall, rss, rc, line = _cli(big)
            print(line)
            summary.append((f"cold grasplan pick {big.stem}, 30 instances (s)", round(wall, 2), "-", "-"))
            summary.append((f"  its peak RSS (MB), exit {rc}", round(rss), 1024, round(rss / 1024, 2)))
    print(table(summary, header=("metric", "value", "target", "ratio")))
    print(f"{len(paths) - 1} scenes; load average {load0:.1f} -> {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    if args.recheck:
        recheck(picker, results, {name: part.mesh for name, part in loaded.items()})
    return 0


def recheck(picker, results, meshes) -> None:
    """Every pick of ``results`` re-checked by tests/pick_recheck.py (independent of grasplan's checks)."""
    sys.path.insert(0, str(ROOT / "tests"))
    from pick_recheck import recheck_pick

    n = n_raising = 0
    failed = []
    for res in results:
        for q in res.picks:
            rc = recheck_pick(picker.robot, picker.gripper, res.cell, q, res.scene.instances, meshes,
                              lift_contact=res.params.lift_contact, lift_depth=res.params.lift_depth,
                              rest_cap=res.params.overlap_tol)
            n += 1
            n_raising += bool(q.carries)
            if not rc.ok:
                failed.append(f"{q.instance}: {rc.problems[0]}")
    print(f"re-checked independently: {n} picks ({n_raising} raising a neighbour), {len(failed)} failed")
    for f in failed[:10]:
        print("  FAILED", f)


if __name__ == "__main__":
    sys.exit(main())
