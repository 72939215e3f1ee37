"""``grasplan database PART -o PART.graspdb.npz``: a part's grasps computed once, in its own frame."""
from __future__ import annotations

import time
from typing import Any

import click

from ..errors import PlanningError
from ..config.params import DEFAULT_GRIPPER, CandidateParams, GraspParams, RunParams
from .common import check_output, info, table, units_option, warn_all
from .options import apply_config_dirs, config_dir_option, output_option, param_options


@click.command(name="database")
@click.argument("part", type=click.Path(dir_okay=True))
@output_option("Output grasp database (*.graspdb.npz), written atomically.")
@click.option("--gripper", default=DEFAULT_GRIPPER, show_default=True,
              help="Gripper name (see --config-dir) or path to a gripper YAML.")
@units_option
@config_dir_option
@param_options(GraspParams, CandidateParams, exclude=("pose_index",))
def command(part: str, output: str, gripper: str, units: str, **kwargs: Any) -> None:
    """PART's collision-free grasps in the part frame, checked against the part alone (no table,
    no neighbours), with their contact patches, epsilon and score: the grasp database that
    `grasplan pick` and `grasplan.Picker` pose in the world for every instance of the part.

    `grasplan pick` computes and caches a missing database itself; this command writes one to a
    file you keep with the part (the scene file's `parts.NAME.grasps`). A database is refused for
    another part (sha256, scale) or gripper. Exit 4 (file still written) when no grasp is
    collision-free. Format: docs/pick.md."""
    from ..grasps.graspdb import build_database, write_database
    from ..part.mesh import load_part
    from ..setup.resolved import build_setup

    t_all = time.perf_counter()
    apply_config_dirs(kwargs)  # first: --config-dir decides which file the gripper name reads
    check_output(output, part, scoring=kwargs.get("scoring"))  # the output itself first
    prm = RunParams.from_options(kwargs, (CandidateParams, GraspParams))
    setup = build_setup(gripper=gripper)
    output = check_output(output, part, setup=setup, scoring=kwargs.get("scoring"))
    g = setup.gripper
    assert g is not None
    info(f"database: {part} (gripper {g.name}; the part alone in its own frame)")
    p = load_part(part, units=units)
    info(f"  {p.units_note}")
    warn_all(p.warnings)
    db = build_database(p, g, candidates=prm.candidates, grasps=prm.grasps)
    write_database(db, output)
    n = db.counts
    rows: list[tuple[str, int | float]] = [
        ("candidates", n["candidates"]), ("poses", n["poses"]), ("grasps (collision-free)", len(db)),
        ("rejected: collision_part", n["collision_part"])]
    if db.mass_props is not None:
        rows.append(("part mass, kg", float(db.mass_props.mass)))
    rows += [(f"seconds: {k}", float(v)) for k, v in db.timing_s.items()]
    rows.append(("seconds: total", time.perf_counter() - t_all))
    click.echo(table(rows))
    click.echo(f"wrote {output}")
    if len(db) == 0:
        raise PlanningError(f"no collision-free grasp for {part} with gripper {g.name} ({n['candidates']} candidates, "
                            f"{n['poses']} poses); {output} holds an empty database")
