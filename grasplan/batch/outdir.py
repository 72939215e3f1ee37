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
from ..outputs import check_outputs, config_files, file_input
from .layout import LOCK_FILE, STAGING_DIR
from .manifest import PartJob

#: the batch's own files in OUTDIR (the summary and the index page)
SUMMARY_FILES = ("summary.csv", "summary.json", "index.html")
#: a part's done.json larger than this is not a record grasplan wrote (the part is planned again)
MAX_DONE_BYTES = 10_000_000


def config_inputs(jobs: Sequence[PartJob]) -> list[Path]:
    """The YAML files the jobs' robot, gripper and cell names resolve to (with the mesh and URDF
    files they name), and their scoring files."""
    out: set[Path] = set()
    for o in {j.options for j in jobs}:
        for kind, name in (("robot", o.robot), ("gripper", o.gripper), ("cell", o.cell)):
            out.update(config_files(kind, name))
        s = file_input(getattr(o.grasps, "scoring", None))
        if s is not None:
            out.add(s)
    return sorted(out)


def _inside(path: Path, folder: Path) -> bool:
    try:
        return Path(os.path.realpath(path)).is_relative_to(os.path.realpath(folder))
    except (OSError, ValueError):
        return False


def check_out_dir(out_dir: str | os.PathLike, jobs: Sequence[PartJob] = (), *,
                  inputs: Iterable[str | os.PathLike], create: bool = True) -> Path:
    """``out_dir`` as a Path once it is a writable folder (created when missing, with ``create``)
    where the batch's files replace no input (``inputs``: parts, manifests, YAMLs); InputError
    otherwise."""
    out = Path(os.fsdecode(out_dir))
    ins = [Path(os.fsdecode(i)) for i in inputs]
    check_output_path(out / SUMMARY_FILES[0], create_parents=True, option="-o")  # /proc, NUL, parent a file...
    if out.exists() and not out.is_dir():
        raise InputError(f"-o {show_path(out)}: exists and is not a folder; give a folder (it is created when missing)")
    for n in SUMMARY_FILES:
        p = out / n
        if p.is_dir() or (p.exists() and not p.is_file()):
            raise InputError(f"-o {show_path(out)}: {n} exists and is not a file (the batch writes its summary "
                             "there); remove or rename it, or choose another -o")
    check_outputs([out / n for n in SUMMARY_FILES], inputs=ins, option="-o")
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
    reserved = [out / STAGING_DIR, *(out / j.dir_name for j in jobs)]
    for i in ins:
        for folder in reserved:
            if _inside(i, folder):
                raise InputError(f"-o {show_path(out)}: input {show_path(i)} lies in {show_path(folder)}, which the "
                                 "batch replaces; move the input out of the output folder or choose another -o")
    if not create:
        return out
    try:
        out.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".grasplan-probe.", dir=out)  # a read-only mount, a full disk
        os.close(fd)
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
