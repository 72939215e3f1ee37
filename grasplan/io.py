"""Output files: atomic writes and JSON encoding shared by every command.

No command ever leaves a half-written output: everything is written to a temporary file in the
destination folder and renamed into place.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import signal
import stat
import tempfile
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError

#: outputs are never written below these folders (kernel and device files, not documents)
FORBIDDEN_OUTPUT_ROOTS = ("/proc", "/sys", "/dev")
#: longest file-name component (bytes) the file systems grasplan runs on accept
NAME_MAX_BYTES = 255
#: longest path (bytes) accepted for an output
PATH_MAX_BYTES = 4096


def show_path(path: str | os.PathLike, *, limit: int = 120) -> str:
    """``path`` for a one-line message: control characters escaped, long paths shortened."""
    text = os.fsdecode(path) if isinstance(path, bytes) else str(path)
    out = "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)
    if len(out) > limit:
        out = f"{out[: limit // 2 - 2]}...{out[-(limit // 2 - 2):]} ({len(text)} characters)"
    return out


def check_output_path(out: str | os.PathLike, *, inputs: Iterable[str | os.PathLike] = (),
                      create_parents: bool = False, option: str = "-o") -> Path:
    """Check, before any work, that ``out`` can be written; return it as a Path.

    Refused with :class:`InputError` (exit 3), the message naming the problem and the fix: an
    empty path, a NUL character, a name longer than :data:`NAME_MAX_BYTES` bytes, a path under
    :data:`FORBIDDEN_OUTPUT_ROOTS` (after resolving symbolic links), an existing folder or
    non-regular file (FIFO, device), a parent folder that is a file, is missing (unless
    ``create_parents``: then the nearest existing ancestor must be a writable folder) or is not
    writable, and ``out`` being the same file as one of ``inputs`` (it would overwrite it).
    """
    text = os.fsdecode(out) if isinstance(out, bytes) else str(out)
    if not text.strip():
        raise InputError(f"{option}: the output path is empty; give a file name, e.g. {option} out.json")
    if "\x00" in text:
        raise InputError(f"{option}: the output path contains a NUL character; give a plain file name")
    raw = os.fsencode(text)
    if len(raw) > PATH_MAX_BYTES:
        raise InputError(f"{option}: the output path is {len(raw)} bytes long (limit {PATH_MAX_BYTES}); "
                         f"use a shorter path")
    path = Path(text)
    for part in path.parts:
        if len(os.fsencode(part)) > NAME_MAX_BYTES:
            raise InputError(f"{option}: the name {show_path(part)} is {len(os.fsencode(part))} bytes long; file "
                             f"systems allow at most {NAME_MAX_BYTES}: use a shorter name")
    real = Path(os.path.realpath(path))
    for root in FORBIDDEN_OUTPUT_ROOTS:
        if real == Path(root) or Path(root) in real.parents:
            raise InputError(f"{option}: {show_path(path)} is under {root} (system files, not documents); write the "
                             f"output to a normal folder")
    try:
        st = os.stat(path)
    except (FileNotFoundError, NotADirectoryError):  # the parent checks below say which part is wrong
        st = None
    except OSError as exc:
        raise InputError(f"{option}: cannot use {show_path(path)} ({exc.strerror or 'operating-system error'})") from None
    if st is not None:
        if stat.S_ISDIR(st.st_mode):
            raise InputError(f"{option}: {show_path(path)} is a folder; give a file name inside it, e.g. "
                             f"{show_path(path / 'out.json')}")
        if not stat.S_ISREG(st.st_mode):
            raise InputError(f"{option}: {show_path(path)} exists and is not a regular file (a pipe or device); "
                             f"give a file name")
    parent = path.parent
    ancestor = parent
    while not os.path.lexists(ancestor) and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if ancestor != parent and not create_parents:
        raise InputError(f"{option}: folder {show_path(parent)} does not exist; create it first "
                         f"(mkdir -p {show_path(parent)})")
    if not ancestor.is_dir():
        raise InputError(f"{option}: {show_path(ancestor)} is a file, not a folder, so {show_path(path)} cannot be "
                         f"created; choose another output path")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise InputError(f"{option}: folder {show_path(ancestor)} is not writable; choose another folder or fix its "
                         f"permissions")
    for inp in inputs:
        if inp is None:
            continue
        same = os.path.realpath(inp) == str(real)
        if not same and st is not None:
            with contextlib.suppress(OSError):
                same = os.path.samefile(inp, path)
        if same:
            raise InputError(f"{option}: {show_path(path)} is also an input ({show_path(inp)}); writing it would "
                             f"overwrite the input: choose another output name")
    return path


class _Terminated(BaseException):
    """Raised by the temporary SIGTERM handler inside :func:`write_atomic_bytes`."""


@contextlib.contextmanager
def _sigterm_raises() -> Iterator[None]:
    """While active, SIGTERM raises :class:`_Terminated` (so the caller's cleanup runs); on exit the
    previous handler is restored and a SIGTERM that arrived is re-delivered to it. A no-op outside
    the main thread or when SIGTERM is ignored."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGTERM)
    if previous is signal.SIG_IGN or previous is None:  # ignored, or installed outside Python
        yield
        return

    def handler(signum, frame):
        raise _Terminated()

    signal.signal(signal.SIGTERM, handler)
    try:
        yield
    except _Terminated:
        signal.signal(signal.SIGTERM, previous)
        if callable(previous):
            previous(signal.SIGTERM, None)
        else:  # SIG_DFL: end the process the way SIGTERM would have
            os.kill(os.getpid(), signal.SIGTERM)
        raise
    finally:
        signal.signal(signal.SIGTERM, previous)


def sha256_file(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _default(o: Any):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"cannot write {type(o).__name__} to JSON")


def to_json_text(data: Any, *, indent: int | None = None) -> str:
    """JSON text; NumPy arrays become nested lists. NaN/inf are refused (invalid JSON)."""
    return json.dumps(data, default=_default, indent=indent, allow_nan=False)


def write_atomic_bytes(path: str | os.PathLike, payload: bytes) -> Path:
    """Write ``payload`` to ``path`` via a temporary file in the same folder + rename; returns the
    path. Missing parent folders are created. The file gets the permissions a plain ``open()``
    would (umask applied). On any error, KeyboardInterrupt or SIGTERM the temporary file is removed
    and an existing ``path`` is left untouched; operating-system errors become InputError."""
    return write_atomic_chunks(path, (payload,))


def write_atomic_chunks(path: str | os.PathLike, chunks: Iterable[bytes | str]) -> Path:
    """Like :func:`write_atomic_bytes`, with the content streamed from ``chunks`` (bytes, or str
    written as UTF-8) so a large document never has to be held in memory whole. An exception raised
    while producing a chunk (e.g. an encoding error) removes the temporary file and leaves an
    existing ``path`` untouched: nothing is written unless every chunk was."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    with _sigterm_raises():
        tmp = None
        try:
            parent.mkdir(parents=True, exist_ok=True)
            # the temporary name stays within NAME_MAX whatever the output's name
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name[:100]}.", suffix=".tmp", dir=parent)
            umask = os.umask(0)
            os.umask(umask)
            os.fchmod(fd, 0o666 & ~umask)
            with os.fdopen(fd, "wb") as f:
                for chunk in chunks:
                    f.write(chunk.encode("utf-8") if isinstance(chunk, str) else chunk)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)
        except BaseException as exc:
            if tmp is not None and os.path.exists(tmp):
                os.unlink(tmp)
            if isinstance(exc, OSError):
                raise InputError(f"cannot write {show_path(path)}: {exc.strerror or 'operating-system error'}; "
                                 f"choose another output path") from None
            raise
    return path


def write_atomic_text(path: str | os.PathLike, text: str) -> Path:
    """UTF-8 ``text`` written atomically; a lone surrogate (a file name's undecodable byte, which
    Python keeps as ``\udcff``) is written as its escape ``\udcff`` rather than failing."""
    return write_atomic_bytes(path, text.encode("utf-8", "backslashreplace"))


def write_json(path: str | os.PathLike, data: Any, *, indent: int | None = None) -> Path:
    """Serialise first (so an encoding error writes nothing), then write atomically."""
    return write_atomic_text(path, to_json_text(data, indent=indent))


def read_json(path: str | os.PathLike) -> Any:
    with open(path, "rb") as f:
        return json.load(f)
