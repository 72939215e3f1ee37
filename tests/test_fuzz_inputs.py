"""Reliability fuzz suite (issue 24): hostile inputs and output paths never lose data, never hang,
and end with the documented exit code.

Every case of ``tests/fuzz_inputs.py`` runs in an empty folder and is checked for:

* its exit code (3 for bad input and bad output folders; 0 where the input is fine);
* no traceback, no "internal error", no library exception name in the output;
* every file that existed before is byte-identical afterwards (symlinks and FIFOs unchanged);
* no leftover files: nothing new on a refusal, only the declared outputs on success, never a
  temporary file, a write probe or a batch's ``.staging``;
* a time limit per case (a blocked FIFO read fails the case instead of hanging the run).

``make test`` runs a subset (every family, a few cases each); ``GRASPLAN_FUZZ_FULL=1`` runs all
of them (docs/fuzz.md has the numbers).
"""
from __future__ import annotations

import fnmatch
import hashlib
import os
import re
import signal
import stat
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import pytest
from click.testing import CliRunner
from fuzz_inputs import PARTS, InputCase, input_cases, subset

import grasplan
from grasplan.cli import main

FULL = os.environ.get("GRASPLAN_FUZZ_FULL", "") not in ("", "0")
ALL = input_cases()
CASES = ALL if FULL else subset(ALL)
#: text only an unhandled exception or a library's internals produce
LEAKS = re.compile(r"Traceback|internal error|\b(?:Key|Index|Type|Attribute|Recursion|Memory|Value|OS|"
                   r"UnicodeDecode|UnicodeEncode|Constructor|Reader|Scanner|Parser|Composer|BadZipFile|"
                   r"IsADirectory|FileNotFound|NotADirectory|BlockingIO)Error\b")
#: names the command line may never leave behind
TEMP = re.compile(r"\.tmp$|\.grasplan-probe\.|(^|/)\.staging(/|$)")


class CaseTimeout(BaseException):
    """Raised by the alarm: a BaseException, so no ``except Exception`` in the code under test eats it."""


@contextmanager
def time_limit(seconds: float):
    def on_alarm(signum, frame):
        raise CaseTimeout(f"no answer within {seconds} s")
    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def snapshot(folder: Path) -> dict[str, tuple]:
    """Every entry under ``folder`` (symlinks not followed): kind and content hash / target."""
    out: dict[str, tuple] = {}
    for dirpath, dirnames, filenames in os.walk(folder, followlinks=False):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            rel = str(p.relative_to(folder))
            st = os.lstat(p)
            if stat.S_ISLNK(st.st_mode):
                out[rel] = ("link", os.readlink(p))
            elif stat.S_ISREG(st.st_mode):
                out[rel] = ("file", hashlib.sha256(p.read_bytes()).hexdigest())
            elif stat.S_ISDIR(st.st_mode):
                out[rel] = ("dir",)
            else:
                out[rel] = ("special", stat.S_IFMT(st.st_mode))
    return out


@pytest.fixture(scope="module")
def res(tmp_path_factory) -> dict:
    """A plan of box.stl (robot ur5) every export/view/simulate case starts from."""
    d = tmp_path_factory.mktemp("fuzzres")
    part = d / "box.stl"
    part.write_bytes((PARTS / "box.stl").read_bytes())
    result = grasplan.plan(grasplan.load_part(part, units="mm"), "ur5",
                           grasps=grasplan.GraspParams(roll_step_deg=90), planning=grasplan.PlanParams(top=1))
    assert result.counts()["planned"] >= 1
    result.write(d / "plan.json")
    return {"plan": d / "plan.json", "part": part}


def _cli_argv(argv: list[str]) -> list[str]:
    return [sys.executable, "-c", "from grasplan.cli import main; main()", *argv]


def _env() -> dict:
    root = str(Path(__file__).resolve().parents[1])
    return {**os.environ, "PYTHONPATH": root + os.pathsep + os.environ.get("PYTHONPATH", "")}


def run_case(case: InputCase, folder: Path, argv: list[str]) -> tuple[int, str]:
    """(exit code, output) of ``grasplan argv``, within the case's time limit."""
    if case.mode == "cli":
        with time_limit(case.limit_s):
            r = CliRunner().invoke(main, argv)
        if r.exception is not None and not isinstance(r.exception, SystemExit):
            raise AssertionError(f"unhandled {type(r.exception).__name__}: {r.exception}")
        return r.exit_code, r.output
    if case.mode == "stdout-full":
        with open("/dev/full", "w") as full:
            p = subprocess.run(_cli_argv(argv), stdout=full, stderr=subprocess.PIPE, text=True, cwd=folder,
                               timeout=case.limit_s, env=_env())
        return p.returncode, p.stderr
    if case.mode == "stdout-closed":
        proc = subprocess.Popen(_cli_argv(argv), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                cwd=folder, env=_env())
        assert proc.stdout is not None and proc.stderr is not None
        proc.stdout.close()  # the reader is gone before the summary is printed
        err = proc.stderr.read()
        return proc.wait(timeout=case.limit_s), err
    if case.mode == "sigterm":
        proc = subprocess.Popen(_cli_argv(argv), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                cwd=folder, env=_env())
        staging = folder / "out" / ".staging"
        t0 = time.monotonic()
        while time.monotonic() - t0 < case.limit_s and proc.poll() is None:
            if staging.is_dir() and any(staging.iterdir()):  # a part is being produced
                break
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        assert proc.stderr is not None
        err = proc.stderr.read()
        code = proc.wait(timeout=case.limit_s)
        return (128 - code if code < 0 else code), err
    raise ValueError(case.mode)


def check_case(case: InputCase, folder: Path, res: dict) -> None:
    argv = case.setup(folder, res)
    before = snapshot(folder)
    t0 = time.monotonic()
    code, output = run_case(case, folder, argv)
    seconds = time.monotonic() - t0
    shown = f"{case.name}: grasplan {' '.join(a[:80] for a in argv)[:600]}\n-> exit {code} in {seconds:.1f} s\n" \
            f"{output[-1500:]}"
    assert code in case.expect, shown
    assert not LEAKS.search(output), shown
    if code not in (0, 143):
        assert output.strip(), f"no message\n{shown}"
    after = snapshot(folder)
    declared = case.outputs if code in (0, 4, 143) else ()
    for rel, what in before.items():  # inputs byte-identical (declared outputs may be replaced)
        if any(fnmatch.fnmatch(rel, pat) for pat in declared):
            continue
        assert after.get(rel) == what, f"{rel} changed or removed\n{shown}"
    new = sorted(set(after) - set(before))
    stray = [n for n in new if not any(fnmatch.fnmatch(n, pat) for pat in declared)]
    assert not stray, f"left behind: {stray[:8]}\n{shown}"
    temps = [n for n in new if TEMP.search(n)]
    assert not temps, f"temporary files left: {temps[:8]}\n{shown}"
    if case.after is not None:
        case.after(folder)


def test_suite_is_large_and_covers_every_class():
    """>= 300 cases (issue 24), every class the issue names, unique names."""
    assert len(ALL) >= 300
    fams = {c.family for c in ALL}
    assert fams >= {"yaml_values", "output_guard", "special_files", "mesh_companions", "angles", "batch_folder",
                    "batch_promises", "repointed_plan", "obstacle_budget", "stdout"}
    assert {c.family for c in subset(ALL)} == fams


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_input_case(case: InputCase, res, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the CLI also looks in ./configs: an empty folder
    folder = tmp_path / "case"
    folder.mkdir()
    check_case(case, folder, res)
