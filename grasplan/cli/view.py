"""``grasplan view RESULT.json -o view.html [--part PATH]``: a self-contained HTML viewer."""
from __future__ import annotations

import warnings
from pathlib import Path

import click

from ..errors import InputError
from .common import info, warn_all


@click.command("view")
@click.argument("result", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="The HTML file to write (one self-contained file; open it in any browser, no server needed).")
@click.option("--part", "part", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="The part's mesh file. Default: part.path recorded in RESULT (a relative path is looked up "
                   "in the current folder, then next to RESULT).")
def command(result: Path, output: Path, part: Path | None) -> None:
    """Write a self-contained HTML viewer for a grasps or plan file (RESULT).

    The page shows the part in its cell pose, the table, every grasp's contacts coloured by status,
    the selected grasp's gripper (jaws at the pre-grasp opening) and, for a plan, the robot at
    q_grasp with a button that plays the path home -> pre-grasp -> grasp. It makes no network
    request (three.js is bundled).
    """
    from ..viewer import write_viewer  # imported here: the CLI stays fast for other commands

    if not result.exists():
        raise InputError(f"{result}: no such file (expected a grasplan grasps or plan JSON)")
    info(f"view: {result}")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        path = write_viewer(result, output, part_path=part)
    warn_all(str(w.message) for w in caught)
    size = path.stat().st_size
    click.echo(f"wrote {path} ({size / 1e6:.2f} MB)")
