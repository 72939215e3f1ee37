"""``grasplan export PLAN.json --format NAME [--grasp ID] -o OUT``: a robot program or data file."""
from __future__ import annotations

import time

import click

from ..errors import InputError
from ..results.export_registry import load_builtin_formats
from ..results.export_registry import DEFAULT_MAX_ACCEL
from .common import check_output, info
from .options import FLOAT, INT

_FORMATS = load_builtin_formats()


def _formats_help() -> str:
    return "\n".join(f"  {f.name:<17} {f.description} ({f.extension})" for f in _FORMATS.values())


@click.command(name="export", epilog="\b\nFormats:\n" + _formats_help())
@click.argument("plan", type=click.Path(dir_okay=True))
@click.option("--format", "fmt", type=click.Choice(sorted(_FORMATS)), required=True,
              help="Output format (list below).")
@click.option("--grasp", "grasp_id", type=INT, default=None,
              help="Id of the grasp to export (must be planned). Default: the best planned grasp. "
                   "For csv and moveit-grasp: only this grasp (default: every grasp).")
@click.option("-o", "--output", "out", type=click.Path(dir_okay=False), required=True,
              help="Output file (written atomically; nothing is written on error). Multi-file formats (krl) "
                   "write their other files next to it with the same stem.")
@click.option("--max-accel", type=FLOAT, default=DEFAULT_MAX_ACCEL, show_default=True,
              help="joint-trajectory: joint acceleration limit, rad/s^2, for every joint (the URDF has none; "
                   "the default is the UR controller's default movej acceleration).")
@click.option("--velocity-scale", type=FLOAT, default=1.0, show_default=True,
              help="joint-trajectory: fraction (0, 1] of the URDF joint velocity limits to use.")
@click.option("--part", "part_path", type=click.Path(dir_okay=True), default=None,
              help="The part's mesh file, when it is no longer at the path recorded in the plan (used to verify "
                   "the timed trajectory against collisions; its sha256 must match).")
@click.option("--instance", default=None,
              help="PLAN is a picks file (grasplan.picks/1, `grasplan pick`): export this instance's pick "
                   "(default: the first pick).")
def command(plan, fmt, grasp_id, out, max_accel, velocity_scale, part_path, instance):
    """Write a planned grasp of PLAN (a grasplan.plan/1 file from `grasplan plan`) in a robot's language.

    PLAN is self-contained: the gripper, cell and robot are rebuilt from it (no YAML needed).

    \b
    Examples:
      grasplan export plan.json --format urscript -o pick.script
      grasplan export plan.json --format krl -o pick.src          # also writes pick.dat
      grasplan export plan.json --format joint-trajectory --grasp 12 --max-accel 2 -o traj.json
      grasplan export plan.json --format csv -o grasps.csv
    """
    from pathlib import Path

    from ..export.api import write
    from ..results.reader import load_result

    t0 = time.perf_counter()
    from ..results.export_registry import output_paths
    from ..results.export_registry import program_options
    from ..setup.outputs import picks_files, result_files
    from ..pick.reader import is_picks_file, load_picks, pick_as_plan

    companions = output_paths(fmt, out)[1:]  # KRL's .dat too
    out = check_output(out, plan, part_path, companions=companions)
    program_options(fmt, out, {})  # a program name from OUT's stem that the language refuses: before any work
    if is_picks_file(plan):
        picks = load_picks(plan)
        # the files it names (parts, its scene's meshes, the robot's files) are inputs too
        check_output(out, plan, *picks_files(picks), companions=companions)
        res = pick_as_plan(picks, instance)  # one pick as a one-grasp plan whose cell holds the other instances
    elif instance is not None:
        raise InputError(f"--instance: {plan} is not a picks file (grasplan.picks/1 from `grasplan pick`)")
    else:
        res = load_result(plan, part=part_path, verify_part=True)  # a re-pointed part block is refused
        check_output(out, plan, part_path, *result_files(res), companions=companions)  # its part, the robot's files
    ids = res.planned_ids()
    info(f"plan {plan}: {len(res.grasps)} grasps, {len(ids)} planned")
    path = write(res, fmt, out, grasp_id=grasp_id, part=part_path, max_accel=max_accel,
                 velocity_scale=velocity_scale, source=Path(plan).name)
    dt = time.perf_counter() - t0
    f = _FORMATS[fmt]
    if fmt == "csv":
        what = f"{len(res.grasps) if grasp_id is None else 1} grasp rows ({len(ids)} planned)"
    elif not f.per_grasp:
        what = f"{len(ids) if grasp_id is None else 1} planned grasps"
    else:
        what = f"grasp {grasp_id if grasp_id is not None else ids[0]}"
    click.echo(f"wrote {path}: {fmt}, {what}, in {dt:.2f} s")
