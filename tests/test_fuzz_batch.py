"""Fuzz classes of ``grasplan batch`` left running (docs/fuzz.md):

* ``manifest_scaling``: the batch's bookkeeping is linear in a manifest's rows. Every function call
  (Python and C) of ``run_batch`` is counted for N and 4N rows (nothing is planned: an engine that
  answers every part at once stands in for the workers) in three phases: setup (manifest read and
  validated, parts and options hashed, folders named, output folder checked, resume scan),
  finish (each part filed, the summary written) and resume (the same command again, every part
  done); 4N rows may cost at most 5x the calls of N rows (a quadratic step costs 16x). The
  seconds are in ``benchmarks/batch.py --scaling``. A YAML manifest beyond the YAML reader's
  entry limit is refused with the advice to write it as CSV; the output-folder check, now linear,
  still refuses a result folder linked to the parts' folder and a summary hard-linked to an input.
* ``manifest_keys``: an unknown top-level key of a YAML manifest, an unknown key in ``defaults``
  or in a part, an unknown or repeated CSV column, one option set under two spellings: exit 3
  naming the key and the accepted keys, nothing written.
* ``description_files``: the robot, gripper, cell, scoring and part_pose fields (manifest column
  or command-line option) naming a file that is not such a description (``/etc/passwd``, a JSON
  file, binary bytes, an empty file): exit 3 naming the field and the file, before any worker
  starts (the output folder is not even created).
* ``batch_signals``: SIGHUP, SIGINT, SIGQUIT, SIGTERM, SIGUSR1, SIGALRM and SIGKILL sent to a
  running batch (a real pool of 2 workers, a few parts): within a few seconds no process of the
  batch is left (its session, checked in /proc), the caller's pipes are closed, and (but for
  SIGKILL, which nothing can catch) no ``.staging`` and no temporary file remain; the exit status
  is the signal's (130 for SIGINT, after the summary). With ``--engine ray`` (full run only: it
  starts a Ray runtime), SIGHUP ends every Ray process and SIGKILL the tasks, raylet and GCS.

``GRASPLAN_FUZZ_FULL=1`` runs every case; the default run a subset of each class.
"""
from __future__ import annotations

import contextlib
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
import zlib
from pathlib import Path

import pytest
from click.testing import CliRunner

from grasplan.cli import main

ROOT = Path(__file__).resolve().parents[1]
BRACKET = ROOT / "examples" / "parts" / "bracket.stl"
FULL = os.environ.get("GRASPLAN_FUZZ_FULL", "") not in ("", "0")
#: fast planning options
QUICK = ("--units", "mm", "--top", "1", "--roll-step", "90")


def _cli(argv: list[str]) -> tuple[int, str]:
    r = CliRunner().invoke(main, argv)
    if r.exception is not None and not isinstance(r.exception, SystemExit):
        raise AssertionError(f"unhandled {type(r.exception).__name__}: {r.exception}\n{r.output[-800:]}")
    return r.exit_code, r.output


def _params(cases: list, default: list) -> list:
    return cases if FULL else [c for c in cases if c[0] in default]


# ------------------------------------------------------------------------------------ manifest_scaling
_TETRA = ("solid {n}\nfacet normal 0 0 -1\nouter loop\nvertex 0 0 0\nvertex 10 0 0\nvertex 0 10 0\nendloop\n"
          "endfacet\nfacet normal 0 -1 0\nouter loop\nvertex 0 0 0\nvertex 0 0 10\nvertex 10 0 0\nendloop\n"
          "endfacet\nfacet normal -1 0 0\nouter loop\nvertex 0 0 0\nvertex 0 10 0\nvertex 0 0 10\nendloop\n"
          "endfacet\nfacet normal 0.577 0.577 0.577\nouter loop\nvertex 10 0 0\nvertex 0 0 10\nvertex 0 10 0\n"
          "endloop\nendfacet\nendsolid {n}\n")


