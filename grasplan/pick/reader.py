"""Reading a picks file back (:func:`load_picks`) and one pick as a one-grasp plan
(:func:`pick_as_plan`), which ``grasplan export`` and ``grasplan view`` take with ``--instance``.

Nothing the file says is trusted: the JSON Schema (the file parsed refusing duplicate keys), the
embedded robot, gripper, cell and scene (rebuilt and checked as when read from their own files),
every pick's motion checked as a plan's planned grasp is
(:func:`grasplan.results.reader.motion_from_json`: finite joint vectors of the robot's length within
its limits, ``q_grasp``/``q_pregrasp`` the path's rows, consecutive transit/approach/lift segments,
the close event at the grasp), every number it carries finite and in range, and its poses re-checked
against each other, the scene and forward kinematics (:func:`grasplan.results.reader.check_fk`).
"""
from __future__ import annotations

import math
import os
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..cell.model import Cell, Obstacle
from ..errors import InputError
from ..results.grasp_table import GraspTable
from ..gripper.load import gripper_from_json
from ..config.inputs import check_input_file
from ..results.joint_motion import Motion
from ..results.plan_result import PartRecord, PlanResult
from ..piles.scene_file import scene_from_dict
from ..status import Status
from .codes import PickStatus
from .params import PickParams
from .result import PICKS_SCHEMA, InstanceReport, Pick, PickResult


#: a pick's transforms (4, 4), each rigid
_POSES = ("T_world_part", "T_part_tcp", "T_world_tcp", "T_world_pregrasp", "T_world_lifted")
#: the largest rank a pick may carry (a grasp's place in its instance's ranking)
MAX_RANK = 2**31 - 1


def _pick_numbers(picks: list[Any], where: str) -> dict[str, np.ndarray]:
    """Every number the picks carry into an export or the viewer, vectorised over the picks and
    checked as a plan's grasps are (:func:`grasplan.results.reader.rows_array`): finite, of their
    shape, the transforms rigid, width, score and normals as
    :func:`grasplan.results.reader.check_grasp_values` checks a plan's, the opening in [0, 10] m,
    ``rank`` a whole number in [0, :data:`MAX_RANK`], ``quality`` values finite numbers >= 0 or null."""
    from ..results.reader import check_grasp_values, check_poses, rows_array

    def rows(key: str, shape: tuple[int, ...]) -> np.ndarray:
        return rows_array(picks, key, shape, np.float64, where, what="picks", id_key="instance")

    out = {k: rows(k, shape) for k, shape in (("contacts", (2, 3)), ("normals", (2, 3)), ("width", ()),
                                               ("opening", ()), ("score", ()), ("rank", ()))}
    for k in _POSES:
        out[k] = check_poses(rows(k, (4, 4)), f"{where}: picks[*].{k}", batch=True).reshape(-1, 4, 4)
    check_grasp_values(out["width"], out["score"], out["normals"], where, "picks")
    bad = np.flatnonzero(~((out["opening"] >= 0) & (out["opening"] <= 10.0)))
    if len(bad):
        raise InputError(f"{where}: picks[{bad[0]}].opening = {out['opening'][bad[0]]:.6g} m: expected a length in "
                         f"[0, 10] m")
    bad = np.flatnonzero((out["rank"] < 0) | (out["rank"] > MAX_RANK) | (out["rank"] != np.round(out["rank"])))
    if len(bad):
        raise InputError(f"{where}: picks[{bad[0]}].rank = {out['rank'][bad[0]]:.6g}: expected a whole number in "
                         f"[0, {MAX_RANK}]")
    for i, d in enumerate(picks):  # as a plan's quality block: finite numbers >= 0 (or null)
        q = d.get("quality")
        if not isinstance(q, dict) or not all(v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)
                                                            and math.isfinite(v) and v >= 0) for v in q.values()):
            raise InputError(f"{where}: picks[{i}].quality: expected {{name: a finite number >= 0, or null}}")
    return out


