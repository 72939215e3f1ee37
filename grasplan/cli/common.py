"""Shared CLI pieces: the units option, the output check, summaries, progress (the option types
are in :mod:`grasplan.cli.options`)."""
from __future__ import annotations

import contextlib
import errno
import io
import os
import sys
import time
from collections.abc import Iterable, Sequence
from contextlib import contextmanager

import click

from ..geometry.units import UNIT_CHOICES

units_option = click.option(
    "--units",
    type=click.Choice(UNIT_CHOICES),
    default="auto",
    show_default=True,
    help="Units of the mesh file's coordinates (STL has none). auto: a largest extent >= 2 is read as mm, else m.",
)


def check_output(output, *inputs, companions=(), families=(), setup=None, scoring=None, part_pose=None,
                 option="-o"):
    """The ``-o`` path and its ``companions`` (other files the command writes) checked before any
    work by the one output guard (:func:`grasplan.setup.outputs.check_outputs`): not empty, not a system
    or special file, not among installed files, its folder writable (missing folders are created),
    and none of them one of the files the command reads: ``inputs`` (None entries skipped; with the
    files a loaded document names: :func:`grasplan.setup.outputs.result_files`, ``picks_files``,
    ``scene_files``), the files of ``setup`` (a :class:`~grasplan.setup.resolved.Setup`: the
    gripper, cell and robot YAMLs it was loaded from and the files they name), the ``scoring`` file
    and a ``part_pose`` file. ``families``: ``(folder, regex)`` of companion
    names known only later (``OUT.pose<k>.json``). ``option`` names the output in messages."""
    from ..setup.outputs import check_outputs, file_input

    ins = [*inputs, *(setup.files if setup is not None else ()), file_input(scoring), file_input(part_pose)]
    return check_outputs([output, *companions], inputs=ins, families=families, option=option)[0]


def pose_family(output) -> tuple:
    """``(folder, regex)`` of the ``OUT.pose<k>.json`` files ``--pose-index all`` writes next to ``output``."""
    import re
    from pathlib import Path

    p = Path(output)
    return (p.parent, re.escape(p.stem) + r"\.pose\d+" + re.escape(p.suffix))


def info(msg: str) -> None:
    """A progress/status line on stderr (stdout stays for summaries)."""
    click.echo(msg, err=True)


def warn_all(warnings: Iterable[str]) -> None:
    for w in warnings:
        click.echo(f"grasplan: warning: {w}", err=True)


def table(rows: Sequence[Sequence[object]], header: Sequence[str] | None = None) -> str:
    """Plain-text table, columns left-aligned for text and right-aligned for numbers."""
    all_rows = ([list(header)] if header else []) + [list(r) for r in rows]
    cells = [[_fmt(c) for c in r] for r in all_rows]
    widths = [max(len(r[i]) for r in cells if i < len(r)) for i in range(max(len(r) for r in cells))]
    out = []
    for k, r in enumerate(cells):
        parts = []
        for i, c in enumerate(r):
            numeric = isinstance(all_rows[k][i], (int, float)) and not isinstance(all_rows[k][i], bool)
            parts.append(c.rjust(widths[i]) if numeric else c.ljust(widths[i]))
        out.append("  ".join(parts).rstrip())
        if header and k == 0:
            out.append("  ".join("-" * w for w in widths))
    return "\n".join(out)


def _fmt(c: object) -> str:
    if isinstance(c, float):
        return f"{c:.3f}" if abs(c) < 1e5 else f"{c:.3e}"
    return str(c)


@contextmanager
def stage(name: str, timing: dict | None = None):
    """Time a stage, report it on stderr, record seconds in ``timing[name]``."""
    info(f"  {name} ...")
    t0 = time.perf_counter()
    yield
    dt = time.perf_counter() - t0
    if timing is not None:
        timing[name] = dt
    info(f"  {name} done in {dt:.2f} s")


def progress(iterable, *, length: int, label: str):
    """A progress bar on stderr (hidden when stderr is not a terminal, e.g. in CI)."""
    return click.progressbar(iterable, length=length, label=label, file=sys.stderr)


class _TolerantStdout:
    """``sys.stdout`` for a command: once the reader is gone (``| true``: EPIPE) or the device is
    full (``> /dev/full``: ENOSPC), further summary lines are dropped instead of failing a command
    whose output files are already written. Everything else is the wrapped stream's."""

    _LOST = (errno.EPIPE, errno.ENOSPC, errno.EBADF, errno.EIO)

    def __init__(self, inner):
        self._inner = inner
        self.lost = False

    def _drop(self, exc: OSError) -> None:
        if exc.errno not in self._LOST:
            raise exc
        self.lost = True
        fd = getattr(self._inner, "fileno", None)
        with contextlib.suppress(OSError, ValueError, AttributeError, io.UnsupportedOperation):
            n = fd() if fd is not None else -1
            if n >= 0:  # what the stream still buffers goes nowhere at exit instead of failing again
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, n)
                os.close(devnull)

    def write(self, s):
        if self.lost:
            return len(s)
        try:
            return self._inner.write(s)
        except OSError as exc:
            self._drop(exc)
            return len(s)

    def flush(self) -> None:
        if self.lost:
            return
        try:
            self._inner.flush()
        except OSError as exc:
            self._drop(exc)

    def __getattr__(self, name):
        return getattr(self._inner, name)


@contextmanager
def tolerant_stdout():
    """While active, a full or closed stdout does not fail the command (see :class:`_TolerantStdout`)."""
    inner = sys.stdout
    if inner is None or isinstance(inner, _TolerantStdout):
        yield
        return
    wrapper = _TolerantStdout(inner)
    sys.stdout = wrapper
    try:
        yield
        wrapper.flush()
    finally:
        if sys.stdout is wrapper:
            sys.stdout = inner
