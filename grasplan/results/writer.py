"""The one writer of ``grasplan.grasps/1`` and ``grasplan.plan/1``: the document dict
(:meth:`grasplan.results.plan_result.PlanResult.to_json`) and the same document streamed as text in chunks
(:meth:`grasplan.results.plan_result.PlanResult.write`), byte-identical to ``json.dumps`` of the dict.

Each per-grasp field is defined once, in :func:`grasp_record` (name, column, formatting, the grasps
that have it; the ``quality`` and ``sim`` fields in :mod:`grasplan.results.quality_json`, the motion keys by
:meth:`grasplan.results.joint_motion.Motion.to_json`); :mod:`grasplan.results.json_columns` derives the dicts and the
text from it. The streamed text holds :data:`WRITE_CHUNK` grasps at a time, so memory stays
bounded however many poses a part has (TLess20: ~6e4).
"""
from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from .compact import DEFAULT_KEEP, KEEP_ALL, KEEP_COLLISION_FREE, RejectedCounts, split_rows, untried_block
from .grasp_table import GraspTable
from ..io import to_json_text, write_atomic_chunks, write_json
from .json_columns import Field, Numbers, Record, Spread, Strings, block_text, block_values, join_rows
from .joint_motion import Motion
from .quality_json import quality_field, sim_field

GRASPS_SCHEMA = "grasplan.grasps/1"
PLAN_SCHEMA = "grasplan.plan/1"
SCHEMAS = (GRASPS_SCHEMA, PLAN_SCHEMA)

#: grasps serialised per chunk by :func:`stream_document` (bounds the writer's memory)
WRITE_CHUNK = 4096


class WritableResult(Protocol):
    """What the writer reads of a result (a :class:`grasplan.results.plan_result.PlanResult`, which imports this
    module to write itself)."""

    @property
    def schema(self) -> str: ...

    @property
    def grasps(self) -> GraspTable: ...

    @property
    def motions(self) -> Mapping[int, Motion]: ...

    @property
    def rejected(self) -> RejectedCounts | None: ...

    @property
    def gripper(self) -> Any: ...  #: a grasplan.gripper.model.Gripper (its grip_force, N)

    def document_head(self, only_ok: bool = False) -> tuple[dict[str, Any], np.ndarray]: ...


def grasp_record(table: GraspTable, motions: Mapping[int, Motion] | None, grip_force: float) -> Record:
    """The JSON object of each grasp (row) of ``table``, in the file's key order; ``motions`` (grasp id
    -> Motion) given: a plan's grasp (score always, rank, reason, the motion's keys when planned),
    None: a grasps file's (score only where there is one); ``grip_force`` (N): the gripper's, for
    each grasp's ``hold_force_N``."""
    plan = motions is not None
    score = Numbers(table.score, null=lambda rows: np.isnan(table.score[rows]))
    fields = [
        Field("id", Numbers(table.ids)),
        Field("candidate", Numbers(table.candidate)),
        Field("region", Numbers(table.region)),
        # 1e-10 m / rad: keeps the files small
        Field("contacts", Numbers(table.contacts, decimals=10)),
        Field("normals", Numbers(table.normals, decimals=10)),
        Field("width", Numbers(table.width, decimals=10)),
        Field("T_part_tcp", Numbers(table.T_part_tcp, decimals=10)),
        Field("roll", Numbers(table.roll, decimals=10)),
        Field("status", Strings(table.status, as_str=True)),
        Field("score", score, present=None if plan else lambda rows: ~np.isnan(table.score[rows])),
    ]
    fields += [f for f in (quality_field(table, score, grip_force), sim_field(table)) if f is not None]
    if motions is not None:
        spread = Spread({int(table.index_of(int(i))): m for i, m in motions.items()})  # type: ignore[arg-type]
        fields += [Field("rank", Numbers(table.rank, null=lambda rows: table.rank[rows] < 0)),
                   Field("reason", Strings(table.reason)),
                   Field(None, spread, present=spread.has)]
    return Record(tuple(fields))


def _record(res: WritableResult) -> Record:
    return grasp_record(res.grasps, res.motions if res.schema == PLAN_SCHEMA else None, float(res.gripper.grip_force))


