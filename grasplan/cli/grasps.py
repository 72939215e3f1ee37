"""``grasplan grasps PART -o OUT.json``: gripper poses from candidates, filtered by collisions."""
from __future__ import annotations

import time
from typing import Any

import click

from ..errors import PlanningError
from ..config.params import CandidateParams, GraspParams, RunParams
from ..status import Status
from .common import check_output, info, table, warn_all
from .options import (
    apply_config_dirs,
    cell_options,
    output_option,
    param_options,
)


@click.command(name="grasps")
@click.argument("part", type=click.Path(dir_okay=True))
@output_option("Output JSON file (grasplan.grasps/1), written atomically.")
@cell_options
@param_options(GraspParams, CandidateParams)
@click.option("--only-ok", is_flag=True,
              help="Write only the ok grasps (counts still cover every pose); keeps files small.")
@click.option("--indent", type=click.IntRange(0, 8), default=None, help="Indent the JSON (default: compact).")
def command(part: str, output: str, gripper: str, cell: str, part_pose: str | None, units: str, only_ok: bool,
            indent: int | None, **kwargs: Any) -> None:
    """Gripper poses for PART's antipodal candidates, rolled about each closing axis, each checked
    for collisions of the gripper body and the closing jaws against the part and the table.

    Prints a summary (candidates, poses, kept, rejected by reason, seconds) and writes
    grasplan.grasps/1 JSON (docs/grasps.md). Exit 4 (file still written) when no pose is
    collision-free."""
    from ..config.poses import parse_part_pose
    from ..grasps.pipeline import compute_grasps
    from ..part.mesh import load_part
    from ..setup.resolved import build_setup

    t_all = time.perf_counter()
    apply_config_dirs(kwargs)  # first: --config-dir decides which files the names below read
    check_output(output, part, scoring=kwargs.get("scoring"), part_pose=part_pose)  # the output itself first
    prm = RunParams.from_options(kwargs, (CandidateParams, GraspParams))  # --scoring is read here
    prm.grasps.single_pose_index()  # one resting pose: InputError for --pose-index all
    setup = build_setup(gripper=gripper, cell=cell)
    output = check_output(output, part, setup=setup, scoring=kwargs.get("scoring"), part_pose=part_pose)
    g, c = setup.gripper, setup.cell
    assert g is not None and c is not None
    T_world_part = parse_part_pose(part_pose) if part_pose is not None else None

    info(f"grasps: {part} (gripper {g.name}, cell {c.name})")
    t = time.perf_counter()
    p = load_part(part, units=units)
    load_s = time.perf_counter() - t
    info(f"  {p.units_note}")
    warn_all(p.warnings)
    res = compute_grasps(p, gripper=g, cell=c, candidates=prm.candidates, grasps=prm.grasps,
                         T_world_part=T_world_part, load_s=load_s)
    warn_all(res.quality_warnings())
    t = time.perf_counter()
    res.to_result().write(output, only_ok=only_ok, indent=indent)
    info(f"  wrote {output} in {time.perf_counter() - t:.2f} s")

    n = res.counts()
    rows: list[tuple[str, int | float]] = [
        ("candidates", n["candidates"]),
        ("posed candidates", n["posed_candidates"]),
        ("poses", n["poses"]),
        ("kept (ok)", n[Status.OK.value]),
        *((f"rejected: {s.value}", n[s.value])
          for s in (Status.COLLISION_PART, Status.COLLISION_TABLE, Status.COLLISION_OBSTACLE)),
    ]
    if res.mass_props is not None:  # grasp quality (docs/quality.md)
        rows.append(("part mass, kg", float(res.mass_props.mass)))
        if n[Status.OK.value] and res.quality is not None:
            rows.append(("ok grasps holding through lift and shake", int((res.quality.gravity_margin >= 1).sum())))
    rows += [(f"seconds: {k}", float(v)) for k, v in res.timing_s.items()]
    rows.append(("seconds: total", time.perf_counter() - t_all))
    click.echo(table(rows))
    click.echo(f"wrote {output}")
    if n[Status.OK.value] == 0:
        from ..grasps.fingers import window_hint

        raise PlanningError(f"no collision-free grasp for {part} with gripper {g.name} in cell {c.name} "
                            f"({n['candidates']} candidates, {n['poses']} poses); {output} lists every pose's status"
                            + window_hint(g, n["candidates"], n.get("posed_candidates", 0)))
