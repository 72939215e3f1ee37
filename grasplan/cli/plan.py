"""``grasplan plan PART --robot NAME -o OUT.json``: grasps a robot can reach, with verified paths."""
from __future__ import annotations

import time

import click
import numpy as np

from ..errors import PlanningError
from ..params import CandidateParams, GraspParams, PlanParams
from ..scoring import SCORING_HELP, with_scoring_file
from .common import POSE_INDEX, check_output, info, progress, table, warn_all
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
@click.option("--place", default=None,
              help="Pick-and-place: the part's pose after release, 'x,y,z,roll,pitch,yaw' (lengths m or with units, "
                   "angles deg, R = Rz(yaw) Ry(pitch) Rx(roll)); overrides the cell's place. Every plan lifts the part "
                   "along the cell's retreat; with a place it is carried there, released and the gripper retreats.")
@click.option("--scoring", type=click.Path(dir_okay=False), default=None, help=SCORING_HELP)
@click.option("--pose-index", "pose_index", type=POSE_INDEX, default=None,
              help="Rest the part in this stable pose (0 = most probable) instead of the cell's pose_index; 'all': "
                   "plan every stable pose of probability >= 2 %, write OUT.pose<k>.json per pose and OUT.json = the "
                   "pose with the most planned grasps plus a 'poses' block with the counts per pose.")
@param_options(PlanParams, GraspParams, CandidateParams, exclude=("pose_index",))
def command(part, robot, output, gripper, cell, part_pose, units, place, scoring, pose_index, **kwargs):
    """Plan grasps of PART that ROBOT can reach: IK, straight approach, OMPL path from home.

    Writes grasplan.plan/1 JSON (the grasps file plus robot, per-grasp status, score, rank and,
    when planned, q_grasp, q_pregrasp, path, pregrasp_index). Exit code 4 (file still written)
    when no grasp could be planned: the per-grasp statuses say why.
    """
    from ..cell import load_cell
    from ..transforms import parse_part_pose, parse_place
    from ..gripper import load_gripper
    from ..mesh import load_part
    from ..planning import plan
    from ..result import PLAN_STATUSES
    from ..robot import load_robot

    t0 = time.perf_counter()
    output = check_output(output, part)
    apply_config_dirs(kwargs)
    prm = params_from_kwargs(kwargs)
    prm["grasps"] = with_scoring_file(prm["grasps"], scoring)
    if pose_index is not None and pose_index != "all":
        from dataclasses import replace

        prm["grasps"] = replace(prm["grasps"], pose_index=pose_index)
    # resolve everything cheap first: nothing is written on bad input
    g = load_gripper(gripper)
    c = load_cell(cell)
    T_world_part = parse_part_pose(part_pose) if part_pose is not None else None
    T_place = parse_place(place) if place is not None else None
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

    if pose_index == "all":
        return _plan_all_poses(p, part, rob, g, c, T_world_part, T_place, output, prm, t0)
    try:
        result = plan(p, rob, gripper=g, cell=c, T_world_part=T_world_part, progress=on_progress, load_s=load_s,
                      place=T_place, **prm)
    finally:
        if bar_state["bar"] is not None:
            bar_state["ctx"].__exit__(None, None, None)
    gr = result.grasp_result
    if gr is not None:
        warn_all(gr.quality_warnings())
    result.write(output)

    counts = result.counts()
    click.echo(f"{part}: {counts['grasps']} grasp poses, robot {result.robot.name}, wrote {output}")
    click.echo(table([(s, counts[s]) for s in PLAN_STATUSES], header=("status", "grasps")))
    click.echo("")
    click.echo(table([(k, float(v)) for k, v in result.timing_s.items()] + [("total", time.perf_counter() - t0)],
                     header=("stage", "seconds")))
    n_place = counts.get("place_unreachable", 0) + counts.get("place_no_path", 0)
    if counts["planned"] == 0 and n_place:
        from ..result import Status

        st = result.grasps.status.astype(str)
        first = next(iter(result.grasps.reason[(st == Status.PLACE_UNREACHABLE.value) | (st == Status.PLACE_NO_PATH.value)]))
        raise PlanningError(f"no grasp could be planned for {part} with {result.robot.name}: {n_place} grasps picked "
                            f"the part but could not place it ({counts.get('place_unreachable', 0)} place_unreachable, "
                            f"{counts.get('place_no_path', 0)} place_no_path; e.g. {first}); move the place "
                            f"(--place or the cell's place) within reach; {output} lists every grasp's status and reason")
    if counts["planned"] == 0:
        hint = "" if T_world_part is not None else _other_poses_hint(p, g, c, prm, result)
        raise PlanningError(f"no grasp could be planned for {part} with {result.robot.name}; "
                            f"{output} lists every grasp's status and reason{hint}")


