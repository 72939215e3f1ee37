"""Result types of the grasps and plan stages, and the one loader that turns a file into them.

:class:`PlanResult` is what :func:`grasplan.plan` returns, what ``grasplan.grasps.compute_grasps``
results become (:meth:`GraspResult.to_result`), and what :func:`load_result` reads back from a
``grasplan.grasps/1`` or ``grasplan.plan/1`` file. Exports and the viewer take a ``PlanResult``;
nothing downstream re-parses JSON or re-resolves a gripper, cell or robot by name: the documents
embed their resolved definitions (``gripper.definition``, the whole ``cell``, ``robot.source``)
and :func:`load_result` rebuilds the models from them.

Per-grasp data are arrays (:class:`GraspTable`; TLess20 has ~1e5 poses), indexed by grasp id.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError
from .params import CandidateParams, GraspParams, PlanParams
from .quality_json import (
    CONTACT_TYPES,
    parse_mass_record,
    parse_quality_sim,
    quality_entries,
    sim_entries,
)
from .status import GRASP_STATUSES, PLAN_STATUSES, Status
from .transforms import check_transform, pose_error

GRASPS_SCHEMA = "grasplan.grasps/1"
PLAN_SCHEMA = "grasplan.plan/1"
SCHEMAS = (GRASPS_SCHEMA, PLAN_SCHEMA)


@dataclass(frozen=True)
class PartRecord:
    """The part a result was computed for: its file, identity and pose in the cell."""

    path: str
    sha256: str
    scale_to_m: float
    triangles: int
    T_world_part: np.ndarray

    def to_json(self) -> dict:
        return {"path": self.path, "sha256": self.sha256, "scale_to_m": float(self.scale_to_m),
                "triangles": int(self.triangles), "T_world_part": np.asarray(self.T_world_part).tolist()}

    @property
    def label(self) -> str:
        """The part's file name (for headers; exporters still reduce it to a safe character set)."""
        return Path(self.path).name if self.path else "(in memory)"


@dataclass(frozen=True)
class GraspTable:
    """Per-grasp arrays (M grasps, id = index). Lengths m, angles rad.

    candidate (M,) int64, region (M,) int64 (-1: none), contacts / normals (M, 2, 3),
    width (M,), T_part_tcp (M, 4, 4), roll (M,), status (M,) object (str), score (M,) float64 (NaN:
    none), rank (M,) int64 (-1: none), reason (M,) object (str; "" in grasps files)."""

    candidate: np.ndarray
    region: np.ndarray
    contacts: np.ndarray
    normals: np.ndarray
    width: np.ndarray
    T_part_tcp: np.ndarray
    roll: np.ndarray
    status: np.ndarray
    score: np.ndarray
    rank: np.ndarray
    reason: np.ndarray
    id_values: np.ndarray | None = None  #: grasp ids when not 0..M-1 (a grasps file written with --only-ok)
    # grasp quality (issue 11, grasplan.quality; None: not computed): contact_area (M, 2) m^2 and
    # contact_type (M, 2) int8 into grasplan.quality_json.CONTACT_TYPES per jaw, gravity_margin (M,),
    # epsilon (M,); NaN / -1 for grasps without quality (collisions)
    contact_area: np.ndarray | None = None
    contact_type: np.ndarray | None = None
    gravity_margin: np.ndarray | None = None
    epsilon: np.ndarray | None = None
    # lift-and-shake simulation (grasplan.simulate; None: none): sim_success (M,) int8 (1 held,
    # 0 slipped, -1 not simulated), sim_slip_m (M,) m, sim_turn_deg (M,) deg (NaN: not simulated)
    sim_success: np.ndarray | None = None
    sim_slip_m: np.ndarray | None = None
    sim_turn_deg: np.ndarray | None = None

    def __len__(self) -> int:
        return int(len(self.width))

    @property
    def ids(self) -> np.ndarray:
        """(M,) grasp ids: 0..M-1, or the ids a filtered file kept (strictly increasing)."""
        return self.id_values if self.id_values is not None else np.arange(len(self), dtype=np.int64)

    def index_of(self, grasp_id: int) -> int | None:
        """Row of grasp ``grasp_id``, None when there is none."""
        if self.id_values is None:
            return int(grasp_id) if 0 <= grasp_id < len(self) else None
        k = int(np.searchsorted(self.id_values, grasp_id))
        return k if k < len(self) and self.id_values[k] == grasp_id else None

    def with_plan(self, status, score, rank, reason) -> "GraspTable":
        return replace(self, status=status, score=score, rank=rank, reason=reason)


#: segment labels of a planned motion, in path order (see :class:`Motion`)
SEGMENT_LABELS: tuple[str, ...] = ("transit", "approach", "lift", "transfer", "descend", "retreat")
#: the label sequences a motion may have: pick only (old files), pick + lift, pick + lift + place
SEGMENT_SEQUENCES: tuple[tuple[str, ...], ...] = (SEGMENT_LABELS[:2], SEGMENT_LABELS[:3], SEGMENT_LABELS)
#: gripper event actions
GRIPPER_ACTIONS: tuple[str, ...] = ("close", "open")


@dataclass(frozen=True)
class GripperEvent:
    """The jaws are commanded to ``width`` (m) at path row ``index``: ``close`` at the grasp (width =
    the contact width), ``open`` at the place (width = the pre-grasp opening)."""

    index: int
    action: str
    width: float

    def to_json(self) -> dict:
        return {"index": int(self.index), "action": str(self.action), "width": float(self.width)}


