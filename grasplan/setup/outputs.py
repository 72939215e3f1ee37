"""The one output guard: before any work, every file a command will write (its ``-o`` file and every
companion: KRL's ``.dat``, ``--pose-index all``'s ``OUT.pose<k>.json``, a batch's summary files) is
checked against every file the command reads, and against what the output path itself is (a
folder, a device, a system folder, an installed file: :func:`grasplan.io.check_output_path`). One
that would replace an input is refused with :class:`~grasplan.errors.InputError` (exit 3) naming
both. The inputs: the files named on the command line; a :class:`~grasplan.setup.resolved.Setup`'s
files (the gripper, cell and robot YAMLs and the files they name: :func:`config_files`,
:func:`robot_yaml_files`); the files a document the command reads names, once it is loaded
(:func:`result_files`, :func:`picks_files`, :func:`scene_files`). Writing is :mod:`grasplan.io`'s.
"""
from __future__ import annotations

import os
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from ..errors import GrasplanError, InputError
from ..io import check_output_path, show_path

PathLike = str | os.PathLike

#: most mesh files of one URDF that count as inputs (the robot loader caps the URDF's size)
MAX_URDF_MESHES = 10_000


def config_input(kind: str, name_or_path: str | os.PathLike | None) -> Path | None:
    """The file a ``--gripper``/``--cell``/``--robot`` name or path reads (None when it names no
    file: the loader reports that later, naming what exists)."""
    if name_or_path is None:
        return None
    from ..config.lookup import resolve_yaml

    try:
        return resolve_yaml(kind, name_or_path)
    except (InputError, OSError, ValueError):
        return None


#: keys of a gripper/cell YAML whose text values name further files next to it
_FILE_KEYS = ("path", "urdf", "srdf")


def _path_text(v: object) -> str | None:
    """``v`` when it can be a file name (a non-empty string without NUL, under 4096 characters)."""
    return v if isinstance(v, str) and v and "\x00" not in v and len(v) < 4096 else None


def config_files(kind: str, name_or_path: str | os.PathLike | None) -> list[Path]:
    """:func:`config_input` and the files its YAML names (a cell's or gripper's mesh ``path``
    relative to the YAML; a robot's files: :func:`robot_yaml_files`): everything a description
    reads. A YAML that cannot be read yields just its own path (its loader reports the problem later)."""
    y = config_input(kind, name_or_path)
    if y is None:
        return []
    from ..config.yamlfile import read_yaml_file

    try:
        doc = read_yaml_file(y, what=f"{kind} file")
    except InputError:
        return [y]
    if kind == "robot":
        return robot_yaml_files(y, doc)
    out, stack = [y], [doc]
    seen: set[int] = set()
    while stack and len(seen) < 100_000:
        node = stack.pop()
        if id(node) in seen:  # an alias (possibly recursive: a: &a [*a]) is walked once
            continue
        seen.add(id(node))
        if isinstance(node, dict):
            for k, v in node.items():
                if k in _FILE_KEYS and _path_text(v):
                    out.append(y.parent / v)
                elif isinstance(v, (dict, list)):
                    stack.append(v)
        elif isinstance(node, list):
            stack += [v for v in node if isinstance(v, (dict, list))]
    return out


def robot_yaml_files(yaml_path: Path, doc: object) -> list[Path]:
    """The robot YAML ``yaml_path`` (parsed: ``doc``) and the files it makes the robot loader read,
    resolved as :mod:`grasplan.robot.description` resolves them: ``urdf``/``srdf`` relative to the installed
    package's ``robots/`` folder when ``package`` is given (:func:`grasplan.robot.files.package_share_dir`),
    else relative to the YAML; then the URDF's meshes (:func:`urdf_mesh_files`)."""
    out = [yaml_path]
    if not isinstance(doc, dict):
        return out
    package = doc.get("package")
    if package is not None:
        from ..robot.files import package_share_dir

        try:
            share = package_share_dir(str(package))
        except (GrasplanError, OSError, ValueError):
            return out  # not installed: the loader says so
        root, dirs = share / str(package) / "robots", [share]
    else:
        root, dirs = yaml_path.parent, [yaml_path.parent]
    urdf, srdf = (_path_text(doc.get(key)) for key in ("urdf", "srdf"))
    files = [Path(v) if Path(v).is_absolute() else root / v for v in (urdf, srdf) if v is not None]
    return out + files + (urdf_mesh_files(files[0], dirs) if urdf is not None else [])


