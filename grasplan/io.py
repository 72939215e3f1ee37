"""Output files: atomic writes and JSON encoding shared by every command.

No command ever leaves a half-written output: everything is written to a temporary file in the
destination folder and renamed into place. A terminating signal arriving during a write (SIGTERM,
SIGHUP, SIGQUIT, SIGUSR1, SIGALRM, ...: :data:`CLEANUP_SIGNALS`) removes the temporary file first,
then ends the process as that signal would have (:func:`signals_raise`).

Outputs are never written among installed files (:func:`installed_root`): grasplan's own package
folder (code and packaged data) and the folders the running Python installs distributions into.
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import os
import signal
import _signal
import site
import stat
import sys
import sysconfig
import tempfile
import threading
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from types import FrameType
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
    writable, a path among installed files (:func:`installed_root`), and ``out`` being the same
    file as one of ``inputs`` (it would overwrite it).
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
    installed = installed_root(real)
    if installed is not None:
        folder, what = installed
        which = "is an installed file" if os.path.lexists(path) else "would be written among installed files"
        raise InputError(f"{option}: {show_path(path)} {which} (in {show_path(folder)}, {what}); grasplan never "
                         f"writes there: give an output path in a folder of your own (the current folder, your "
                         f"project, /tmp)")
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


#: the folders of each Python prefix (``sys.prefix``, ``sys.base_prefix``) holding installed files
INSTALLED_PREFIX_FOLDERS = ("lib", "lib64", "share", "include", "bin")


def _installed_folders() -> list[tuple[str, str]]:
    """``(folder, what)`` for every folder :func:`installed_root` protects, before resolving."""
    dist = "installed distributions' files"
    out = [(os.path.dirname(os.path.abspath(__file__)), "grasplan's package folder: its code and packaged data")]
    what = {"purelib": dist, "platlib": dist, "stdlib": "Python's standard library",
            "platstdlib": "Python's standard library", "include": "Python's C headers",
            "platinclude": "Python's C headers", "scripts": "installed distributions' scripts"}
    paths = sysconfig.get_paths()
    out += [(paths[key], text) for key, text in what.items() if paths.get(key)]
    with contextlib.suppress(AttributeError):  # site.getsitepackages is missing in some virtualenv builds
        out += [(d, dist) for d in site.getsitepackages()]
    with contextlib.suppress(AttributeError):
        out += [(site.getusersitepackages(), dist)]
    out += [(d, dist) for d in sys.path if d and os.path.basename(os.path.normpath(d)) in ("site-packages", "dist-packages")]
    for prefix in {sys.prefix, sys.base_prefix, sys.exec_prefix, sys.base_exec_prefix}:
        out += [(os.path.join(prefix, sub), f"the Python installation's {sub}/ folder") for sub in INSTALLED_PREFIX_FOLDERS]
    return out


@functools.lru_cache(maxsize=1)
def installed_roots() -> tuple[tuple[Path, str], ...]:
    """The folders no output may be written into, resolved (symbolic links followed): grasplan's
    package folder, the running Python's ``site-packages`` (``sysconfig`` purelib/platlib,
    :func:`site.getsitepackages`, the user site, ``site-packages``/``dist-packages`` entries of
    ``sys.path``), its standard library, include and scripts folders, and the :data:`INSTALLED_PREFIX_FOLDERS`
    of ``sys.prefix`` and ``sys.base_prefix`` (data files such as ``share/``). A prefix itself is
    not protected (a project folder may hold its ``.venv``), nor is any folder holding the home or
    the temporary folder. Computed once per process."""
    keep: dict[Path, str] = {}
    open_ = {Path(os.path.realpath(d)) for d in (os.path.expanduser("~"), tempfile.gettempdir())}
    for folder, what in _installed_folders():
        try:
            real = Path(os.path.realpath(folder))
        except (OSError, ValueError):
            continue
        if real == real.parent or any(real == o or real in o.parents for o in open_):
            continue  # "/" or a folder around the home or the temporary folder: never refused whole
        keep.setdefault(real, what)
    return tuple(sorted(keep.items(), key=lambda kv: -len(kv[0].parts)))


def installed_root(real: str | os.PathLike) -> tuple[Path, str] | None:
    """``(folder, what)`` of the :func:`installed_roots` folder holding the resolved path ``real``,
    else None (a prefix check: no scan of installed files)."""
    p = Path(real)
    for folder, what in installed_roots():
        if p == folder or folder in p.parents:
            return folder, what
    return None


class _Terminated(BaseException):
    """Raised by the temporary signal handler of :func:`signals_raise`."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