@dataclass(frozen=True)
class Motion:
    """A planned grasp's joint motion (rad), ``path`` (k, n) with labelled segments.

    ``segments``: ``(label, start, end)`` inclusive path rows; consecutive segments share their
    boundary row. Labels in order: ``transit`` (q_home -> q_pregrasp at ``pregrasp_index``),
    ``approach`` (-> q_grasp, straight, jaws at the pre-grasp opening), ``lift`` (the TCP straight
    along the cell's retreat direction by its retreat distance, part attached), and with a place
    ``transfer`` (-> above the place, attached), ``descend`` (straight down to the place, attached),
    ``retreat`` (straight back along the TCP -z by ``backoff``, part released at the place).
    ``gripper``: the ``close`` event at the grasp row and the ``open`` event at the place row.
    ``T_tcp_part``: the part in the jaws while attached (= inv(T_part_tcp)); ``T_world_part_place``:
    the part's pose after release. Old files (``segments`` empty) have only transit + approach.
    """

    q_grasp: np.ndarray
    q_pregrasp: np.ndarray
    path: np.ndarray
    pregrasp_index: int
    segments: tuple[tuple[str, int, int], ...] = ()
    gripper: tuple[GripperEvent, ...] = ()
    T_world_part_place: np.ndarray | None = None
    T_tcp_part: np.ndarray | None = None

    def segment_list(self) -> list[tuple[str, int, int]]:
        """The effective segments: ``segments``, or transit + approach for a motion without them."""
        if self.segments:
            return [(str(a), int(s), int(e)) for a, s, e in self.segments]
        k = len(self.path)
        return [("transit", 0, int(self.pregrasp_index)), ("approach", int(self.pregrasp_index), k - 1)]

    def segment(self, label: str) -> tuple[int, int] | None:
        """``(start, end)`` rows of segment ``label``, None when the motion has none."""
        for a, s, e in self.segment_list():
            if a == label:
                return s, e
        return None

    @property
    def grasp_index(self) -> int:
        """Row of ``q_grasp`` in ``path`` (the end of the approach)."""
        return self.segment("approach")[1]

    def event(self, action: str) -> GripperEvent | None:
        """The first gripper event ``action`` ("close" / "open"), None when there is none."""
        return next((g for g in self.gripper if g.action == action), None)

    def attached_range(self) -> tuple[int, int]:
        """``(close row, open row)``: the rows between which the part rides in the jaws. Without a
        close event (old files) the close row is the grasp row; without an open event the open row
        is the path's last row."""
        c, o = self.event("close"), self.event("open")
        return (c.index if c is not None else self.grasp_index), (o.index if o is not None else len(self.path) - 1)

    def to_json(self) -> dict:
        d = {"q_grasp": np.asarray(self.q_grasp).tolist(), "q_pregrasp": np.asarray(self.q_pregrasp).tolist(),
             "path": np.asarray(self.path).tolist(), "pregrasp_index": int(self.pregrasp_index),
             "segments": [{"label": a, "start": s, "end": e} for a, s, e in self.segment_list()],
             "gripper": [g.to_json() for g in self.gripper]}
        if self.T_tcp_part is not None:
            d["T_tcp_part"] = np.asarray(self.T_tcp_part, dtype=np.float64).tolist()
        if self.T_world_part_place is not None:
            d["T_world_part_place"] = np.asarray(self.T_world_part_place, dtype=np.float64).tolist()
        return d


@dataclass(frozen=True)
class GraspView:
    """One grasp of a result, as exporters read it."""

    id: int
    T_part_tcp: np.ndarray
    T_world_tcp: np.ndarray
    width: float
    status: str
    score: float | None
    rank: int | None
    motion: Motion | None


@dataclass(frozen=True)
class Params:
    """The three parameter objects a result was made with."""

    candidates: CandidateParams = field(default_factory=CandidateParams)
    grasps: GraspParams = field(default_factory=GraspParams)
    planning: PlanParams = field(default_factory=PlanParams)


