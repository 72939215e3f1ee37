"""``grasplan plan PART --robot NAME -o OUT.json``: grasps a robot can reach, with verified paths."""
from __future__ import annotations

import time

import click

from ..candidates import CandidateParams
from ..errors import InputError, PlanningError
from .common import ANGLE, LENGTH, LENGTH_OR_ZERO, info, progress, table, units_option, warn_all


@click.command(name="plan")
@click.argument("part", type=click.Path(dir_okay=False))
@click.option("--robot", "robot_name", default="ur5", show_default=True,
              help="Robot name (robots/*.yaml) or path to a robot YAML; an unknown name lists the available ones.")
@click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False),
              help="Output JSON (grasplan.plan/1).")
@click.option("--gripper", default="schunk_egp_c_40", show_default=True, help="Gripper name or YAML path.")
@click.option("--cell", default="table", show_default=True, help="Cell name or YAML path.")
@click.option("--part-pose", default=None,
              help="Override the part's pose: x,y,z,roll,pitch,yaw (lengths with optional units, angles deg; "
                   "R = Rz(yaw) Ry(pitch) Rx(roll)) or a JSON/YAML file with a 4x4 T_world_part. "
                   "Default: the cell's stable pose (the most probable one).")
@click.option("--top", type=click.IntRange(min=1), default=20, show_default=True,
              help="Plan at most K grasps, best score first; the other ok grasps are not_tried.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of IK and OMPL (deterministic results).")
@click.option("--roll-step", "roll_step_deg", type=ANGLE, default=15.0, show_default=True,
              help="Roll step of the TCP about the closing axis, degrees.")
@click.option("--thin", "thin_spacing", type=LENGTH_OR_ZERO, default=0.003, show_default="3mm",
              help="Pose one candidate per cluster (grasp-centre grid of this pitch x closing axis in 10 deg "
                   "steps); 0 poses every candidate.")
@click.option("--pose-index", type=click.IntRange(min=0), default=None,
              help="Rest the part in this stable pose (0 = most probable) instead of the cell's pose_index.")
@click.option("--time-limit", "time_limit", type=click.FloatRange(min=0.0, min_open=True), default=1.0,
              show_default=True, help="RRTConnect time per attempt (seconds).")
@click.option("--budget", "budget_s", type=click.FloatRange(min=0.0, min_open=True), default=100.0,
              show_default=True, help="Wall-clock budget of the planning loop (seconds); later grasps are not_tried.")
@click.option("--no-blm", is_flag=True, help="Skip the boundary layer mesher.")
@click.option("--alpha", type=LENGTH, default=1e-4, show_default="0.1mm", help="BLM boundary-layer width.")
@click.option("--gamma", "gamma_deg", type=ANGLE, default=135.0, show_default=True,
              help="BLM surface angle (degrees): facets join a surface when normals differ <= 180 - gamma.")
@click.option("--d-shift", type=LENGTH, default=1e-5, show_default="0.01mm", help="Convexity test shift.")
@click.option("--epsilon", type=LENGTH, default=5e-3, show_default="5mm", help="Antipodal overlap threshold.")
@click.option("--max-opening", type=LENGTH, default=None,
              help="Largest contact distance searched [default: the gripper's max_opening].")
@click.option("--beta", "beta_deg", type=ANGLE, default=2.0, show_default=True,
              help="Normals anti-parallel within this (degrees).")
@click.option("--mu", type=click.FloatRange(min=0.0), default=0.3, show_default=True, help="Friction coefficient.")
@units_option
def command(part, robot_name, output, gripper, cell, part_pose, top, seed, roll_step_deg, thin_spacing, pose_index,
            time_limit, budget_s, no_blm, alpha, gamma_deg, d_shift, epsilon, max_opening, beta_deg, mu, units):
    """Plan grasps of PART that ROBOT can reach: IK, straight approach, OMPL path from home.

    Writes grasplan.plan/1 JSON (the grasps file plus robot, per-grasp status, score, rank and,
    when planned, q_grasp, q_pregrasp, path, pregrasp_index). Exit code 4 (file still written)
    when no grasp could be planned: the per-grasp statuses say why.
    """
    from ..mesh import load_part
    from ..planning import STATUSES, plan
    from ..robot import load_robot

    t0 = time.perf_counter()
    # validate cheap inputs first: nothing is written on bad input
    try:
        cand_params = CandidateParams(blm=not no_blm, alpha=alpha, gamma_deg=gamma_deg, d_shift=d_shift,
                                      epsilon=epsilon, max_opening=max_opening, beta_deg=beta_deg, mu=mu)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    if pose_index is not None:
        from dataclasses import replace

        from ..cell import load_cell

        cell = replace(load_cell(cell), pose_index=pose_index)
    T_world_part = None
    if part_pose is not None:
        from ..cell import parse_part_pose

        T_world_part = parse_part_pose(part_pose)
    load_robot(robot_name)  # unknown robot -> ConfigError listing the available ones
    t = time.perf_counter()
    p = load_part(part, units=units)
    load_s = time.perf_counter() - t
    info(f"part {part}: {p.triangles} triangles ({p.units_note})")
    warn_all(p.warnings)
    info("computing grasps (candidates, frames, collision) ...")

    bar_state = {"bar": None, "done": 0}

    def on_progress(ev: dict) -> None:
        if ev.get("stage") == "grasps":
            c = ev["counts"]
            info(f"grasps: {c}")
            return
        if bar_state["bar"] is None:
            n = max(1, min(ev["top"], ev["candidates"]))
            bar_state["ctx"] = progress(range(n), length=n, label=f"planning grasps ({ev['candidates']} ok, top {ev['top']})")
            bar_state["bar"] = bar_state["ctx"].__enter__()
        if ev["planned"] > bar_state["done"]:
            bar_state["bar"].update(ev["planned"] - bar_state["done"])
            bar_state["done"] = ev["planned"]

    try:
        result = plan(p, robot=robot_name, gripper=gripper, cell=cell, top=top, seed=seed, cand_params=cand_params,
                      roll_step_deg=roll_step_deg, thin_spacing=thin_spacing, T_world_part=T_world_part,
                      time_limit_per_query=time_limit,
                      budget_s=budget_s, progress=on_progress, load_s=load_s)
    finally:
        if bar_state["bar"] is not None:
            bar_state["ctx"].__exit__(None, None, None)
    result.write(output)

    counts = result.counts()
    click.echo(f"{p.path}: {counts['grasps']} grasp poses, robot {result.robot.name}, wrote {output}")
    click.echo(table([(s, counts[s]) for s in STATUSES], header=("status", "grasps")))
    click.echo("")
    timing = {**result.grasps.timing_s, **result.timing_s}
    click.echo(table([(k, float(v)) for k, v in timing.items()] + [("total", time.perf_counter() - t0)],
                     header=("stage", "seconds")))
    if counts["planned"] == 0:
        raise PlanningError(f"no grasp could be planned for {part} with {robot_name}; "
                            f"{output} lists every grasp's status and reason")