#: signals whose default action ends the process and that can arrive from outside at any time
#: (synchronous faults such as SIGSEGV, and SIGKILL/SIGSTOP, are not caught); real-time signals too
CLEANUP_SIGNALS: tuple[int, ...] = tuple(sorted({
    int(getattr(signal, name)) for name in
    ("SIGHUP", "SIGINT", "SIGQUIT", "SIGABRT", "SIGUSR1", "SIGUSR2", "SIGPIPE", "SIGALRM", "SIGTERM", "SIGSTKFLT",
     "SIGXCPU", "SIGXFSZ", "SIGVTALRM", "SIGPROF", "SIGIO", "SIGPOLL", "SIGPWR", "SIGLOST", "SIGEMT", "SIGINFO")
    if hasattr(signal, name)} | (set(range(signal.SIGRTMIN, signal.SIGRTMAX + 1)) if hasattr(signal, "SIGRTMIN")
                                 else set())))


@contextlib.contextmanager
def signals_raise() -> Iterator[None]:
    """While active, every signal of :data:`CLEANUP_SIGNALS` whose action is the default one (end
    the process) raises :class:`_Terminated` instead, so the caller's cleanup (``finally``,
    ``except BaseException``) runs; then the default action is restored and the signal sent again,
    so the process ends exactly as the signal would have ended it (killed by it: status 128 + its
    number in a shell). Signals that are ignored or have a Python handler (SIGINT's
    KeyboardInterrupt, a caller's own handler) keep it: that handler decides, and an exception it
    raises runs the same cleanup. A no-op outside the main thread. Nested uses are fine (the outermost one handles the
    signal); a second signal during the cleanup of the first is ignored."""
    global _depth
    if threading.current_thread() is not threading.main_thread() or _depth:  # an enclosing use is active
        yield
        return
    pending: list[int] = []

    def handler(signum: int, frame: FrameType | None) -> None:
        if pending:  # a later signal during the cleanup of the first: the first one ends the process
            return
        pending.append(signum)
        raise _Terminated(signum)

    replaced: list[int] = []
    _depth += 1
    try:
        for sig in CLEANUP_SIGNALS:
            with contextlib.suppress(OSError, ValueError):
                if _signal.getsignal(sig) == _signal.SIG_DFL:  # the C module: no enum conversion per call
                    _signal.signal(sig, handler)
                    replaced.append(sig)
        yield
    except _Terminated as exc:
        if exc.signum not in replaced:  # raised by a handler installed elsewhere: that one decides
            raise
        _restore(replaced)
        replaced = []
        if hasattr(signal, "pthread_kill"):  # to this thread: delivered before the call returns
            signal.pthread_kill(threading.get_ident(), exc.signum)
        else:
            os.kill(os.getpid(), exc.signum)
        raise SystemExit(128 + exc.signum) from None  # the signal is blocked here: the shell's status for it
    finally:
        _depth -= 1
        _restore(replaced)


#: active :func:`signals_raise` contexts (main thread only; the outermost installs the handlers)
_depth = 0


def _restore(sigs: list[int]) -> None:
    for sig in sigs:
        with contextlib.suppress(OSError, ValueError):
            _signal.signal(sig, _signal.SIG_DFL)


def sha256_doc(doc: Any) -> str:
    """sha256 of ``doc``'s canonical JSON (keys sorted, no spaces): the caches' keys."""
    return hashlib.sha256(json.dumps(doc, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def sha256_file(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _default(o: Any) -> object:
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
    would (umask applied). On any error, KeyboardInterrupt or terminating signal the temporary file is removed
    and an existing ``path`` is left untouched; operating-system errors become InputError."""
    return write_atomic_chunks(path, (payload,))


def write_atomic_chunks(path: str | os.PathLike, chunks: Iterable[bytes | str]) -> Path:
    """Like :func:`write_atomic_bytes`, with the content streamed from ``chunks`` (bytes, or str
    written as UTF-8) so a large document never has to be held in memory whole. An exception raised
    while producing a chunk (e.g. an encoding error) removes the temporary file and leaves an
    existing ``path`` untouched: nothing is written unless every chunk was."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    with signals_raise():
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


def write_files_atomic(files: Sequence[tuple[str | os.PathLike, bytes | str]]) -> list[Path]:
    """Write every ``(path, content)`` all or nothing: each to a temporary file in its folder first;
    when all are complete they are renamed into place. Any failure removes the temporary files and
    leaves every existing file untouched; operating-system errors become InputError."""
    paths = [Path(p) for p, _ in files]
    for p in paths:
        if p.is_dir():
            raise InputError(f"cannot write {show_path(p)}: it is a folder; choose another output name")
    temps: list[str] = []
    with signals_raise():  # a terminating signal: the temporary files go first (finally), then the process
        try:
            _write_all(paths, files, temps)
        except OSError as exc:
            raise InputError(f"cannot write {', '.join(show_path(p) for p in paths)}: "
                             f"{exc.strerror or 'operating-system error'}; choose another output path") from None
        finally:
            for tmp in temps:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)
    return paths


def _write_all(paths: list[Path], files: Sequence[tuple[str | os.PathLike, bytes | str]], temps: list[str]) -> None:
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