def grasp_entries(res: WritableResult, rows: Any) -> list[dict[str, Any]]:
    """Grasps (table rows) ``rows`` of ``res`` as their JSON dicts."""
    return _record(res).values(np.asarray(rows, dtype=np.int64))


def document_parts(res: WritableResult, *, only_ok: bool = False,
                   keep: str = DEFAULT_KEEP) -> tuple[dict[str, Any], np.ndarray, dict[str, Any]]:
    """The document's head (``keep`` recorded in a plan's), the rows its ``grasps`` list holds and
    the blocks that follow the list (a plan's ``untried`` and ``rejected``:
    :mod:`grasplan.results.compact`; lists as :class:`~grasplan.results.json_columns.Listed`
    columns, :func:`~grasplan.results.json_columns.block_values` makes them lists). A result
    loaded from a compact file keeps its counts (its rejected poses are not there to write in
    full)."""
    head, rows = res.document_head(only_ok)
    if res.schema != PLAN_SCHEMA:
        return head, rows, {}
    if res.rejected is not None:
        keep = KEEP_COLLISION_FREE
    split = split_rows(res.grasps, rows, keep)
    head["keep"] = keep
    if keep == KEEP_ALL:
        return head, split.grasps, {}
    rejected = RejectedCounts.of_rows(res.grasps, split.rejected)
    if res.rejected is not None:
        rejected = res.rejected.merged(rejected)
    untried = untried_block(res.grasps, split.untried, float(res.gripper.grip_force))
    return head, split.grasps, {"untried": untried, "rejected": rejected.to_json()}


def document(res: WritableResult, *, only_ok: bool = False, keep: str = DEFAULT_KEEP) -> dict[str, Any]:
    """The whole document as a dict (``grasps`` after the head, then a plan's ``untried`` and
    ``rejected`` blocks)."""
    doc, rows, tail = document_parts(res, only_ok=only_ok, keep=keep)
    doc["grasps"] = grasp_entries(res, rows)
    doc.update(block_values(tail))
    return doc


def stream_document(res: WritableResult, *, only_ok: bool = False, keep: str = DEFAULT_KEEP,
                    extra: dict[str, Any] | None = None) -> Iterator[str] | None:
    """Chunks (str) whose concatenation is byte-identical to ``json.dumps(doc)`` for ``doc =
    document(res, only_ok=only_ok, keep=keep)`` updated with ``extra`` (what
    :func:`grasplan.io.write_json` writes), :data:`WRITE_CHUNK` grasps at a time; None when the
    document must go through the dict (a value json refuses (NaN / inf), ``extra`` repeating a
    key), so that path raises exactly what it raised before."""
    head, rows, tail = document_parts(res, only_ok=only_ok, keep=keep)
    if extra and (set(extra) & (set(head) | {"grasps"} | set(tail))):
        return None
    record = _record(res)
    if not record.encodable(rows):
        return None
    return _chunks(head, record, rows, {**tail, **(extra or {})})


def _chunks(head: dict[str, Any], record: Record, rows: np.ndarray, tail: dict[str, Any]) -> Iterator[str]:
    text = to_json_text(head)
    yield text[:-1] + (", " if len(head) else "") + '"grasps": ['
    for c0 in range(0, len(rows), WRITE_CHUNK):
        chunk = rows[c0:c0 + WRITE_CHUNK]
        yield ("" if c0 == 0 else ", ") + join_rows(record.pieces(chunk), len(chunk))
    end = "]"
    if tail:
        end += ", " + block_text(tail)[1:-1]
    yield end + "}"


def write_result(res: WritableResult, path: str | os.PathLike[str], *, only_ok: bool = False,
                 keep: str = DEFAULT_KEEP, indent: int | None = None, extra: dict[str, Any] | None = None) -> Path:
    """Write the document atomically: the text of ``json.dumps(document(res, only_ok, keep))``
    (with ``extra``'s keys appended at the end), streamed in chunks by :func:`stream_document`
    (``indent`` given, or a value json refuses: through the dict)."""
    chunks = None if indent is not None else stream_document(res, only_ok=only_ok, keep=keep, extra=extra)
    if chunks is None:
        doc = document(res, only_ok=only_ok, keep=keep)
        doc.update(extra or {})
        return write_json(path, doc, indent=indent)
    return write_atomic_chunks(path, chunks)