@dataclass(frozen=True, eq=False)
class PlanResult:
    """A grasps or plan result (``robot`` is None for a grasps result).

    part : PartRecord; gripper : Gripper; cell : Cell; robot : Robot or None;
    grasps : GraspTable; motions : {grasp id: Motion} for the planned grasps;
    params : Params; counts : stage counts (candidates, poses, ...); timing_s : seconds per stage;
    part_pose_source : "stable_pose" | "given"; grasp_result : the in-memory GraspResult (None when
    loaded from a file); part_mesh : the part's trimesh in metres when known (in memory, or loaded
    by :func:`load_result` with ``load_mesh=True``).
    """

    part: PartRecord
    gripper: Any
    cell: Any
    robot: Any
    grasps: GraspTable
    motions: dict = field(default_factory=dict)
    params: Params = field(default_factory=Params)
    counts_stage: dict = field(default_factory=dict)
    timing_s: dict = field(default_factory=dict)
    part_pose_source: str = "stable_pose"
    grasp_result: Any = None
    part_mesh: Any = None
    origin: Path | None = None   #: the file this result was loaded from (relative part paths resolve next to it)
    mass: dict | None = None     #: the part's mass record (grasplan.mass.MassProperties.record), written under part

    def mesh(self, part=None, *, allow_other_part: bool = False):
        """The part's trimesh (metres): in memory, else loaded from ``part`` or the recorded path
        (sha256-checked)."""
        if self.part_mesh is not None and part is None:
            return self.part_mesh
        dirs = (self.origin.parent,) if self.origin is not None else ()
        return load_part_mesh(self.part, part=part, search_dirs=dirs, allow_other_part=allow_other_part)

    # ---- views ------------------------------------------------------------------------------
    @property
    def schema(self) -> str:
        return PLAN_SCHEMA if self.robot is not None else GRASPS_SCHEMA

    @property
    def T_world_part(self) -> np.ndarray:
        return self.part.T_world_part

    @property
    def retreat_distance(self) -> float:
        """Straight retreat after closing, m: back along the approach, the back-off."""
        return float(self.params.planning.backoff)

    def counts(self) -> dict:
        """Grasps per status (every status of this result's stage) and ``grasps`` (the total)."""
        names = PLAN_STATUSES if self.robot is not None else GRASP_STATUSES
        u, c = np.unique(self.grasps.status.astype(str), return_counts=True)
        got = dict(zip(u.tolist(), c.tolist()))
        out = {s: int(got.get(s, 0)) for s in names}
        out["grasps"] = len(self.grasps)
        return out

    def planned_ids(self) -> list[int]:
        """Ids of the planned grasps, best first (rank, then id)."""
        ids = np.flatnonzero(self.grasps.status.astype(str) == Status.PLANNED.value)
        rank = self.grasps.rank[ids]
        order = np.lexsort((ids, np.where(rank < 0, np.iinfo(np.int64).max, rank)))
        return ids[order].tolist()

    def grasp(self, grasp_id: int) -> GraspView:
        t = self.grasps
        i = t.index_of(int(grasp_id))
        if i is None:
            raise InputError(f"unknown grasp id {grasp_id}; the result has ids {int(t.ids[0])}..{int(t.ids[-1])}"
                             if len(t) else f"unknown grasp id {grasp_id}; the result has no grasps")
        sc = float(t.score[i])
        return GraspView(id=int(t.ids[i]), T_part_tcp=t.T_part_tcp[i], T_world_tcp=self.T_world_part @ t.T_part_tcp[i],
                         width=float(t.width[i]), status=str(t.status[i]),
                         score=None if math.isnan(sc) else sc, rank=None if t.rank[i] < 0 else int(t.rank[i]),
                         motion=self.motions.get(i))

    def select(self, grasp_id: int | None = None) -> GraspView:
        """The planned grasp ``grasp_id``, or the best planned one; InputError saying what exists."""
        ids = self.planned_ids()
        if self.robot is None:
            raise InputError("this is a grasps result (no robot, no motion); run `grasplan plan PART --robot NAME` "
                             "to get a plan to export")
        if grasp_id is None:
            if not ids:
                c = {k: v for k, v in self.counts().items() if v and k != "grasps"}
                summary = ", ".join(f"{k}: {v}" for k, v in sorted(c.items())) or "no grasps at all"
                raise InputError(f"the plan has no planned grasp to export ({summary}); try `grasplan plan` "
                                 "with a larger --top or another gripper/cell")
            return self.grasp(ids[0])
        if isinstance(grasp_id, bool) or not isinstance(grasp_id, (int, np.integer)) \
                or self.grasps.index_of(int(grasp_id)) is None:
            shown = ", ".join(map(str, ids[:50])) + (" ..." if len(ids) > 50 else "")
            raise InputError(f"unknown grasp id {grasp_id}; planned grasps: {shown or '(none)'}")
        g = self.grasp(int(grasp_id))
        if g.motion is None:
            shown = ", ".join(map(str, ids[:20])) + (" ..." if len(ids) > 20 else "")
            raise InputError(f"grasp {grasp_id} is not planned (status: {g.status}); planned grasps: {shown or '(none)'}")
        return g

    def entry(self, i: int) -> dict:
        """Grasp ``i`` as its JSON dict."""
        return self._entries([int(i)])[0]

    def planned(self) -> list[dict]:
        """Planned grasps as JSON dicts, best first."""
        return self._entries(self.planned_ids())

    # ---- JSON -------------------------------------------------------------------------------
    def _entries(self, ids) -> list[dict]:
        t = self.grasps
        ids = np.asarray(ids, dtype=np.int64)
        r = lambda a: np.round(a, 10).tolist()  # noqa: E731 - 1e-10 m / rad: keeps the files small
        contacts, normals, width = r(t.contacts[ids]), r(t.normals[ids]), r(t.width[ids])
        T, roll = r(t.T_part_tcp[ids]), r(t.roll[ids])
        cand, region = t.candidate[ids].tolist(), t.region[ids].tolist()
        status = t.status[ids].astype(str).tolist()
        plan = self.robot is not None
        score, rank, reason = t.score[ids].tolist(), t.rank[ids].tolist(), t.reason[ids].tolist()
        gid = t.ids[ids].tolist()
        quality, sim = quality_entries(t, ids), sim_entries(t, ids)
        out = []
        for k, i in enumerate(ids.tolist()):
            e = {"id": gid[k], "candidate": cand[k], "region": region[k], "contacts": contacts[k], "normals": normals[k],
                 "width": width[k], "T_part_tcp": T[k], "roll": roll[k], "status": status[k]}
            if plan or score[k] == score[k]:
                e["score"] = None if score[k] != score[k] else score[k]
            if quality is not None:
                e["quality"] = quality[k]
            if sim is not None and sim[k] is not None:
                e["sim"] = sim[k]
            if plan:
                e["rank"] = None if rank[k] < 0 else rank[k]
                e["reason"] = reason[k]
                m = self.motions.get(i)
                if m is not None:
                    e.update(m.to_json())
            out.append(e)
        return out

    def to_json(self, *, only_ok: bool = False) -> dict:
        """``grasplan.grasps/1`` (no robot) or ``grasplan.plan/1``; self-contained: the gripper's
        resolved shapes, the whole cell and the robot's source are embedded."""
        doc, ids = self._document_head(only_ok)
        doc["grasps"] = self._entries(ids)
        return doc

    def _document_head(self, only_ok: bool) -> tuple[dict, np.ndarray]:
        """The document without its ``grasps`` list (which comes last), and the rows it lists."""
        part = self.part.to_json()
        if self.mass:
            part.update(self.mass)
        cell = self.cell.to_json()
        cell["part_pose"] = self.part_pose_source
        params = self.params.candidates.to_json()
        params.update(self.params.grasps.to_json())
        doc = {"schema": self.schema, "part": part, "gripper": self.gripper.to_json(definition=True),
               "cell": cell, "params": params}
        counts = dict(self.counts_stage)
        st = self.grasps.status.astype(str)
        if self.robot is None:
            counts.update({s: int(np.count_nonzero(st == s)) for s in GRASP_STATUSES})
        else:
            counts.pop("ok", None)
            counts["collision_free"] = int(np.count_nonzero((st != Status.COLLISION_PART.value)
                                                            & (st != Status.COLLISION_TABLE.value)
                                                            & (st != Status.COLLISION_OBSTACLE.value)))
            c = self.counts()
            c.pop("grasps")
            counts.update(c)
            doc["robot"] = self.robot.to_json(source=True)
            doc["plan_params"] = self.params.planning.to_json()
        doc["counts"] = counts
        doc["timing_s"] = {k: float(v) for k, v in self.timing_s.items()}
        ids = np.flatnonzero(st == "ok") if only_ok else np.arange(len(self.grasps))
        if only_ok:
            doc["only_ok"] = True
        return doc, ids

    def write(self, path, *, only_ok: bool = False, indent: int | None = None, extra: dict | None = None) -> Path:
        """Write the result's JSON atomically: the text of ``json.dumps(to_json(only_ok))`` (with
        ``extra``'s keys appended after ``grasps``), streamed in chunks by :func:`_stream_document`
        (``indent`` given: through the dict)."""
        from .io import write_atomic_chunks, write_json

        chunks = None if indent is not None else _stream_document(self, only_ok=only_ok, extra=extra)
        if chunks is None:
            doc = self.to_json(only_ok=only_ok)
            doc.update(extra or {})
            return write_json(path, doc, indent=indent)
        return write_atomic_chunks(path, chunks)

    def export(self, fmt: str, path, grasp_id: int | None = None, **options) -> Path:
        """Write ``fmt`` (a name in :data:`grasplan.export.FORMATS`) to ``path``."""
        from .export import write

        return write(self, fmt, path, grasp_id=grasp_id, **options)


