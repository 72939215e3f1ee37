"""Every catchable signal during a write: no temporary file is left, an existing output is intact
or completely replaced, and the process ends exactly as the signal ends it when no write is in
progress (grasplan/io.py ``signals_raise``).

Each case starts two child processes that wait at the same point for a release file: a writer,
inside a write (``write_atomic_chunks`` with a slow generator, ``write_files_atomic`` with a slow
fsync, or the real ``grasplan candidates`` command with a slow fsync), its temporary file present;
and a baseline, at the same point of the same program with no write in progress. Both get the
signal (a stop signal is followed by SIGCONT), then the release. The writer must end the way the
baseline ends (killed by the signal, an exit status, or going on to finish), leave no ``*.tmp``,
and leave the old output untouched unless it finished.

Not covered: SIGKILL and SIGSTOP (cannot be caught) and the synchronous fault signals SIGSEGV,
SIGBUS, SIGFPE, SIGILL, SIGTRAP and SIGSYS (a Python handler returning from a real fault would
re-run the faulting instruction forever, so they keep their default action).

Default run: every other signal through ``write_atomic_chunks`` (the real-time ones: SIGRTMIN,
SIGRTMIN+1 and SIGRTMAX), the signals a shift in a cell sends (HUP, INT, QUIT, USR1, ALRM, TERM)
through ``write_files_atomic`` and the CLI. ``GRASPLAN_FUZZ_FULL=1``: every signal through all three.
"""
from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BOX = ROOT / "examples" / "parts" / "box.stl"
FULL = os.environ.get("GRASPLAN_FUZZ_FULL") == "1"

UNCATCHABLE = {signal.SIGKILL, signal.SIGSTOP}
FAULTS = {signal.SIGSEGV, signal.SIGBUS, signal.SIGFPE, signal.SIGILL, signal.SIGTRAP, signal.SIGSYS}
STOPS = {signal.SIGTSTP, signal.SIGTTIN, signal.SIGTTOU}
SHIFT = (signal.SIGHUP, signal.SIGINT, signal.SIGQUIT, signal.SIGUSR1, signal.SIGALRM, signal.SIGTERM)
CATCHABLE = sorted(int(s) for s in signal.valid_signals() if s not in UNCATCHABLE | FAULTS)
REALTIME = [s for s in CATCHABLE if s >= signal.SIGRTMIN]
SAMPLE_RT = {signal.SIGRTMIN, signal.SIGRTMIN + 1, signal.SIGRTMAX}
CHUNK = 1 << 16
CHUNKS = 64  # 4 MB when a write finishes

CHILD = r"""
import os, sys, time
role, mode, out, release = sys.argv[1:5]
CHUNK, CHUNKS = int(sys.argv[5]), int(sys.argv[6])

def wait():
    print("@@waiting@@", flush=True)
    t0 = time.monotonic()
    while not os.path.exists(release) and time.monotonic() - t0 < 60:
        time.sleep(0.02)

if mode == "cli":
    import grasplan.part.mesh as gm
    if role == "baseline":  # the same command, stopped before its work instead of inside its write
        real_load = gm.load_part
        def load_part(*a, **k):
            wait()
            return real_load(*a, **k)
        gm.load_part = load_part
    else:
        real_fsync = os.fsync
        def fsync(fd):
            wait()
            real_fsync(fd)
        os.fsync = fsync
    from grasplan.cli import main
    sys.argv = ["grasplan", "candidates", sys.argv[7], "-o", out]
    main()
import grasplan.io as gio
if role == "baseline":
    wait()
elif mode == "chunks":
    def chunks():
        yield b"x" * CHUNK
        wait()
        for _ in range(CHUNKS - 1):
            yield b"x" * CHUNK
    gio.write_atomic_chunks(out, chunks())
else:
    real_fsync, first = os.fsync, [True]
    def fsync(fd):
        if first.pop() if first else False:
            wait()
        real_fsync(fd)
    os.fsync = fsync
    gio.write_files_atomic([(out, b"x" * (CHUNK * CHUNKS)), (out + ".dat", b"d" * CHUNK)])
"""


def _name(sig: int) -> str:
    if sig in (signal.SIGRTMIN, signal.SIGRTMAX):
        return signal.Signals(sig).name
    if sig > signal.SIGRTMIN:
        return f"SIGRTMIN+{sig - signal.SIGRTMIN}"
    return signal.Signals(sig).name


def _cases() -> list[tuple[str, int]]:
    out = []
    for sig in CATCHABLE:
        if FULL or sig not in REALTIME or sig in SAMPLE_RT:
            out.append(("chunks", sig))
    for mode in ("group", "cli"):
        out += [(mode, sig) for sig in (CATCHABLE if FULL else [int(s) for s in SHIFT])]
    return out


