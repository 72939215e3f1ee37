"""``grasplan plan PART --robot NAME -o OUT.json``: grasps a robot can reach, with verified paths."""
from __future__ import annotations

import time
from typing import Any

import click

from ..errors import PlanningError
from ..config.params import ALL_POSES, CandidateParams, GraspParams, PlanParams
from ..status import PLAN_STATUSES, Status
from .common import check_output, info, pose_family, progress, table, warn_all
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
    from ..cell.model import load_cell
    from ..gripper.load import load_gripper
    from ..part.mesh import load_part
    from ..motion.planning import plan
    from ..robot.description import load_robot
    from ..config.poses import parse_part_pose

    t0 = time.perf_counter()
    apply_config_dirs(kwargs)  # first: --config-dir decides which files the names below read
    fam = [pose_family(output)] if kwargs.get("pose_index") == ALL_POSES else []
    output = check_output(output, part, gripper=gripper, cell=cell, robot=robot, scoring=kwargs.get("scoring"),
                          part_pose=part_pose, families=fam)
    prm = params_from_kwargs(kwargs)  # --scoring is read here, --place and --pose-index parsed
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

    bar_state: dict[str, Any] = {"bar": None, "done": 0}

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

    if prm["grasps"].pose_index == ALL_POSES:
        return _plan_all_poses(p, part, rob, g, c, T_world_part, output, prm, t0)
    try:
        result = plan(p, rob, gripper=g, cell=c, T_world_part=T_world_part, progress=on_progress, load_s=load_s,
                      place=prm["planning"].place_matrix(), **prm)
    finally:
        if bar_state["bar"] is not None:
            bar_state["ctx"].__exit__(None, None, None)
    gr = result.grasp_result
    if gr is not None:
        warn_all(gr.quality_warnings())
    result.write(output)

    counts = result.counts()
    robot_name = rob.name
    click.echo(f"{part}: {counts['grasps']} grasp poses, robot {robot_name}, wrote {output}")
    click.echo(table([(s, counts[s]) for s in PLAN_STATUSES], header=("status", "grasps")))
    click.echo("")
    click.echo(table([(k, float(v)) for k, v in result.timing_s.items()] + [("total", time.perf_counter() - t0)],
                     header=("stage", "seconds")))
    unplaced, no_transfer = counts.get(Status.PLACE_UNREACHABLE.value, 0), counts.get(Status.PLACE_NO_PATH.value, 0)
    n_place = unplaced + no_transfer
    if counts[Status.PLANNED.value] == 0 and n_place:
        st = result.grasps.status.astype(str)
        first = next(iter(result.grasps.reason[(st == Status.PLACE_UNREACHABLE.value) | (st == Status.PLACE_NO_PATH.value)]))
        raise PlanningError(f"no grasp could be planned for {part} with {robot_name}: {n_place} grasps picked "
                            f"the part but could not place it ({unplaced} place_unreachable, "
                            f"{no_transfer} place_no_path; e.g. {first}); move the place "
                            f"(--place or the cell's place) within reach; {output} lists every grasp's status and reason")
    if counts[Status.PLANNED.value] == 0:
        hint = "" if T_world_part is not None else _other_poses_hint(p, g, c, prm, result)
        raise PlanningError(f"no grasp could be planned for {part} with {robot_name}; "
                            f"{output} lists every grasp's status and reason{hint}")


def _other_poses_hint(p, g, c, prm, result) -> str:
    """``"; other resting poses: 1 (23 %): 812 collision-free grasps, ..."`` (the grasp stage only)."""
    from ..motion.planning import grasp_counts_by_pose

    chosen = result.params.grasps.pose_index
    chosen = c.pose_index if chosen is None else chosen
    rows = grasp_counts_by_pose(p, gripper=g, cell=c, candidates=prm["candidates"], grasps=prm["grasps"],
                                skip=chosen)
    good = [f"{k} ({pr * 100:.0f} %): {n} collision-free grasps" for k, pr, n in rows if n > 0]
    if not good:
        return "; no other resting pose (probability >= 2 %) has a collision-free grasp either"
    return (f"; resting pose {chosen} was used; other resting poses with collision-free grasps: "
            f"{', '.join(good)}: try --pose-index {rows[[n > 0 for _, _, n in rows].index(True)][0]} or --pose-index all")


def _plan_all_poses(p, part, rob, g, c, T_world_part, output, prm, t0) -> None:
    """``--pose-index all``: one standalone plan file per pose (OUT.pose<k>.json), OUT.json = the
    pose with the most planned grasps (ties: the more probable) plus a ``poses`` block."""
    from ..motion.planning import MIN_POSE_PROBABILITY, plan_poses
    from ..results.pose_plans import write_pose_plans

    info(f"planning every stable pose of probability >= {MIN_POSE_PROBABILITY * 100:g} % ...")
    runs = plan_poses(p, rob, gripper=g, cell=c, T_world_part=T_world_part, place=prm["planning"].place_matrix(), **prm)
    done = write_pose_plans(runs, output, min_probability=MIN_POSE_PROBABILITY)
    click.echo(table(done.table_rows(), header=("pose", "probability", "planned", "collision-free", "file")), err=True)
    if done.result is None:
        raise done.error(str(part))
    click.echo(f"{part}: {len(done.poses)} resting poses planned; wrote {output} (pose {done.chosen}, {done.planned} "
               f"planned) and one file per pose; total {time.perf_counter() - t0:.1f} s")
    if done.planned == 0:
        raise PlanningError(f"no grasp could be planned for {part} in any resting pose of probability >= "
                            f"{MIN_POSE_PROBABILITY * 100:g} %; the files list every grasp's status and reason")
