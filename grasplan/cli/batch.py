"""``grasplan batch PARTS... -o OUTDIR``: plan a catalogue of parts, resumable, locally or on Ray."""
from __future__ import annotations

import sys

import click

from ..batch.engines import ENGINES
from ..config.params import CandidateParams, GraspParams, PlanParams
from .common import info
from .options import cell_options, keep_option, param_options, robot_option


def _split_exports(ctx, param, value):
    names = [n.strip() for v in value for n in v.split(",") if n.strip()]
    return tuple(names)


@click.command(name="batch")
@click.argument("parts", nargs=-1, required=True, type=click.Path(exists=True))
@click.option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Output folder: one <stem>-<sha8>/ per part, summary.csv, summary.json, index.html.")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Parallel parts: local pool size (default: one per core) / CPUs of a local Ray runtime.")
@click.option("--engine", type=click.Choice(list(ENGINES)), default="local", show_default=True,
              help="local: a process pool on this machine; ray: Ray tasks (pip install 'grasplan[ray]').")
@click.option("--ray-address", default=None,
              help="Join this Ray cluster (HOST:6379, ray://HOST:10001 or auto) instead of starting a local runtime.")
@click.option("--export", "exports", multiple=True, callback=_split_exports,
              help="Export formats written per part, comma-separated (see `grasplan export --help`).")
@click.option("--no-view", is_flag=True, help="Do not write each part's view.html.")
@robot_option
@cell_options
@keep_option
@param_options(CandidateParams, GraspParams, PlanParams)
def command(parts, out_dir, workers, engine, ray_address, exports, no_view, **kwargs):
    """Plan every part in PARTS: mesh files, folders (searched recursively for STL/OBJ/PLY) or
    CSV/YAML manifests (a 'path' column, optional 'units', 'robot', 'gripper', 'cell', 'part_pose'
    and any plan option per part, e.g. 'pose_index', 'place', 'scoring').

    Per part OUTDIR/<stem>-<sha8>/ gets plan.json (as `grasplan plan` writes it), the --export
    files, view.html and log.txt. A bad part is recorded in the summary and the batch goes on.
    Rerunning the same command skips finished parts (same file sha256 and options). Exit code 0
    when some part has a planned grasp, 4 when none has, 3 for bad inputs (nothing written), 130
    after Ctrl-C. Ctrl-C or a signal (SIGTERM, SIGHUP, ...) stops the workers and keeps the
    finished parts; the workers also end if the batch is killed.
    """
    from ..batch.run import run_batch
    from ..batch.layout import BatchStatus
    from ..batch.options import BatchOptions
    from ..batch.report import format_row
    from ..config.params import RunParams

    params = RunParams.from_options(kwargs)  # --scoring is read here, --place and --pose-index parsed
    part_pose = kwargs.pop("part_pose")
    T_world_part = None
    if part_pose is not None:
        from ..config.poses import parse_part_pose

        T_world_part = parse_part_pose(part_pose).tolist()
    options = BatchOptions(robot=kwargs.pop("robot"), gripper=kwargs.pop("gripper"), cell=kwargs.pop("cell"),
                           units=kwargs.pop("units"), T_world_part=T_world_part, exports=exports,
                           view=not no_view, candidates=params.candidates, grasps=params.grasps,
                           planning=params.planning, keep=kwargs.pop("keep"))
    config_dirs = kwargs.pop("config_dir")  # run_batch puts them first in the lookup, here and in every worker

    bar = _Progress()
    try:
        summary = run_batch(parts, out_dir, options=options, engine=engine, workers=workers,
                            ray_address=ray_address, config_dirs=config_dirs, progress=bar.update)
    except KeyboardInterrupt:
        bar.close()
        info(f"interrupted: finished parts are in {out_dir} (summary.csv); rerun the same command to finish")
        sys.exit(130)
    bar.close()
    c = summary.counts
    click.echo(f"{len(summary.rows)} parts: {c[BatchStatus.PLANNED.value]} planned, "
               f"{c[BatchStatus.NOTHING.value]} nothing planned, {c[BatchStatus.BAD.value]} bad input, "
               f"{c[BatchStatus.ERROR.value]} errors ({c['resumed']} already done)")
    for row in summary.rows:
        if row["status"] != BatchStatus.PLANNED:
            click.echo("  " + format_row(row))
    click.echo(f"wrote {summary.out_dir / 'summary.csv'} and {summary.out_dir / 'index.html'}")
    if summary.exit_code == 4:
        click.echo("grasplan: no part has a planned grasp; each part's log.txt and plan.json say why", err=True)
    sys.exit(summary.exit_code)


class _Progress:
    """A bar (parts done, failures, ETA) on a terminal, one plain line per part otherwise."""

    def __init__(self):
        self.tty = sys.stderr.isatty()
        self.ctx = None
        self.bar = None
        self.failed = 0

    def update(self, ev: dict) -> None:
        from ..batch.report import format_row

        if not self.tty:
            info(f"[{ev['done']}/{ev['total']}] {format_row(ev['row'])}")
            return
        if self.bar is None:
            self.ctx = click.progressbar(length=ev["total"], label="parts", file=sys.stderr, show_eta=True,
                                         show_pos=True, item_show_func=lambda _: f"{self.failed} failed")
            self.bar = self.ctx.__enter__()
            self.bar.update(ev["done"] - 1)  # parts finished by an earlier run
        self.failed = ev["failed"]
        self.bar.update(1, ev["row"])

    def close(self) -> None:
        if self.ctx is not None:
            self.ctx.__exit__(None, None, None)
            self.ctx = None