# ------------------------------------------------------------------------------------------------
# fast writing: the text json.dumps(to_json()) gives, built column by column
# ------------------------------------------------------------------------------------------------
#: grasps serialised per chunk by :func:`_stream_document` (bounds the writer's memory)
WRITE_CHUNK = 4096


def _reprs(a) -> np.ndarray:
    """Object array (a's shape) of the text json writes for each element: ``float.__repr__`` /
    ``int.__repr__`` of the Python number ``tolist`` gives."""
    a = np.asarray(a)
    flat = a.ravel()
    if flat.dtype.kind == "f":
        flat = flat.astype(np.float64)  # tolist would give these Python floats too
    if not flat.size:
        return np.zeros(a.shape, dtype=object)
    # poses repeat few distinct numbers: format each distinct bit pattern once (bits, not values:
    # -0.0 and 0.0 are written differently)
    key = flat.view(np.int64) if flat.dtype == np.float64 else flat
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    texts = np.array(list(map(repr, flat[first].tolist())), dtype=object)
    return texts[inv.reshape(-1)].reshape(a.shape)


def _nested(cols: list, texts: np.ndarray) -> None:
    """Append to ``cols`` the pieces of the JSON lists of ``texts`` (n, *shape) row by row."""
    if texts.ndim == 1:
        cols.append(texts)
        return
    cols.append("[")
    for j in range(texts.shape[1]):
        if j:
            cols.append(", ")
        _nested(cols, texts[:, j])
    cols.append("]")


def _encoded(values: np.ndarray) -> np.ndarray:
    """Object array of the JSON text of each value, encoded once per distinct value."""
    from .io import to_json_text

    u, inv = np.unique(values, return_inverse=True)
    if not len(values):
        return np.zeros(0, dtype=object)
    return np.array([to_json_text(v) for v in u.tolist()], dtype=object)[inv.reshape(-1)]


def _masked(mask: np.ndarray):
    """``f(x)``: x (a constant or an (n,) array) where ``mask``, "" elsewhere, as an object array."""
    return lambda x: np.where(mask, x, "").astype(object)


def _join(cols: list, n: int) -> str:
    """The n rows' text: column pieces (str constants or (n,) object arrays) concatenated per row,
    rows separated by ", "."""
    merged: list = []
    for c in cols:  # adjacent constants become one piece
        if isinstance(c, str) and merged and isinstance(merged[-1], str):
            merged[-1] += c
        else:
            merged.append(c)
    merged[-1] = merged[-1] + ", " if isinstance(merged[-1], str) else merged[-1]
    P = np.empty((n, len(merged)), dtype=object)
    for j, c in enumerate(merged):
        P[:, j] = c
    return "".join(P.ravel().tolist())[:-2]