def robot_files(robot: Any) -> list[Path]:
    """The files a loaded :class:`~grasplan.robot.model.Robot` was built from: its YAML (when it
    came from one), URDF, SRDF and the URDF's meshes in its ``package_dirs``."""
    if robot is None:
        return []
    out = [Path(p) for p in (robot.config_path, robot.urdf_path, robot.srdf_path) if p]
    if robot.urdf_path:
        out += urdf_mesh_files(Path(robot.urdf_path), [Path(d) for d in robot.package_dirs])
    return out


def urdf_mesh_files(urdf: Path, package_dirs: Sequence[Path]) -> list[Path]:
    """The mesh files the URDF's links load (``<collision>`` and ``<visual>`` meshes), found as the
    robot loader finds them (:func:`grasplan.robot.files.urdf_meshes`: ``package://`` in
    ``package_dirs``, then the ROS folders); an unreadable URDF names nothing (its loader reports
    it). At most :data:`MAX_URDF_MESHES` distinct files."""
    from ..robot.files import urdf_meshes

    dirs = [str(d) for d in package_dirs]
    out: dict[Path, None] = {}
    for kind in ("collision", "visual"):
        try:
            meshes = urdf_meshes(urdf, dirs, kind)
        except (GrasplanError, OSError, ValueError, RecursionError):
            break
        out.update((path, None) for _, _, path in meshes if path is not None)
    return list(out)[:MAX_URDF_MESHES]


def _recorded(path: object, search_dirs: Iterable[Path | None] = ()) -> list[Path]:
    """Where a reader looks for a path recorded in a document: as written (absolute), else in the
    current folder and in each of ``search_dirs``."""
    v = _path_text(path)
    if v is None:
        return []
    p = Path(v)
    if p.is_absolute():
        return [p]
    return [Path.cwd() / p, *(Path(d) / p for d in search_dirs if d is not None)]


def scene_files(scene: Any) -> list[Path]:
    """The files a loaded :class:`~grasplan.piles.scene_file.Scene` names, relative to its folder as the
    planner resolves them: part meshes, grasp databases, the cloud, and a cell given as a path
    (with the files that YAML names)."""
    out: list[Path] = []
    for part in scene.parts:
        out += [scene.resolve(v) for v in (part.mesh, part.grasps) if _path_text(v)]
    if scene.cloud is not None and _path_text(scene.cloud.path):
        out.append(scene.resolve(scene.cloud.path))
    cell = _path_text(scene.cell)
    if cell is not None:
        from ..config.lookup import document_ref, is_path_like

        if is_path_like(cell, scene.base):
            out += config_files("cell", document_ref(cell, scene.base))
    return out


def picks_files(picks: Any) -> list[Path]:
    """The files a loaded picks result (:class:`~grasplan.pick.result.PickResult`) names, as its
    reader looks for them: every part's recorded path (also in its scene's folder), the scene's
    files (:func:`scene_files`) and the robot's (:func:`robot_files`)."""
    base = picks.scene.base
    out = [p for rec in picks.parts.values() if isinstance(rec, dict) for p in _recorded(rec.get("path"), [base])]
    return out + scene_files(picks.scene) + robot_files(picks.robot)