def _check_poses(robot: Any, gripper: Any, n: dict[str, np.ndarray], k: int, m: Motion, T_scene: np.ndarray,
                 where: str) -> None:
    """The poses pick ``k`` records against each other, the scene and forward kinematics (within
    :data:`grasplan.results.reader.FK_POS_TOL` / ``FK_ROT_TOL``): its part at the scene instance's
    pose, ``T_world_tcp = T_world_part @ T_part_tcp``, the pre-grasp and lifted TCPs at FK of
    ``q_pregrasp`` and the lift's last row (the TCP at the grasp's width), the opening the
    gripper's pre-grasp opening for that width. FK of ``q_grasp`` itself: :func:`check_fk`."""
    from ..results.reader import FK_POS_TOL, FK_ROT_TOL
    from ..geometry.transforms import pose_error

    T_tcp = np.asarray(gripper.T_flange_tcp_at(float(n["width"][k])), dtype=np.float64)
    lift_end = next(e for lab, _, e in m.segment_list() if lab == "lift")
    fk = robot.fk_batch(np.stack([m.q_pregrasp, m.path[lift_end]])) @ T_tcp
    for name, a, b_name, b in (("T_world_part", n["T_world_part"][k], "the scene's pose of the instance", T_scene),
                               ("T_world_tcp", n["T_world_tcp"][k], "T_world_part @ T_part_tcp",
                                n["T_world_part"][k] @ n["T_part_tcp"][k]),
                               ("T_world_pregrasp", n["T_world_pregrasp"][k], "FK(q_pregrasp)", fk[0]),
                               ("T_world_lifted", n["T_world_lifted"][k], f"FK(path[{lift_end}]) (the lift's end)", fk[1])):
        dp, dr = pose_error(a, b)
        if not (dp <= FK_POS_TOL and dr <= FK_ROT_TOL):
            raise InputError(f"{where}: {name} is {dp * 1000:.3g} mm / {dr:.3g} rad from {b_name} (tolerance "
                             f"{FK_POS_TOL * 1000:g} mm / {FK_ROT_TOL:g} rad); the picks file was edited or made "
                             f"with another robot or gripper")
    want = float(gripper.pregrasp_opening(float(n["width"][k])))
    if abs(float(n["opening"][k]) - want) > 1e-6:
        raise InputError(f"{where}: opening {float(n['opening'][k]):.6g} m is not the gripper's pre-grasp opening for "
                         f"its width ({want:.6g} m); the picks file was edited")


def result_from_picks(doc: Any, *, where: str = "picks", base: Path | None = None) -> PickResult:
    """A :class:`PickResult` from a parsed ``grasplan.picks/1`` document (see the module docstring)."""
    from ..robot.description import robot_from_json
    from ..results.reader import check_fk, motion_from_json
    from ..schemas.documents import validate

    if not isinstance(doc, dict) or doc.get("schema") != PICKS_SCHEMA:
        raise InputError(f"{where}: not a {PICKS_SCHEMA} file (schema {str(doc.get('schema') if isinstance(doc, dict) else None)[:40]!r})")
    try:
        validate(doc, PICKS_SCHEMA)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    robot = robot_from_json(doc["robot"], where=f"{where}: robot")
    gripper = gripper_from_json(doc["gripper"], where=f"{where}: gripper")
    cell = Cell.from_json(doc["cell"])
    scene = scene_from_dict(doc["scene"], source=f"{where}: scene", base=base)
    poses = {i.id: np.asarray(i.T_world_part, dtype=np.float64) for i in scene.instances}
    nums = _pick_numbers(doc["picks"], where)
    picks = []
    for k, d in enumerate(doc["picks"]):
        w = f"{where}: picks[{k}]"
        if d["instance"] not in poses:
            raise InputError(f"{w}: instance {d['instance']!r} is not in the scene ({', '.join(sorted(poses))})")
        odd = [i for i in d.get("lift_carries", ()) if i not in poses or i == d["instance"]]
        if odd:
            raise InputError(f"{w}: lift_carries names {odd[0]!r}, not another instance of the scene "
                             f"({', '.join(sorted(set(poses) - {d['instance']}))})")
        m = motion_from_json(d, robot, w)
        if "lift" not in {lab for lab, _, _ in m.segment_list()}:
            raise InputError(f"{w}: a pick's segments are transit, approach, lift (and transfer, descend, retreat "
                             "with a place)")
        check_fk(robot, gripper, nums["T_world_part"][k], nums["T_part_tcp"][k][None], {0: m}, w,
                 width=nums["width"][k:k + 1])
        _check_poses(robot, gripper, nums, k, m, poses[d["instance"]], w)
        picks.append(Pick(instance=d["instance"], part=d["part"], T_world_part=nums["T_world_part"][k],
                          T_part_tcp=nums["T_part_tcp"][k], contacts=nums["contacts"][k], normals=nums["normals"][k],
                          width=float(nums["width"][k]), opening=float(nums["opening"][k]),
                          score=float(nums["score"][k]),
                          quality={q: float("nan") if v is None else float(v) for q, v in d["quality"].items()},
                          motion=m, T_world_tcp=nums["T_world_tcp"][k], T_world_pregrasp=nums["T_world_pregrasp"][k],
                          T_world_lifted=nums["T_world_lifted"][k], rank=int(nums["rank"][k]),
                          carries=tuple(d.get("lift_carries", ()))))
    reports = tuple(InstanceReport(r["id"], r["part"], PickStatus(r["status"]), r["reason"], tuple(r["blocked_by"]))
                    for r in doc["instances"])
    return PickResult(picks=tuple(picks), instances=reports, timing_s=dict(doc["timing_s"]), scene=scene,
                      robot=robot, gripper=gripper, cell=cell, params=PickParams.from_json(doc["params"]),
                      parts={k: dict(v) for k, v in doc["parts"].items()}, warnings=tuple(doc["warnings"]),
                      sequence=bool(doc["sequence"]),
                      stats={k: int(v) for k, v in doc["counts"].items() if k in ("grasps_checked", "grasps_tried")})


