"""``grasplan batch`` left running for a shift: workers that end with their batch process (the
kernel's parent-death signal and the watchdog, each on its own), the options hash built from
cached pieces (the same hash as the plain definition), Ray's wrapped signal exceptions, and the
file-name rules the linear bookkeeping relies on. The command-level cases are in
``tests/test_fuzz_batch.py``."""
from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

_FAMILY = """
import multiprocessing as mp, os, sys, time
import grasplan.batch.lifeline as lifeline

def worker(parent, how, flag):
    if how == "watchdog":  # as where the kernel offers no parent-death signal
        lifeline._parent_death_signal = lambda signum: False
    if how == "kernel":  # the kernel alone: no watchdog
        lifeline._watch = lambda parent: None
    lifeline.bind_to_parent(parent)
    open(flag, "w").close()
    time.sleep(120)

if __name__ == "__main__":
    how, flag = sys.argv[1], sys.argv[2]
    parent = os.getpid() if how != "wrong-parent" else os.getpid() + 1_000_000
    p = mp.get_context("spawn").Process(target=worker, args=(parent, how, flag))
    p.start()
    print(p.pid, flush=True)
    p.join() if how == "wrong-parent" else time.sleep(120)
    print(p.exitcode, flush=True)
"""


def _alive(pid: int) -> bool:
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return text[text.rindex(")") + 2] != "Z"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc (Linux)")
@pytest.mark.parametrize("how", ["kernel", "watchdog"])
def test_worker_ends_with_its_parent_killed(how, tmp_path):
    """kill -9 of the process that started a worker ends the worker within 2 s: by the kernel's
    parent-death signal alone, and by the watchdog thread alone (where that signal is not available)."""
    script = tmp_path / "family.py"
    script.write_text(_FAMILY)
    flag = tmp_path / "bound"
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen([sys.executable, str(script), how, str(flag)], stdout=subprocess.PIPE, text=True,
                            env=env, cwd=tmp_path, start_new_session=True)
    assert proc.stdout is not None
    child = int(proc.stdout.readline())
    try:
        t0 = time.monotonic()
        while not flag.exists() and time.monotonic() - t0 < 60:
            time.sleep(0.02)
        assert flag.exists() and _alive(child), "the worker did not start"
        proc.kill()
        proc.wait()
        t1 = time.monotonic()
        while _alive(child) and time.monotonic() - t1 < 2.0:
            time.sleep(0.02)
        assert not _alive(child), f"{how}: the worker outlived its parent by 2 s"
    finally:
        if proc.poll() is None:
            proc.kill()
        if _alive(child):
            os.kill(child, signal.SIGKILL)


def test_worker_of_a_parent_already_gone_ends_at_once(tmp_path):
    """A worker whose parent is not the process it was told (its parent died before the kernel
    was asked to watch it) ends at once instead of running orphaned."""
    script = tmp_path / "family.py"
    script.write_text(_FAMILY)
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    out = subprocess.run([sys.executable, str(script), "wrong-parent", str(tmp_path / "bound")], capture_output=True,
                         text=True, env=env, cwd=tmp_path, timeout=60)
    assert out.stdout.split()[-1] == "1", out.stdout + out.stderr
    assert not (tmp_path / "bound").exists()


def test_options_hash_pieces_give_the_plain_hash():
    """The options hash built from cached, pre-encoded pieces is the sha256 of the canonical JSON
    of the whole document, as it always was (so a rerun still finds finished parts)."""
    from grasplan import __version__
    from grasplan.batch.options import OPTIONS_SCHEMA, BatchOptions, _config_fingerprint, options_hash
    from grasplan.config.params import CandidateParams, GraspParams, PlanParams

    def plain(o: BatchOptions) -> str:
        doc = {"schema": OPTIONS_SCHEMA, "grasplan": __version__, "options": o.to_json(),
               "configs": {k: _config_fingerprint(k, getattr(o, k)) for k in ("robot", "gripper", "cell")}}
        return hashlib.sha256(json.dumps(doc, sort_keys=True, separators=(",", ":")).encode()).hexdigest()

    memo: dict = {}
    for o in (BatchOptions(), BatchOptions(planning=PlanParams(top=3, seed=5)),
              BatchOptions(units="mm", exports=("csv", "urscript"), view=False, gripper="onrobot_rg2", cell="bin",
                           T_world_part=((1, 0, 0, 0.1), (0, 1, 0, 0), (0, 0, 1, 0.2), (0, 0, 0, 1))),
              BatchOptions(grasps=GraspParams(pose_index="all"), candidates=CandidateParams(spacing=0.004))):
        assert options_hash(o, fingerprints=memo) == plain(o) == options_hash(o)
    assert len({k for k in memo if k[0] == "robot"}) == 1  # the robot's YAML read once


def test_ray_signal_exception_is_raised_as_itself():
    """A signal handler's exception that Ray hands back wrapped in a SystemError is raised as
    itself (the batch then stops as the signal asks); other SystemErrors stay what they are."""
    from grasplan.batch.engines import _signal_safe

    class Stop(BaseException):
        pass

    def wrapped():
        try:
            raise Stop()
        except Stop as exc:
            raise SystemError("returned a result with an exception set") from exc

    with pytest.raises(Stop):
        _signal_safe(wrapped)

    def plain_error():
        try:
            raise ValueError("x")
        except ValueError as exc:
            raise SystemError("y") from exc

    with pytest.raises(SystemError):
        _signal_safe(plain_error)
    assert _signal_safe(lambda a, b=0: a + b, 2, b=3) == 5


@pytest.mark.parametrize("path", ["a/b.stl", "b.tar.gz", ".hidden", "name.", "a/.x.stl", "/abs/p", "x..stl",
                                  "dir/part.STL"])
def test_stem_is_pathlib_stem(path):
    """Result folders are named from the part's stem, taken without pathlib: the same name."""
    from grasplan.batch.manifest import _stem

    assert _stem(path) == Path(path).stem
