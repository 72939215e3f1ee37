"""Shared CLI pieces: the units option, the output check, summaries, progress (the option types
are in :mod:`grasplan.cli.options`)."""
from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Sequence
from contextlib import contextmanager

import click

from ..mesh import UNIT_CHOICES

units_option = click.option(
    "--units",
    type=click.Choice(UNIT_CHOICES),
    default="auto",
    show_default=True,
    help="Units of the mesh file's coordinates (STL has none). auto: a largest extent >= 2 is read as mm, else m.",
)


def check_output(output, *inputs):
    """The ``-o`` path checked before any work (:func:`grasplan.io.check_output_path`): not empty, not
    a system or special file, its folder writable (missing folders are created), not one of the
    ``inputs`` (None entries are skipped)."""
    from ..io import check_output_path

    return check_output_path(output, inputs=[i for i in inputs if i is not None], create_parents=True)


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
