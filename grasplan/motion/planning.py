"""Stages 7-8 composed: grasps a robot can reach, each with a verified joint path from home.

:func:`plan` (behind ``grasplan plan``) runs the grasp stage (:func:`~grasplan.grasps.placed.grasp_stage`:
the part's grasp database placed in the pose and the cell) and :func:`plan_grasps`: the ``ok`` grasps ranked by score (:mod:`grasplan.config.scoring`, distinct
ones first), planned in rank order (the per-grasp pipeline ``pick`` shares,
:func:`grasplan.motion.grasp_motion.plan_pick_motion`: IK, approach, lift, place, paths) until
``top`` are planned or ``budget_s`` is spent; ``ok`` grasps never tried are ``not_tried``, grasps
the grasp stage rejected keep its status (docs/plan.md).
``simulate > 0`` lifts and shakes the top planned grasps in MuJoCo (:mod:`grasplan.sim.simulate`).

:func:`plan_poses` plans every stable pose (``--pose-index all``), one
:class:`~grasplan.results.pose_plans.PosePlan` each. Typed hand-offs: :class:`PlanOutcome` for the
stage (:class:`~grasplan.motion.grasp_motion.Outcome` per grasp), :data:`PlanProgress` events
for a ``progress`` callback; the result types and their JSON: :mod:`grasplan.results.plan_result`.
"""
from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Union

import numpy as np

from ..cell.model import NO_CELL_NAME, Cell, load_cell
from ..errors import ConfigError, InputError
from ..grasps.graspdb import GraspDatabase, database_for
from ..grasps.placed import PlacedGrasps, cached_database, grasp_stage
from ..gripper.load import load_gripper
from ..gripper.model import Gripper
from ..part.mass import MassProperties
from ..geometry.meshdata import TriangleMesh
from ..part.mesh import Part, load_part
from ..config.params import (
    DEFAULT_CELL, DEFAULT_GRIPPER, DEFAULT_ROBOT, GRASP_DB_OFF, CandidateParams, GraspParams, PlanParams
)
from .codes import Reason
from .grasp_motion import PLAN_TIMING, MotionContext, Outcome, plan_pick_motion
from ..results.compact import KEEP_ALL
from ..results.joint_motion import Motion
from ..results.plan_result import Params, PartRecord, PlanResult
from ..results.pose_plans import PosePlan
from ..robot.description import load_robot
from ..robot.model import Robot
from .collision_scene import CollisionScene
from ..config.scoring import ScoringConfig, score_grasps
from ..grasps.ranking import distinct_order
from ..cell.resting import stable_pose
from ..part.stability import stable_poses
from .start_checks import check_part_placement, check_start
from ..status import Status
from ..geometry.transforms import check_transform

SCHEMA = "grasplan.plan/1"

#: the reason of an ``ok`` grasp the planner did not try
NOT_TRIED_REASON = "not tried: beyond the top K or the planning budget"
#: the reason of the ``ok`` grasps ``min_gravity_margin`` leaves out (the value follows, then ")")
WEAK_REASON = "not tried: predicted to slip (gravity margin below --min-gravity-margin"
#: the reason of each grasp-stage rejection (when the grasp stage recorded none of its own)
STAGE_REJECTION_REASONS = {
    Status.COLLISION_PART: "grasp stage: the gripper hits the part at the grasp or while closing",
    Status.COLLISION_TABLE: "grasp stage: the gripper hits the table at the grasp or while closing",
    Status.COLLISION_OBSTACLE: "grasp stage: the gripper hits an obstacle at the grasp or while closing",
}


# -- progress events ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class GraspStageDone:
    """The grasp stage is done: ``counts`` per status and stage (:meth:`PlacedGrasps.counts
    <grasplan.grasps.placed.PlacedGrasps.counts>`)."""

    counts: dict[str, int]


@dataclass(frozen=True)
class GraspDatabaseNote:
    """A line about the part's grasp database: computing it (the first plan of a part), done, cached."""

    message: str


