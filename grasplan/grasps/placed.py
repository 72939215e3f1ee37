"""The grasp stage as the planner takes it: a part resting in a cell and the gripper poses there.

:class:`PlacedGrasps` holds one resting pose's grasps (a :class:`~grasplan.results.grasp_table.GraspTable`:
id, pose, grasp-stage status and reason, score, quality) and the poses the table leaves out
(they hit the part) counted per candidate. Two roads lead to it, with the same poses, ids,
statuses, quality and scores (:func:`grasp_stage` chooses):

* :func:`place_database`: the part's grasp database (:mod:`grasplan.grasps.graspdb`, computed once
  in the part frame and cached) placed in the pose and the cell: its collision-free poses checked
  against the table and the obstacles, their gravity margin and score computed for the pose;
* :func:`placed_from_result`: the whole stage computed in the cell
  (:func:`grasplan.grasps.pipeline.compute_grasps`), every pose in the table.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..cell.model import Cell
from ..config.params import CandidateParams, GraspParams
from ..errors import InputError
from ..gripper.model import Gripper
from ..io import read_json, sha256_doc, write_json
from ..part.mass import MassProperties
from ..part.mesh import Part
from ..results.compact import REJECTED, RejectedCounts
from ..results.grasp_table import GraspTable
from ..status import GRASP_STATUSES, Status
from .collision import GripperCollider
from .graspdb import GraspDatabase, cache_path, database_for, options_key, read_cached
from .pipeline import GraspResult, compute_grasps, part_pose
from .quality import Quality, mass_or_note, quality_columns, stage_score, stage_warnings


@dataclass(frozen=True, eq=False)
class PlacedGrasps:
    """One resting pose's grasps, as the planner (:func:`grasplan.motion.planning.plan_grasps`) takes them.

    ``table``: the poses held in full, grasp ids increasing (``table.ids``), ``status`` a grasp-stage
    status (:data:`grasplan.status.GRASP_STATUSES`), ``reason`` ("" for ``ok``), ``score`` (NaN
    but for ``ok``) and the quality columns; ``quality``: the :class:`~grasplan.grasps.quality.Quality`
    of the table's ``ok`` rows in row order (None: no mass properties, ``quality_note`` says why);
    ``rejected``: the poses not in the table (they hit the part), counted per candidate (None:
    every pose is in the table); ``counts_stage``: ``candidates``, ``posed_candidates``, ``poses``
    (every pose, in the table or counted) and ``regions``; ``notes``: the work bounds the candidate
    and pose stages applied."""

    part: Part
    gripper: Gripper
    cell: Cell
    T_world_part: np.ndarray
    part_pose_source: str
    candidate_params: CandidateParams
    params: GraspParams
    table: GraspTable
    quality: Quality | None
    mass_props: MassProperties | None
    rejected: RejectedCounts | None = None
    counts_stage: dict[str, int] = field(default_factory=dict)
    timing_s: dict[str, float] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    quality_note: str = ""

    @property
    def status(self) -> np.ndarray:
        """(M,) grasp-stage status of the table's rows."""
        return self.table.status

    def counts(self) -> dict[str, int]:
        """``counts_stage`` and the poses per grasp-stage status (the counted ones included)."""
        st = self.table.status.astype(str)
        out = dict(self.counts_stage)
        out.update({s: int(np.count_nonzero(st == s)) for s in GRASP_STATUSES})
        if self.rejected is not None:
            for s, n in self.rejected.totals().items():
                out[s] = out.get(s, 0) + n
        return out

    def quality_warnings(self) -> list[str]:
        """What to tell the user: the work bounds applied, the mass properties' warnings (or why
        there is no quality) and :func:`grasplan.grasps.quality.holding_warning`."""
        return stage_warnings(self.notes, self.quality, self.mass_props, self.quality_note,
                              part=Path(self.part.path).name)


def placed_from_result(gr: GraspResult) -> PlacedGrasps:
    """A whole grasp stage (every pose computed in the cell) as :class:`PlacedGrasps`."""
    counts = gr.counts()
    stage: dict[str, int] = {k: counts[k] for k in ("candidates", "posed_candidates", "poses", "regions") if k in counts}
    return PlacedGrasps(part=gr.cand.part, gripper=gr.gripper, cell=gr.cell, T_world_part=gr.T_world_part,
                        part_pose_source=gr.part_pose_source, candidate_params=gr.cand.params, params=gr.params,
                        table=gr.table(), quality=gr.quality, mass_props=gr.mass_props, counts_stage=stage,
                        timing_s=dict(gr.timing_s), notes=tuple(gr.cand.notes), quality_note=gr.quality_note)


