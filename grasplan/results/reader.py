"""Reading a result back: :func:`load_result` turns a ``grasplan.grasps/1`` or ``grasplan.plan/1``
file (or a parsed document) into a typed :class:`grasplan.results.plan_result.PlanResult`.

Nothing a file says is trusted: :func:`result_from_document` checks the JSON Schema (on a sample
of a large file) and then every grasp, vectorised (finite numbers, rigid transforms, statuses of
the file's stage, joint vectors of the robot's length within its limits, consecutive motion
segments with their gripper events), and re-checks each planned grasp by forward kinematics
(:func:`check_fk`: ``FK(q_grasp)`` at the recorded TCP, the attached part and the place). The
gripper, cell and robot are rebuilt from the definitions the file embeds. Every problem is an
:class:`~grasplan.errors.InputError` naming the file, the grasp and what would pass.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..cell.model import Cell
from ..errors import InputError
from ..config.inputs import read_input_bytes
from ..config.jsontext import DuplicateKeyError, loads_strict
from ..io import show_path
from .compact import KEEP_COLLISION_FREE, RejectedCounts, untried_from_json
from .grasp_table import GraspTable, join_tables
from ..gripper.model import Gripper
from ..gripper.load import gripper_from_json
from .joint_motion import GRIPPER_ACTIONS, SEGMENT_SEQUENCES, GripperEvent, Motion
from ..config.params import CandidateParams, GraspParams, PlanParams
from .quality_json import parse_mass_record, parse_quality_sim
from .plan_result import Params, PartRecord, PlanResult
from .writer import GRASPS_SCHEMA, PLAN_SCHEMA, SCHEMAS
from ..schemas.documents import validate
from ..status import GRASP_STATUSES, PLAN_STATUSES, Status
from ..geometry.transforms import check_transform, pose_error

if TYPE_CHECKING:
    from ..geometry.meshdata import TriangleMesh
    from ..robot.model import Robot

#: documents with more grasps than this get the JSON Schema on a sample plus a vectorised check
#: of every grasp (jsonschema checks ~1000 grasps/s)
SCHEMA_SAMPLE = 50
MAX_JSON_BYTES = 2 * 1024**3


def read_document(path: str | os.PathLike[str]) -> Any:
    """Parse a grasplan JSON file (a plan, grasps or picks file); InputError for anything that is
    not one, also for an object naming one key twice (:func:`grasplan.config.jsontext.loads_strict`)."""
    p = Path(path)
    try:
        if not p.exists():
            raise InputError(f"{show_path(p)}: no such file (expected a grasplan grasps or plan JSON file)")
        # a regular file only (a FIFO or a device is refused before reading), at most MAX_JSON_BYTES
        doc = loads_strict(read_input_bytes(p, what="result", max_bytes=MAX_JSON_BYTES))
    except OSError as exc:
        raise InputError(f"{show_path(p)}: cannot read it ({exc.strerror or exc})") from None
    except RecursionError:
        raise InputError(f"{p}: JSON nested too deeply; not a grasplan result") from None
    except DuplicateKeyError as exc:
        raise InputError(f"{show_path(p)}: {exc}") from None
    except (UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"{p}: not a JSON file ({str(exc)[:80]}); expected a result written by grasplan") from None
    return doc


def rows_array(rows: list[Any], key: str, shape: tuple[int, ...], dtype: Any, where: str, *, default: Any = None,
               what: str = "grasps", id_key: str = "id") -> np.ndarray:
    """``rows[*][key]`` (a plan's grasps, a picks file's picks) as one array ``(len(rows), *shape)``
    of finite numbers (any value for ``dtype=object``), vectorised; InputError naming the first
    bad row (``what[i]``, its ``id_key``) and what would pass. ``default``: the value of a missing key."""
    if not rows:  # a result with no grasp at all (no candidate fits the gripper): written so, read so
        return np.zeros((0, *shape), dtype=dtype)
    try:
        if default is not None:
            vals = [g.get(key, default) if isinstance(g, dict) else None for g in rows]
        else:
            vals = [g[key] for g in rows]
        a = np.array(vals, dtype=dtype)
        if a.shape == (len(rows), *shape) and (dtype is object or np.all(np.isfinite(a))):
            return a
    except (KeyError, TypeError, ValueError, OverflowError):
        pass
    for i, g in enumerate(rows):
        try:
            v = np.asarray(g[key] if default is None else g.get(key, default), dtype=dtype)
            ok = v.shape == shape and (dtype is object or bool(np.all(np.isfinite(v))))
        except (KeyError, TypeError, ValueError, OverflowError, AttributeError):
            ok = False
        if not ok:
            gid = g.get(id_key) if isinstance(g, dict) else None
            raise InputError(f"{where}: {what}[{i}] ({id_key} {str(gid)[:20]}): {key!r} missing or malformed; expected "
                             f"{'a finite number' if not shape else 'finite numbers of shape ' + str(shape)}")
    raise InputError(f"{where}: {what}: {key!r} malformed")


def check_poses(T: Any, name: str, *, batch: bool = False) -> np.ndarray:
    """``T`` as rigid transforms ((4, 4), or (N, 4, 4) with ``batch``) whose translations lie within
    :data:`grasplan.part.mesh.MAX_COORD_M` of the origin: the entries are bounded first (no overflow in
    the rigidity check or in FK comparisons), then :func:`grasplan.geometry.transforms.check_transform`.
    InputError naming ``name`` and what is wrong."""
    from ..part.mesh import MAX_COORD_M

    try:
        A = np.asarray(T, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{name}: expected a 4x4 matrix of numbers") from None
    if A.shape[-2:] == (4, 4) and A.size and np.all(np.isfinite(A)):
        rot = float(np.abs(A[..., :3, :3]).max())
        far = float(np.abs(A[..., :3, 3]).max())
        if rot > 1.0 + 1e-6:
            raise InputError(f"{name}: rotation entries up to {rot:.3g}: not a rotation matrix (entries in [-1, 1])")
        if far > MAX_COORD_M:
            raise InputError(f"{name}: a translation of {far:.3g} m, beyond the {MAX_COORD_M:g} m any pose lies within")
    return check_transform(A, name, batch=batch)


#: a score is a weighted mean of terms in [0, 1] (grasplan.config.scoring): it lies in [0, 1] within this
SCORE_SLACK = 1e-6
#: a contact normal is a unit vector within this
NORMAL_TOL = 1e-3


def check_grasp_values(width: np.ndarray, score: np.ndarray, normals: np.ndarray, where: str,
                       what: str = "grasps") -> None:
    """The values a grasp carries into exports, checked for a plan's grasps and a picks file's
    picks alike: widths (M,) in [0, 10] m, scores (M,) in [0, 1] (NaN: none), normals (M, 2, 3)
    unit vectors. InputError naming the first bad row (``what[i]``) and what would pass."""
    with np.errstate(over="ignore", invalid="ignore"):  # 1e300 has no norm: it is bad, not a warning
        unit = np.all(np.abs(np.linalg.norm(normals, axis=-1) - 1.0) <= NORMAL_TOL, axis=-1) if len(normals) \
            else np.ones(0, dtype=bool)
    for name, bad, want in (
            ("width", ~((width >= 0) & (width <= 10)), "a length in [0, 10] m"),
            ("score", ~np.isnan(score) & ~((score >= -SCORE_SLACK) & (score <= 1 + SCORE_SLACK)),
             "a number in [0, 1] (a weighted mean of terms in [0, 1]) or null"),
            ("normals", ~unit, "two unit vectors")):
        rows = np.flatnonzero(bad)
        if len(rows):
            i = int(rows[0])
            shown = np.round(np.asarray(normals[i]), 6).tolist() if name == "normals" else f"{float((width if name == 'width' else score)[i]):.6g}"
            raise InputError(f"{where}: {what}[{i}].{name} = {shown}: expected {want}")


def result_from_document(doc: Any, *, where: str = "document", part_mesh: TriangleMesh | None = None) -> PlanResult:
    """Validate a parsed grasps/plan document in full (schema on a sample, every grasp vectorised,
    finite numbers, rigid transforms, joint vectors of the robot's length within its limits, FK of
    each planned grasp at its recorded TCP) and rebuild the typed result."""
    if not isinstance(doc, dict) or doc.get("schema") not in SCHEMAS:
        found = doc.get("schema") if isinstance(doc, dict) else type(doc).__name__
        raise InputError(f"{where}: not a grasplan grasps or plan file: schema is {str(found)[:60]!r}, expected "
                         f"{' or '.join(map(repr, SCHEMAS))}")
    schema = doc["schema"]
    grasps = doc.get("grasps")
    if not isinstance(grasps, list):
        raise InputError(f"{where}: $.grasps must be a list")
    # the untried columns and rejected counts are checked in full by their parsers (compact.py)
    head = {k: v for k, v in doc.items() if k not in ("untried", "rejected")}
    if len(grasps) > SCHEMA_SAMPLE:
        step = max(1, len(grasps) // SCHEMA_SAMPLE)
        picked = [i for i, g in enumerate(grasps) if i % step == 0
                  or (isinstance(g, dict) and g.get("status") == Status.PLANNED.value)]
        _validate({**head, "grasps": [grasps[i] for i in picked]}, schema, where, picked)
    else:
        _validate(head, schema, where)
    compact = schema == PLAN_SCHEMA and doc.get("keep") == KEEP_COLLISION_FREE
    if schema == PLAN_SCHEMA and compact != ("untried" in doc and "rejected" in doc):
        raise InputError(f"{where}: a plan with keep {KEEP_COLLISION_FREE!r} has 'untried' and 'rejected' blocks "
                         "and no other plan has them")
    M = len(grasps)
    ids = rows_array(grasps, "id", (), np.float64, where)
    id_values = None
    if M and not np.array_equal(ids, np.arange(M)):
        filtered = (doc.get("only_ok") is True and schema == GRASPS_SCHEMA) or compact
        if not (filtered and np.all(ids == np.round(ids)) and ids[0] >= 0 and np.all(np.diff(ids) > 0)
                and ids[-1] < 2**53):
            raise InputError(f"{where}: grasp ids must be 0..{M - 1} in order (a file written with --only-ok or "
                             f"keep {KEEP_COLLISION_FREE!r}: strictly increasing ids)")
        id_values = ids.astype(np.int64)
    names = PLAN_STATUSES if schema == PLAN_SCHEMA else GRASP_STATUSES
    status = rows_array(grasps, "status", (), object, where)
    bad = sorted(set(status.tolist()) - set(names)) if M else []
    if bad:
        raise InputError(f"{where}: unknown grasp status {str(bad[:3])[:80]}; expected one of {', '.join(names)}")
    T = rows_array(grasps, "T_part_tcp", (4, 4), np.float64, where)
    if M:
        check_poses(T, f"{where}: grasps[*].T_part_tcp", batch=True)
    width = rows_array(grasps, "width", (), np.float64, where)
    table = GraspTable(
        candidate=rows_array(grasps, "candidate", (), np.float64, where).astype(np.int64),
        region=rows_array(grasps, "region", (), np.float64, where, default=-1).astype(np.int64),
        contacts=rows_array(grasps, "contacts", (2, 3), np.float64, where),
        normals=rows_array(grasps, "normals", (2, 3), np.float64, where),
        width=width, T_part_tcp=T.reshape(M, 4, 4),
        roll=rows_array(grasps, "roll", (), np.float64, where),
        status=status,
        score=np.array([np.nan if (s := g.get("score")) is None else s for g in grasps], dtype=np.float64)
        if M else np.full(M, np.nan),
        rank=np.array([-1 if (r := g.get("rank")) is None else r for g in grasps], dtype=np.int64)
        if schema == PLAN_SCHEMA else np.full(M, -1, dtype=np.int64),
        reason=rows_array(grasps, "reason", (), object, where, default="") if M else np.zeros(0, dtype=object),
        id_values=id_values,
        **parse_quality_sim(grasps, where),
    )
    check_grasp_values(table.width, table.score, table.normals, where)
    listed = table.ids
    rejected = None
    if compact:
        table, rejected = _join_compact(table, doc, where)
    p = doc["part"]
    part = PartRecord(path=str(p["path"]), sha256=str(p["sha256"]), scale_to_m=float(p["scale_to_m"]),
                      triangles=int(p["triangles"]),
                      T_world_part=check_poses(p["T_world_part"], f"{where}: part.T_world_part"))
    if not (math.isfinite(part.scale_to_m) and 0 < part.scale_to_m <= 1e3):
        raise InputError(f"{where}: part.scale_to_m must be a positive scale, got {part.scale_to_m!r}")
    gripper = gripper_from_json(doc["gripper"], where=f"{where}: gripper")
    cell = Cell.from_json({k: v for k, v in doc["cell"].items() if k != "part_pose"}
                          if isinstance(doc["cell"], dict) else doc["cell"])
    cp, gp, pp = _params_from_doc(doc, where)
    robot: Robot | None = None
    motions: dict[int, Motion] = {}
    if schema == PLAN_SCHEMA:
        from ..robot.description import robot_from_json  # Pinocchio loads only when a plan is read

        robot = robot_from_json(doc["robot"], where=f"{where}: robot")
        motions = {int(listed[i]): m for i, m in _motions(grasps, status, robot, where).items()}  # by grasp id
        rows = {int(table.index_of(i)): m for i, m in motions.items()}  # type: ignore[arg-type]
        check_fk(robot, gripper, part.T_world_part, table.T_part_tcp, rows, where, width=table.width,
                 ids=table.ids)
    counts = {k: v for k, v in (doc.get("counts") or {}).items() if k in ("candidates", "posed_candidates", "poses",
                                                                           "regions")}
    timing = {str(k): float(v) for k, v in (doc.get("timing_s") or {}).items()
              if isinstance(v, (int, float)) and not isinstance(v, bool)}
    return PlanResult(part=part, gripper=gripper, cell=cell, robot=robot, grasps=table, motions=motions,
                      params=Params(cp, gp, pp), counts_stage=counts, timing_s=timing,
                      part_pose_source=str((doc.get("cell") or {}).get("part_pose", "stable_pose")), part_mesh=part_mesh,
                      mass=parse_mass_record(p, where), rejected=rejected)


def _join_compact(table: GraspTable, doc: dict[str, Any], where: str) -> tuple[GraspTable, RejectedCounts]:
    """The grasps of a compact plan's list and ``untried`` block in one table, and its rejected
    counts; InputError for a malformed block or an id in both."""
    untried = untried_from_json(doc["untried"], where)
    check_grasp_values(untried.width, untried.score, untried.normals, where, what="untried")
    try:
        joined = join_tables(table, untried)
    except ValueError:
        raise InputError(f"{where}: a grasp id is both in $.grasps and in $.untried.id; each grasp is listed once") from None
    if joined.id_values is not None and (joined.id_values[0] < 0 or joined.id_values[-1] >= 2**53):
        raise InputError(f"{where}: $.untried.id: grasp ids must be non-negative integers")
    return joined, RejectedCounts.from_json(doc["rejected"], where)


def _validate(doc: dict[str, Any], schema: str, where: str, picked: list[int] | None = None) -> None:
    try:
        validate(doc, schema)
    except InputError as exc:
        msg = str(exc)
        if picked is not None:  # name the grasp in the file, not its place in the sample
            msg = re.sub(r"\$\.grasps\[(\d+)\]", lambda m: f"$.grasps[{picked[int(m.group(1))]}]", msg)
        raise InputError(f"{where}: {msg}") from None
    except RecursionError:
        raise InputError(f"{where}: JSON nested too deeply; not a grasplan result") from None


def _params_from_doc(doc: dict[str, Any], where: str) -> tuple[CandidateParams, GraspParams, PlanParams]:
    prm = doc.get("params") or {}
    try:
        cp = CandidateParams.from_json({k: v for k, v in prm.items() if k in {f.name for f in fields(CandidateParams)}})
        gp = GraspParams.from_json({k: v for k, v in prm.items() if k in {f.name for f in fields(GraspParams)}})
        pp = PlanParams.from_json(doc.get("plan_params") or {})
    except (InputError, TypeError) as exc:
        raise InputError(f"{where}: params: {exc}") from None
    return cp, gp, pp


def _motions(grasps: list[Any], status: np.ndarray, robot: Robot, where: str) -> dict[int, Motion]:
    return {i: motion_from_json(grasps[i], robot, f"{where}: planned grasp {i}")
            for i in np.flatnonzero(status == Status.PLANNED.value).tolist()}


def motion_from_json(g: Any, robot: Robot, where: str) -> Motion:
    """The :class:`Motion` of one planned grasp (a plan's grasp, a picks file's pick), checked:
    numeric ``q_grasp``, ``q_pregrasp``, ``path`` (>= 2 rows) of the robot's joints, all finite and
    within its limits (1e-6 rad), ``pregrasp_index`` an index into the path, ``path[0]`` at the
    robot's ``q_home``, ``q_pregrasp`` and ``q_grasp`` the path's rows (1e-6 rad), segments and
    gripper events as :func:`_motion_extras` checks them. InputError naming ``where`` and the field."""
    n = robot.nq
    if not isinstance(g, dict):
        raise InputError(f"{where}: expected an object")
    try:
        path = np.asarray(g["path"], dtype=np.float64)
        qg = np.asarray(g["q_grasp"], dtype=np.float64)
        qp = np.asarray(g["q_pregrasp"], dtype=np.float64)
        k = g["pregrasp_index"]
    except (KeyError, TypeError, ValueError, OverflowError):
        raise InputError(f"{where} needs numeric q_grasp, q_pregrasp, path and pregrasp_index") from None
    if path.ndim != 2 or path.shape[1] != n or len(path) < 2 or qg.shape != (n,) or qp.shape != (n,):
        raise InputError(f"{where}: joint vectors must have the robot's {n} joints "
                         f"({', '.join(robot.joint_names)}) and the path >= 2 of them")
    for name, a in (("path", path), ("q_grasp", qg), ("q_pregrasp", qp)):
        if not np.all(np.isfinite(a)):
            raise InputError(f"{where}: {name}: joint values must be finite numbers")
        if not np.all(robot.within_limits(a, tol=1e-6)):
            bad = np.argwhere(~((a >= robot.lower - 1e-6) & (a <= robot.upper + 1e-6)))[0]
            j = int(bad[-1])
            raise InputError(f"{where}: {name}: joint {robot.joint_names[j]} = {float(a[tuple(bad)]):.6g} rad leaves the "
                             f"joint limits of robot {robot.name!r} ([{robot.lower[j]:.6g}, {robot.upper[j]:.6g}] rad)")
    if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < len(path):
        raise InputError(f"{where}: pregrasp_index must be an index into its path")
    segments, events, T_place, T_tcp_part = _motion_extras(g, len(path), k, where)
    m = Motion(q_grasp=qg, q_pregrasp=qp, path=path, pregrasp_index=int(k), segments=segments, gripper=events,
               T_world_part_place=T_place, T_tcp_part=T_tcp_part)
    gi = m.grasp_index
    for a_name, a, b_name, b in (("path[0]", path[0], "q_home", robot.q_home),
                                 ("path[pregrasp_index]", path[k], "q_pregrasp", qp),
                                 (f"path[{gi}] (the end of the approach)", path[gi], "q_grasp", qg)):
        if np.max(np.abs(a - b)) > 1e-6:
            raise InputError(f"{where}: {a_name} differs from {b_name} by {np.max(np.abs(a - b)):.3g} rad; the file "
                             "is inconsistent")
    return m


def _index(v: Any, k: int) -> int | None:
    return int(v) if isinstance(v, int) and not isinstance(v, bool) and 0 <= v < k else None


def _motion_extras(g: dict[str, Any], k: int, pregrasp_index: int, where: str) -> tuple[
        tuple[tuple[str, int, int], ...], tuple[GripperEvent, ...], np.ndarray | None, np.ndarray | None]:
    """Segments, gripper events and the place / attached-part transforms of one planned grasp,
    validated: labels in their order, consecutive inclusive ranges covering the path, the approach
    starting at ``pregrasp_index``, a ``close`` event at the end of the approach exactly when there
    is a lift, an ``open`` event at the end of the descent exactly when there is a place."""
    segs_in = g.get("segments")
    ev_in = g.get("gripper", [])
    if segs_in is None or segs_in == []:
        segs_in = [{"label": "transit", "start": 0, "end": pregrasp_index},
                   {"label": "approach", "start": pregrasp_index, "end": k - 1}]
        explicit = False
    else:
        explicit = True
    if not isinstance(segs_in, list) or not all(isinstance(s, dict) for s in segs_in):
        raise InputError(f"{where}: segments must be a list of {{label, start, end}}")
    labels = tuple(s.get("label") for s in segs_in)
    if labels not in SEGMENT_SEQUENCES:
        raise InputError(f"{where}: segment labels {list(labels)!s:.120} are not one of "
                         f"{' | '.join('/'.join(q) for q in SEGMENT_SEQUENCES)}")
    segs = []
    prev_end = 0
    for s in segs_in:
        a, b = _index(s.get("start"), k), _index(s.get("end"), k)
        if a is None or b is None or b <= a:
            raise InputError(f"{where}: segment {s.get('label')!r}: start and end must be path rows 0..{k - 1} "
                             "with end > start")
        if a != prev_end:
            raise InputError(f"{where}: segment {s.get('label')!r} starts at row {a}, not where the previous one "
                             f"ends ({prev_end}); segments must be consecutive")
        segs.append((str(s["label"]), a, b))
        prev_end = b
    if prev_end != k - 1:
        raise InputError(f"{where}: the last segment ends at row {prev_end}, not at the path's last row {k - 1}")
    if segs[1][1] != pregrasp_index:
        raise InputError(f"{where}: the approach segment starts at row {segs[1][1]}, not at pregrasp_index "
                         f"{pregrasp_index}")
    if not isinstance(ev_in, list) or not all(isinstance(e, dict) for e in ev_in):
        raise InputError(f"{where}: gripper must be a list of {{index, action, width}}")
    events = []
    for e in ev_in:
        idx, act, w = _index(e.get("index"), k), e.get("action"), e.get("width")
        if idx is None or act not in GRIPPER_ACTIONS or isinstance(w, bool) or not isinstance(w, (int, float)) \
                or not (math.isfinite(w) and 0 <= w <= 10):
            raise InputError(f"{where}: gripper event {str(e)[:80]}: needs index (a path row), action "
                             f"({' | '.join(GRIPPER_ACTIONS)}) and width in [0, 10] m")
        events.append(GripperEvent(index=idx, action=str(act), width=float(w)))
    bounds = {lab: (a, b) for lab, a, b in segs}
    expected = []
    if "lift" in bounds:
        expected.append(("close", bounds["approach"][1]))
    if "descend" in bounds:
        expected.append(("open", bounds["descend"][1]))
    got = [(e.action, e.index) for e in events]
    if got != expected:
        want = ", ".join(f"{a} at row {r}" for a, r in expected) or "none"
        raise InputError(f"{where}: gripper events {got!s:.120} must be at the segment boundaries: {want}")
    T_place = T_tcp = None
    if "T_tcp_part" in g or "lift" in bounds:
        if "T_tcp_part" not in g:
            raise InputError(f"{where}: a motion with a lift needs T_tcp_part (the part in the jaws)")
        T_tcp = check_poses(g["T_tcp_part"], f"{where}: T_tcp_part")
    if "T_world_part_place" in g or "descend" in bounds:
        if "T_world_part_place" not in g or "descend" not in bounds:
            raise InputError(f"{where}: T_world_part_place and the transfer/descend/retreat segments go together")
        T_place = check_poses(g["T_world_part_place"], f"{where}: T_world_part_place")
    return (tuple(segs) if explicit else ()), tuple(events), T_place, T_tcp


#: FK check tolerances (m, rad): FK(q_grasp) @ T_flange_tcp must be the recorded grasp TCP
FK_POS_TOL = 1e-3
FK_ROT_TOL = 1e-2


def check_fk(robot: Robot, gripper: Gripper, T_world_part: np.ndarray, T_part_tcp: np.ndarray,
             motions: dict[int, Motion], where: str, *, width: np.ndarray | None = None,
             ids: np.ndarray | None = None) -> None:
    """Each planned grasp re-checked by forward kinematics: ``FK(q_grasp) @ T_flange_tcp`` is its
    recorded TCP, the attached part is the grasp's inverse, and at the open event the part is at
    ``T_world_part_place`` (within :data:`FK_POS_TOL` / :data:`FK_ROT_TOL`); InputError otherwise.
    For a gripper whose TCP moves with the opening (``moving_tcp``) the TCPs are first taken to the
    frame ``T_flange_tcp`` is given in, at each grasp's ``width`` (m). ``motions`` are keyed by row
    of ``T_part_tcp``; ``ids`` (per row) name the grasps in messages (default: the rows)."""
    if not motions:
        return
    if gripper.moving_tcp and width is not None:
        T_part_tcp = np.asarray(T_part_tcp, dtype=np.float64) @ gripper.T_tcp_gripper(np.asarray(width, dtype=np.float64))
    rows = np.fromiter(motions, dtype=np.int64)
    name = rows if ids is None else np.asarray(ids)[rows]  # the grasp ids messages name
    q = np.stack([motions[i].q_grasp for i in rows])
    T_fk = robot.fk_batch(q) @ gripper.T_flange_tcp
    T_rec = T_world_part @ T_part_tcp[rows]
    dp = np.linalg.norm(T_fk[:, :3, 3] - T_rec[:, :3, 3], axis=1)
    cos = np.clip((np.einsum("nij,nij->n", T_fk[:, :3, :3], T_rec[:, :3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    dr = np.arccos(cos)
    bad = np.flatnonzero(~((dp <= FK_POS_TOL) & (dr <= FK_ROT_TOL)))
    if len(bad):
        b = int(bad[0])
        raise InputError(f"{where}: planned grasp {int(name[b])}: FK(q_grasp) is {dp[b] * 1000:.1f} mm / {dr[b]:.3f} rad "
                         f"from its recorded TCP with robot {robot.name!r}; the plan was made with another robot or "
                         "gripper, or was edited")
    # the part in the jaws is the grasp's own inverse, and the jaws open where the part is placed
    for k, i in enumerate(rows.tolist()):
        m, gid = motions[i], int(name[k])
        if m.T_tcp_part is None:
            continue
        d_att = pose_error(m.T_tcp_part @ T_part_tcp[i], np.eye(4))
        if not (d_att[0] <= FK_POS_TOL and d_att[1] <= FK_ROT_TOL):
            raise InputError(f"{where}: planned grasp {gid}: T_tcp_part is not the inverse of its T_part_tcp "
                             f"({d_att[0] * 1000:.1f} mm / {d_att[1]:.3f} rad); the plan file was edited")
        if m.T_world_part_place is not None:
            opened = m.event("open")
            if opened is None:
                raise InputError(f"{where}: planned grasp {gid}: a placed part needs an open gripper event")
            o = opened.index
            T_part = robot.fk_batch(m.path[o][None])[0] @ gripper.T_flange_tcp @ m.T_tcp_part
            d_pl = pose_error(T_part, m.T_world_part_place)
            if not (d_pl[0] <= FK_POS_TOL and d_pl[1] <= FK_ROT_TOL):
                raise InputError(f"{where}: planned grasp {gid}: at the open event (row {o}) the part is "
                                 f"{d_pl[0] * 1000:.1f} mm / {d_pl[1]:.3f} rad from T_world_part_place with robot "
                                 f"{robot.name!r}; the plan was made with another robot or gripper, or was edited")


def load_result(source: str | os.PathLike[str] | dict[str, Any] | PlanResult, *,
                part: str | os.PathLike[str] | None = None,
                load_mesh: bool = False, allow_other_part: bool = False, verify_part: bool = False) -> PlanResult:
    """A :class:`PlanResult` from a grasps/plan file (or a parsed document, or a result).

    ``load_mesh``: also load the part's mesh (from ``part`` or the recorded path, relative paths
    also looked up next to the file) at the recorded scale; its sha256 must match unless
    ``allow_other_part``. ``verify_part``: load it only when it can be found (an export needs no
    mesh). A loaded mesh is checked against the grasps (:func:`check_contacts_on_part`): a plan
    whose ``part`` block was re-pointed to another mesh is refused."""
    if isinstance(source, PlanResult):
        res = source
    elif isinstance(source, dict):
        res = result_from_document(source, where="document")
    else:
        res = replace(result_from_document(read_document(source), where=str(source)), origin=Path(source).resolve())
    where = str(source) if isinstance(source, (str, os.PathLike)) else "the result"
    if verify_part and not load_mesh and not allow_other_part and _part_findable(res, part):
        load_mesh = True
    if load_mesh and (res.part_mesh is None or part is not None):
        res = replace(res, part_mesh=res.mesh(part, allow_other_part=allow_other_part))
        if not allow_other_part:
            check_contacts_on_part(res, where)
    return res


def _part_findable(res: PlanResult, part: str | os.PathLike[str] | None) -> bool:
    """Whether the part's mesh is where :meth:`PlanResult.mesh` looks (``part``, the recorded
    path, the recorded name next to the result file)."""
    if part is not None:
        return True
    places = [Path(res.part.path)] if res.part.path else []
    if res.origin is not None and res.part.path:
        places.append(res.origin.parent / Path(res.part.path).name)
    for p in places:
        try:
            if p.is_file():
                return True
        except (OSError, ValueError):
            continue
    return False


#: contacts checked per result (the planned grasps' first, then evenly spaced others)
CONTACT_CHECKS = 256
#: a contact lies on the part when within this fraction of the part's diagonal (or 10 um) of it
CONTACT_TOL_REL, CONTACT_TOL_ABS = 1e-3, 1e-5


def check_contacts_on_part(res: PlanResult, where: str) -> None:
    """InputError unless the grasps' contact points lie on the part's mesh (within
    :data:`CONTACT_TOL_REL` of its diagonal): a result whose ``part`` block (path and sha256) names
    another mesh than the one its grasps were computed on. Cheap: at most :data:`CONTACT_CHECKS`
    points, each a BVH distance query (coal)."""
    import coal

    from ..cell.shapes import bvh

    mesh = res.part_mesh
    t = res.grasps
    if mesh is None or len(t) == 0:
        return
    planned = np.flatnonzero(t.status.astype(str) == Status.PLANNED.value)
    spread = np.unique(np.linspace(0, len(t) - 1, min(len(t), CONTACT_CHECKS)).astype(np.int64))
    rows = np.concatenate([planned, spread])
    _, first = np.unique(rows, return_index=True)
    rows = rows[np.sort(first)][:CONTACT_CHECKS]
    pts = np.asarray(t.contacts, dtype=np.float64)[rows].reshape(-1, 3)
    v, f = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces)
    tol = max(CONTACT_TOL_ABS, CONTACT_TOL_REL * float(np.linalg.norm(np.ptp(v, axis=0))))
    model, probe = bvh(v, f), coal.Sphere(1e-9)
    req, out, at = coal.DistanceRequest(), coal.DistanceResult(), coal.Transform3s()
    for k, p in enumerate(pts):
        out.clear()
        d = coal.distance(probe, coal.Transform3s(np.eye(3), p), model, at, req, out)
        if d > tol:
            gid = int(t.ids[rows[k // 2]])
            raise InputError(f"{where}: grasp {gid}'s contact lies {d * 1000:.3g} mm from the part "
                             f"{show_path(res.part.path)} (tolerance {tol * 1000:.3g} mm): the result's part block "
                             "names another mesh than the one it was planned for; give the part it was made from")