CASES = _cases()


def _no_core() -> None:
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))  # SIGQUIT/SIGABRT: no core file in the test folder
    # a shell starts background jobs with SIGINT and SIGQUIT ignored, and children inherit that
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGQUIT, signal.SIG_DFL)


def _start(role: str, mode: str, folder: Path, release: Path) -> subprocess.Popen:
    folder.mkdir()
    out = folder / "out.json"
    out.write_bytes(b"old")
    argv = [sys.executable, "-c", CHILD, role, mode, str(out), str(release), str(CHUNK), str(CHUNKS), str(BOX)]
    return subprocess.Popen(argv, cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_no_core)


def _wait_ready(proc: subprocess.Popen) -> None:
    assert proc.stdout is not None
    for line in proc.stdout:
        if line.strip() == "@@waiting@@":
            return
    raise AssertionError(f"the child ended before its write (exit {proc.wait()}): {proc.stderr.read()[-2000:]}")


def _stopped(pid: int) -> bool:
    with open(f"/proc/{pid}/stat") as f:
        return f.read().rsplit(")", 1)[1].split()[0] == "T"


def _temporaries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="signal numbers and /proc of Linux")
@pytest.mark.parametrize(("mode", "sig"), CASES, ids=[f"{m}-{_name(s)}" for m, s in CASES])
def test_signal_during_a_write_leaves_no_temporary_file(tmp_path, mode, sig):
    release = tmp_path / "release"
    base = _start("baseline", mode, tmp_path / "baseline", release)
    writer = _start("writer", mode, tmp_path / "writer", release)
    procs = (base, writer)
    try:
        for p in procs:
            _wait_ready(p)
        assert _temporaries(tmp_path / "writer"), "no temporary file while writing: the case tests nothing"
        for p in procs:
            os.kill(p.pid, sig)
        if sig in STOPS:
            t0 = time.monotonic()
            while not all(_stopped(p.pid) for p in procs) and time.monotonic() - t0 < 30:
                time.sleep(0.01)
            for p in procs:
                os.kill(p.pid, signal.SIGCONT)
        t0 = time.monotonic()  # a signal that ends the process has done so well before the release
        while any(p.poll() is None for p in procs) and time.monotonic() - t0 < 0.3:
            time.sleep(0.01)
        release.touch()
        codes = [p.wait(timeout=120) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    errs = writer.stderr.read()[-3000:] if writer.stderr else ""
    assert codes[1] == codes[0], f"{_name(sig)}: the writer ended with {codes[1]}, the process without a write " \
                                 f"in progress with {codes[0]}\n{errs}"
    assert _temporaries(tmp_path / "writer") == [], errs
    out = tmp_path / "writer" / "out.json"
    if codes[1] == 0:  # the signal does not end the process: the write finished
        assert out.stat().st_size > len(b"old"), errs
    else:
        assert out.read_bytes() == b"old", "the existing output was changed by an interrupted write"
        assert not (tmp_path / "writer" / "out.json.dat").exists()


def test_every_terminating_signal_is_in_the_cleanup_set():
    """The set the writer handles is every catchable signal whose default action ends the process
    (as the kernel documents them: not the ignored or stopping ones)."""
    from grasplan.io import CLEANUP_SIGNALS

    ignored_or_stop = {signal.SIGCHLD, signal.SIGCONT, signal.SIGURG, signal.SIGWINCH} | STOPS
    assert set(CLEANUP_SIGNALS) == set(CATCHABLE) - ignored_or_stop


_CLEANUP_RACE = """
import os, signal, sys
from grasplan.io import signals_raise
marker = sys.argv[1]
with signals_raise():
    with signals_raise():  # nested: the outer one handles the signal
        try:
            os.kill(os.getpid(), signal.SIGHUP)
            for _ in range(10_000_000):  # the handler raises before this ends
                pass
        finally:
            os.kill(os.getpid(), signal.SIGUSR1)  # a second signal during the first one's cleanup
            with open(marker, "w") as f:
                f.write("cleaned")
"""


def test_a_second_signal_does_not_cut_the_cleanup_short(tmp_path):
    """The cleanup of the first signal runs to its end although another signal arrives meanwhile, and
    the process ends by the first one."""
    marker = tmp_path / "marker"
    r = subprocess.run([sys.executable, "-c", _CLEANUP_RACE, str(marker)], capture_output=True, text=True,
                       timeout=60, cwd=ROOT)
    assert marker.read_text() == "cleaned", r.stderr[-2000:]
    assert r.returncode == -signal.SIGHUP, (r.returncode, r.stderr[-2000:])
