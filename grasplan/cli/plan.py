"""``grasplan plan PART --robot NAME -o OUT.json``: grasps a robot can reach, with verified paths."""
from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import click

from ..errors import PlanningError
from ..config.params import ALL_POSES, CandidateParams, GraspParams, PlanParams, RunParams
from ..status import PLAN_STATUSES, Status
from .common import check_output, info, pose_family, progress, table, warn_all
from .options import apply_config_dirs, cell_options, keep_option, output_option, param_options, robot_option

if TYPE_CHECKING:
    import numpy as np

    from ..cell.model import Cell
    from ..gripper.model import Gripper
    from ..motion.planning import PlanProgress
    from ..part.mesh import Part
    from ..results.plan_result import PlanResult
    from ..robot.model import Robot


@click.command(name="plan")
@click.argument("part", type=click.Path(dir_okay=True))
@robot_option
@output_option("Output JSON (grasplan.plan/1), self-contained: export and view need only it and the part.")
@cell_options
@keep_option
@param_options(PlanParams, GraspParams, CandidateParams)
def command(part: str, robot: str, output: str, gripper: str, cell: str, part_pose: str | None, units: str,
            keep: str, **kwargs: Any) -> None:
    """Plan grasps of PART that ROBOT can reach: IK, straight approach, OMPL path from home.

    Writes grasplan.plan/1 JSON (the grasps file plus robot, per-grasp status, score, rank and,
    when planned, q_grasp, q_pregrasp, path, pregrasp_index). Exit code 4 (file still written)
    when no grasp could be planned: the per-grasp statuses say why.
    """
    from dataclasses import replace

    from ..part.mesh import load_part
    from ..motion.planning import plan, planning_for_keep
    from ..config.poses import parse_part_pose
    from ..setup.resolved import build_setup

    t0 = time.perf_counter()
    apply_config_dirs(kwargs)  # first: --config-dir decides which files the names below read
    fam = [pose_family(output)] if kwargs.get("pose_index") == ALL_POSES else []
    check_output(output, part, scoring=kwargs.get("scoring"), part_pose=part_pose, families=fam)  # the output itself first
    prm = RunParams.from_options(kwargs)  # --scoring is read here, --place and --pose-index parsed
    prm = replace(prm, planning=planning_for_keep(prm.planning, keep))
    # resolve everything cheap first: nothing is written on bad input
    setup = build_setup(robot=robot, gripper=gripper, cell=cell)  # gripper, cell, robot: each loaded once
    output = check_output(output, part, setup=setup, scoring=kwargs.get("scoring"), part_pose=part_pose, families=fam)
    g, c, rob = setup.gripper, setup.cell, setup.robot
    assert g is not None and c is not None and rob is not None
    T_world_part = parse_part_pose(part_pose) if part_pose is not None else None
    t = time.perf_counter()
    p = load_part(part, units=units)
    load_s = time.perf_counter() - t
    info(f"part {part}: {p.triangles} triangles ({p.units_note})")
    warn_all(p.warnings)

    if prm.grasps.pose_index == ALL_POSES:
        return _plan_all_poses(p, part, rob, g, c, T_world_part, output, prm, t0, keep)
    bar = _PlanBar()
    try:
        result = plan(p, rob, gripper=g, cell=c, candidates=prm.candidates, grasps=prm.grasps,
                      planning=prm.planning, T_world_part=T_world_part, progress=bar.update, load_s=load_s)
    finally:
        bar.close()
    gr = result.grasp_result
    if gr is not None:
        warn_all(gr.quality_warnings())
        if T_world_part is None and _holds_none(result):
            warn_all([_holding_poses_hint(p, g, c, prm, result)])
    result.write(output, keep=keep)

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
        from ..grasps.fingers import window_hint

        stage = result.counts_stage
        hint = window_hint(g, stage.get("candidates", 0), stage.get("posed_candidates", 0)) + _weak_hint(result)
        if not hint and T_world_part is None:
            hint = _other_poses_hint(p, g, c, prm, result)
        raise PlanningError(f"no grasp could be planned for {part} with {robot_name}; "
                            f"{output} lists every grasp's status and reason{hint}")


class _PlanBar:
    """The grasp stage's counts as a line, then a bar of the planned grasps (stderr, on a terminal)."""

    def __init__(self) -> None:
        self.ctx: Any = None
        self.bar: Any = None
        self.done = 0

    def update(self, ev: PlanProgress) -> None:
        from ..motion.planning import GraspDatabaseNote, GraspStageDone

        if isinstance(ev, GraspDatabaseNote):
            info(ev.message)
            return
        if isinstance(ev, GraspStageDone):
            info(f"grasps: {ev.counts}")
            return
        if self.bar is None:
            n = max(1, min(ev.top, ev.candidates))
            self.ctx = progress(range(n), length=n, label=f"planning grasps ({ev.candidates} ok, top {ev.top})")
            self.bar = self.ctx.__enter__()
        if ev.planned > self.done:
            self.bar.update(ev.planned - self.done)
            self.done = ev.planned

    def close(self) -> None:
        if self.ctx is not None:
            self.ctx.__exit__(None, None, None)
            self.ctx = None