def place_database(db: GraspDatabase, part: Part, cell: Cell, *, params: GraspParams,
                   T_world_part: np.ndarray | None = None, timing_s: dict[str, float] | None = None,
                   gripper: Gripper | None = None) -> PlacedGrasps:
    """``db``'s grasps with ``part`` resting in ``cell`` (at ``T_world_part``, else the cell's stable
    pose, ``params.pose_index`` when given): the database's collision-free poses checked against
    the table and the obstacles (:meth:`~grasplan.grasps.collision.GripperCollider.check_detail` with
    ``part_free``), the ``ok`` ones' quality for this pose (:meth:`GraspDatabase.quality_at`: the
    stored patches and epsilon, the gravity margin for gravity's direction here) and score
    (:func:`grasplan.grasps.quality.stage_score`); the poses that hit the part counted per candidate.
    ``params``: the grasp options the database was computed with (and the pose index);
    ``gripper``: the caller's model of the database's gripper (default the database's own copy);
    ``timing_s``: seconds already spent (the database's load or computation), added to:
    ``stable_pose``, ``place_collision`` (of it ``collision_table``, ``_obstacle``, ``_shapes``)
    and ``place_quality`` (gravity margin and score)."""
    timing = dict(timing_s or {})
    db.check_for(part, gripper)
    k = params.single_pose_index()
    c = replace(cell, pose_index=k) if k is not None else cell
    t = time.perf_counter()
    T, source = part_pose(part, c, T_world_part)
    timing["stable_pose"] = time.perf_counter() - t
    t = time.perf_counter()
    order = np.argsort(db.pose, kind="stable")
    T_part_tcp, width = db.T_part_tcp[order], db.width[order]
    g = db.gripper if gripper is None else gripper
    collider = GripperCollider(part.mesh, g, c, T)
    status, elem, body = collider.check_detail(T_part_tcp, width, part_free=True)
    reasons = collider.reasons(status, elem, body)
    timing["place_collision"] = time.perf_counter() - t
    for key, v in collider.timing_s().items():  # the table and obstacles here, the part when the database was built
        timing[key] = timing.get(key, 0.0) + v
    t = time.perf_counter()
    ok = np.flatnonzero(status == Status.OK.value)
    mp, note = (db.mass_props, "") if db.mass_props is not None else mass_or_note(part.mesh, params)
    q = db.quality_at(T, order[ok]) if mp is not None else None
    M = len(order)
    score = np.full(M, np.nan)
    score[ok] = stage_score(part.mesh, g, T, T_part_tcp[ok], width[ok], params, q, mp)
    quality = quality_columns(q, ok, M) if q is not None else {}
    timing["place_quality"] = time.perf_counter() - t
    table = GraspTable(candidate=db.candidate[order], region=db.region[order], contacts=db.contacts[order],
                       normals=db.normals[order], width=width, T_part_tcp=T_part_tcp, roll=db.roll[order],
                       status=status.astype(object), score=score, rank=np.full(M, -1, dtype=np.int64),
                       reason=reasons, id_values=db.pose[order], **quality)
    counts = np.zeros((len(db.rejected_candidate), len(REJECTED)), dtype=np.int64)
    counts[:, REJECTED.index(Status.COLLISION_PART.value)] = db.rejected_part
    stage: dict[str, int] = {key: int(db.counts[key]) for key in ("candidates", "posed_candidates", "poses", "regions")
             if key in db.counts}
    return PlacedGrasps(part=part, gripper=g, cell=c, T_world_part=T, part_pose_source=source,
                        candidate_params=db.candidates, params=params, table=table, quality=q, mass_props=mp,
                        rejected=RejectedCounts(db.rejected_candidate, counts), counts_stage=stage,
                        timing_s=timing, notes=tuple(db.notes), quality_note=note)


def grasp_stage(part: Part, gripper: Gripper, cell: Cell, *, candidates: CandidateParams, grasps: GraspParams,
                T_world_part: np.ndarray | None = None, every_pose: bool = False,
                database: GraspDatabase | None = None, load_s: float = 0.0,
                notify: Callable[[str], None] | None = None, database_s: float | None = None) -> PlacedGrasps:
    """The grasp stage of a plan: ``part`` in ``cell`` with ``gripper``.

    By default the part's grasp database (``database``, else :func:`grasplan.grasps.graspdb.database_for`:
    read from the cache, or computed and cached; ``notify`` gets its progress lines) placed in the
    pose (:func:`place_database`). ``every_pose``: the whole stage computed in the cell instead
    (:func:`grasplan.grasps.pipeline.compute_grasps`), every pose in the table. ``timing_s``
    records ``load`` and, from the cache, ``database`` (seconds to read it; ``database_s`` when the
    caller read it with :func:`cached_database`), else the computation's stages."""
    if every_pose:
        return placed_from_result(compute_grasps(part, gripper=gripper, cell=cell, candidates=candidates,
                                                 grasps=grasps, T_world_part=T_world_part, load_s=load_s))
    timing: dict[str, float] = {"load": float(load_s)}
    if database is None:
        t = time.perf_counter()
        database = database_for(part, gripper, candidates=candidates, grasps=grasps, progress=notify)
        if database.origin:
            timing["database"] = time.perf_counter() - t
        else:
            timing.update({k: v for k, v in database.timing_s.items() if k != "load"})
    elif database_s is not None:  # read by the caller from the cache
        timing["database"] = float(database_s)
        database.check_for(part, gripper, source=database.origin)
    else:
        database.check_for(part, gripper, source=database.origin)
        if database.params_key != options_key(gripper, candidates, grasps):
            raise InputError(f"grasp database {database.origin or '(in memory)'}: computed with other candidate or "
                             f"grasp options than this plan's (its own: {database.candidates.options_json()}, "
                             f"{database.grasps.options_json()}); plan with those, or let the plan compute its own")
    return place_database(database, part, cell, params=grasps, T_world_part=T_world_part, timing_s=timing,
                          gripper=gripper)


