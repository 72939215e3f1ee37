"""Start-up: ``grasplan --help`` and ``grasplan COMMAND --help`` import no heavy library (each
command imports what it needs when it runs), and the numba warm-up of ``make install``
(``python -m grasplan.cli.warmup``) fills numba's cache so a later run compiles nothing, and never
fails. Timings are benchmarks (``benchmarks/bench_plan.py --startup``), not tests."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from grasplan.cli.group import COMMANDS

ROOT = Path(__file__).resolve().parents[1]
#: libraries no help text needs (each costs 0.03-0.5 s to import)
HEAVY = ("scipy", "numba", "llvmlite", "pinocchio", "coal", "ompl", "trimesh", "mujoco", "fcl", "toppra",
         "networkx", "coacd", "ray", "fastapi", "uvicorn")
#: runs the command line in a fresh interpreter and prints the heavy modules it imported, last
_CHILD = r"""
import json, sys
from grasplan.cli import main
try:
    main(sys.argv[1:], prog_name="grasplan")
except SystemExit as e:
    code = e.code
else:
    code = 0
heavy = sorted(m for m in sys.modules if m.split(".")[0] in HEAVY)
print("\nIMPORTED " + json.dumps({"code": code, "heavy": heavy}))
"""


def imported_heavy(*args: str, prelude: str = "") -> tuple[int, list[str], str]:
    """``(exit code, heavy modules in sys.modules, stdout)`` of ``grasplan *args`` in a fresh
    interpreter (after ``prelude``, a statement)."""
    code = f"HEAVY = {HEAVY!r}\n{prelude}\n" + _CHILD
    r = subprocess.run([sys.executable, "-c", code, *args], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    line = [ln for ln in r.stdout.splitlines() if ln.startswith("IMPORTED ")][-1]
    got = json.loads(line[len("IMPORTED "):])
    return got["code"], got["heavy"], r.stdout


def imported_heavy_module(statement: str) -> list[str]:
    """Heavy top-level modules in ``sys.modules`` after ``statement`` in a fresh interpreter."""
    code = (f"import sys\n{statement}\n"
            f"print(' '.join(sorted({{m.split('.')[0] for m in sys.modules}} & set({HEAVY!r}))))")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return r.stdout.splitlines()[-1].split() if r.stdout.strip() else []


def test_the_check_sees_heavy_imports():
    """The child reports what was imported: a heavy library imported before ``--help`` is seen, and
    writing a URScript rotation vector loads SciPy (so a check that never saw anything would fail)."""
    code, heavy, out = imported_heavy("--help", prelude="import scipy.spatial")
    assert code == 0 and "Usage:" in out and "scipy" in " ".join(heavy)
    assert "scipy" in imported_heavy_module("import numpy, grasplan.export.urscript as u; u.rotvec(numpy.eye(3))")


@pytest.mark.parametrize("args", [
    pytest.param(["--help"], id="help"), pytest.param(["plan", "--help"], id="plan-help")] + [
    pytest.param([name, "--help"], id=f"{name}-help") for name in COMMANDS if name != "plan"])
def test_help_imports_no_heavy_library(args):
    code, heavy, out = imported_heavy(*args)
    assert code == 0 and "Usage:" in out
    assert heavy == [], f"grasplan {' '.join(args)} imported {heavy}"


def test_modules_every_command_loads_import_no_heavy_library():
    """What the CLI group, the shared CLI pieces, the options and the export registry import."""
    assert imported_heavy_module("import grasplan.cli.group, grasplan.cli.common, grasplan.cli.options, "
                                 "grasplan.results.export_registry as r; r.load_builtin_formats()") == []


def test_warm_up_failure_is_one_line_and_no_error(monkeypatch, capsys):
    from grasplan.cli import warmup

    def broken() -> None:
        raise OSError("read-only file system")

    monkeypatch.setattr(warmup, "run_kernels", broken)
    assert warmup.main() == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not cached" in err and "read-only file system" in err


def test_warm_up_says_when_numba_could_not_store_what_it_compiled(tmp_path):
    from collections import Counter
    from types import SimpleNamespace

    from grasplan.cli.warmup import _summary

    def kernel(misses: int, hits: int, index: Path) -> SimpleNamespace:
        return SimpleNamespace(_cache_misses=Counter({"sig": misses}), _cache_hits=Counter({"sig": hits}),
                               _cache=SimpleNamespace(_cache_file=SimpleNamespace(_index_path=str(index))))

    stored = tmp_path / "a.nbi"
    stored.write_bytes(b"")
    ok = _summary([("m.a", kernel(1, 0, stored)), ("m.b", kernel(0, 2, tmp_path / "b.nbi"))], 1.0)
    assert "1 compiled, 2 loaded" in ok and str(tmp_path) in ok
    lost = _summary([("m.a", kernel(1, 0, stored)), ("m.c", kernel(1, 0, tmp_path / "c.nbi"))], 1.0)
    assert "could not store 1 of 2" in lost and "m.c" in lost and "NUMBA_CACHE_DIR" in lost
    assert "compiled or loaded" in _summary([("m.d", SimpleNamespace())], 1.0)  # other numba internals


def test_warm_up_lists_the_cached_kernels():
    from grasplan.cli.warmup import KERNEL_MODULES, kernels

    names = [name for name, _ in kernels(KERNEL_MODULES)]
    for module in KERNEL_MODULES:
        assert any(n.startswith(module + ".") for n in names), module
    assert "grasplan.robot.ik.ur_batch._branch" in names and "grasplan.motion.pathboxes.obb_apart" in names


@pytest.mark.slow
def test_after_the_warm_up_plan_and_pick_compile_nothing(tmp_path):
    """A cold numba cache: the warm-up compiles (saying so once) and builds the ahead-of-time
    module; then ``grasplan plan`` of an example imports no numba at all and writes the same
    document as numba's JIT (``GRASPLAN_AOT=0``), and ``grasplan pick`` compiles nothing."""
    from grasplan.compiled.jit import COMPILE_MESSAGE

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba"), "GRASPLAN_CACHE_DIR": str(tmp_path / "cache"),
           "GRASPLAN_KERNELS_DIR": str(tmp_path / "kernels")}
    warm = subprocess.run([sys.executable, "-m", "grasplan.cli.warmup"], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=1200)
    assert warm.returncode == 0, warm.stderr
    assert warm.stderr.count(COMPILE_MESSAGE) == 1, warm.stderr
    assert "kernels cached" in warm.stderr and " 0 compiled" not in warm.stderr, warm.stderr
    assert "compiled ahead of time" in warm.stderr and (tmp_path / "kernels" / "manifest.json").is_file(), warm.stderr
    assert any((tmp_path / "numba").rglob("*.nbi"))
    assert not (tmp_path / "cache").exists()  # the box's grasp database is not kept
    child = ("import sys\nfrom grasplan.cli import main\ntry:\n    main(sys.argv[1:], prog_name='grasplan')\n"
             "finally:\n    print('NUMBA', 'numba' in sys.modules, file=sys.stderr)")
    bracket = str(ROOT / "examples" / "parts" / "bracket.stl")
    docs = {}
    for name, extra, args in (("aot", {}, ["plan", bracket, "-o", str(tmp_path / "aot.json")]),
                              ("jit", {"GRASPLAN_AOT": "0"}, ["plan", bracket, "-o", str(tmp_path / "jit.json")]),
                              ("pick", {}, ["pick", str(ROOT / "examples" / "scenes" / "pile.json"),
                                            "-o", str(tmp_path / "k.json")])):
        r = subprocess.run([sys.executable, "-c", child, *args], cwd=tmp_path, env={**env, **extra},
                           capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, r.stderr
        assert COMPILE_MESSAGE not in r.stderr, (name, r.stderr)
        if name != "pick":
            assert ("NUMBA False" in r.stderr) == (name == "aot"), (name, r.stderr)
            doc = json.loads((tmp_path / f"{name}.json").read_text())
            doc.pop("timing_s")
            docs[name] = doc
    assert docs["aot"] == docs["jit"] and docs["aot"]["grasps"]


def test_numba_gets_a_cache_folder_when_its_own_places_are_read_only(tmp_path, monkeypatch):
    """A read-only install with an unwritable home: numba would refuse every cached kernel ("no
    locator available"); grasplan sends its cache to a temporary folder instead, where a kernel
    defined afterwards stores its cache."""
    import tempfile

    import numba

    from grasplan.compiled import jit

    monkeypatch.setattr(numba.config, "CACHE_DIR", "")
    monkeypatch.setattr(tempfile, "gettempdir", lambda: str(tmp_path))
    assert jit.ensure_cache_dir(writable=lambda folder: True) is None  # numba's own places do
    folder = jit.ensure_cache_dir(writable=lambda folder: False)
    assert folder is not None and folder.parent == tmp_path and folder.name.startswith("grasplan-numba-")
    assert numba.config.CACHE_DIR == str(folder)
    assert jit.ensure_cache_dir(writable=lambda folder: False) is None  # set once: numba uses it

    @numba.njit(cache=True)
    def twice(x):
        return 2 * x

    assert twice(21) == 42
    assert any(folder.rglob("*.nbi")), "the kernel's cache index is in the folder grasplan chose"


@pytest.mark.parametrize("given", [None, "2"])
def test_a_command_runs_openblas_on_one_thread_unless_told(given):
    """A command sets ``OPENBLAS_NUM_THREADS=1`` before NumPy loads (idle BLAS threads spin after
    each call); a value in the environment is kept. The garbage collector, paused while the
    command's modules load, runs again after."""
    BLAS_THREADS_ENV = "OPENBLAS_NUM_THREADS"
    env = {k: v for k, v in os.environ.items() if k != BLAS_THREADS_ENV}
    if given is not None:
        env[BLAS_THREADS_ENV] = given
    code = ("import os, sys\nfrom grasplan.cli import main\ntry:\n    main(['plan', '--help'], prog_name='grasplan')\n"
            "except SystemExit:\n    pass\nimport gc\nprint('NUMPY', 'numpy' in sys.modules, os.environ.get(%r), gc.isenabled(), "
            "gc.get_freeze_count() > 0)" % BLAS_THREADS_ENV)
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == f"NUMPY True {given or '1'} True True"