def _stream_document(res: PlanResult, *, only_ok: bool = False, extra: dict | None = None):
    """Chunks (str) whose concatenation is byte-identical to ``json.dumps(doc)`` for ``doc =
    res.to_json(only_ok)`` updated with ``extra`` (what :func:`grasplan.io.write_json` writes), the
    grasps serialised :data:`WRITE_CHUNK` at a time from the table's columns; None when the
    document must go through the dict (a value json refuses (NaN / inf), ``extra`` repeating a key),
    so that path raises exactly what it raised before."""
    from .io import to_json_text

    head, ids = res._document_head(only_ok)
    if extra and (set(extra) & (set(head) | {"grasps"})):
        return None
    t = res.grasps
    plan = res.robot is not None
    def fin(a):
        return bool(np.all(np.isfinite(a)))

    def r10(a):  # as PlanResult._entries
        return np.round(a, 10)

    def sel(a):
        return a if len(ids) == len(t) else a[ids]

    if not all(fin(r10(sel(a))) for a in (t.contacts, t.normals, t.width, t.T_part_tcp, t.roll)):
        return None
    if np.any(np.isinf(sel(t.score))):
        return None
    has_q = t.gravity_margin is not None
    if has_q:
        has = np.isfinite(sel(t.gravity_margin))
        if not (fin(sel(t.epsilon)[has]) and fin(np.round(sel(t.contact_area)[has], 12))):
            return None
        ct = sel(t.contact_type)[has]
        if ct.size and (ct.min() < -len(CONTACT_TYPES) or ct.max() >= len(CONTACT_TYPES)):
            return None
    has_s = t.sim_success is not None
    if has_s:
        on = sel(t.sim_success) >= 0
        if not (fin(sel(t.sim_slip_m)[on]) and fin(sel(t.sim_turn_deg)[on])):
            return None
    try:
        status_all = _encoded(sel(t.status).astype(str))
        reason_all = _encoded(sel(t.reason)) if plan else None
    except TypeError:  # values np.unique cannot order: not plain strings
        return None
    mkeys = np.fromiter((int(k) for k in res.motions), dtype=np.int64, count=len(res.motions)) if plan else None
    types = np.array([to_json_text(k) for k in CONTACT_TYPES], dtype=object)

    def chunks():
        text = to_json_text(head)
        yield text[:-1] + (", " if len(head) else "") + '"grasps": ['
        gid_all = t.ids
        for c0 in range(0, len(ids), WRITE_CHUNK):
            rows = ids[c0:c0 + WRITE_CHUNK]
            n = len(rows)
            sc = t.score[rows]
            nan = np.isnan(sc)
            sc_txt = np.where(nan, "null", _reprs(sc)).astype(object)
            cols: list = ['{"id": ', _reprs(gid_all[rows]), ', "candidate": ', _reprs(t.candidate[rows]),
                          ', "region": ', _reprs(t.region[rows]), ', "contacts": ']
            _nested(cols, _reprs(r10(t.contacts[rows])))
            cols.append(', "normals": ')
            _nested(cols, _reprs(r10(t.normals[rows])))
            cols += [', "width": ', _reprs(r10(t.width[rows])), ', "T_part_tcp": ']
            _nested(cols, _reprs(r10(t.T_part_tcp[rows])))
            cols += [', "roll": ', _reprs(r10(t.roll[rows])), ', "status": ', status_all[c0:c0 + n]]
            if plan:
                cols += [', "score": ', sc_txt]
            else:
                cols += [np.where(nan, "", ', "score": ').astype(object), np.where(nan, "", sc_txt).astype(object)]
            if has_q:
                h = np.isfinite(t.gravity_margin[rows])
                on_q = _masked(h)
                area = _reprs(np.round(t.contact_area[rows], 12))
                kind = types[np.where(h[:, None], t.contact_type[rows], 0).astype(np.int64)]
                cols += [', "quality": ', np.where(h, '{"score": ', "null").astype(object), on_q(sc_txt),
                         on_q(', "gravity_margin": '), on_q(_reprs(t.gravity_margin[rows])),
                         on_q(', "epsilon": '), on_q(_reprs(t.epsilon[rows])),
                         on_q(', "contact": [{"area_m2": '), on_q(area[:, 0]), on_q(', "type": '), on_q(kind[:, 0]),
                         on_q('}, {"area_m2": '), on_q(area[:, 1]), on_q(', "type": '), on_q(kind[:, 1]),
                         on_q("}]}")]
            if has_s:
                s_on = t.sim_success[rows] >= 0
                on_s = _masked(s_on)
                cols += [on_s(', "sim": {"success": '), on_s(np.where(t.sim_success[rows] != 0, "true", "false")),
                         on_s(', "slip_m": '), on_s(_reprs(t.sim_slip_m[rows])),
                         on_s(', "turn_deg": '), on_s(_reprs(t.sim_turn_deg[rows])), on_s("}")]
            if plan:
                rk = t.rank[rows]
                cols += [', "rank": ', np.where(rk < 0, "null", _reprs(rk)).astype(object),
                         ', "reason": ', reason_all[c0:c0 + n]]
                mot = np.full(n, "", dtype=object)
                for k in np.flatnonzero(np.isin(rows, mkeys)).tolist():
                    mot[k] = ", " + to_json_text(res.motions[int(rows[k])].to_json())[1:-1]
                cols.append(mot)
            cols.append("}")
            yield ("" if c0 == 0 else ", ") + _join(cols, n)
        tail = "]"
        if extra:
            tail += ", " + to_json_text(extra)[1:-1]
        yield tail + "}"

    return chunks()


