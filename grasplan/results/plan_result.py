"""The result of the grasps and plan stages: :class:`PlanResult` and the records it is made of.

:class:`PlanResult` is what :func:`grasplan.plan` returns, what ``grasplan.grasps.pipeline.compute_grasps``
results become (:meth:`grasplan.grasps.pipeline.GraspResult.to_result`), and what
:func:`grasplan.results.reader.load_result` reads back from a ``grasplan.grasps/1`` or
``grasplan.plan/1`` file. Exports and the viewer take a ``PlanResult``; nothing downstream
re-parses JSON or re-resolves a gripper, cell or robot by name: the documents embed their resolved
definitions (``gripper.definition``, the whole ``cell``, ``robot.source``) and the reader rebuilds
the models from them.

Per-grasp data are arrays (:class:`grasplan.results.grasp_table.GraspTable`; TLess20 has ~1e5 poses),
indexed by grasp id; planned grasps have a :class:`grasplan.results.joint_motion.Motion`. The JSON is written by
:mod:`grasplan.results.writer`, exports by :mod:`grasplan.results.export_registry` (both below this module:
a result writes and exports itself without importing the reader or the format modules).
"""
from __future__ import annotations

import math
import os
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ..errors import InputError
from .compact import DEFAULT_KEEP, REJECTED, RejectedCounts
from .export_registry import write_export
from .grasp_table import GraspTable
from ..part.mesh import load_recorded_part
from .joint_motion import Motion
from ..config.params import CandidateParams, GraspParams, PlanParams
from .writer import GRASPS_SCHEMA, PLAN_SCHEMA, document, grasp_entries, write_result
from ..status import GRASP_STATUSES, PLAN_STATUSES, Status

if TYPE_CHECKING:
    from ..cell.model import Cell
    from ..gripper.model import Gripper
    from ..part.mass import MassProperties
    from ..geometry.meshdata import TriangleMesh
    from ..robot.model import Robot


@dataclass(frozen=True)
class PartRecord:
    """The part a result was computed for: its file, identity and pose in the cell."""

    path: str
    sha256: str
    scale_to_m: float
    triangles: int
    T_world_part: np.ndarray

    def to_json(self) -> dict[str, Any]:
        return {"path": self.path, "sha256": self.sha256, "scale_to_m": float(self.scale_to_m),
                "triangles": int(self.triangles), "T_world_part": np.asarray(self.T_world_part).tolist()}

    @property
    def label(self) -> str:
        """The part's file name (for headers; exporters still reduce it to a safe character set)."""
        return Path(self.path).name if self.path else "(in memory)"


def load_part_mesh(record: PartRecord, *, part: str | os.PathLike[str] | None = None,
                   search_dirs: tuple[str | os.PathLike[str], ...] = (),
                   allow_other_part: bool = False) -> TriangleMesh:
    """The part's mesh (metres) for a result; InputError when its sha256 differs from the record."""
    p = load_recorded_part({"path": record.path, "scale_to_m": record.scale_to_m}, path=part,
                           search_dirs=tuple(str(d) for d in search_dirs))
    if p.sha256 != record.sha256 and not allow_other_part:
        raise InputError(f"{p.path}: sha256 {p.sha256[:12]}... differs from the result's part {record.sha256[:12]}...; "
                         "give the mesh the result was made from with --part (or --allow-other-part to draw it anyway)")
    return p.mesh


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


class GraspStage(Protocol):
    """What a result keeps of the in-memory grasp stage it came from: a
    :class:`grasplan.grasps.pipeline.GraspResult` (named by its shape: grasps.py builds results from this
    module, so this module does not import it)."""

    @property
    def status(self) -> np.ndarray: ...

    @property
    def mass_props(self) -> MassProperties | None: ...

    def quality_warnings(self) -> list[str]: ...


