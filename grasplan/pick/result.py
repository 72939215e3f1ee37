"""Typed results of a pick and their JSON, ``grasplan.picks/1`` (schema:
``grasplan/schemas/picks.schema.json``; reference in docs/pick.md).

The document embeds what reproduces and executes the picks: the scene (poses as 4x4), each part's
record (path, sha256, scale), the robot (with its source), the gripper (with its shapes) and the
cell; then ``picks`` (one per picked instance, in pick order: the fields of a planned grasp of
``grasplan.plan/1`` plus ``instance``, ``part`` and ``T_world_part``), ``instances`` (every
instance's status and reason; ``blocked_by``: the neighbours that block it or block the grasps
ranked ahead of the one picked), ``warnings`` and ``timing_s`` (``first_pick``: seconds from the
loaded scene to the first feasible pick).
"""
from __future__ import annotations

import json
import os
import weakref
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ..cell.model import Cell
from ..gripper.model import Gripper
from ..io import to_json_text, write_json
from ..results.joint_motion import Motion
from ..robot.model import Robot
from ..piles.scene_file import Scene
from .codes import INSTANCE_STATUSES, PickStatus
from ..motion.codes import Reason
from .params import PickParams

if TYPE_CHECKING:
    from .push import Push

PICKS_SCHEMA = "grasplan.picks/1"
__all__ = ["INSTANCE_STATUSES", "PICKS_SCHEMA", "InstanceReport", "Pick", "PickResult"]


class _Text(NamedTuple):
    """A value already serialised (JSON text)."""

    text: str


#: the JSON text of each robot, gripper and cell a picks document embedded, kept while the object
#: lives (they are frozen; a warm picker's are the same in every document)
_STATIC: dict[str, weakref.WeakKeyDictionary[Any, str]] = {k: weakref.WeakKeyDictionary()
                                                          for k in ("robot", "gripper", "cell")}


def _static_json(kind: str, obj: Any) -> dict[str, Any]:
    """The document's record of the robot (with its source), gripper (with its shapes) or cell."""
    if kind == "robot":
        return obj.to_json(source=True)
    if kind == "gripper":
        return obj.to_json(definition=True)
    return obj.to_json()


def _static_text(kind: str, obj: Any) -> str:
    cache = _STATIC[kind]
    text = cache.get(obj)
    if text is None:
        text = cache[obj] = to_json_text(_static_json(kind, obj))
    return text


def _m(a: np.ndarray) -> list:
    return np.round(np.asarray(a, dtype=np.float64), 10).tolist()


@dataclass(frozen=True, eq=False)
class Pick:
    """One planned pick (see the module docstring); poses (4, 4), lengths m."""

    instance: str
    part: str
    T_world_part: np.ndarray
    T_part_tcp: np.ndarray
    contacts: np.ndarray
    normals: np.ndarray
    width: float
    opening: float
    score: float
    quality: dict[str, float]
    motion: Motion
    T_world_tcp: np.ndarray
    T_world_pregrasp: np.ndarray
    T_world_lifted: np.ndarray
    rank: int = 0  #: the grasp's place in the instance's ranking (0 = best)
    #: ids of the neighbours lying on the part that the lift raises with it (``lift_carry``)
    carries: tuple[str, ...] = ()

    def to_json(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "instance": self.instance, "part": self.part, "T_world_part": _m(self.T_world_part),
            "contacts": _m(self.contacts), "normals": _m(self.normals), "width": round(float(self.width), 10),
            "opening": round(float(self.opening), 10), "T_part_tcp": _m(self.T_part_tcp),
            "score": float(self.score), "rank": int(self.rank),
            "quality": {k: (None if not np.isfinite(v) else float(v)) for k, v in self.quality.items()},
            "T_world_tcp": _m(self.T_world_tcp), "T_world_pregrasp": _m(self.T_world_pregrasp),
            "T_world_lifted": _m(self.T_world_lifted), "lift_carries": list(self.carries)}
        d.update(self.motion.to_json())
        return d


@dataclass(frozen=True)
class InstanceReport:
    """Status of one instance (:class:`~grasplan.pick.codes.PickStatus`), why in words
    (``reason``) and as a code (``code``, :class:`~grasplan.pick.codes.Reason`; None in a report
    read from a file, which holds the words only), and the neighbours that block it or block the
    grasps ranked ahead of the one picked (``blocked_by``)."""

    id: str
    part: str
    status: PickStatus
    reason: str
    blocked_by: tuple[str, ...] = ()
    code: Reason | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", PickStatus(self.status))  # a status string given: its member

    def to_json(self) -> dict[str, Any]:
        return {"id": self.id, "part": self.part, "status": self.status.value, "reason": self.reason,
                "blocked_by": list(self.blocked_by)}


