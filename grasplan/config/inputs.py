"""Reading input files the user names: the one way grasplan opens them.

:func:`read_input_bytes` refuses, before reading a byte, anything that is not a regular file (a
FIFO would block forever, ``/dev/zero`` never ends, a folder is not a document) and anything larger
than the caller's limit; it opens with ``O_NONBLOCK`` and checks the opened descriptor again, so a
file swapped for a FIFO between the check and the open cannot hang the process either. Errors are
:class:`~grasplan.errors.InputError` (exit 3) naming the file, what it is and what would work.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path

from ..errors import InputError
from ..io import show_path

#: what an input path may be instead of a regular file, for the message
_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def _kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def _show(path: str | os.PathLike) -> str:
    return show_path(path)


def check_input_file(path: str | os.PathLike, *, what: str, max_bytes: int | None = None) -> os.stat_result:
    """``os.stat`` of ``path`` when it is a regular file of at most ``max_bytes``; InputError otherwise."""
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise InputError(f"{what} {_show(p)}: file not found") from None
    except (OSError, ValueError) as exc:
        raise InputError(f"{what} {_show(p)}: cannot read it ({getattr(exc, 'strerror', None) or exc})") from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{what} {_show(p)}: is {_kind(st.st_mode)}, not a file; give a regular file")
    if max_bytes is not None and st.st_size > max_bytes:
        raise InputError(f"{what} {_show(p)}: {st.st_size} bytes is larger than the limit of {max_bytes} bytes")
    return st


def read_input_bytes(path: str | os.PathLike, *, what: str, max_bytes: int) -> bytes:
    """The bytes of the regular file ``path`` (at most ``max_bytes``), never blocking on a FIFO or
    reading a device. ``what`` names the input in errors (``"cloud"``, ``"--part-pose"``)."""
    check_input_file(path, what=what, max_bytes=max_bytes)
    try:
        fd = os.open(os.fspath(path), os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise InputError(f"{what} {_show(path)}: cannot open it ({exc.strerror or exc})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):  # swapped after the check
            raise InputError(f"{what} {_show(path)}: is {_kind(st.st_mode)}, not a file; give a regular file")
        chunks, total = [], 0
        while True:
            b = os.read(fd, min(1 << 20, max_bytes + 1 - total))
            if not b:
                break
            chunks.append(b)
            total += len(b)
            if total > max_bytes:
                raise InputError(f"{what} {_show(path)}: larger than the limit of {max_bytes} bytes")
        return b"".join(chunks)
    except OSError as exc:
        raise InputError(f"{what} {_show(path)}: cannot read it ({exc.strerror or exc})") from None
    finally:
        os.close(fd)