@dataclass(frozen=True, eq=False)
class PlanResult:
    """A grasps or plan result (``robot`` is None for a grasps result).

    ``motions``: {grasp id: Motion} for the planned grasps; ``counts_stage``: stage counts
    (candidates, poses, ...); ``timing_s``: seconds per stage; ``part_pose_source``:
    "stable_pose" | "given" | "part_frame" (cell ``none``); ``grasp_result``: the in-memory grasp stage (None when loaded from a
    file); ``part_mesh``: the part's mesh in metres when known (in memory, or loaded by
    :func:`grasplan.results.reader.load_result` with ``load_mesh=True``).
    """

    part: PartRecord
    gripper: Gripper
    cell: Cell
    robot: Robot | None
    grasps: GraspTable
    motions: dict[int, Motion] = field(default_factory=dict)
    params: Params = field(default_factory=Params)
    counts_stage: dict[str, int] = field(default_factory=dict)
    timing_s: dict[str, float] = field(default_factory=dict)
    part_pose_source: str = "stable_pose"
    grasp_result: GraspStage | None = None
    part_mesh: TriangleMesh | None = None
    origin: Path | None = None   #: the file this result was loaded from (relative part paths resolve next to it)
    mass: dict[str, Any] | None = None  #: the part's mass record (grasplan.part.mass.MassProperties.record), written under part
    #: poses that collide, counted per candidate, that ``grasps`` does not hold (read from a compact plan)
    rejected: RejectedCounts | None = None

    def mesh(self, part: str | os.PathLike[str] | None = None, *, allow_other_part: bool = False) -> TriangleMesh:
        """The part's mesh (metres): in memory, else loaded from ``part`` or the recorded path
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

    def counts(self) -> dict[str, int]:
        """Grasps per status (every status of this result's stage) and ``grasps`` (the total)."""
        names = PLAN_STATUSES if self.robot is not None else GRASP_STATUSES
        got = Counter(map(str, self.grasps.status.tolist()))  # a few distinct strings: no sort
        if self.rejected is not None:
            for s, n in self.rejected.totals().items():
                got[s] = got.get(s, 0) + n
        out = {s: int(got.get(s, 0)) for s in names}
        out["grasps"] = len(self.grasps) + (int(self.rejected.counts.sum()) if self.rejected is not None else 0)
        return out

    def planned_ids(self) -> list[int]:
        """Ids of the planned grasps, best first (rank, then id)."""
        rows = np.flatnonzero(self.grasps.status.astype(str) == Status.PLANNED.value)
        ids, rank = self.grasps.ids[rows], self.grasps.rank[rows]
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
                         motion=self.motions.get(int(t.ids[i])))

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

    def entry(self, i: int) -> dict[str, Any]:
        """Grasp ``i`` as its JSON dict."""
        return grasp_entries(self, [int(i)])[0]

    def planned(self) -> list[dict[str, Any]]:
        """Planned grasps as JSON dicts, best first."""
        return grasp_entries(self, [self.grasps.index_of(i) for i in self.planned_ids()])

    # ---- JSON and exports -------------------------------------------------------------------
    def to_json(self, *, only_ok: bool = False, keep: str = DEFAULT_KEEP) -> dict[str, Any]:
        """``grasplan.grasps/1`` (no robot) or ``grasplan.plan/1``; self-contained: the gripper's
        resolved shapes, the whole cell and the robot's source are embedded. ``keep``: what a plan
        keeps of its rejected and untried poses (:mod:`grasplan.results.compact`)."""
        return document(self, only_ok=only_ok, keep=keep)

    def document_head(self, only_ok: bool = False) -> tuple[dict[str, Any], np.ndarray]:
        """The document without its ``grasps`` list (which comes last), and the rows it lists."""
        part = self.part.to_json()
        if self.mass:
            part.update(self.mass)
        cell = self.cell.to_json()
        cell["part_pose"] = self.part_pose_source
        params = self.params.candidates.to_json()
        params.update(self.params.grasps.to_json())
        doc: dict[str, Any] = {"schema": self.schema, "part": part, "gripper": self.gripper.to_json(definition=True),
                               "cell": cell, "params": params}
        counts: dict[str, int] = dict(self.counts_stage)
        st = self.grasps.status.astype(str)
        if self.robot is None:
            counts.update({s: int(np.count_nonzero(st == s)) for s in GRASP_STATUSES})
        else:
            counts.pop(Status.OK.value, None)
            counts["collision_free"] = int(np.count_nonzero(~np.isin(st, REJECTED)))
            c = self.counts()
            c.pop("grasps")
            counts.update(c)
            doc["robot"] = self.robot.to_json(source=True)
            doc["plan_params"] = self.params.planning.to_json()
        doc["counts"] = counts
        doc["timing_s"] = {k: float(v) for k, v in self.timing_s.items()}
        ids = np.flatnonzero(st == Status.OK.value) if only_ok else np.arange(len(self.grasps))
        if only_ok:
            doc["only_ok"] = True
        return doc, ids

    def write(self, path: str | os.PathLike[str], *, only_ok: bool = False, keep: str = DEFAULT_KEEP,
              indent: int | None = None, extra: dict[str, Any] | None = None) -> Path:
        """Write the result's JSON atomically: the text of ``json.dumps(to_json(only_ok, keep))``
        (with ``extra``'s keys appended at the end), streamed in chunks
        (:func:`grasplan.results.writer.write_result`; ``indent`` given: through the dict)."""
        return write_result(self, path, only_ok=only_ok, keep=keep, indent=indent, extra=extra)

    def export(self, fmt: str, path: str | os.PathLike[str], grasp_id: int | None = None, *,
               part: str | os.PathLike[str] | None = None, **options: Any) -> Path:
        """Write ``fmt`` (a name in :data:`grasplan.export.FORMATS`) to ``path``; ``part``: the part's
        mesh when the recorded path does not find it. Options: :class:`grasplan.export.ExportOptions`."""
        res = self if part is None else replace(self, part_mesh=self.mesh(part))
        return write_export(res, fmt, path, grasp_id=grasp_id, **options)