@dataclass(frozen=True, eq=False)
class PickResult:
    """What :meth:`grasplan.Picker.plan` returns (see the module docstring)."""

    picks: tuple[Pick, ...]
    instances: tuple[InstanceReport, ...]
    timing_s: dict[str, float]
    scene: Scene
    robot: Robot | None = None
    gripper: Gripper | None = None
    cell: Cell | None = None
    params: PickParams = PickParams()
    parts: dict[str, dict[str, Any]] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    sequence: bool = False
    stats: dict[str, int] = field(default_factory=dict)  #: grasps_checked, grasps_tried
    #: with ``push=True`` and no pick: the planned push (None: none could be planned; docs/pick.md)
    push: Push | None = None
    push_asked: bool = False
    push_tried: tuple[str, ...] = ()  #: why each push candidate tried failed

    def pick(self, instance: str | None = None) -> Pick:
        """The pick of ``instance`` (default: the first pick); InputError listing the picked ids."""
        from ..errors import InputError

        if not self.picks:
            counts = ", ".join(f"{n} {st}" for st, n in self.counts().items())
            first = f"; e.g. {self.instances[0].id}: {self.instances[0].reason[:160]}" if self.instances else ""
            raise InputError(f"the picks file has no pick ({len(self.instances)} instances: {counts or 'none'}"
                             f"{first}); every instance's status and reason are in its 'instances'")
        if instance is None:
            return self.picks[0]
        for p in self.picks:
            if p.instance == instance:
                return p
        raise InputError(f"instance {instance!r} has no pick; picked: {', '.join(p.instance for p in self.picks)}")

    def report(self, instance: str) -> InstanceReport:
        return next(r for r in self.instances if r.id == instance)

    def counts(self) -> dict[str, int]:
        st = [r.status.value for r in self.instances]
        return {s: st.count(s) for s in INSTANCE_STATUSES if s in st}

    def _items(self, parts: dict[str, dict[str, Any]] | None, static_text: bool) -> list[tuple[str, Any]]:
        """The document's (key, value) pairs in order; ``static_text``: the robot, gripper and cell
        as their JSON text (:class:`_Text`, made once per object)."""
        items: list[tuple[str, Any]] = [
            ("schema", PICKS_SCHEMA), ("scene", self.scene.to_json()),
            ("parts", {k: dict(v) for k, v in (self.parts if parts is None else parts).items()})]
        for key, obj in (("robot", self.robot), ("gripper", self.gripper), ("cell", self.cell)):
            if obj is not None:
                items.append((key, _Text(_static_text(key, obj)) if static_text else _static_json(key, obj)))
        items += [("params", self.params.to_json()), ("sequence", bool(self.sequence)),
                  ("counts", {"instances": len(self.instances), "picks": len(self.picks), **self.counts(),
                              **{k: int(v) for k, v in self.stats.items()}}),
                  ("timing_s", {k: float(v) for k, v in self.timing_s.items()}),
                  ("warnings", list(self.warnings)), ("instances", [r.to_json() for r in self.instances]),
                  ("picks", [p.to_json() for p in self.picks])]
        if self.push_asked:
            items += [("push", None if self.push is None else self.push.to_json()),
                      ("push_tried", list(self.push_tried))]
        return items

    def to_json(self) -> dict[str, Any]:
        """The ``grasplan.picks/1`` document."""
        return dict(self._items(None, False))

    def to_json_text(self, *, parts: dict[str, dict[str, Any]] | None = None) -> str:
        """``grasplan.io.to_json_text(self.to_json())``, byte for byte, with the robot, gripper and
        cell serialised once per object (a warm picker embeds the same ones in every document);
        ``parts``: these part records instead of :attr:`parts` (the pick service's, without its
        folder's paths). ValueError for NaN or infinity, as json's."""
        return "{" + ", ".join(f"{json.dumps(k)}: {v.text if isinstance(v, _Text) else to_json_text(v)}"
                               for k, v in self._items(parts, True)) + "}"

    def write(self, path: str | os.PathLike) -> Path:
        """Write :meth:`to_json` atomically (a temporary file, then a rename)."""
        return write_json(path, self.to_json())
