"""A batch's output folder, checked before any part is planned: every file the batch writes there
(``summary.csv``, ``summary.json``, ``index.html``, the part folders, ``.staging/`` and the lock)
can be written and replaces no input. Everything refused is an
:class:`~grasplan.errors.InputError` (exit 3) naming the path and the fix, with nothing written."""
from __future__ import annotations

import contextlib
import os
import shutil
import stat
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path

from ..errors import InputError
from ..io import check_output_path, show_path
from ..setup.outputs import check_outputs, config_files, file_input
from .layout import LOCK_FILE, STAGING_DIR
from .manifest import PartJob

#: the batch's own files in OUTDIR (the summary and the index page)
SUMMARY_FILES = ("summary.csv", "summary.json", "index.html")
#: a part's done.json larger than this is not a record grasplan wrote (the part is planned again)
MAX_DONE_BYTES = 10_000_000


def config_inputs(jobs: Sequence[PartJob]) -> list[Path]:
    """The files the jobs' robot, gripper and cell were loaded from (their setups' files: the YAMLs,
    the meshes and URDF files they name) and the jobs' scoring files; each set read once."""
    out: set[Path] = set()
    names: set[tuple[str, str]] = set()
    scoring: set[str | None] = set()
    setups = {id(j.setup): j.setup for j in jobs if j.setup is not None}  # jobs share their setups
    for o in {id(j.options): j.options for j in jobs}.values():  # and their option sets' objects
        scoring.add(o.grasps.scoring)
    for j in {id(j.options): j for j in jobs if j.setup is None}.values():  # jobs made without a setup
        names.update((("robot", j.options.robot), ("gripper", j.options.gripper), ("cell", j.options.cell)))
    for setup in setups.values():
        out.update(setup.files)
    for kind, name in sorted(names):
        out.update(config_files(kind, name))
    for sc in scoring:
        s = file_input(sc)
        if s is not None:
            out.add(s)
    return sorted(out)


class _RealPaths:
    """``os.path.realpath`` of many files in few folders, each computed once: a folder is resolved
    once, then a file takes one ``lstat`` (a symbolic link is resolved in full)."""

    def __init__(self) -> None:
        self._folders: dict[str, str] = {}
        self._files: dict[str, str] = {}

    def __call__(self, path: str | os.PathLike) -> str:
        text = os.fsdecode(path)
        real = self._files.get(text)
        if real is None:
            real = self._files[text] = self._resolve(text)
        return real

    def _resolve(self, text: str) -> str:
        full = os.path.abspath(text)
        folder, name = os.path.split(full)
        if name in ("", ".", ".."):
            return os.path.realpath(full)
        try:
            if stat.S_ISLNK(os.lstat(full).st_mode):
                return os.path.realpath(full)
        except OSError:
            pass  # a missing file resolves to its resolved folder + its name, as realpath does
        real = self._folders.get(folder)
        if real is None:
            real = self._folders[folder] = os.path.realpath(folder)
        return os.path.join(real, name)


def _reserved_folders(out: Path, names: Iterable[str], real: _RealPaths) -> dict[str, str]:
    """The folders the batch replaces (``names`` under ``out``): resolved path -> name (one listing
    of ``out``: only entries that are symbolic links are resolved one by one)."""
    base = real(out)
    try:
        links = {e.name for e in os.scandir(out) if e.is_symlink()}
    except OSError:
        links = set()
    return {(os.path.realpath(out / n) if n in links else os.path.join(base, n)): n for n in names}


def _inside_reserved(real_input: str, reserved: dict[str, str], folders: dict[str, str | None]) -> str | None:
    """The name of the reserved folder ``real_input`` (a resolved path) is or lies in, or None;
    ``folders`` keeps the answer for each folder above an input (many inputs share one)."""
    walked: list[str] = []
    found: str | None
    at = real_input
    while True:
        if at in reserved:
            found = reserved[at]
            break
        if at in folders:
            found = folders[at]
            break
        walked.append(at)
        up = os.path.dirname(at)
        if up == at:
            found = None
            break
        at = up
    for w in walked[1:]:  # the folders above the input
        folders[w] = found
    return found


