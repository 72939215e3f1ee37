"""``grasplan export PLAN.json --format urscript|joint-trajectory|csv [--grasp ID] -o OUT``."""
from __future__ import annotations

import time
from pathlib import Path

import click

from ..export import DEFAULT_MAX_ACCEL, FORMATS, load_plan, planned_ids
from .common import info


@click.command(name="export")
@click.argument("plan", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--format", "fmt", type=click.Choice(FORMATS), required=True,
              help="urscript: a UR program (movej path, movel approach, gripper stubs); joint-trajectory: a "
                   "timed, collision-checked ROS JointTrajectory as JSON; csv: one row per grasp.")
@click.option("--grasp", "grasp_id", type=int, default=None,
              help="Id of the grasp to export (must be planned). Default: the best planned grasp (highest score). "
                   "For csv: only this grasp's row (default: every grasp).")
@click.option("-o", "--output", "out", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="Output file (written atomically; nothing is written on error).")
@click.option("--max-accel", type=float, default=DEFAULT_MAX_ACCEL, show_default=True,
              help="joint-trajectory: joint acceleration limit, rad/s^2, for every joint (the URDF has none; "
                   "the default is the UR controller's default movej acceleration).")
@click.option("--velocity-scale", type=click.FloatRange(0.0, 1.0, min_open=True), default=1.0, show_default=True,
              help="joint-trajectory: fraction of the URDF joint velocity limits to use.")
@click.option("--part", "part_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="joint-trajectory: the part's mesh file, when it is no longer at the path recorded in the plan "
                   "(used to verify the timed trajectory against collisions; its sha256 must match).")
def command(plan, fmt, grasp_id, out, max_accel, velocity_scale, part_path):
    """Write a planned grasp of PLAN (a grasplan.plan/1 file from `grasplan plan`) as a robot program.

    \b
    Examples:
      grasplan export plan.json --format urscript -o pick.script
      grasplan export plan.json --format joint-trajectory --grasp 12 --max-accel 2 -o traj.json
      grasplan export plan.json --format csv -o grasps.csv
    """
    from ..export import write

    t0 = time.perf_counter()
    doc = load_plan(plan)
    ids = planned_ids(doc)
    if fmt != "csv" or grasp_id is not None:
        info(f"plan {plan}: {len(doc['grasps'])} grasps, {len(ids)} planned")
    path = write(doc, fmt, out, grasp_id=grasp_id, max_accel=max_accel, velocity_scale=velocity_scale,
                 part_path=part_path, source=str(plan), check=False)
    dt = time.perf_counter() - t0
    if fmt == "csv":
        rows = len(doc["grasps"]) if grasp_id is None else 1
        click.echo(f"wrote {path}: {rows} grasp rows ({len(ids)} planned) in {dt:.2f} s")
    else:
        gid = grasp_id if grasp_id is not None else ids[0]
        extra = ""
        if fmt == "joint-trajectory":
            import json

            traj = json.loads(Path(path).read_text())
            g = traj["grasplan"]
            extra = (f", {len(traj['points'])} points, {g['duration_s']:.2f} s, "
                     f"peak velocity {g['max_velocity_ratio'] * 100:.0f} % of the limit, collision-free")
        click.echo(f"wrote {path}: {fmt} for grasp {gid}{extra} in {dt:.2f} s")