def _catalogue(folder: Path, n: int, kind: str) -> Path:
    """``n`` rows of ``kind``: the input to give ``run_batch``."""
    parts = folder / "parts"
    parts.mkdir(parents=True)
    names = [f"p{i:05d}.stl" for i in range(n)]
    for name in names:  # each file its own bytes: no row is a duplicate of another
        (parts / name).write_text(_TETRA.format(n=name[:-4]))
    if kind == "folder":
        return parts
    if kind == "yaml":
        m = folder / "m.yaml"
        m.write_text("defaults: {units: mm}\nparts:\n"
                     + "".join(f"  - {{path: parts/{x}, top: {1 + i % 5}}}\n" for i, x in enumerate(names)))
    elif kind == "csv-seed":  # every row its own option set
        m = folder / "m.csv"
        m.write_text("path,units,seed\n" + "".join(f"parts/{x},mm,{i}\n" for i, x in enumerate(names)))
    elif kind == "duplicates":  # one file named n times
        m = folder / "m.csv"
        m.write_text("path,units\n" + "".join(f"parts/{names[0]},mm\n" for _ in names))
    else:
        m = folder / "m.csv"
        m.write_text("path,units,top\n" + "".join(f"parts/{x},mm,{1 + i % 5}\n" for i, x in enumerate(names)))
    return m


def _answer_all(jobs, **_kw):
    """An engine that plans nothing: every part planned at once, with a one-line log."""
    _answer_all.started = True  # type: ignore[attr-defined]
    for job in jobs:
        row = {"status": "planned", "exit_code": 0, "planned": 1, "grasps": 1, "best_score": 0.5,
               "timing_s": {"load": 0.001, "total": 0.01}, "error": ""}
        yield job, {"row": row, "files": {"log.txt": zlib.compress(f"part: {job.path}\n".encode())}}, None


def _count_calls(folder: Path, n: int, kind: str) -> dict[str, int]:
    """Function calls of each phase of a batch of ``n`` rows (see the module doc)."""
    from grasplan.batch.run import run_batch

    src = _catalogue(folder, n, kind)
    counts = {"calls": 0}
    marks: dict[str, int] = {}

    def prof(frame, event, arg):
        if event in ("call", "c_call"):
            counts["calls"] += 1

    def engine(jobs, **kw):
        marks["setup"] = counts["calls"]
        yield from _answer_all(jobs, **kw)

    from grasplan.batch.engines import ENGINES

    ENGINES["test-answer-all"] = engine
    try:
        sys.setprofile(prof)
        try:
            s1 = run_batch([src], folder / "out", engine="test-answer-all", workers=1)
            marks["finish"] = counts["calls"] - marks["setup"]
            before = counts["calls"]
            s2 = run_batch([src], folder / "out", engine="test-answer-all", workers=1)
            marks["resume"] = counts["calls"] - before
        finally:
            sys.setprofile(None)
    finally:
        ENGINES.pop("test-answer-all", None)
    assert len(s1.rows) == n and s1.counts["planned"] == n, s1.counts
    assert s2.counts["resumed"] == n, s2.counts  # a duplicate row shares its first row's result
    return marks


SCALING = [(k,) for k in ("csv", "yaml", "folder", "csv-seed", "duplicates")]


@pytest.mark.parametrize("kind", [c[0] for c in _params(SCALING, ["csv", "yaml", "duplicates"])])
def test_manifest_scaling(kind, tmp_path, monkeypatch):
    """4x the rows cost at most 5x the function calls, in every phase."""
    monkeypatch.setattr(os, "fsync", lambda fd: None)  # the bookkeeping, not the disk
    _count_calls(tmp_path / "warm", 4, kind)  # imports, loaded descriptions: not part of the count
    n = 60
    small = _count_calls(tmp_path / "small", n, kind)
    large = _count_calls(tmp_path / "large", 4 * n, kind)
    for phase in ("setup", "finish", "resume"):
        ratio = large[phase] / max(1, small[phase])
        assert ratio <= 5.0, (f"{kind} {phase}: {small[phase]:,} calls for {n} rows, {large[phase]:,} for {4 * n} "
                              f"(x{ratio:.1f}; linear is about x4)")


def test_yaml_manifest_beyond_the_entry_limit_says_csv(tmp_path):
    from grasplan.config.yamlfile import MAX_MANIFEST_ENTRIES

    (tmp_path / "p.stl").write_text(_TETRA.format(n="p"))
    rows = MAX_MANIFEST_ENTRIES // 8 + 10  # each row: - { : , : , : and a line break
    m = tmp_path / "m.yaml"
    m.write_text("parts:\n" + "".join(f"  - {{path: p.stl, top: 1, seed: {i}}}\n" for i in range(rows)))
    t = time.monotonic()
    code, out = _cli(["batch", str(m), "-o", str(tmp_path / "out")])
    assert code == 3 and "CSV" in out and f"{MAX_MANIFEST_ENTRIES:,}" in out, out
    assert time.monotonic() - t < 30
    assert not (tmp_path / "out").exists()


