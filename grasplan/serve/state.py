"""What a running service holds warm: its parts (by name), robot, gripper, cell, grasp databases
and picker. Built once per worker process (:meth:`Service.start`); nothing here imports FastAPI.

A part's name is its mesh file's stem in ``--parts`` (``TLess20.stl`` -> ``TLess20``), by the rule
``scene drop`` and ``clutter`` name parts with (:func:`grasplan.piles.scene_file.part_name`), so a
pile they write can be posted to ``/pick``; names are valid scene names
(:data:`grasplan.piles.scene_file.NAME_RE`), so a client can only ever name a part the folder holds.
Each part's grasp database is ``NAME.graspdb.npz`` next to its mesh when there
is one, else it comes from the cache or is computed when the service starts
(:func:`grasplan.grasps.graspdb.database_for`, through the picker), with a progress line per part.
"""
from __future__ import annotations

import importlib.util
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import InputError
from ..part.meshfile import SUPPORTED_SUFFIXES
from ..piles.scene_file import MAX_PARTS, NAME_RE, NAME_RULE, PART_NAME_RULE, name_parts
from .config import ServeConfig

if TYPE_CHECKING:
    from ..setup.resolved import Setup

#: a part's grasp database kept next to its mesh (``grasplan database PART -o NAME.graspdb.npz``)
SIDE_DB_SUFFIX = ".graspdb.npz"
#: a request's planning budget is this share of its time limit (the rest: queueing, the JSON)
BUDGET_SHARE = 0.8


@dataclass(frozen=True)
class PartEntry:
    """One part of the service: ``name`` (the file's stem), the mesh ``path`` (server side, never
    shown to clients) and the loaded :class:`grasplan.part.mesh.Part`."""

    name: str
    path: Path
    part: Any  # grasplan.part.mesh.Part (loaded with Pinocchio-free modules only)

    def to_json(self) -> dict[str, Any]:
        p = self.part
        return {"name": self.name, "file": self.path.name, "sha256": p.sha256, "scale_to_m": float(p.scale_to_m),
                "units": p.units, "triangles": int(p.triangles)}


def scan_parts(folder: Path, warn: Callable[[str], None]) -> dict[str, Path]:
    """``{name: mesh path}`` of the meshes in ``folder`` (not recursive), in file-name order; a part's
    name is :func:`grasplan.piles.scene_file.part_name` of its file (the stem as written, as ``scene
    drop`` and ``clutter`` name it). Two meshes that give one name are an InputError naming both."""
    meshes = [p for p in sorted(folder.iterdir()) if p.suffix.lower() in SUPPORTED_SUFFIXES and p.is_file()]
    named = name_parts([p.name for p in meshes], where=f"--parts {folder}")
    out = {name: folder / f for name, f in named.items()}
    for name, p in out.items():
        if name != p.stem:
            warn(f"{p.name}: part name {name!r} (a part's name is {PART_NAME_RULE})")
    if not out:
        raise InputError(f"--parts {folder}: no part meshes ({', '.join(SUPPORTED_SUFFIXES)}) in it")
    if len(out) > MAX_PARTS:
        raise InputError(f"--parts {folder}: {len(out)} parts; a service holds at most {MAX_PARTS}")
    return out