def is_picks_file(path: str | os.PathLike) -> bool:
    """True when ``path`` is a JSON file whose ``schema`` is ``grasplan.picks/1`` (looked up in its head)."""
    if not Path(path).exists():
        return False  # the plan reader says it is missing, in its words
    check_input_file(path, what="plan or picks file")  # a FIFO or a device is refused, never opened
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except OSError:
        return False
    return b'"schema": "grasplan.picks/1"' in head or b'"schema":"grasplan.picks/1"' in head


def load_picks(path: str | os.PathLike) -> PickResult:
    """A :class:`PickResult` from a ``grasplan.picks/1`` file; InputError naming the file and the problem."""
    from ..results.reader import read_document

    p = Path(path)
    return result_from_picks(read_document(p), where=str(p), base=p.resolve().parent)


def _part_meshes(res: PickResult) -> dict[str, Any]:
    """Each part's mesh, loaded from its recorded path (sha256 checked)."""
    from ..part.mesh import load_recorded_part

    if res.robot is None or res.gripper is None or res.cell is None:
        raise InputError("the picks result has no robot, gripper or cell")
    meshes: dict[str, Any] = {}
    for name, rec in res.parts.items():
        loaded = load_recorded_part(rec, search_dirs=(str(res.scene.base),) if res.scene.base else ())
        if loaded.sha256 != rec["sha256"]:
            raise InputError(f"{loaded.path}: sha256 {loaded.sha256[:12]}... differs from the picks file's part "
                             f"{name} ({str(rec['sha256'])[:12]}...)")
        meshes[name] = loaded.mesh
    return meshes


def _as_plan(res: PickResult, meshes: dict[str, Any], instance: str, gone: set[str], cell: Cell,
             table: GraspTable, motions: dict[int, Motion], T_world_part: np.ndarray | None = None) -> PlanResult:
    """A plan/1 result whose part is ``instance`` at its pose and whose cell (``cell``, the picks
    file's) has every other instance not in ``gone`` as an obstacle (mesh ``instance_<id>``)."""
    inst = next(i for i in res.scene.instances if i.id == instance)
    others = tuple(Obstacle(f"instance_{i.id}", "mesh", np.asarray(i.T_world_part),
                            vertices=np.asarray(meshes[i.part].vertices), faces=np.asarray(meshes[i.part].faces))
                   for i in res.scene.instances if i.id != instance and i.id not in gone and i.part in meshes)
    rec = res.parts[inst.part]
    part = PartRecord(path=str(rec["path"]), sha256=str(rec["sha256"]), scale_to_m=float(rec["scale_to_m"]),
                      triangles=int(rec.get("triangles", len(meshes[inst.part].faces))),
                      T_world_part=np.asarray(inst.T_world_part if T_world_part is None else T_world_part,
                                              dtype=np.float64))
    assert res.gripper is not None
    return PlanResult(part=part, gripper=res.gripper, cell=replace(cell, obstacles=tuple(cell.obstacles) + others),
                      robot=res.robot, grasps=table, motions=motions, part_pose_source="given",
                      part_mesh=meshes[inst.part])