def _other_poses_hint(p, g, c, prm, result) -> str:
    """``"; other resting poses: 1 (23 %): 812 collision-free grasps, ..."`` (the grasp stage only)."""
    from ..planning import grasp_counts_by_pose

    chosen = result.params.grasps.pose_index
    chosen = c.pose_index if chosen is None else chosen
    rows = grasp_counts_by_pose(p, gripper=g, cell=c, candidates=prm["candidates"], grasps=prm["grasps"],
                                skip=chosen)
    good = [f"{k} ({pr * 100:.0f} %): {n} collision-free grasps" for k, pr, n in rows if n > 0]
    if not good:
        return "; no other resting pose (probability >= 2 %) has a collision-free grasp either"
    return (f"; resting pose {chosen} was used; other resting poses with collision-free grasps: "
            f"{', '.join(good)}: try --pose-index {rows[[n > 0 for _, _, n in rows].index(True)][0]} or --pose-index all")


def _plan_all_poses(p, part, rob, g, c, T_world_part, T_place, output, prm, t0) -> None:
    """``--pose-index all``: one standalone plan file per pose (OUT.pose<k>.json), OUT.json = the
    pose with the most planned grasps (ties: the more probable) plus a ``poses`` block."""
    from ..planning import MIN_POSE_PROBABILITY, plan_poses

    info(f"planning every stable pose of probability >= {MIN_POSE_PROBABILITY * 100:g} % ...")
    runs = plan_poses(p, rob, gripper=g, cell=c, T_world_part=T_world_part, place=T_place, **prm)
    rows, block, best = [], [], None
    for k, pr, res in runs:
        f = output.with_name(f"{output.stem}.pose{k}{output.suffix}")
        if isinstance(res, str):
            rows.append((k, f"{pr * 100:.1f} %", "-", "-", res[:60]))
            block.append({"pose_index": k, "probability": pr, "planned": 0, "collision_free": 0, "file": None,
                          "error": res})
            continue
        res.write(f)
        n = res.counts()
        cf = int(np.count_nonzero(~np.isin(res.grasps.status.astype(str),
                                           ("collision_part", "collision_table", "collision_obstacle"))))
        rows.append((k, f"{pr * 100:.1f} %", n["planned"], cf, f.name))
        block.append({"pose_index": k, "probability": pr, "planned": int(n["planned"]), "collision_free": cf,
                      "file": f.name, "T_world_part": np.asarray(res.T_world_part).tolist()})
        if best is None or n["planned"] > best[1]:
            best = (k, n["planned"], res)
    click.echo(table(rows, header=("pose", "probability", "planned", "collision-free", "file")), err=True)
    if best is None:
        raise PlanningError(f"no resting pose of {part} could be planned: "
                            + "; ".join(f"pose {b['pose_index']}: {b.get('error', '')}" for b in block))
    best[2].write(output, extra={"poses": {"chosen": best[0], "min_probability": MIN_POSE_PROBABILITY,
                                           "poses": block}})
    click.echo(f"{part}: {len(block)} resting poses planned; wrote {output} (pose {best[0]}, {best[1]} planned) and "
               f"one file per pose; total {time.perf_counter() - t0:.1f} s")
    if best[1] == 0:
        raise PlanningError(f"no grasp could be planned for {part} in any resting pose of probability >= "
                            f"{MIN_POSE_PROBABILITY * 100:g} %; the files list every grasp's status and reason")
