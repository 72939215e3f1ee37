"""Reading a picks file back (:func:`load_picks`) and one pick as a one-grasp plan
(:func:`pick_as_plan`), which ``grasplan export`` and ``grasplan view`` take with ``--instance``.

Nothing the file says is trusted: the JSON Schema, the embedded robot, gripper, cell and scene
(rebuilt and checked as when read from their own files), and every pick's motion (joint vectors of
the robot's length within its limits, consecutive transit/approach/lift segments, the close event
at the grasp) re-checked by forward kinematics (:func:`grasplan.result_reader.check_fk`).
"""
from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..cell import Cell, Obstacle
from ..errors import InputError
from ..grasp_table import GraspTable
from ..gripper import gripper_from_json
from ..inputs import check_input_file
from ..motion import GripperEvent, Motion
from ..result import PartRecord, PlanResult
from ..scenefile import scene_from_dict
from ..status import Status
from .params import PickParams
from .result import PICKS_SCHEMA, InstanceReport, Pick, PickResult


def _motion(d: dict[str, Any], nq: int, where: str) -> Motion:
    try:
        path = np.asarray(d["path"], dtype=np.float64)
        segs = tuple((str(s["label"]), int(s["start"]), int(s["end"])) for s in d["segments"])
        events = tuple(GripperEvent(int(g["index"]), str(g["action"]), float(g["width"])) for g in d["gripper"])
        k = int(d["pregrasp_index"])
        T_tcp_part = np.asarray(d["T_tcp_part"], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{where}: a pick needs path, segments, gripper, pregrasp_index and T_tcp_part") from None
    if path.ndim != 2 or path.shape[1] != nq or len(path) < 2 or not np.all(np.isfinite(path)):
        raise InputError(f"{where}: path must be >= 2 finite joint vectors of the robot's {nq} joints")
    labels = [s[0] for s in segs]
    place = labels == ["transit", "approach", "lift", "transfer", "descend", "retreat"]
    if (labels != ["transit", "approach", "lift"] and not place) or segs[0][1] != 0 or segs[-1][2] != len(path) - 1 \
            or any(a[2] != b[1] for a, b in zip(segs[:-1], segs[1:])) or segs[0][2] != k:
        raise InputError(f"{where}: segments must be consecutive transit, approach, lift (and transfer, descend, "
                         f"retreat with a place) covering the path")
    want = ["close", "open"] if place else ["close"]
    if [e.action for e in events] != want or events[0].index != segs[1][2] or (place and events[1].index != segs[4][2]):
        raise InputError(f"{where}: a pick closes the jaws at the end of the approach (and opens them at the end of "
                         f"the descent with a place)")
    T_place = None
    if place:
        try:
            T_place = np.asarray(d["T_world_part_place"], dtype=np.float64)
        except (KeyError, TypeError, ValueError):
            raise InputError(f"{where}: a pick with a place needs T_world_part_place") from None
    return Motion(q_grasp=path[segs[1][2]].copy(), q_pregrasp=path[k].copy(), path=path, pregrasp_index=k,
                  segments=segs, gripper=events, T_tcp_part=T_tcp_part, T_world_part_place=T_place)


def result_from_picks(doc: Any, *, where: str = "picks", base: Path | None = None) -> PickResult:
    """A :class:`PickResult` from a parsed ``grasplan.picks/1`` document (see the module docstring)."""
    from ..robot import robot_from_json
    from ..result_reader import check_fk
    from ..schemas import validate

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
    ids = set(scene.ids)
    picks = []
    for k, d in enumerate(doc["picks"]):
        w = f"{where}: picks[{k}]"
        if d["instance"] not in ids:
            raise InputError(f"{w}: instance {d['instance']!r} is not in the scene ({', '.join(sorted(ids))})")
        odd = [i for i in d.get("lift_carries", ()) if i not in ids or i == d["instance"]]
        if odd:
            raise InputError(f"{w}: lift_carries names {odd[0]!r}, not another instance of the scene "
                             f"({', '.join(sorted(ids - {d['instance']}))})")
        m = _motion(d, robot.nq, w)
        if not np.all(robot.within_limits(m.path, tol=1e-6)):
            raise InputError(f"{w}: the path leaves the joint limits of robot {robot.name!r}")
        T_wp = np.asarray(d["T_world_part"], dtype=np.float64)
        T_pt = np.asarray(d["T_part_tcp"], dtype=np.float64)
        check_fk(robot, gripper, T_wp, T_pt[None], {0: m}, w, width=np.array([float(d["width"])]))
        picks.append(Pick(instance=d["instance"], part=d["part"], T_world_part=T_wp, T_part_tcp=T_pt,
                          contacts=np.asarray(d["contacts"], dtype=np.float64),
                          normals=np.asarray(d["normals"], dtype=np.float64), width=float(d["width"]),
                          opening=float(d["opening"]), score=float(d["score"]),
                          quality={q: float("nan") if v is None else float(v) for q, v in d["quality"].items()},
                          motion=m, T_world_tcp=np.asarray(d["T_world_tcp"], dtype=np.float64),
                          T_world_pregrasp=np.asarray(d["T_world_pregrasp"], dtype=np.float64),
                          T_world_lifted=np.asarray(d["T_world_lifted"], dtype=np.float64), rank=int(d["rank"]),
                          carries=tuple(d.get("lift_carries", ()))))
    reports = tuple(InstanceReport(r["id"], r["part"], r["status"], r["reason"], tuple(r["blocked_by"]))
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
    from ..result_reader import read_document

    p = Path(path)
    return result_from_picks(read_document(p), where=str(p), base=p.resolve().parent)


def _part_meshes(res: PickResult) -> dict[str, Any]:
    """Each part's mesh, loaded from its recorded path (sha256 checked)."""
    from ..mesh import load_recorded_part

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
    (``T_world_tcp -> T_world_lifted``: a lift tilted away from a neighbour, docs/pick.md)."""
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
    return _as_plan(res, meshes, p.instance, gone, cell, table, {0: p.motion}, p.T_world_part)


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