def result_files(res: Any) -> list[Path]:
    """The files a loaded grasps or plan result (:class:`~grasplan.results.plan_result.PlanResult`) names, as its
    reader looks for them: the part's recorded path (in the current folder, next to the file, and
    its name next to the file) and, for a plan, the robot's files (:func:`robot_files`)."""
    folder = res.origin.parent if res.origin is not None else None
    out = _recorded(res.part.path, [folder])
    if folder is not None and _path_text(res.part.path):
        out.append(folder / Path(res.part.path).name)
    return out + robot_files(res.robot)


def file_input(path: PathLike | None) -> Path | None:
    """``path`` when it names an existing file (``--part-pose`` may be a pose text instead)."""
    if path is None:
        return None
    try:
        text = os.fspath(path)
        if isinstance(text, bytes) or "\x00" in text or len(text) > 4096:
            return None
        p = Path(text)
        return p if p.exists() else None
    except (OSError, ValueError, TypeError):
        return None


class _Files:
    """Files found by resolved path or by inode (a hard link), each resolved once, so checking
    k outputs against n inputs costs k + n resolutions, not k x n."""

    def __init__(self) -> None:
        self.by_path: dict[str, Path] = {}
        self.by_inode: dict[tuple[int, int], Path] = {}

    @staticmethod
    def _keys(p: PathLike) -> tuple[str | None, tuple[int, int] | None]:
        try:
            real = os.path.realpath(p)
        except (OSError, ValueError):
            return None, None
        try:
            st = os.stat(real)
            return real, (st.st_dev, st.st_ino)
        except (OSError, ValueError):
            return real, None

    def add(self, p: Path, shown: Path | None = None) -> None:
        real, inode = self._keys(p)
        if real is not None:
            self.by_path.setdefault(real, shown or p)
        if inode is not None:
            self.by_inode.setdefault(inode, shown or p)

    def find(self, p: PathLike) -> Path | None:
        real, inode = self._keys(p)
        hit = self.by_path.get(real) if real is not None else None
        if hit is None and inode is not None:
            hit = self.by_inode.get(inode)
        return hit


def check_outputs(outputs: Sequence[PathLike], *, inputs: Iterable[PathLike | None] = (),
                  families: Iterable[tuple[PathLike, str]] = (), option: str = "-o") -> list[Path]:
    """Check every output path a command will write, before any work; return them as Paths.

    ``outputs``: the files written (the first is the one the user named; the others its
    companions); ``inputs``: every file read (None entries skipped); ``families``: ``(folder,
    regex)`` of file names the command may write in ``folder`` whose exact names are known only
    later (``OUT\\.pose\\d+\\.json``): an input there matching ``regex`` is refused as well.
    Raises :class:`InputError` (exit 3) naming the output, the input it would replace and the fix.
    """
    ins = [Path(os.fsdecode(i)) for i in inputs if i is not None]
    read = _Files()
    for i in ins:
        read.add(i)
    written = _Files()
    out: list[Path] = []
    first = show_path(outputs[0]) if outputs else ""
    for k, o in enumerate(outputs):
        what = option if k == 0 else f"{option} {first}: its companion file"
        p = check_output_path(o, inputs=(), create_parents=True, option=what)
        hit = read.find(p)
        if hit is not None:
            also = "" if k == 0 else f" (written with {first})"
            raise InputError(f"{option}: {show_path(p)}{also} is also an input ({show_path(hit)}); writing it "
                             f"would overwrite the input: choose another output name")
        if written.find(p) is not None:
            raise InputError(f"{option}: {show_path(p)} would be written twice; choose another output name")
        written.add(p)
        out.append(p)
    for folder, pattern in families:
        rx = re.compile(pattern)
        there = _Files()
        there.add(Path(folder))
        for i in ins:
            if rx.fullmatch(i.name) and there.find(i.parent) is not None:
                raise InputError(f"{option} {first}: the command also writes files named like {show_path(i.name)} "
                                 f"next to it, and {show_path(i)} is an input; choose another output name")
    return out
