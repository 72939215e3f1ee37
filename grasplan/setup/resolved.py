"""A run's setup, resolved once at the edge: the robot, gripper and cell a command plans with, each
loaded from the name or path it was given, with the files it was read from (:class:`Setup`, made
by :func:`build_setup`). The CLI, the service and a batch's parent build one; library functions
take its models; the output guard takes its :attr:`Setup.files`; a process started later (a batch
worker, a service planner) gets :meth:`Setup.resolved_refs` and reads the same files by path, so
nothing looks a name up twice. Name or path: :func:`grasplan.config.lookup.is_path_like`.
"""
from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, MutableMapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .outputs import config_files, file_input, robot_files

if TYPE_CHECKING:
    from ..cell.model import Cell
    from ..gripper.model import Gripper
    from ..robot.model import Robot

#: the kinds of description a setup holds, in the order :func:`build_setup` loads them (the order
#: the CLI always reported a bad one in)
KINDS = ("gripper", "cell", "robot")
#: a reference: a name or a path (str or path object), or a model already loaded
Ref = Any
#: what :func:`load_description` keeps per ``(kind, reference)`` when given a cache
Cache = MutableMapping[tuple[str, str], "tuple[Any, Source]"]


@dataclass(frozen=True)
class Source:
    """Where one description came from: ``kind`` (gripper, cell, robot), ``ref`` as given (a name
    or a path; for a model given already loaded, its name), ``path`` the YAML it was read from
    (None: built in, such as the cell ``none``, or a model given without a file) and ``files``:
    that YAML and the files it names (meshes; a robot's URDF, SRDF and URDF meshes)."""

    kind: str
    ref: str
    path: Path | None
    files: tuple[Path, ...] = ()

    @property
    def resolved_ref(self) -> str:
        """The reference another process loads the same description by: the YAML's absolute
        path, or the reference itself when there is no file (the cell ``none``)."""
        return str(self.path) if self.path is not None else self.ref


@dataclass(frozen=True)
class Setup:
    """The loaded ``robot`` (None when the command plans no motion), ``gripper`` and ``cell``
    (None when not asked for), the :class:`Source` of each (``sources``, in load order) and
    ``files``: every file they were read from, each once (the output guard's inputs)."""

    robot: Robot | None = None
    gripper: Gripper | None = None
    cell: Cell | None = None
    sources: tuple[Source, ...] = ()
    files: tuple[Path, ...] = ()

    def source(self, kind: str) -> Source | None:
        """The :class:`Source` of ``kind`` (None when the setup has none)."""
        return next((s for s in self.sources if s.kind == kind), None)

    def ref(self, kind: str) -> str | None:
        """The reference ``kind`` was given by (a name or a path as typed; None when not in the setup)."""
        s = self.source(kind)
        return None if s is None else s.ref

    def resolved_refs(self) -> dict[str, str]:
        """``{kind: reference}`` that loads the same descriptions in another process without a
        lookup (:attr:`Source.resolved_ref`): what a batch worker or a service planner is sent."""
        return {s.kind: s.resolved_ref for s in self.sources}


def _is_ref(ref: Ref) -> bool:
    return isinstance(ref, (str, os.PathLike))


def _loader(kind: str) -> Any:
    if kind == "robot":
        from ..robot.description import load_robot

        return load_robot
    if kind == "gripper":
        from ..gripper.load import load_gripper

        return load_gripper
    from ..cell.model import load_cell

    return load_cell


def _given_model(kind: str, model: Any) -> tuple[Any, Source]:
    """A model passed in already loaded: its name as the reference and the files it came from."""
    if kind == "robot":
        path = model.config_path
        files = tuple(robot_files(model))
    else:  # a gripper's or cell's source is the YAML it was read from (or a note when it was not)
        source = str(getattr(model, "source", "") or "")
        path = file_input(source) if source.lower().endswith((".yaml", ".yml")) else None
        files = tuple(config_files(kind, path)) if path is not None else ()
    return model, Source(kind, str(getattr(model, "name", "")), Path(path) if path is not None else None, files)


def load_description(kind: str, ref: Ref, cache: Cache | None = None) -> tuple[Any, Source]:
    """The ``kind`` description ``ref`` names (a name, a path or a model already loaded) loaded
    once, and its :class:`Source`. A name is looked up (:func:`grasplan.config.lookup.resolve_yaml`)
    and the YAML it resolves to is loaded by path. Raises what the kind's loader raises (ConfigError,
    exit 3: an unknown name lists the available ones, a bad file names the field). ``cache``: a
    dict kept by the caller, so each ``(kind, reference)`` is loaded once however often it is named."""
    if kind not in KINDS:
        raise ValueError(f"unknown description kind {kind!r}; one of {', '.join(KINDS)}")
    if not _is_ref(ref):
        return _given_model(kind, ref)
    key = (kind, os.fspath(ref))
    if cache is not None and key in cache:
        return cache[key]
    from ..config.lookup import resolve_yaml

    out: tuple[Any, Source]
    if kind == "cell" and isinstance(ref, str) and ref == _no_cell_name():
        out = (_loader("cell")(ref), Source("cell", ref, None))
    else:
        path = resolve_yaml(kind, ref)
        model = _loader(kind)(path)
        out = (model, Source(kind, os.fspath(ref), path, tuple(config_files(kind, path))))
    if cache is not None:
        cache[key] = out
    return out


def _no_cell_name() -> str:
    from ..cell.model import NO_CELL_NAME

    return NO_CELL_NAME


@contextlib.contextmanager
def _config_dirs(dirs: tuple[str | os.PathLike, ...]) -> Iterator[None]:
    if not dirs:
        yield
        return
    from ..config.lookup import use_config_dirs

    with use_config_dirs(*dirs):
        yield


def build_setup(*, robot: Ref | None = None, gripper: Ref | None = None, cell: Ref | None = None,
                config_dirs: tuple[str | os.PathLike, ...] = (), cache: Cache | None = None) -> Setup:
    """The :class:`Setup` of ``robot``, ``gripper`` and ``cell``: each a name, a path or a model
    already loaded (None: not part of this setup), loaded gripper first, then the cell, then the
    robot (the first bad one raises, as its loader does). ``config_dirs``: looked in first for
    names (``--config-dir``; default: the lookup in force). ``cache``: see
    :func:`load_description`."""
    given = {"robot": robot, "gripper": gripper, "cell": cell}
    models: dict[str, Any] = {}
    sources: list[Source] = []
    with _config_dirs(tuple(config_dirs)):
        for kind in KINDS:
            if given[kind] is not None:
                models[kind], src = load_description(kind, given[kind], cache)
                sources.append(src)
    files = tuple(dict.fromkeys(f for s in sources for f in s.files))
    return Setup(robot=models.get("robot"), gripper=models.get("gripper"), cell=models.get("cell"),
                 sources=tuple(sources), files=files)