def _dir_of(part: Path) -> str:
    """The result folder a part gets: <stem>-<sha8>."""
    import hashlib

    return f"{part.stem}-{hashlib.sha256(part.read_bytes()).hexdigest()[:8]}"


def test_out_dir_result_folder_linked_to_the_parts(tmp_path):
    """The output folder check, linear: a part's result folder that is a symbolic link to the
    folder holding the part (the batch would replace it) is still refused."""
    parts = tmp_path / "parts"
    parts.mkdir()
    part = parts / "p.stl"
    part.write_text(_TETRA.format(n="p"))
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / _dir_of(part)).symlink_to(parts)
    code, out = _cli(["batch", str(part), "-o", str(tmp_path / "out"), "--units", "mm"])
    assert code == 3 and "lies in" in out, out
    assert sorted(x.name for x in (tmp_path / "out").iterdir()) == [_dir_of(part)]


def test_out_dir_summary_hard_linked_to_an_input(tmp_path):
    """... and an input that is out/summary.csv under another name (a hard link) is refused."""
    part = tmp_path / "p.stl"
    part.write_text(_TETRA.format(n="p"))
    m = tmp_path / "m.csv"
    m.write_text("path\np.stl\n")
    (tmp_path / "out").mkdir()
    os.link(m, tmp_path / "out" / "summary.csv")
    code, out = _cli(["batch", str(m), "-o", str(tmp_path / "out"), "--units", "mm"])
    assert code == 3 and "summary.csv" in out, out
    assert m.read_text() == "path\np.stl\n"


# ------------------------------------------------------------------------------------ manifest_keys
#: (case, manifest file name, text, what the message must name)
KEYS = [
    ("yaml-top-options", "m.yaml", "parts: [p.stl]\noptions: {top: 3}\n", ["'options'", "'defaults'", "'parts'"]),
    ("yaml-top-part-typo", "m.yaml", "part: [p.stl]\n", ["'part'", "'parts'"]),
    ("yaml-top-robot", "m.yaml", "robot: ur5\nparts: [p.stl]\n", ["'robot'", "'defaults'"]),
    ("yaml-top-capital-defaults", "m.yaml", "Defaults: {top: 2}\nparts: [p.stl]\n", ["'Defaults'", "'defaults'"]),
    ("yaml-no-parts", "m.yaml", "defaults: {top: 2}\n", ["'parts'"]),
    ("yaml-defaults-unknown", "m.yaml", "defaults: {topp: 3}\nparts: [p.stl]\n", ["'topp'", "accepted:", "top"]),
    ("yaml-defaults-path", "m.yaml", "defaults: {path: p.stl}\nparts: [{top: 1}]\n", ["defaults", "'path'"]),
    ("yaml-part-unknown", "m.yaml", "parts:\n  - {path: p.stl, pose_idx: 1}\n", ["'pose_idx'", "accepted:"]),
    ("yaml-part-two-spellings", "m.yaml", "parts:\n  - {path: p.stl, thin: 2mm, thin_spacing: 3mm}\n",
     ["'thin'", "'thin_spacing'"]),
    ("csv-unknown-column", "m.csv", "path,tpo\np.stl,3\n", ["'tpo'", "accepted:"]),
    ("csv-unknown-empty-cells", "m.csv", "path,tpo\np.stl,\n", ["'tpo'", "accepted:"]),
    ("csv-column-twice", "m.csv", "path,top,top\np.stl,1,2\n", ["'top'", "twice"]),
    ("csv-two-spellings", "m.csv", "path,pose_index,pose-index\np.stl,1,2\n", ["'pose_index'", "'pose-index'"]),
]


@pytest.mark.parametrize("case,name,text,names", KEYS, ids=[k[0] for k in KEYS])
def test_manifest_keys(case, name, text, names, tmp_path):
    (tmp_path / "p.stl").write_text(_TETRA.format(n="p"))
    m = tmp_path / name
    m.write_text(text)
    code, out = _cli(["batch", str(m), "-o", str(tmp_path / "out"), "--workers", "1"])
    assert code == 3, out
    line = out.strip().splitlines()[-1]
    for n in names:
        assert n in line, f"{case}: {n} not named in: {line}"
    assert "Traceback" not in out and not (tmp_path / "out").exists()


