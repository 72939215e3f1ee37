"""A planned grasp's joint motion: the path, its labelled segments and the gripper events.

:func:`grasplan.motion.planning.plan` and :mod:`grasplan.motion.pickplace` build a :class:`Motion` per planned
grasp; the exports, the viewer and :mod:`grasplan.results.writer` read it; :meth:`Motion.to_json`
is its one JSON (the keys a planned grasp carries in a ``grasplan.plan/1`` file).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

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

    def to_json(self) -> dict[str, Any]:
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
        approach = self.segment("approach")
        if approach is None:
            raise ValueError(f"motion segments {[a for a, _, _ in self.segment_list()]} have no approach; "
                             f"expected one of {' | '.join('/'.join(q) for q in SEGMENT_SEQUENCES)}")
        return approach[1]

    def event(self, action: str) -> GripperEvent | None:
        """The first gripper event ``action`` ("close" / "open"), None when there is none."""
        return next((g for g in self.gripper if g.action == action), None)

    def attached_range(self) -> tuple[int, int]:
        """``(close row, open row)``: the rows between which the part rides in the jaws. Without a
        close event (old files) the close row is the grasp row; without an open event the open row
        is the path's last row."""
        c, o = self.event("close"), self.event("open")
        return (c.index if c is not None else self.grasp_index), (o.index if o is not None else len(self.path) - 1)

    def to_json(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "q_grasp": np.asarray(self.q_grasp).tolist(), "q_pregrasp": np.asarray(self.q_pregrasp).tolist(),
            "path": np.asarray(self.path).tolist(), "pregrasp_index": int(self.pregrasp_index),
            "segments": [{"label": a, "start": s, "end": e} for a, s, e in self.segment_list()],
            "gripper": [g.to_json() for g in self.gripper]}
        if self.T_tcp_part is not None:
            d["T_tcp_part"] = np.asarray(self.T_tcp_part, dtype=np.float64).tolist()
        if self.T_world_part_place is not None:
            d["T_world_part_place"] = np.asarray(self.T_world_part_place, dtype=np.float64).tolist()
        return d