# ------------------------------------------------------------------------------------------------
# loading
# ------------------------------------------------------------------------------------------------
#: documents with more grasps than this get the JSON Schema on a sample plus a vectorised check
#: of every grasp (jsonschema checks ~1000 grasps/s)
SCHEMA_SAMPLE = 50
MAX_JSON_BYTES = 2 * 1024**3


def read_document(path: str | os.PathLike) -> dict:
    """Parse a grasplan JSON file; InputError for anything that is not one."""
    import json

    p = Path(path)
    try:
        if not p.is_file():
            raise InputError(f"{p}: no such file (expected a grasplan grasps or plan JSON file)")
        if p.stat().st_size > MAX_JSON_BYTES:
            raise InputError(f"{p}: {p.stat().st_size / 1e9:.1f} GB is larger than grasplan reads ({MAX_JSON_BYTES / 1e9:.0f} GB)")
        with open(p, "rb") as f:
            doc = json.load(f)
    except OSError as exc:
        raise InputError(f"{p}: cannot read it ({exc.strerror or exc})") from None
    except RecursionError:
        raise InputError(f"{p}: JSON nested too deeply; not a grasplan result") from None
    except (UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"{p}: not a JSON file ({str(exc)[:80]}); expected a result written by grasplan") from None
    return doc


def _arr(grasps: list, key: str, shape: tuple, dtype, where: str, *, default=None) -> np.ndarray:
    try:
        if default is not None:
            vals = [g.get(key, default) if isinstance(g, dict) else None for g in grasps]
        else:
            vals = [g[key] for g in grasps]
        a = np.array(vals, dtype=dtype)
        if a.shape == (len(grasps), *shape) and (dtype is object or np.all(np.isfinite(a))):
            return a
    except (KeyError, TypeError, ValueError, OverflowError):
        pass
    for i, g in enumerate(grasps):
        try:
            v = np.asarray(g[key] if default is None else g.get(key, default), dtype=dtype)
            ok = v.shape == shape and (dtype is object or bool(np.all(np.isfinite(v))))
        except (KeyError, TypeError, ValueError, OverflowError, AttributeError):
            ok = False
        if not ok:
            gid = g.get("id") if isinstance(g, dict) else None
            raise InputError(f"{where}: grasps[{i}] (id {str(gid)[:20]}): {key!r} missing or malformed; expected "
                             f"{'a finite number' if not shape else 'finite numbers of shape ' + str(shape)}")
    raise InputError(f"{where}: grasps: {key!r} malformed")