# ------------------------------------------------------------------------------------ description_files
def _bad_file(folder: Path, how: str) -> Path:
    if how == "passwd":
        return Path("/etc/passwd")
    p = folder / {"json": "desc.json", "binary": "desc.yaml", "empty": "empty.yaml"}[how]
    if how == "json":
        p.write_text('{"name": "x", "weights": [1, 2], "urdf": 5}\n')
    elif how == "binary":
        p.write_bytes(bytes(range(256)) * 4)
    else:
        p.write_bytes(b"")
    return p


FIELDS = ("robot", "gripper", "cell", "scoring", "part_pose")
FILES = ("passwd", "json", "binary", "empty")
DESCRIPTIONS = [(f"{via}-{field}-{how}", via, field, how) for via in ("manifest", "option") for field in FIELDS
                for how in FILES]
DESCRIPTIONS_DEFAULT = [c[0] for c in DESCRIPTIONS if c[1] == "manifest" or c[3] == "passwd"]


@pytest.mark.parametrize("case,via,field,how", _params(DESCRIPTIONS, DESCRIPTIONS_DEFAULT),
                         ids=[c[0] for c in _params(DESCRIPTIONS, DESCRIPTIONS_DEFAULT)])
def test_description_files(case, via, field, how, tmp_path):
    if how == "passwd" and not Path("/etc/passwd").is_file():
        pytest.skip("no /etc/passwd on this system")
    shutil.copy(BRACKET, tmp_path / "bracket.stl")
    bad = _bad_file(tmp_path, how)
    out = tmp_path / "out"
    if via == "manifest":
        m = tmp_path / "m.csv"
        m.write_text(f"path,{field}\nbracket.stl,{bad}\n")
        argv = ["batch", str(m), "-o", str(out), "--workers", "1", *QUICK]
    else:
        argv = ["batch", str(tmp_path / "bracket.stl"), "-o", str(out), "--workers", "1", *QUICK,
                f"--{field.replace('_', '-')}", str(bad)]
    code, text = _cli(argv)
    assert code == 3, f"{case}: exit {code}\n{text[-600:]}"
    line = text.strip().splitlines()[-1]
    assert field.replace("_", "-") in line or field in line, f"{case}: the field is not named: {line}"
    assert bad.name in line, f"{case}: the file is not named: {line}"
    assert "Traceback" not in text
    assert not out.exists(), f"{case}: the output folder was created before the refusal"


# ------------------------------------------------------------------------------------ batch_signals
def _kill_session(proc: subprocess.Popen) -> None:
    """End ``proc`` and every process of its session still alive (what the test started)."""
    if proc.poll() is None:
        proc.kill()
        proc.wait()
    for pid, _ in _session(proc.pid):
        with contextlib.suppress(OSError):  # gone between the listing and the kill
            os.kill(pid, signal.SIGKILL)


