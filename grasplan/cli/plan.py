"""``grasplan plan PART --robot NAME -o OUT.json``: grasps a robot can reach, with verified paths."""
from __future__ import annotations

import time

import click

from ..errors import PlanningError
from ..params import CandidateParams, GraspParams, PlanParams
from .common import check_output, info, progress, table, warn_all
from .options import (
    apply_config_dirs,
    cell_options,
    output_option,
    param_options,
    params_from_kwargs,
    robot_option,
)


@click.command(name="plan")
@click.argument("part", type=click.Path(dir_okay=True))
@robot_option
@output_option("Output JSON (grasplan.plan/1), self-contained: export and view need only it and the part.")
@cell_options
@param_options(PlanParams, GraspParams, CandidateParams)
def command(part, robot, output, gripper, cell, part_pose, units, **kwargs):
    """Plan grasps of PART that ROBOT can reach: IK, straight approach, OMPL path from home.

    Writes grasplan.plan/1 JSON (the grasps file plus robot, per-grasp status, score, rank and,
    when planned, q_grasp, q_pregrasp, path, pregrasp_index). Exit code 4 (file still written)
    when no grasp could be planned: the per-grasp statuses say why.
    """
    from ..cell import load_cell, parse_part_pose
    from ..gripper import load_gripper
    from ..mesh import load_part
    from ..planning import plan
    from ..result import PLAN_STATUSES
    from ..robot import load_robot

    t0 = time.perf_counter()
    output = check_output(output, part)
    apply_config_dirs(kwargs)
    prm = params_from_kwargs(kwargs)
    # resolve everything cheap first: nothing is written on bad input
    g = load_gripper(gripper)
    c = load_cell(cell)
    T_world_part = parse_part_pose(part_pose) if part_pose is not None else None
    rob = load_robot(robot)
    t = time.perf_counter()
    p = load_part(part, units=units)
    load_s = time.perf_counter() - t
    info(f"part {part}: {p.triangles} triangles ({p.units_note})")
    warn_all(p.warnings)
    info("computing grasps (candidates, frames, collision) ...")

    bar_state = {"bar": None, "done": 0}

    def on_progress(ev: dict) -> None:
        if ev.get("stage") == "grasps":
            info(f"grasps: {ev['counts']}")
            return
        if bar_state["bar"] is None:
            n = max(1, min(ev["top"], ev["candidates"]))
            bar_state["ctx"] = progress(range(n), length=n, label=f"planning grasps ({ev['candidates']} ok, top {ev['top']})")
            bar_state["bar"] = bar_state["ctx"].__enter__()
        if ev["planned"] > bar_state["done"]:
            bar_state["bar"].update(ev["planned"] - bar_state["done"])
            bar_state["done"] = ev["planned"]

    try:
        result = plan(p, rob, gripper=g, cell=c, T_world_part=T_world_part, progress=on_progress, load_s=load_s, **prm)
    finally:
        if bar_state["bar"] is not None:
            bar_state["ctx"].__exit__(None, None, None)
    result.write(output)

    counts = result.counts()
    click.echo(f"{part}: {counts['grasps']} grasp poses, robot {result.robot.name}, wrote {output}")
    click.echo(table([(s, counts[s]) for s in PLAN_STATUSES], header=("status", "grasps")))
    click.echo("")
    click.echo(table([(k, float(v)) for k, v in result.timing_s.items()] + [("total", time.perf_counter() - t0)],
                     header=("stage", "seconds")))
    if counts["planned"] == 0:
        raise PlanningError(f"no grasp could be planned for {part} with {result.robot.name}; "
                            f"{output} lists every grasp's status and reason")