def _may_be(inputs: list[str], outputs: Sequence[Path], real: _RealPaths) -> list[str]:
    """The inputs that might be one of ``outputs`` (the same resolved path, or the same file
    through another hard link): what :func:`grasplan.setup.outputs.check_outputs` then checks in full.
    Inputs are stat'ed only when an output exists with more than one link."""
    real_outs = {real(o) for o in outputs}
    inodes = set()
    for o in outputs:
        with contextlib.suppress(OSError, ValueError):
            st = os.stat(o)
            if st.st_nlink > 1:
                inodes.add((st.st_dev, st.st_ino))
    out = []
    for i in inputs:
        try:
            if real(i) in real_outs:
                out.append(i)
                continue
            if inodes:
                st = os.stat(i)
                if (st.st_dev, st.st_ino) in inodes:
                    out.append(i)
        except (OSError, ValueError):
            out.append(i)  # the full check decides
    return out


def check_out_dir(out_dir: str | os.PathLike, jobs: Sequence[PartJob] = (), *,
                  inputs: Iterable[str | os.PathLike], create: bool = True) -> Path:
    """``out_dir`` as a Path once it is a writable folder (created when missing, with ``create``)
    where the batch's files replace no input (``inputs``: parts, manifests, YAMLs); InputError
    otherwise. Linear in the inputs and jobs (each input resolved once)."""
    out = Path(os.fsdecode(out_dir))
    ins = list(dict.fromkeys(os.fsdecode(i) for i in inputs))
    check_output_path(out / SUMMARY_FILES[0], create_parents=True, option="-o")  # /proc, NUL, parent a file...
    if out.exists() and not out.is_dir():
        raise InputError(f"-o {show_path(out)}: exists and is not a folder; give a folder (it is created when missing)")
    for n in SUMMARY_FILES:
        p = out / n
        if p.is_dir() or (p.exists() and not p.is_file()):
            raise InputError(f"-o {show_path(out)}: {n} exists and is not a file (the batch writes its summary "
                             "there); remove or rename it, or choose another -o")
    real = _RealPaths()
    summary = [out / n for n in SUMMARY_FILES]
    check_outputs(summary, inputs=_may_be(ins, summary, real), option="-o")
    for name, want in ((STAGING_DIR, "folder"), (LOCK_FILE, "file")):
        p = out / name
        try:
            st = os.lstat(p)
        except OSError:
            continue
        ok = stat.S_ISDIR(st.st_mode) if want == "folder" else stat.S_ISREG(st.st_mode)
        if not ok:
            raise InputError(f"-o {show_path(out)}: {name} exists and is not a {want}; grasplan batch keeps its "
                             f"{'work in progress' if want == 'folder' else 'lock'} there: remove it or choose another -o")
    reserved = _reserved_folders(out, dict.fromkeys([STAGING_DIR, *(j.dir_name for j in jobs)]), real)
    above: dict[str, str | None] = {}
    for i in ins:
        try:
            folder = _inside_reserved(real(i), reserved, above)
        except (OSError, ValueError):
            continue
        if folder is not None:
            raise InputError(f"-o {show_path(out)}: input {show_path(i)} lies in {show_path(out / folder)}, which the "
                             "batch replaces; move the input out of the output folder or choose another -o")
    if not create:
        return out
    try:
        out.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".grasplan-probe.", dir=out)  # a read-only mount, a full disk
        try:
            os.close(fd)
        finally:  # also when a signal ends the batch here
            os.unlink(probe)
    except OSError as exc:
        raise InputError(f"-o {show_path(out)}: cannot write in this folder ({exc.strerror or 'operating-system error'}); "
                         "choose another output folder") from None
    return out


def clear_staging(staging: Path) -> None:
    """Remove what an interrupted batch left in ``staging`` (never a finished result)."""
    shutil.rmtree(staging, ignore_errors=True)
    with contextlib.suppress(FileNotFoundError):
        if staging.is_symlink() or staging.exists():
            raise InputError(f"{show_path(staging)}: cannot remove the work left by an earlier batch; remove it by "
                             "hand and rerun")