def pick_as_plan(res: PickResult, instance: str | None = None) -> PlanResult:
    """The pick of ``instance`` (default: the first pick) as a ``grasplan.plan/1`` result with one
    planned grasp: the instance is the plan's part, every other instance of the scene (with
    ``sequence``: still in the pile when it was planned) is an obstacle (mesh ``instance_<id>``) of
    its cell, so exports and the viewer see the whole pile; the cell's retreat is the pick's own lift
    (``T_world_tcp -> T_world_lifted``: a lift tilted away from a neighbour, docs/pick.md). The
    pick's contacts must lie on its part's mesh (:func:`grasplan.results.reader.check_contacts_on_part`)."""
    p = res.pick(instance)
    meshes = _part_meshes(res)
    gone = set()  # --sequence: the instances picked before this one are out of the pile
    if res.sequence:
        for q in res.picks:
            if q.instance == p.instance:
                break
            gone.add(q.instance)
    lift = np.asarray(p.T_world_lifted, dtype=np.float64)[:3, 3] - np.asarray(p.T_world_tcp, dtype=np.float64)[:3, 3]
    dist = float(np.linalg.norm(lift))
    assert res.cell is not None
    cell = replace(res.cell, place=p.motion.T_world_part_place if p.motion.T_world_part_place is not None else res.cell.place)
    if dist > 0:
        u = lift / dist
        cell = replace(cell, retreat_direction=(float(u[0]), float(u[1]), float(u[2])), retreat_distance=dist)
    table = GraspTable(candidate=np.zeros(1, dtype=np.int64), region=np.full(1, -1, dtype=np.int64),
                       contacts=p.contacts[None], normals=p.normals[None], width=np.array([p.width]),
                       T_part_tcp=p.T_part_tcp[None], roll=np.zeros(1), status=np.array([Status.PLANNED.value], dtype=object),
                       score=np.array([p.score]), rank=np.zeros(1, dtype=np.int64),
                       reason=np.array([res.report(p.instance).reason], dtype=object))
    plan = _as_plan(res, meshes, p.instance, gone, cell, table, {0: p.motion}, p.T_world_part)
    from ..results.reader import check_contacts_on_part

    check_contacts_on_part(plan, f"pick of instance {p.instance!r}")  # as a plan's contacts are checked
    return plan


def pile_as_plan(res: PickResult) -> tuple[PlanResult, list[str]]:
    """A picks result with no pick, for the viewer: a ``grasplan.plan/1`` result without grasps whose
    part is the scene's first instance and whose cell holds every other one (as :func:`pick_as_plan`),
    and one line per instance: ``id (part): status: reason``."""
    if not res.scene.instances:
        raise InputError("the picks file's scene has no instance")
    meshes = _part_meshes(res)
    assert res.cell is not None
    first = res.scene.instances[0].id
    table = GraspTable(candidate=np.zeros(0, dtype=np.int64), region=np.zeros(0, dtype=np.int64),
                       contacts=np.zeros((0, 2, 3)), normals=np.zeros((0, 2, 3)), width=np.zeros(0),
                       T_part_tcp=np.zeros((0, 4, 4)), roll=np.zeros(0), status=np.zeros(0, dtype=object),
                       score=np.zeros(0), rank=np.zeros(0, dtype=np.int64), reason=np.zeros(0, dtype=object))
    lines = [f"no pick: the part shown is {first}, every other instance is drawn as an obstacle"]
    lines += [f"{r.id} ({r.part}): {r.status}: {r.reason}" for r in res.instances]
    return _as_plan(res, meshes, first, set(), res.cell, table, {}), lines