def result_from_document(doc: Any, *, where: str = "document", part_mesh=None) -> PlanResult:
    """Validate a parsed grasps/plan document in full (schema on a sample, every grasp vectorised,
    finite numbers, rigid transforms, joint vectors of the robot's length within its limits, FK of
    each planned grasp at its recorded TCP) and rebuild the typed result."""
    from .cell import Cell
    from .gripper import gripper_from_json
    from .schemas import validate

    if not isinstance(doc, dict) or doc.get("schema") not in SCHEMAS:
        found = doc.get("schema") if isinstance(doc, dict) else type(doc).__name__
        raise InputError(f"{where}: not a grasplan grasps or plan file: schema is {str(found)[:60]!r}, expected "
                         f"{' or '.join(map(repr, SCHEMAS))}")
    schema = doc["schema"]
    grasps = doc.get("grasps")
    if not isinstance(grasps, list):
        raise InputError(f"{where}: $.grasps must be a list")
    if len(grasps) > SCHEMA_SAMPLE:
        step = max(1, len(grasps) // SCHEMA_SAMPLE)
        picked = [i for i, g in enumerate(grasps) if i % step == 0
                  or (isinstance(g, dict) and g.get("status") == "planned")]
        _validate(validate, {**doc, "grasps": [grasps[i] for i in picked]}, schema, where, picked)
    else:
        _validate(validate, doc, schema, where)
    M = len(grasps)
    ids = _arr(grasps, "id", (), np.float64, where)
    id_values = None
    if M and not np.array_equal(ids, np.arange(M)):
        filtered = doc.get("only_ok") is True and schema == GRASPS_SCHEMA
        if not (filtered and np.all(ids == np.round(ids)) and ids[0] >= 0 and np.all(np.diff(ids) > 0)
                and ids[-1] < 2**53):
            raise InputError(f"{where}: grasp ids must be 0..{M - 1} in order (a file written with --only-ok: "
                             "strictly increasing ids)")
        id_values = ids.astype(np.int64)
    names = PLAN_STATUSES if schema == PLAN_SCHEMA else GRASP_STATUSES
    status = _arr(grasps, "status", (), object, where)
    bad = sorted(set(status.tolist()) - set(names)) if M else []
    if bad:
        raise InputError(f"{where}: unknown grasp status {str(bad[:3])[:80]}; expected one of {', '.join(names)}")
    T = _arr(grasps, "T_part_tcp", (4, 4), np.float64, where)
    if M:
        check_transform(T, f"{where}: grasps[*].T_part_tcp", batch=True)
    width = _arr(grasps, "width", (), np.float64, where)
    if np.any(width < 0) or np.any(width > 10):
        raise InputError(f"{where}: grasp widths must be in [0, 10] m")
    table = GraspTable(
        candidate=_arr(grasps, "candidate", (), np.float64, where).astype(np.int64),
        region=_arr(grasps, "region", (), np.float64, where, default=-1).astype(np.int64),
        contacts=_arr(grasps, "contacts", (2, 3), np.float64, where),
        normals=_arr(grasps, "normals", (2, 3), np.float64, where),
        width=width, T_part_tcp=T.reshape(M, 4, 4),
        roll=_arr(grasps, "roll", (), np.float64, where),
        status=status,
        score=np.array([np.nan if (s := g.get("score")) is None else s for g in grasps], dtype=np.float64)
        if M else np.full(M, np.nan),
        rank=np.array([-1 if (r := g.get("rank")) is None else r for g in grasps], dtype=np.int64)
        if schema == PLAN_SCHEMA else np.full(M, -1, dtype=np.int64),
        reason=_arr(grasps, "reason", (), object, where, default="") if M else np.zeros(0, dtype=object),
        id_values=id_values,
        **parse_quality_sim(grasps, where),
    )
    if M and not np.all(np.isfinite(table.score[~np.isnan(table.score)])):
        raise InputError(f"{where}: grasp scores must be finite numbers or null")
    p = doc["part"]
    part = PartRecord(path=str(p["path"]), sha256=str(p["sha256"]), scale_to_m=float(p["scale_to_m"]),
                      triangles=int(p["triangles"]),
                      T_world_part=check_transform(p["T_world_part"], f"{where}: part.T_world_part"))
    if not (math.isfinite(part.scale_to_m) and 0 < part.scale_to_m <= 1e3):
        raise InputError(f"{where}: part.scale_to_m must be a positive scale, got {part.scale_to_m!r}")
    gripper = gripper_from_json(doc["gripper"], where=f"{where}: gripper")
    cell = Cell.from_json({k: v for k, v in doc["cell"].items() if k != "part_pose"}
                          if isinstance(doc["cell"], dict) else doc["cell"])
    cp, gp, pp = _params_from_doc(doc, where)
    robot = None
    motions: dict[int, Motion] = {}
    if schema == PLAN_SCHEMA:
        from .robot import robot_from_json

        robot = robot_from_json(doc["robot"], where=f"{where}: robot")
        motions = _motions(grasps, status, robot, where)
        _check_fk(robot, gripper, part.T_world_part, table.T_part_tcp, motions, where)
    counts = {k: v for k, v in (doc.get("counts") or {}).items() if k in ("candidates", "posed_candidates", "poses",
                                                                           "regions")}
    timing = {str(k): float(v) for k, v in (doc.get("timing_s") or {}).items()
              if isinstance(v, (int, float)) and not isinstance(v, bool)}
    return PlanResult(part=part, gripper=gripper, cell=cell, robot=robot, grasps=table, motions=motions,
                      params=Params(cp, gp, pp), counts_stage=counts, timing_s=timing,
                      part_pose_source=str((doc.get("cell") or {}).get("part_pose", "stable_pose")), part_mesh=part_mesh,
                      mass=parse_mass_record(p, where))


def _validate(validate, doc, schema, where, picked=None):
    import re

    try:
        validate(doc, schema)
    except InputError as exc:
        msg = str(exc)
        if picked is not None:  # name the grasp in the file, not its place in the sample
            msg = re.sub(r"\$\.grasps\[(\d+)\]", lambda m: f"$.grasps[{picked[int(m.group(1))]}]", msg)
        raise InputError(f"{where}: {msg}") from None
    except RecursionError:
        raise InputError(f"{where}: JSON nested too deeply; not a grasplan result") from None


def _params_from_doc(doc: dict, where: str):
    from dataclasses import fields

    prm = doc.get("params") or {}
    try:
        cp = CandidateParams.from_json({k: v for k, v in prm.items() if k in {f.name for f in fields(CandidateParams)}})
        gp = GraspParams.from_json({k: v for k, v in prm.items() if k in {f.name for f in fields(GraspParams)}})
        pp = PlanParams.from_json(doc.get("plan_params") or {})
    except (InputError, TypeError) as exc:
        raise InputError(f"{where}: params: {exc}") from None
    return cp, gp, pp


def _motions(grasps: list, status: np.ndarray, robot, where: str) -> dict[int, Motion]:
    n = robot.nq
    out: dict[int, Motion] = {}
    for i in np.flatnonzero(status == "planned").tolist():
        g = grasps[i]
        try:
            path = np.asarray(g["path"], dtype=np.float64)
            qg = np.asarray(g["q_grasp"], dtype=np.float64)
            qp = np.asarray(g["q_pregrasp"], dtype=np.float64)
            k = g["pregrasp_index"]
        except (KeyError, TypeError, ValueError, OverflowError):
            raise InputError(f"{where}: planned grasp {i} needs numeric q_grasp, q_pregrasp, path and pregrasp_index") from None
        if path.ndim != 2 or path.shape[1] != n or len(path) < 2 or qg.shape != (n,) or qp.shape != (n,):
            raise InputError(f"{where}: planned grasp {i}: joint vectors must have the robot's {n} joints "
                             f"({', '.join(robot.joint_names)}) and the path >= 2 of them")
        if not (np.all(np.isfinite(path)) and np.all(np.isfinite(qg)) and np.all(np.isfinite(qp))):
            raise InputError(f"{where}: planned grasp {i}: joint values must be finite numbers")
        if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < len(path):
            raise InputError(f"{where}: planned grasp {i}: pregrasp_index must be an index into its path")
        if not np.all(robot.within_limits(path, tol=1e-6)):
            raise InputError(f"{where}: planned grasp {i}: the path leaves the joint limits of robot {robot.name!r}")
        segments, events, T_place, T_tcp_part = _motion_extras(g, len(path), k, f"{where}: planned grasp {i}")
        m = Motion(q_grasp=qg, q_pregrasp=qp, path=path, pregrasp_index=int(k), segments=segments, gripper=events,
                   T_world_part_place=T_place, T_tcp_part=T_tcp_part)
        gi = m.grasp_index
        for a_name, a, b_name, b in (("path[0]", path[0], "q_home", robot.q_home),
                                     ("path[pregrasp_index]", path[k], "q_pregrasp", qp),
                                     (f"path[{gi}] (the end of the approach)", path[gi], "q_grasp", qg)):
            if np.max(np.abs(a - b)) > 1e-6:
                raise InputError(f"{where}: planned grasp {i}: {a_name} differs from {b_name} by "
                                 f"{np.max(np.abs(a - b)):.3g} rad; the plan file is inconsistent")
        out[i] = m
    return out


def _index(v, k: int) -> int | None:
    return int(v) if isinstance(v, int) and not isinstance(v, bool) and 0 <= v < k else None


def _motion_extras(g: dict, k: int, pregrasp_index: int, where: str):
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
        T_tcp = check_transform(g["T_tcp_part"], f"{where}: T_tcp_part")
    if "T_world_part_place" in g or "descend" in bounds:
        if "T_world_part_place" not in g or "descend" not in bounds:
            raise InputError(f"{where}: T_world_part_place and the transfer/descend/retreat segments go together")
        T_place = check_transform(g["T_world_part_place"], f"{where}: T_world_part_place")
    return (tuple(segs) if explicit else ()), tuple(events), T_place, T_tcp


#: FK check tolerances (m, rad): FK(q_grasp) @ T_flange_tcp must be the recorded grasp TCP
FK_POS_TOL = 1e-3
FK_ROT_TOL = 1e-2


def _check_fk(robot, gripper, T_world_part, T_part_tcp, motions: dict, where: str) -> None:
    if not motions:
        return
    ids = np.fromiter(motions, dtype=np.int64)
    q = np.stack([motions[i].q_grasp for i in ids])
    T_fk = robot.fk_batch(q) @ gripper.T_flange_tcp
    T_rec = T_world_part @ T_part_tcp[ids]
    dp = np.linalg.norm(T_fk[:, :3, 3] - T_rec[:, :3, 3], axis=1)
    cos = np.clip((np.einsum("nij,nij->n", T_fk[:, :3, :3], T_rec[:, :3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    dr = np.arccos(cos)
    bad = np.flatnonzero((dp > FK_POS_TOL) | (dr > FK_ROT_TOL))
    if len(bad):
        b = int(bad[0])
        raise InputError(f"{where}: planned grasp {int(ids[b])}: FK(q_grasp) is {dp[b] * 1000:.1f} mm / {dr[b]:.3f} rad "
                         f"from its recorded TCP with robot {robot.name!r}; the plan was made with another robot or "
                         "gripper, or was edited")
    # the part in the jaws is the grasp's own inverse, and the jaws open where the part is placed
    for i in ids.tolist():
        m = motions[i]
        if m.T_tcp_part is None:
            continue
        d_att = pose_error(m.T_tcp_part @ T_part_tcp[i], np.eye(4))
        if d_att[0] > FK_POS_TOL or d_att[1] > FK_ROT_TOL:
            raise InputError(f"{where}: planned grasp {i}: T_tcp_part is not the inverse of its T_part_tcp "
                             f"({d_att[0] * 1000:.1f} mm / {d_att[1]:.3f} rad); the plan file was edited")
        if m.T_world_part_place is not None:
            o = m.event("open").index
            T_part = robot.fk_batch(m.path[o][None])[0] @ gripper.T_flange_tcp @ m.T_tcp_part
            d_pl = pose_error(T_part, m.T_world_part_place)
            if d_pl[0] > FK_POS_TOL or d_pl[1] > FK_ROT_TOL:
                raise InputError(f"{where}: planned grasp {i}: at the open event (row {o}) the part is "
                                 f"{d_pl[0] * 1000:.1f} mm / {d_pl[1]:.3f} rad from T_world_part_place with robot "
                                 f"{robot.name!r}; the plan was made with another robot or gripper, or was edited")


def load_result(source: str | os.PathLike | dict | PlanResult, *, part: str | os.PathLike | None = None,
                load_mesh: bool = False, allow_other_part: bool = False) -> PlanResult:
    """A :class:`PlanResult` from a grasps/plan file (or a parsed document, or a result).

    ``load_mesh``: also load the part's mesh (from ``part`` or the recorded path, relative paths
    also looked up next to the file) at the recorded scale; its sha256 must match unless
    ``allow_other_part``."""
    if isinstance(source, PlanResult):
        res = source
    elif isinstance(source, dict):
        res = result_from_document(source, where="document")
    else:
        res = replace(result_from_document(read_document(source), where=str(source)), origin=Path(source).resolve())
    if load_mesh and (res.part_mesh is None or part is not None):
        res = replace(res, part_mesh=res.mesh(part, allow_other_part=allow_other_part))
    return res


def load_part_mesh(record: PartRecord, *, part=None, search_dirs=(), allow_other_part: bool = False):
    """The part's trimesh (metres) for a result; InputError when its sha256 differs from the record."""
    from .mesh import load_recorded_part

    p = load_recorded_part({"path": record.path, "scale_to_m": record.scale_to_m}, path=part,
                           search_dirs=tuple(str(d) for d in search_dirs))
    if p.sha256 != record.sha256 and not allow_other_part:
        raise InputError(f"{p.path}: sha256 {p.sha256[:12]}... differs from the result's part {record.sha256[:12]}...; "
                         "give the mesh the result was made from with --part (or --allow-other-part to draw it anyway)")
    return p.mesh