@dataclass(frozen=True)
class GraspTried:
    """The planner tried one more grasp: ``tried`` so far, ``planned`` of them, of at most ``top``
    to plan among ``candidates`` ranked ones; the last one is ``grasp_id``, now ``status``."""

    tried: int
    planned: int
    top: int
    candidates: int
    grasp_id: int
    status: Status


#: an event of a plan's progress, and the ``progress`` callback of :func:`plan` that gets them
PlanProgress = Union[GraspDatabaseNote, GraspStageDone, GraspTried]
ProgressCallback = Callable[[PlanProgress], None]


@dataclass(frozen=True, eq=False)
class PlanOutcome:
    """The plan stage's result for the M poses of a grasp result.

    ``status`` (M,) object: the plan status values (:class:`~grasplan.status.Status` ``.value``);
    ``score`` (M,) float64 (NaN: not ranked); ``rank`` (M,) int64 (-1: not ranked); ``reason``
    (M,) object str; ``motions`` ``{pose id: Motion}`` of the planned grasps; ``timing_s`` seconds
    per stage."""

    status: np.ndarray
    score: np.ndarray
    rank: np.ndarray
    reason: np.ndarray
    motions: dict[int, Motion]
    timing_s: dict[str, float]


def plan_grasps(grasps: PlacedGrasps, robot: Robot, scene: CollisionScene, *, params: PlanParams = PlanParams(),
                progress: ProgressCallback | None = None) -> PlanOutcome:
    """Plan the ranked ``ok`` grasps of ``grasps`` for ``robot`` in ``scene``.

    Returns a :class:`PlanOutcome` ((M,) status, score, rank and reason arrays over the rows of
    ``grasps.table``, ``{grasp id: Motion}`` for the planned grasps and seconds per stage).
    ``progress`` gets a :class:`GraspTried` after every tried grasp.
    """
    t_all = time.perf_counter()
    timing = {"ik": 0.0, "approach": 0.0, "joint_path": 0.0, "lift": 0.0, "place": 0.0, "transfer": 0.0}
    tab = grasps.table
    status_in = tab.status.astype(str)
    T_part_tcp = np.asarray(tab.T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    width = np.asarray(tab.width, dtype=np.float64)
    ids = tab.ids
    scores, order = _ranking(grasps, status_in, T_part_tcp, width, params)
    status, reason = _stage_statuses(grasps, status_in)
    order = _margin_filter(tab.gravity_margin, order, params.min_gravity_margin, reason)
    rank = np.full(len(status_in), -1, dtype=np.int64)
    rank[order] = np.arange(len(order))
    motions: dict[int, Motion] = {}
    ctx = _setting(grasps, robot, scene, params, timing)
    gripper = grasps.gripper
    T_world_part = np.asarray(grasps.T_world_part, dtype=np.float64)
    planned = tried = 0
    n_candidates = len(order)
    for i in order:
        if planned >= params.top:
            break
        if params.budget_s is not None and time.perf_counter() - t_all > params.budget_s:
            break
        tried += 1
        gid = int(ids[i])
        T_g, w = T_part_tcp[i], float(width[i])
        if gripper.moving_tcp:  # plan in the frame the gripper's shapes and T_flange_tcp are given in
            T_g = T_g @ gripper.T_tcp_gripper(w)
        out = plan_pick_motion(ctx, T_world_part @ T_g, T_g, w, seed=params.seed * 1_000_003 + gid)
        if out.motion is not None:
            motions[gid] = out.motion
            planned += 1
        st = plan_status(out)
        status[i], reason[i] = st.value, out.reason
        if progress is not None:
            progress(GraspTried(tried=tried, planned=planned, top=params.top, candidates=n_candidates,
                                grasp_id=gid, status=st))
    timing["plan"] = time.perf_counter() - t_all
    return PlanOutcome(status=status, score=scores, rank=rank, reason=reason, motions=motions, timing_s=timing)


def _ranking(grasps: PlacedGrasps, status_in: np.ndarray, T_part_tcp: np.ndarray, width: np.ndarray,
             params: PlanParams) -> tuple[np.ndarray, np.ndarray]:
    """The (M,) scores (NaN but for ``ok`` grasps: the grasp stage's, or re-scored with
    ``params.score_weights``) and the ``ok`` pose ids in plan order (best score first, ties by id,
    distinct grasps ahead of near-duplicates)."""
    T_world_part = np.asarray(grasps.T_world_part, dtype=np.float64)
    ok = np.flatnonzero(status_in == Status.OK.value)
    scores = np.full(len(status_in), np.nan)
    if params.score_weights is None:
        scores[ok] = np.asarray(grasps.table.score, dtype=np.float64)[ok]  # the grasp stage's score (quality + reach)
    elif len(ok):
        mp = grasps.mass_props
        gp = grasps.params
        cfg = ScoringConfig.from_params(params.score_weights or gp.score_weights, gp.score_refs)
        scores[ok] = score_grasps(grasps.part.mesh, T_world_part, T_part_tcp[ok], width[ok],
                                  float(grasps.gripper.max_opening), weights=cfg.weights, quality=grasps.quality,
                                  scoring=cfg, com=mp.com if isinstance(mp, MassProperties) else None)
    order = ok[np.lexsort((ok, -scores[ok]))] if len(ok) else ok
    order, _ = distinct_order(T_part_tcp, order, min_distance=params.distinct_distance,
                              min_angle_deg=params.distinct_angle_deg)
    return scores, order


def _margin_filter(margin: np.ndarray | None, order: np.ndarray, min_margin: float, reason: np.ndarray) -> np.ndarray:
    """``order`` without the grasps whose gravity margin is below ``min_margin`` (0: off; no
    quality: none left out), their ``reason`` saying why they stay ``not_tried``."""
    if min_margin <= 0.0 or margin is None or not len(order):
        return order
    gm = np.asarray(margin, dtype=np.float64)[order]
    weak = ~(gm >= min_margin)  # NaN (no quality) counts as weak
    reason[order[weak]] = f"{WEAK_REASON} {min_margin:g})"
    return order[~weak]


def _stage_statuses(grasps: PlacedGrasps, status_in: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (M,) plan status and reason before planning: ``ok`` grasps ``not_tried``, the grasp
    stage's rejections with its reasons (naming the gripper element and the body)."""
    M = len(status_in)
    status = np.where(status_in == Status.OK.value, Status.NOT_TRIED.value, status_in).astype(object)
    reason = np.empty(M, dtype=object)
    reason[:] = NOT_TRIED_REASON
    for st, text in STAGE_REJECTION_REASONS.items():
        reason[status_in == st.value] = text
    stage_reasons = np.asarray(grasps.table.reason, dtype=object)
    rejected = (status_in != Status.OK.value) & (stage_reasons != "")
    reason[rejected] = stage_reasons[rejected]
    return status, reason


#: the part alone may rest on the table or an obstacle within this TCP travel (m) of the grasp on the
#: lift and of the place on the descent (``MotionContext.lift_contact``; ``pick``: ``--lift-contact``)
PLAN_LIFT_CONTACT = 0.002

#: the plan status of each reason code of the per-grasp pipeline (``place``: its ``place_status``)
PLAN_STATUS: dict[Reason, Status] = {
    Reason.PLANNED: Status.PLANNED, Reason.NO_IK: Status.UNREACHABLE,
    Reason.LINE_NOT_FOLLOWED: Status.UNREACHABLE, Reason.IK_COLLISION: Status.IK_COLLISION,
    Reason.LIFT_COLLISION: Status.IK_COLLISION, Reason.LIFT_GRIPPER: Status.IK_COLLISION,
    Reason.NO_TRANSIT: Status.NO_PATH, Reason.PLACE: Status.PLACE_NO_PATH}


def plan_status(out: Outcome) -> Status:
    """The plan status of one grasp's outcome (:data:`PLAN_STATUS`; a failed place keeps
    ``place_unreachable`` or ``place_no_path``)."""
    if out.code == Reason.PLACE and out.place_status is not None:
        return out.place_status
    return PLAN_STATUS[out.code]


def _setting(grasps: PlacedGrasps, robot: Robot, scene: CollisionScene, params: PlanParams,
             timing: dict[str, float]) -> MotionContext:
    """What every grasp of the plan shares (the per-grasp pipeline's context): ``scene`` and one
    attached variant whose part is moved per grasp; the lift always, the place when the cell has
    one (:mod:`grasplan.motion.pickplace`); the lift's support allowance
    :data:`PLAN_LIFT_CONTACT`, no depth rule, no checks before IK, no budget (``budget_s`` is
    checked between grasps), the plan's timing keys."""
    cell = grasps.cell
    T_place = None if cell.place is None else np.asarray(cell.place, dtype=np.float64)
    return MotionContext(robot, grasps.gripper, params, scene, scene.attached(np.eye(4)),
                         np.asarray(cell.retreat_direction, dtype=np.float64), float(cell.retreat_distance), timing,
                         lift_contact=PLAN_LIFT_CONTACT, depth_limit=0.0, keys=PLAN_TIMING, T_place=T_place)


def plan(
    part: Part | str | os.PathLike,
    robot: Robot | str | Path = DEFAULT_ROBOT,
    *,
    gripper: Gripper | str | os.PathLike = DEFAULT_GRIPPER,
    cell: Cell | str | os.PathLike = DEFAULT_CELL,
    candidates: CandidateParams = CandidateParams(),
    grasps: GraspParams = GraspParams(),
    planning: PlanParams = PlanParams(),
    T_world_part: np.ndarray | None = None,
    units: str = "auto",
    progress: ProgressCallback | None = None,
    load_s: float = 0.0,
    place: np.ndarray | None = None,
    database: GraspDatabase | None = None,
) -> PlanResult:
    """Grasps of ``part`` that ``robot`` can reach, each with a verified path from ``q_home``.

    The grasp stage is the part's grasp database placed in the pose and the cell
    (:func:`grasplan.grasps.placed.grasp_stage`: read from the cache, or computed and cached on the
    first plan of a part); ``planning.grasp_db == "off"`` computes it in the cell instead, every
    pose in the result. Both give the same grasps, ids and statuses.

    Parameters
    ----------
    part : Part or path
        From :func:`grasplan.part.mesh.load_part`, or a mesh file path (loaded with ``units``).
    robot, gripper, cell : name, path or model
        A :class:`~grasplan.robot.description.Robot` / :class:`~grasplan.gripper.Gripper` /
        :class:`~grasplan.cell.model.Cell`, or a name or YAML path resolved once here (unknown names
        raise ``ConfigError`` listing what exists and where grasplan looked).
    candidates, grasps, planning : CandidateParams, GraspParams, PlanParams
        Every option of the stages, validated by the dataclasses (see :mod:`grasplan.config.params`).
    T_world_part : (4, 4), optional
        The part's pose in the world instead of its stable resting pose.
    progress : callable(PlanProgress) or None
        Called with :class:`GraspStageDone` after the grasp stage and :class:`GraspTried` after
        every tried grasp.
    load_s : float
        Seconds the caller spent loading ``part`` (recorded as ``timing_s["load"]``).
    place : (4, 4), optional
        ``T_world_part`` after release (pick-and-place, :mod:`grasplan.motion.pickplace`); overrides the
        cell's ``place``. Every plan lifts the part after the grasp; with a place it is also carried
        there, released and the gripper retreats. A place reaching into the table or an obstacle
        raises ``InputError`` before planning.
    database : GraspDatabase, optional
        The part's grasp database computed with these options (from ``grasplan database`` or
        :func:`grasplan.grasps.graspdb.database_for`) instead of the cache's.
    """
    t = time.perf_counter()
    rob = load_robot(robot)
    g = load_gripper(gripper)
    c = load_cell(cell)
    if c.name == NO_CELL_NAME:
        raise InputError("cell 'none' holds the part alone, with nothing to plan a robot against: it is for "
                         "`grasplan grasps` and `grasplan database`; plan in a cell (e.g. --cell table or bin)")
    t_robot = time.perf_counter() - t
    if place is None:
        place = planning.place_matrix()  # PlanParams.place (--place in a batch manifest)
    if place is not None:
        c = replace(c, place=check_transform(place, "place (T_world_part after release)"))
    if not isinstance(part, Part):
        t = time.perf_counter()
        part = load_part(part, units=units)
        load_s = time.perf_counter() - t
    database_s = None
    if database is None and planning.grasp_db != GRASP_DB_OFF:  # read first: it holds the resting poses
        database, read_s = cached_database(part, g, candidates=candidates, grasps=grasps)
        database_s = read_s if database is not None else None
    start_scene = _check_before_planning(part, rob, g, c, grasps, T_world_part)
    notify = (lambda text: progress(GraspDatabaseNote(text))) if progress is not None else None
    gr = grasp_stage(part, g, c, candidates=candidates, grasps=grasps, T_world_part=T_world_part,
                     every_pose=planning.grasp_db == GRASP_DB_OFF, database=database, load_s=load_s, notify=notify,
                     database_s=database_s)
    if progress is not None:
        progress(GraspStageDone(gr.counts()))
    t = time.perf_counter()
    # the checks' scene is the plan's: the same robot, gripper, part, pose and cell (the pose index aside)
    same = start_scene.T_world_part is not None and np.array_equal(start_scene.T_world_part, gr.T_world_part) \
        and gr.gripper is g
    scene = start_scene if same else CollisionScene(rob, gr.gripper, part.mesh, gr.T_world_part, gr.cell)
    t_robot += time.perf_counter() - t
    out = plan_grasps(gr, rob, scene, params=planning, progress=progress)
    return _plan_result(part, rob, gr, out, planning, t_robot)


def planning_for_keep(planning: PlanParams, keep: str) -> PlanParams:
    """``planning`` for a plan file that keeps ``keep``: ``all`` (every pose written in full) needs
    the grasp stage computed in the cell (``grasp_db`` ``off``: a grasp database holds the poses
    that hit the part as counts only)."""
    return replace(planning, grasp_db=GRASP_DB_OFF) if keep == KEEP_ALL else planning


def _check_before_planning(part: Part, robot: Robot, gripper: Gripper, cell: Cell, grasps: GraspParams,
                           T_world_part: np.ndarray | None) -> CollisionScene:
    """The checks before planning (:mod:`grasplan.motion.start_checks`; InputError, exit 3, with what
    to change): the place and the part inside the table or an obstacle, the robot's base inside an
    obstacle, q_home in collision. Returns the scene it checked (the part at its start pose)."""
    if cell.place is not None:
        check_part_placement(part.mesh, cell.place, cell, what="the part at the place (--place or the cell's place)",
                             pose_option="--place or the cell's place.T")
    k = grasps.single_pose_index()
    T_start = T_world_part if T_world_part is not None else stable_pose(
        part.mesh, cell if k is None else replace(cell, pose_index=k))
    scene = CollisionScene(robot, gripper, part.mesh, T_start, cell)
    check_start(scene, part_mesh=part.mesh)
    return scene


def _plan_result(part: Part, robot: Robot, gr: PlacedGrasps, out: PlanOutcome, planning: PlanParams,
                 t_robot: float) -> PlanResult:
    """The :class:`PlanResult` of the grasp stage ``gr`` and the plan stage ``out`` (with
    ``planning.simulate``: the top planned grasps lifted and shaken in MuJoCo, held ones first)."""
    rec = PartRecord(path=part.path, sha256=part.sha256, scale_to_m=part.scale_to_m, triangles=part.triangles,
                     T_world_part=np.asarray(gr.T_world_part, dtype=np.float64))
    mp = gr.mass_props
    result = PlanResult(part=rec, gripper=gr.gripper, cell=gr.cell, robot=robot,
                        grasps=gr.table.with_plan(out.status, out.score, out.rank, out.reason),
                        motions=out.motions, params=Params(gr.candidate_params, gr.params, planning),
                        counts_stage=dict(gr.counts_stage), timing_s={**gr.timing_s, "robot": t_robot, **out.timing_s},
                        part_pose_source=gr.part_pose_source, grasp_result=gr, part_mesh=part.mesh,
                        mass=None if mp is None else mp.record(), rejected=gr.rejected)
    if planning.simulate > 0:
        from ..sim.simulate import simulate_plan  # MuJoCo and trimesh load only when simulating

        result = simulate_plan(result, planning.simulate, mass_props=mp if isinstance(mp, MassProperties) else None,
                               seed=planning.seed)
    return result


# -- every resting pose (--pose-index all) -----------------------------------------------------------
#: ``--pose-index all`` plans every stable pose at least this probable
MIN_POSE_PROBABILITY = 0.02


def stable_pose_indices(part_mesh: TriangleMesh, min_probability: float = MIN_POSE_PROBABILITY
                        ) -> list[tuple[int, float]]:
    """``[(pose_index, probability)]`` of the part's stable poses with probability >= ``min_probability``."""
    _, prob = stable_poses(part_mesh)
    return [(int(k), float(p)) for k, p in enumerate(prob) if p >= min_probability]


def plan_poses(part: Part | str | os.PathLike, robot: Robot | str | Path = DEFAULT_ROBOT, *,
               gripper: Gripper | str | os.PathLike = DEFAULT_GRIPPER, cell: Cell | str | os.PathLike = DEFAULT_CELL,
               candidates: CandidateParams = CandidateParams(), grasps: GraspParams = GraspParams(),
               planning: PlanParams = PlanParams(), T_world_part: np.ndarray | None = None,
               min_probability: float = MIN_POSE_PROBABILITY, units: str = "auto",
               progress: ProgressCallback | None = None, load_s: float = 0.0,
               place: np.ndarray | None = None) -> list[PosePlan]:
    """:func:`plan` for every stable pose of probability >= ``min_probability`` (``--pose-index
    all``; the other keywords as :func:`plan` takes them): one :class:`PosePlan` per pose, most
    probable first. A pose whose checks before planning fail (the part inside an obstacle,
    InputError) gets the message as its ``error``; errors of the cell or robot (q_home in
    collision, ConfigError) are raised."""
    if T_world_part is not None:
        raise InputError("--pose-index all: the resting poses replace --part-pose; give one or the other")
    if not isinstance(part, Part):
        part = load_part(part, units=units)
    rob = load_robot(robot)
    g = load_gripper(gripper)
    db = None
    if planning.grasp_db != GRASP_DB_OFF:  # one database serves every pose
        notify = (lambda text: progress(GraspDatabaseNote(text))) if progress is not None else None
        db = database_for(part, g, candidates=candidates, grasps=grasps, progress=notify)
    out: list[PosePlan] = []
    for k, p in stable_pose_indices(part.mesh, min_probability):
        try:
            res = plan(part, rob, gripper=g, cell=cell, candidates=candidates,
                       grasps=replace(grasps, pose_index=k), planning=planning, progress=progress, load_s=load_s,
                       place=place, database=db)
        except ConfigError:
            raise
        except InputError as exc:
            out.append(PosePlan(k, p, error=str(exc)))
            continue
        out.append(PosePlan(k, p, result=res))
    return out


def grasp_counts_by_pose(part: Part, *, gripper: Gripper | str = DEFAULT_GRIPPER, cell: Cell | str = DEFAULT_CELL,
                         candidates: CandidateParams = CandidateParams(), grasps: GraspParams = GraspParams(),
                         min_probability: float = MIN_POSE_PROBABILITY, skip: int | None = None
                         ) -> list[tuple[int, float, int]]:
    """``[(pose_index, probability, collision-free grasps)]`` for the stable poses of probability
    >= ``min_probability`` except ``skip``: the grasp stage only (the part's grasp database placed
    in each pose), for the exit-4 message."""
    g = load_gripper(gripper)
    c = load_cell(cell)
    db = database_for(part, g, candidates=candidates, grasps=grasps)
    out = []
    for k, p in stable_pose_indices(part.mesh, min_probability):
        if k == skip:
            continue
        gr = grasp_stage(part, g, c, candidates=candidates, grasps=replace(grasps, pose_index=k), database=db)
        out.append((k, p, int(np.count_nonzero(gr.table.status.astype(str) == Status.OK.value))))
    return out
