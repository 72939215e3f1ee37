"""The gripper-kind registry: one :class:`GripperKind` per ``kind:`` a gripper YAML may name.

A kind is one module that ends with ``KIND = register(GripperKind(...))``; the shipped ones are
listed once in :data:`grasplan.gripper.BUILTIN_KINDS`. :func:`grasplan.gripper.load_gripper` and
:func:`grasplan.gripper.gripper_from_json` read the optional ``kind`` key (default
``parallel_jaw``, so files written before kinds existed read unchanged) and hand the document to
the kind's readers; an unknown kind is a ConfigError that lists the registered ones.

What a kind provides: its gripper class (:class:`~grasplan.gripper.model.Gripper` or a subclass
whose ``kind`` class attribute is the kind's name: every stage reads that interface: ``body``,
``fingers(opening)``, ``swept_fingers(a, b)``, ``pregrasp_opening``, ``T_flange_tcp``, ...), a
reader of its YAML fields and a reader of its ``to_json(definition=True)`` output. A kind whose
TCP moves with the opening (Robotiq 2F linkages) will need the stages to ask the gripper for the
flange-to-TCP transform at an opening instead of reading the constant ``T_flange_tcp``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from ..errors import unknown_name
from .model import Gripper


class YAMLReader(Protocol):
    """Builds a gripper from its parsed YAML mapping (``kind`` included): ``base`` is the folder
    mesh paths are relative to, ``name`` the default name (the file stem), ``source`` the file."""

    def __call__(self, data: dict[str, Any], *, base: Path, name: str, source: str) -> Gripper: ...


class JSONReader(Protocol):
    """Builds a gripper from its ``to_json(definition=True)`` block; ``where`` labels errors."""

    def __call__(self, d: dict[str, Any], *, where: str) -> Gripper: ...


@dataclass(frozen=True)
class GripperKind:
    """A gripper kind: its name (the YAML / JSON ``kind``), its class and its two readers."""

    name: str
    description: str
    model: type[Gripper]
    from_yaml: YAMLReader
    from_json: JSONReader


#: name -> kind; filled by the kind modules when they are imported
KINDS: dict[str, GripperKind] = {}


def register(kind: GripperKind) -> GripperKind:
    """Add ``kind`` to :data:`KINDS` (idempotent for the same object); returns it."""
    if kind.model.kind != kind.name:
        raise ValueError(f"gripper kind {kind.name!r}: its class {kind.model.__name__} says kind "
                         f"{kind.model.kind!r}")
    if kind.name in KINDS and KINDS[kind.name] is not kind:
        raise ValueError(f"gripper kind {kind.name!r} is registered twice")
    KINDS[kind.name] = kind
    return kind


def get_kind(name: object, *, where: str) -> GripperKind:
    """The registered kind ``name``; ConfigError naming ``where`` and listing the kinds."""
    if not isinstance(name, str) or name not in KINDS:
        raise unknown_name("gripper kind", str(name)[:80], KINDS, hint=where)
    return KINDS[name]