def _database_lines(ev: PlanProgress) -> None:
    """The grasp database's progress lines of a plan (stderr)."""
    from ..motion.planning import GraspDatabaseNote

    if isinstance(ev, GraspDatabaseNote):
        info(ev.message)


def _holds_none(result: PlanResult) -> bool:
    """No collision-free grasp of ``result`` is predicted to hold (and there are some)."""
    import numpy as np

    gm = result.grasps.gravity_margin
    free = result.grasps.status.astype(str) != Status.COLLISION_PART.value
    if gm is None:
        return False
    gm = gm[free & np.isfinite(gm)]
    return bool(len(gm)) and float(gm.max()) < 1.0


def _weak_hint(result: PlanResult) -> str:
    """``"; N grasps ... left out"`` when ``--min-gravity-margin`` left collision-free grasps out."""
    import numpy as np

    from ..motion.planning import WEAK_REASON

    n = int(np.char.startswith(np.asarray(result.grasps.reason).astype(str), WEAK_REASON).sum())
    m = result.params.planning.min_gravity_margin
    return (f"; {n} collision-free grasps predicted to slip were not tried (--min-gravity-margin {m:g}; "
            f"lower it, or see their hold_force_N)" if n else "")


def _holding_poses_hint(p: Part, g: Gripper, c: Cell, prm: RunParams, result: PlanResult) -> str:
    """Which other resting poses have grasps predicted to hold (the grasp database placed in each)."""
    from ..grasps.placed import hold_by_pose
    from ..motion.planning import stable_pose_indices

    chosen = result.params.grasps.single_pose_index()
    chosen = c.pose_index if chosen is None else chosen
    others = [(k, pr) for k, pr in stable_pose_indices(p.mesh) if k != chosen]
    rows = hold_by_pose(p, g, c, candidates=prm.candidates, grasps=prm.grasps, poses=others)
    good = [(k, pr, n, f) for k, pr, n, f in rows if n > 0]
    if not good:
        return (f"no other resting pose (probability >= 2 %) has a grasp predicted to hold at {g.grip_force:g} N "
                f"either: the least force any would need is "
                + (f"{min(f for *_, f in rows if f is not None):.1f} N" if any(f is not None for *_, f in rows)
                   else "unknown (no collision-free grasp)"))
    listed = ", ".join(f"{k} ({pr * 100:.1f} %): {n} grasps" for k, pr, n, _ in good)
    return (f"resting pose {chosen} has no grasp predicted to hold; poses that have: {listed}; plan one with "
            f"--pose-index {good[0][0]}, or every pose with --pose-index all")


def _other_poses_hint(p: Part, g: Gripper, c: Cell, prm: RunParams, result: PlanResult) -> str:
    """``"; other resting poses: 1 (23 %): 812 collision-free grasps, ..."`` (the grasp stage only)."""
    from ..motion.planning import grasp_counts_by_pose

    chosen = result.params.grasps.single_pose_index()  # one pose here (not "all")
    chosen = c.pose_index if chosen is None else chosen
    rows = grasp_counts_by_pose(p, gripper=g, cell=c, candidates=prm.candidates, grasps=prm.grasps,
                                skip=chosen)
    good = [f"{k} ({pr * 100:.0f} %): {n} collision-free grasps" for k, pr, n in rows if n > 0]
    if not good:
        return "; no other resting pose (probability >= 2 %) has a collision-free grasp either"
    return (f"; resting pose {chosen} was used; other resting poses with collision-free grasps: "
            f"{', '.join(good)}: try --pose-index {rows[[n > 0 for _, _, n in rows].index(True)][0]} or --pose-index all")


def _plan_all_poses(p: Part, part: str, rob: Robot, g: Gripper, c: Cell, T_world_part: np.ndarray | None,
                    output: str, prm: RunParams, t0: float, keep: str) -> None:
    """``--pose-index all``: one standalone plan file per pose (OUT.pose<k>.json), OUT.json = the
    pose with the most planned grasps predicted to hold (then the most planned; ties: the more
    probable) plus a ``poses`` block."""
    from ..motion.planning import MIN_POSE_PROBABILITY, plan_poses
    from ..results.pose_plans import write_pose_plans

    info(f"planning every stable pose of probability >= {MIN_POSE_PROBABILITY * 100:g} % ...")
    runs = plan_poses(p, rob, gripper=g, cell=c, candidates=prm.candidates, grasps=prm.grasps,
                      planning=prm.planning, T_world_part=T_world_part, progress=_database_lines)
    done = write_pose_plans(runs, output, min_probability=MIN_POSE_PROBABILITY, keep=keep)
    click.echo(table(done.table_rows(), header=("pose", "probability", "planned", "planned holding", "collision-free", "holds from N",
                                                "file")), err=True)
    if done.result is None:
        raise done.error(str(part))
    click.echo(f"{part}: {len(done.poses)} resting poses planned; wrote {output} (pose {done.chosen}, {done.planned} "
               f"planned) and one file per pose; total {time.perf_counter() - t0:.1f} s")
    note = done.hold_note(float(g.grip_force))
    if note:
        warn_all([note])
    if done.planned == 0:
        raise PlanningError(f"no grasp could be planned for {part} in any resting pose of probability >= "
                            f"{MIN_POSE_PROBABILITY * 100:g} %; the files list every grasp's status and reason")
