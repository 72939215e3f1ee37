"""The per-grasp arrays of a result: one row per gripper pose, indexed by grasp id.

:class:`GraspTable` is what the grasp stage produces (:meth:`grasplan.grasps.pipeline.GraspResult.table`),
what the plan stage fills in (:meth:`GraspTable.with_plan`), what :mod:`grasplan.results.writer`
writes and :mod:`grasplan.results.reader` reads back. TLess20 has ~1e5 poses: columns, not objects.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np


@dataclass(frozen=True)
class GraspTable:
    """Per-grasp arrays (M grasps, id = index). Lengths m, angles rad.

    candidate (M,) int64, region (M,) int64 (-1: none), contacts / normals (M, 2, 3),
    width (M,), T_part_tcp (M, 4, 4), roll (M,), status (M,) object (str, a
    :class:`grasplan.status.Status` value), score (M,) float64 (NaN: none), rank (M,) int64 (-1:
    none), reason (M,) object (str; "" in grasps files)."""

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
    # grasp quality (grasplan.grasps.quality; None: not computed): contact_area (M, 2) m^2 and
    # contact_type (M, 2) int8 into grasplan.results.quality_json.CONTACT_TYPES per jaw, gravity_margin (M,),
    # epsilon (M,); NaN / -1 for grasps without quality (collisions)
    contact_area: np.ndarray | None = None
    contact_type: np.ndarray | None = None
    gravity_margin: np.ndarray | None = None
    epsilon: np.ndarray | None = None
    # lift-and-shake simulation (grasplan.sim.simulate; None: none): sim_success (M,) int8 (1 held,
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

    def with_plan(self, status: np.ndarray, score: np.ndarray, rank: np.ndarray, reason: np.ndarray) -> GraspTable:
        """This table with the plan stage's status, score, rank and reason columns."""
        return replace(self, status=status, score=score, rank=rank, reason=reason)


#: optional columns and the value of a row that lacks them
_OPTIONAL_FILL = {"contact_area": np.nan, "contact_type": -1, "gravity_margin": np.nan, "epsilon": np.nan,
                  "sim_success": -1, "sim_slip_m": np.nan, "sim_turn_deg": np.nan}
_REQUIRED = ("candidate", "region", "contacts", "normals", "width", "T_part_tcp", "roll", "status", "score", "rank",
             "reason")


def join_tables(a: GraspTable, b: GraspTable) -> GraspTable:
    """The rows of ``a`` and ``b`` in one table ordered by grasp id (ids 0..M-1 when they are
    exactly those); an optional column present in one only is filled (NaN, -1) for the other's
    rows. ValueError when an id is in both."""
    ids = np.concatenate([a.ids, b.ids])
    order = np.argsort(ids, kind="stable")
    ids = ids[order]
    if len(ids) > 1 and np.any(np.diff(ids) <= 0):
        raise ValueError("a grasp id appears twice")
    cols: dict[str, np.ndarray | None] = {k: np.concatenate([getattr(a, k), getattr(b, k)])[order] for k in _REQUIRED}
    for k, fill in _OPTIONAL_FILL.items():
        x, y = getattr(a, k), getattr(b, k)
        if x is None and y is None:
            cols[k] = None
            continue
        like = x if x is not None else y
        assert like is not None
        x = x if x is not None else np.full((len(a), *like.shape[1:]), fill, dtype=like.dtype)
        y = y if y is not None else np.full((len(b), *like.shape[1:]), fill, dtype=like.dtype)
        cols[k] = np.concatenate([x, y])[order]
    dense = len(ids) == 0 or (ids[0] == 0 and ids[-1] == len(ids) - 1)
    return GraspTable(id_values=None if dense else ids.astype(np.int64), **cols)  # type: ignore[arg-type]
