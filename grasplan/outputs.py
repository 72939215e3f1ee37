"""The one output guard: before any work, every file a command will write (its ``-o`` file and every
companion: KRL's ``.dat`` next to the ``.src``, ``--pose-index all``'s ``OUT.pose<k>.json``, a
batch's ``summary.csv``/``summary.json``/``index.html``) is checked against every file the command
reads (the part, the plan, the cell/gripper/robot/scoring YAMLs, the ``--part-pose`` file, a batch
manifest), and against what the output path itself is (a folder, a device, a system folder: see
:func:`grasplan.io.check_output_path`). An output that would replace an input is refused with
:class:`~grasplan.errors.InputError` (exit 3) naming both, so no command can destroy its input.

:func:`write_files_atomic` writes a group of files (a KRL ``.src``/``.dat`` pair) all or nothing:
every file goes to a temporary file first; only when all are complete are they renamed into place,
so a failure (one name being a folder, a full disk) leaves every existing file as it was.
"""
from __future__ import annotations

import contextlib
import os
import re
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path

from .errors import InputError
from .io import _sigterm_raises, check_output_path, show_path

PathLike = str | os.PathLike


def config_input(kind: str, name_or_path: str | os.PathLike | None) -> Path | None:
    """The file a ``--gripper``/``--cell``/``--robot`` name or path reads (None when it names no
    file: the loader reports that later, naming what exists)."""
    if name_or_path is None:
        return None
    from .config_files import resolve_yaml

    try:
        return resolve_yaml(kind, name_or_path)
    except (InputError, OSError, ValueError):
        return None


#: keys of a gripper/cell/robot YAML whose text values name further files next to it
_FILE_KEYS = ("path", "urdf", "srdf")


def config_files(kind: str, name_or_path: str | os.PathLike | None) -> list[Path]:
    """:func:`config_input` and the files its YAML names (a cell's or gripper's mesh ``path``, a
    robot's ``urdf``/``srdf`` relative to the YAML): everything a description reads. A YAML that
    cannot be read yields just its own path (its loader reports the problem later)."""
    y = config_input(kind, name_or_path)
    if y is None:
        return []
    from .yamlfile import read_yaml_file

    try:
        doc = read_yaml_file(y, what=f"{kind} file")
    except InputError:
        return [y]
    out, stack = [y], [doc]
    while stack and len(out) < 10_000:
        node = stack.pop()
        if isinstance(node, dict):
            for k, v in node.items():
                if k in _FILE_KEYS and isinstance(v, str) and v and "\x00" not in v and len(v) < 4096:
                    out.append(y.parent / v)
                elif isinstance(v, (dict, list)):
                    stack.append(v)
        elif isinstance(node, list):
            stack += [v for v in node if isinstance(v, (dict, list))]
    return out


def file_input(path: PathLike | None) -> Path | None:
    """``path`` when it names an existing file (``--part-pose`` may be a pose text instead)."""
    if path is None:
        return None
    try:
        text = os.fspath(path)
        if isinstance(text, bytes) or "\x00" in text or len(text) > 4096:
            return None
        p = Path(text)
        return p if p.exists() else None
    except (OSError, ValueError, TypeError):
        return None


def _same(a: PathLike, b: Path) -> bool:
    """Whether ``a`` and ``b`` name the same file (by resolved path, or by inode when both exist)."""
    try:
        if os.path.realpath(a) == os.path.realpath(b):
            return True
        return os.path.exists(a) and os.path.exists(b) and os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


def check_outputs(outputs: Sequence[PathLike], *, inputs: Iterable[PathLike | None] = (),
                  families: Iterable[tuple[PathLike, str]] = (), option: str = "-o") -> list[Path]:
    """Check every output path a command will write, before any work; return them as Paths.

    ``outputs``: the files written (the first is the one the user named; the others its
    companions); ``inputs``: every file read (None entries skipped); ``families``: ``(folder,
    regex)`` of file names the command may write in ``folder`` whose exact names are known only
    later (``OUT\\.pose\\d+\\.json``): an input there matching ``regex`` is refused as well.
    Raises :class:`InputError` (exit 3) naming the output, the input it would replace and the fix.
    """
    ins = [Path(os.fsdecode(i)) for i in inputs if i is not None]
    out: list[Path] = []
    first = show_path(outputs[0]) if outputs else ""
    for k, o in enumerate(outputs):
        what = option if k == 0 else f"{option} {first}: its companion file"
        p = check_output_path(o, inputs=(), create_parents=True, option=what)
        for i in ins:
            if _same(i, p):
                also = "" if k == 0 else f" (written with {first})"
                raise InputError(f"{option}: {show_path(p)}{also} is also an input ({show_path(i)}); writing it "
                                 f"would overwrite the input: choose another output name")
        if any(_same(p, q) for q in out):
            raise InputError(f"{option}: {show_path(p)} would be written twice; choose another output name")
        out.append(p)
    for folder, pattern in families:
        rx = re.compile(pattern)
        for i in ins:
            if rx.fullmatch(i.name) and _same(i.parent, Path(folder)):
                raise InputError(f"{option} {first}: the command also writes files named like {show_path(i.name)} "
                                 f"next to it, and {show_path(i)} is an input; choose another output name")
    return out


def write_files_atomic(files: Sequence[tuple[PathLike, bytes | str]]) -> list[Path]:
    """Write every ``(path, content)`` all or nothing: each to a temporary file in its folder first;
    when all are complete they are renamed into place. Any failure removes the temporary files and
    leaves every existing file untouched; operating-system errors become InputError."""
    paths = [Path(p) for p, _ in files]
    for p in paths:
        if p.is_dir():
            raise InputError(f"cannot write {show_path(p)}: it is a folder; choose another output name")
    temps: list[str] = []
    try:
        with _sigterm_raises():
            _write_all(paths, files, temps)
    except OSError as exc:
        raise InputError(f"cannot write {', '.join(show_path(p) for p in paths)}: "
                         f"{exc.strerror or 'operating-system error'}; choose another output path") from None
    finally:
        for tmp in temps:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
    return paths


def _write_all(paths: list[Path], files: Sequence[tuple[PathLike, bytes | str]], temps: list[str]) -> None:
    for p, (_, content) in zip(paths, files):
        parent = p.parent if str(p.parent) else Path(".")
        parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name[:100]}.", suffix=".tmp", dir=parent)
        temps.append(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)
        with os.fdopen(fd, "wb") as f:
            f.write(content.encode("utf-8") if isinstance(content, str) else content)
            f.flush()
            os.fsync(f.fileno())
    for p, tmp in zip(paths, list(temps)):
        os.replace(tmp, p)
        temps.remove(tmp)
