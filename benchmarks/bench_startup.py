"""Start-up of the ``grasplan`` command: what a process pays before it works.

    .venv/bin/python benchmarks/bench_startup.py [--runs 5] [--tree OTHER_CHECKOUT ...]
    .venv/bin/python benchmarks/bench_plan.py --startup [--runs 5]

Per checkout (this one, and each ``--tree``, measured alternately run by run so the machine's
load hits all alike), medians over ``--runs`` whole processes (wall and CPU seconds) of:

- ``python -c pass``: the interpreter's own floor;
- ``grasplan --help``, ``grasplan plan --help``, ``grasplan pick --help``: wall seconds, and the
  heavy libraries imported;
- ``grasplan plan examples/parts/bracket.stl -o OUT``: wall seconds, and its imports: the sum of
  the self times ``python -X importtime`` reports (slightly inflated by the tracing itself); the
  same plan again with ``GRASPLAN_AOT=0`` (numba's JIT loading its cache instead of the install's
  ahead-of-time kernels, :mod:`grasplan.compiled.aot`);
- ``grasplan export OUT --format csv``: wall seconds of a command that only reads a plan.

The processes run with bytecode caching on (``PYTHONPYCACHEPREFIX``: a temporary folder, when
``PYTHONDONTWRITEBYTECODE`` is set here), as an installed package runs; one unmeasured run of each
command first fills it. The numba kernels must be in numba's cache already (``make install``
compiles them and the ahead-of-time module; otherwise the first plan run compiles them, unmeasured).
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
BRACKET = ROOT / "examples" / "parts" / "bracket.stl"
#: the libraries a command should import only when it needs them
HEAVY = ("scipy", "numba", "pinocchio", "coal", "ompl", "trimesh", "mujoco", "fcl", "toppra", "networkx")
_CLI = ("import sys\nfrom grasplan.cli import main\n"
        "try:\n    main(sys.argv[1:], prog_name='grasplan')\nexcept SystemExit:\n    pass\n"
        "print(' '.join(sorted({m.split('.')[0] for m in sys.modules} & set(%r))), file=sys.stderr)" % (HEAVY,))


def _env(pycache: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    if "PYTHONDONTWRITEBYTECODE" in os.environ:
        env["PYTHONPYCACHEPREFIX"] = pycache
    return env


def _run(tree: Path, argv: list[str], env: dict[str, str], importtime: bool = False
         ) -> tuple[float, float, float, str]:
    """(wall s, CPU s, import s or nan, heavy modules) of ``python [-X importtime] -c CLI argv`` in
    ``tree``; CPU (user + system, ``wait4``) is the figure to compare on a loaded machine."""
    cmd = [sys.executable, *(["-X", "importtime"] if importtime else []), "-c", _CLI, *argv]
    t = time.perf_counter()
    with tempfile.TemporaryFile("w+") as err:
        p = subprocess.Popen(cmd, cwd=tree, env=env, stdout=subprocess.DEVNULL, stderr=err, text=True)
        _, _, usage = os.wait4(p.pid, 0)
        p.returncode = 0  # reaped by wait4
        wall = time.perf_counter() - t
        err.seek(0)
        lines = err.read().splitlines()
    imports = sum(int(ln.split(":", 1)[1].split("|")[0]) for ln in lines
                  if ln.startswith("import time:") and ln.split(":", 1)[1].split("|")[0].strip().isdigit()) / 1e6
    return wall, usage.ru_utime + usage.ru_stime, imports if importtime else float("nan"), lines[-1] if lines else ""


def _pass(env: dict[str, str]) -> tuple[float, float]:
    t = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-c", "pass"], env=env)
    _, _, usage = os.wait4(p.pid, 0)
    p.returncode = 0
    return time.perf_counter() - t, usage.ru_utime + usage.ru_stime


def bench_startup(runs: int = 5, trees: tuple[Path, ...] = (ROOT,)) -> list[tuple]:
    """Rows ``(tree, what, median wall s, median CPU s, median import s, heavy modules)``, printed."""
    out_dir = tempfile.mkdtemp(prefix="grasplan-startup-")
    env = _env(os.path.join(out_dir, "pycache"))
    plan_file = os.path.join(out_dir, "bracket.json")
    cases = {"--help": ["--help"], "plan --help": ["plan", "--help"], "pick --help": ["pick", "--help"],
             "plan bracket": ["plan", str(BRACKET), "-o", plan_file],
             "plan bracket, numba JIT": ["plan", str(BRACKET), "-o", plan_file],
             "export bracket csv": ["export", plan_file, "--format", "csv", "-o", os.path.join(out_dir, "b.csv")]}
    samples: dict[tuple[str, str], list[tuple[float, float, float, str]]] = {}
    jit_env = {**env, "GRASPLAN_AOT": "0"}

    def env_of(what: str) -> dict[str, str]:
        return jit_env if "numba JIT" in what else env

    for tree in trees:  # unmeasured: fills the bytecode cache (and numba's, if it was cold)
        for what, argv in cases.items():
            _run(tree, argv, env_of(what))
    floor = []
    for _ in range(runs):
        floor.append(_pass(env))
        for tree in trees:
            for what, argv in cases.items():
                samples.setdefault((str(tree), what), []).append(_run(tree, argv, env_of(what)))
                if what == "plan bracket":
                    samples.setdefault((str(tree), "plan bracket imports"), []).append(
                        _run(tree, argv, env, importtime=True))
    med = statistics.median
    rows = [("-", "python -c pass", med(f[0] for f in floor), med(f[1] for f in floor), float("nan"), "")]
    for (tree, what), got in samples.items():
        if what == "plan bracket imports":
            rows.append((tree, "  its imports (-X importtime)", float("nan"), float("nan"), med(g[2] for g in got),
                         got[-1][3]))
        else:
            rows.append((tree, f"grasplan {what}", med(g[0] for g in got), med(g[1] for g in got), float("nan"),
                         got[-1][3]))
    sys.path.insert(0, str(ROOT))
    from grasplan.cli.common import table

    from grasplan.compiled import aot

    aot.load()
    print(f"\nstart-up: medians of {runs} whole processes (bracket: examples/parts/bracket.stl, UR5, table); "
          f"kernels: {aot.status()}")
    def f(x: float) -> str:
        return f"{x:.3f}" if x == x else ""

    print(table([(t, w, f(s), f(c), f(i), h) for t, w, s, c, i, h in rows],
                ("checkout", "command", "wall s", "CPU s", "imports s", "heavy modules imported")))
    if os.getloadavg()[0] > (os.cpu_count() or 1):
        print(f"note: load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; wall times are inflated")
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=5, help="whole processes per command (medians)")
    ap.add_argument("--tree", action="append", default=[], type=Path,
                    help="another checkout to measure alongside this one (e.g. a `git archive` of an older commit)")
    args = ap.parse_args(argv)
    bench_startup(max(1, args.runs), (ROOT, *args.tree))
    return 0


if __name__ == "__main__":
    sys.exit(main())
