"""Grippers: find a gripper description by name or path and build it with its kind's reader.

A gripper YAML (``configs/grippers/<name>.yaml``) or a result file's ``gripper`` block names its
kind with an optional ``kind:`` key (default ``parallel_jaw``, :mod:`grasplan.gripper.parallel_jaw`,
which documents the YAML schema; ``parallel_linkage``, :mod:`grasplan.gripper.linkage`: pads on an
arc, the Robotiq 2F). The kinds are registered in :mod:`grasplan.gripper.registry`;
the gripper model and its shapes are in :mod:`grasplan.gripper.model`.

Adding a kind: a module that defines its gripper class (a subclass of
:class:`~grasplan.gripper.model.Gripper`), its YAML and JSON readers and ends with
``KIND = register(GripperKind(...))``, plus its entry in :data:`BUILTIN_KINDS`.
"""
from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

from ..config.lookup import available, packaged_file, read_yaml, resolve_yaml
from ..errors import ConfigError
from ..config.params import DEFAULT_GRIPPER
from . import linkage, parallel_jaw
from .model import PARALLEL_JAW, Gripper
from .registry import GripperKind, get_kind

#: the shipped gripper kinds (importing their modules registered them)
BUILTIN_KINDS: tuple[GripperKind, ...] = (parallel_jaw.KIND, linkage.KIND)
#: the packaged grippers (``grasplan/data/configs/grippers``)
GRIPPER_DIR = packaged_file("configs", "grippers")


def available_grippers() -> list[str]:
    """Names of the grippers found on the config search path (``configs/grippers/*.yaml``)."""
    return available("gripper")


def gripper_from_dict(data: object, *, base: Path, name: str, source: str = "") -> Gripper:
    """Build the gripper a parsed YAML describes with its kind's reader (``base``: folder that mesh
    paths are relative to; ``name``: the default name, the file stem)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source or name}: a gripper file must be a YAML mapping")
    kind = get_kind(data.get("kind", PARALLEL_JAW), where="field 'kind'")
    return kind.from_yaml(data, base=base, name=name, source=source)


def gripper_from_json(d: object, *, where: str = "gripper") -> Gripper:
    """Rebuild a gripper from its :meth:`~grasplan.gripper.model.Gripper.to_json` ``(definition=True)``
    block, with the reader of the kind it names (default ``parallel_jaw``)."""
    if not isinstance(d, dict) or not isinstance(d.get("definition"), dict):
        raise ConfigError(f"{where}: the file embeds no gripper definition (written by an older grasplan?); "
                          "re-run `grasplan grasps` / `grasplan plan` to get a self-contained result")
    kind = get_kind(d.get("kind", PARALLEL_JAW), where=f"{where}.kind")
    return kind.from_json(d, where=where)


@lru_cache(maxsize=32)
def _load_file(path: str, mtime: float) -> Gripper:
    p = Path(path)
    data = read_yaml("gripper", p)
    try:
        return gripper_from_dict(data, base=p.parent, name=p.stem, source=str(p))
    except ConfigError as exc:
        msg = str(exc)
        raise ConfigError(msg if msg.startswith(str(p)) else f"{p}: {msg}") from None


def load_gripper(name_or_path: str | os.PathLike[str] | Gripper = DEFAULT_GRIPPER) -> Gripper:
    """A gripper by name (``configs/grippers/<name>.yaml``) or by path to a YAML file.

    Raises ConfigError for an unknown name (listing the available ones), an unknown kind (listing
    the registered ones) or a malformed file (naming the field). A :class:`Gripper` is returned as is."""
    if isinstance(name_or_path, Gripper):
        return name_or_path
    p = resolve_yaml("gripper", name_or_path)
    return _load_file(str(p), p.stat().st_mtime)