def process_rss_mib(pid: int | None = None) -> float | None:
    """The resident memory of process ``pid`` (None: this one) in MiB, from ``/proc``; None where
    it cannot be read (no ``/proc``, the process is gone)."""
    try:
        with open(f"/proc/{'self' if pid is None else int(pid)}/status", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return round(int(line.split()[1]) / 1024.0, 1)
    except (OSError, ValueError, IndexError):
        pass
    return None


def picker_available() -> bool:
    """True when this build has :mod:`grasplan.pick` (the picker of ``POST /pick``)."""
    return importlib.util.find_spec("grasplan.pick") is not None


class Service:
    """The warm state of one worker: see the module docstring. Built by :meth:`start`; ``setup``:
    the robot, gripper and cell (:class:`~grasplan.setup.resolved.Setup`), resolved once."""

    def __init__(self, config: ServeConfig, *, setup: Setup, parts: dict[str, PartEntry], picker: Any | None,
                 started_s: float, available: dict[str, list[str]] | None = None):
        self.config = config
        self.setup = setup
        self.parts = parts
        self.picker = picker
        self.started_s = started_s
        #: the robot and gripper names grasplan knows (GET /robots, /grippers), looked up at start
        self.available = available or {"robots": [], "grippers": []}
        self._by_sha = {(e.part.sha256): e for e in parts.values()}

    @property
    def robot(self) -> Any:
        """The :class:`~grasplan.robot.model.Robot` every plan and pick is for."""
        return self.setup.robot

    @property
    def gripper(self) -> Any:
        """The :class:`~grasplan.gripper.model.Gripper` every plan and pick uses."""
        return self.setup.gripper

    @property
    def cell(self) -> Any:
        """The :class:`~grasplan.cell.model.Cell` every plan and pick is in."""
        return self.setup.cell

    @classmethod
    def start(cls, config: ServeConfig, progress: Callable[[str], None] = lambda s: None) -> Service:
        """Load the robot, gripper, cell and every part; with ``config.databases`` also each part's
        grasp database and the picker. InputError/ConfigError (exit 3) for anything unusable."""
        from ..config.lookup import use_config_dirs
        from ..gripper.load import available_grippers
        from ..part.mesh import load_part
        from ..robot.description import available_robots
        from ..setup.resolved import build_setup

        t0 = time.perf_counter()
        with use_config_dirs(*config.config_dirs):
            setup = build_setup(robot=config.robot, gripper=config.gripper, cell=config.cell)
            available = {"robots": available_robots(), "grippers": available_grippers()}
        robot, gripper, cell = setup.robot, setup.gripper, setup.cell
        assert robot is not None and gripper is not None and cell is not None  # build_setup loaded each
        progress(f"robot {robot.name}, gripper {gripper.name}, cell {cell.name} ({time.perf_counter() - t0:.1f} s)")
        parts: dict[str, PartEntry] = {}
        for name, path in scan_parts(config.parts_dir, lambda w: progress(f"warning: {w}")).items():
            p = load_part(path, units=config.units)
            parts[name] = PartEntry(name, path, p)
            progress(f"part {name}: {p.triangles} triangles ({p.units_note})")
        picker = None
        if config.databases and picker_available():
            picker = _warm_picker(config, robot, gripper, cell, parts, progress)
        elif config.databases:
            progress("warning: this build has no grasplan.pick; POST /pick answers 503")
        progress(f"ready: {len(parts)} parts in {time.perf_counter() - t0:.1f} s")
        return cls(config, setup=setup, parts=parts, picker=picker, started_s=time.time(), available=available)

    def with_config(self, config: ServeConfig) -> Service:
        """This warm state served with other limits (token, body size, time limit, queue); the
        robot, gripper, cell, parts and picker stay the ones loaded."""
        return Service(config, setup=self.setup, parts=self.parts, picker=self.picker, started_s=self.started_s,
                       available=self.available)

    def resolved_config(self, config: ServeConfig) -> ServeConfig:
        """``config`` with the robot, gripper and cell given as the files this service loaded them
        from (:meth:`~grasplan.setup.resolved.Setup.resolved_refs`): what a planner process starts
        from, so that it loads the same files without looking a name up again."""
        refs = self.setup.resolved_refs()
        return replace(config, robot=refs["robot"], gripper=refs["gripper"], cell=refs["cell"])

    # -- look-ups ------------------------------------------------------------------------------
    def part(self, name: Any, where: str = "part") -> PartEntry:
        """The part called ``name``; InputError naming ``where`` and listing the parts otherwise
        (a name with a path in it is refused as such: the service reads no file a client names)."""
        if not isinstance(name, str):
            raise InputError(f"{where}: expected a part name (a string), got {type(name).__name__}")
        if not NAME_RE.match(name):
            shown = name[:60].encode("unicode_escape").decode("ascii")
            raise InputError(f"{where}: {shown!r} is not a part name ({NAME_RULE}); the service takes parts by "
                             f"name from its parts folder, never a path; its parts: {', '.join(self.parts)}")
        if name not in self.parts:
            raise InputError(f"{where}: unknown part {name!r}; the service's parts: {', '.join(self.parts)}")
        return self.parts[name]

    def part_by_sha256(self, sha: Any) -> PartEntry | None:
        return self._by_sha.get(sha) if isinstance(sha, str) else None

    def info(self) -> dict[str, Any]:
        """What ``GET /health`` reports besides the status."""
        return {"robot": self.robot.name, "gripper": self.gripper.name, "cell": self.cell.name,
                "parts": len(self.parts), "pick": self.picker is not None,
                "uptime_s": round(time.time() - self.started_s, 3)}


def _warm_picker(config: ServeConfig, robot: Any, gripper: Any, cell: Any, parts: dict[str, PartEntry],
                 progress: Callable[[str], None]) -> Any:
    """A :class:`grasplan.Picker` holding every part with its grasp database: ``NAME.graspdb.npz``
    next to the mesh when there is one (refused for another part or gripper), else from the cache
    or computed now (:func:`grasplan.grasps.graspdb.database_for`); the planning budget is capped below
    the request time limit."""
    from ..pick import Picker, PickParams

    picker = Picker(robot, gripper=gripper, cell=cell, params=PickParams(budget_s=BUDGET_SHARE * config.time_limit_s),
                    progress=lambda line: progress(f"  {line}"))
    for name, e in parts.items():
        t = time.perf_counter()
        side = e.path.with_name(name + SIDE_DB_SUFFIX)
        picker.add_part(name, e.part, grasps=side if side.is_file() else None)
        how = f"from {side.name}" if side.is_file() else "from the cache or computed"
        progress(f"part {name}: grasp database ready ({how}, {time.perf_counter() - t:.1f} s)")
    t = time.perf_counter()
    picker.warm()  # the parts' depth probes and voxel grids now, not in the first request
    progress(f"depth probes and voxel grids of {len(parts)} part(s) ready ({time.perf_counter() - t:.1f} s)")
    return picker