def cached_database(part: Part, gripper: Gripper, *, candidates: CandidateParams, grasps: GraspParams
                    ) -> tuple[GraspDatabase | None, float]:
    """``(database, seconds)``: :func:`grasplan.grasps.graspdb.read_cached` timed, ``(None, 0)`` when
    the cache holds no usable one (:func:`grasp_stage` then computes it, saying why)."""
    t = time.perf_counter()
    db, _ = read_cached(part, gripper, candidates=candidates, grasps=grasps)
    return (db, time.perf_counter() - t) if db is not None else (None, 0.0)


def hold_by_pose(part: Part, gripper: Gripper, cell: Cell, *, candidates: CandidateParams, grasps: GraspParams,
                 poses: list[tuple[int, float]], cache: bool = True) -> list[tuple[int, float, int, float | None]]:
    """``[(pose_index, probability, grasps predicted to hold, least hold force N or None)]`` for
    ``poses`` (``(index, probability)`` of resting poses): the part's grasp database placed in each
    (collision-free grasps with ``gravity_margin >= 1`` at the gripper's force; the least
    ``hold_force`` of any collision-free one). The grasp stage only: no robot. With ``cache``, the
    rows are kept beside the database (:func:`hold_cache_path`: one small file per database, cell,
    options and poses) and read from there the next time."""
    path = hold_cache_path(part, gripper, cell, candidates=candidates, grasps=grasps, poses=poses) if cache else None
    if path is not None:
        rows = _read_hold_rows(path, poses)
        if rows is not None:
            return rows
    db = database_for(part, gripper, candidates=candidates, grasps=grasps, cache=cache)
    db.check_for(part)
    out: list[tuple[int, float, int, float | None]] = []
    for k, p in poses:
        c = replace(cell, pose_index=k)
        T, _ = part_pose(part, c, None)
        status = GripperCollider(part.mesh, db.gripper, c, T).check_detail(db.T_part_tcp, db.width, part_free=True)[0]
        n, best = db.holding_at(T, np.flatnonzero(status == Status.OK.value))
        out.append((k, p, n, float(gripper.grip_force) / best if best > 0 else None))
    if path is not None:
        try:
            write_json(path, [list(r) for r in out])
        except OSError:  # a read-only cache folder: the next run computes the rows again
            return out
    return out


def hold_cache_path(part: Part, gripper: Gripper, cell: Cell, *, candidates: CandidateParams, grasps: GraspParams,
                    poses: list[tuple[int, float]]) -> Path:
    """Where :func:`hold_by_pose` keeps its rows: beside the database (:func:`~grasplan.grasps.graspdb.cache_path`),
    named by a sha256 of the database's name, the cell (:meth:`~grasplan.cell.model.Cell.to_json`),
    the grasp options and the poses."""
    db_path = cache_path(part, gripper, candidates, grasps)
    key = sha256_doc({"database": db_path.name, "cell": cell.to_json(), "grasps": grasps.options_json(),
                      "poses": [[int(k), float(p)] for k, p in poses]})
    return db_path.with_name(f"{db_path.name.split('.')[0]}.holds-{key[:16]}.json")


def _read_hold_rows(path: Path, poses: list[tuple[int, float]]) -> list[tuple[int, float, int, float | None]] | None:
    """The rows kept at ``path`` when they are a well-formed answer for ``poses``, else None."""
    if not path.is_file():
        return None
    try:
        doc = read_json(path)
    except (OSError, ValueError, InputError):
        return None
    if not isinstance(doc, list) or len(doc) != len(poses):
        return None
    rows: list[tuple[int, float, int, float | None]] = []
    for row, (k, p) in zip(doc, poses):
        if not (isinstance(row, list) and len(row) == 4 and row[0] == k and isinstance(row[2], int)
                and (row[3] is None or isinstance(row[3], (int, float)))):
            return None
        rows.append((int(k), float(p), int(row[2]), None if row[3] is None else float(row[3])))
    return rows