def _session(sid: int) -> list[tuple[int, str]]:
    """(pid, command line) of every live process of session ``sid`` (zombies aside)."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
            fields = stat[stat.rindex(")") + 2:].split()
            cmd = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except (OSError, ValueError):
            continue
        if int(fields[3]) == sid and fields[0] != "Z":
            found.append((int(entry), cmd[:160]))
    return found


def _no_core() -> None:
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))  # SIGQUIT's default action dumps core
    # a shell starts background jobs with SIGINT and SIGQUIT ignored, and children inherit that:
    # the batch must meet these signals as a terminal's user sends them
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGQUIT, signal.SIG_DFL)


SIGNALS = [(name,) for name in ("SIGHUP", "SIGINT", "SIGQUIT", "SIGTERM", "SIGUSR1", "SIGALRM", "SIGKILL")]


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc (Linux)")
@pytest.mark.parametrize("name", [s[0] for s in SIGNALS])
def test_batch_signals(name, tmp_path):
    sig = getattr(signal, name)
    shutil.copy(BRACKET, tmp_path / "bracket.stl")
    (tmp_path / "m.csv").write_text("path,seed\n" + "".join(f"bracket.stl,{i}\n" for i in range(1, 9)))
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen([sys.executable, "-c", "from grasplan.cli import main; main()", "batch", "m.csv", "-o",
                             str(out), "--workers", "2", "--no-view", *QUICK],
                            cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True, preexec_fn=_no_core)
    staging = out / ".staging"
    try:
        t0 = time.monotonic()
        while time.monotonic() - t0 < 120 and proc.poll() is None:
            if staging.is_dir() and any(staging.iterdir()):  # a worker is planning a part
                break
            time.sleep(0.02)
        assert proc.poll() is None, f"the batch ended before the signal:\n{proc.communicate()[1].decode()[-600:]}"
        workers = [p for p, cmd in _session(proc.pid) if p != proc.pid]
        assert workers, "no worker process seen"
        proc.send_signal(sig)
        try:  # the caller's pipes close once every process holding them is gone
            _, err = proc.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"{name}: the caller's pipes still open 20 s after the signal; processes: "
                                 f"{_session(proc.pid)}") from None
        deadline = time.monotonic() + 5
        while _session(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        left = _session(proc.pid)
        assert not left, f"{name}: processes of the batch still alive 5 s after it ended: {left}"
        want = {130} if sig == signal.SIGINT else {-sig, 128 + sig}
        assert proc.returncode in want, f"{name}: exit {proc.returncode}, want {want}\n{err.decode()[-600:]}"
        text = err.decode(errors="replace")
        assert "Traceback" not in text, text[-1500:]
        if sig != signal.SIGKILL:
            assert not staging.exists(), f"{name} left {staging}"
            temps = [str(p) for p in tmp_path.rglob("*") if p.name.endswith(".tmp") or ".grasplan-probe." in p.name]
            assert not temps, f"{name} left temporary files: {temps}"
    finally:
        _kill_session(proc)


#: Ray's processes that must end with the batch process (its agents, idle, end on their own within about a minute)
_RAY_WORK = ("ray::run_part", "raylet", "gcs_server")


@pytest.mark.skipif(not FULL, reason="starts a Ray runtime (about 20 s): GRASPLAN_FUZZ_FULL=1")
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc (Linux)")
@pytest.mark.parametrize("name", ["SIGHUP", "SIGKILL"])
def test_batch_signals_ray(name, tmp_path):
    """--engine ray (a private local runtime): SIGHUP stops every Ray process, removes .staging and
    leaves no task's temporary folder; after SIGKILL the tasks, the raylet and the GCS end within
    seconds (Ray's own fate sharing)."""
    pytest.importorskip("ray")
    sig = getattr(signal, name)
    shutil.copy(BRACKET, tmp_path / "bracket.stl")
    (tmp_path / "m.csv").write_text("path,seed\n" + "".join(f"bracket.stl,{i}\n" for i in range(1, 7)))
    tmp = tmp_path / "tmp"  # the tasks' temporary folders (Ray keeps its own in /tmp: short socket paths)
    tmp.mkdir()
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""),
           "TMPDIR": str(tmp), "RAY_TMPDIR": os.environ.get("RAY_TMPDIR", "/tmp")}
    proc = subprocess.Popen([sys.executable, "-c", "from grasplan.cli import main; main()", "batch", "m.csv", "-o",
                             "out", "--engine", "ray", "--workers", "2", "--no-view", *QUICK],
                            cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True, preexec_fn=_no_core)
    try:
        t0 = time.monotonic()
        while time.monotonic() - t0 < 180 and proc.poll() is None:
            if any("ray::run_part" in cmd for _, cmd in _session(proc.pid)):
                break
            time.sleep(0.1)
        assert proc.poll() is None, f"the batch ended before the signal:\n{proc.communicate()[1].decode()[-600:]}"
        proc.send_signal(sig)
        proc.wait(timeout=60)
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline:
            left = _session(proc.pid) if sig != signal.SIGKILL else \
                [(p, c) for p, c in _session(proc.pid) if any(w in c for w in _RAY_WORK)]
            if not left:
                break
            time.sleep(0.2)
        assert not left, f"{name}: Ray processes alive 15 s after the batch ended: {left}"
        if sig != signal.SIGKILL:
            assert proc.returncode in (-sig, 128 + sig), proc.returncode
            assert not (tmp_path / "out" / ".staging").exists()
            left_tmp = sorted(p.name for p in tmp.iterdir() if p.name.startswith("grasplan-"))
            assert not left_tmp, f"{name}: the tasks' temporary folders left: {left_tmp}"
    finally:
        _kill_session(proc)
