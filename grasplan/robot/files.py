"""The files a robot description reads, found without loading it: the installed
``example-robot-data`` share folder (``package:`` and ``package://`` root), a URDF's mesh files
resolved as Pinocchio resolves them, their triangles counted before Pinocchio reads them, and an
SRDF's disabled pairs. Light on purpose (no Pinocchio): the output guard asks it which files a
robot YAML names.
"""
from __future__ import annotations

import os
import sys
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path

from ..errors import ConfigError

_PKG_SHARE = "cmeel.prefix/share"


# --------------------------------------------------------------------------------------------
# Finding the installed example-robot-data
# --------------------------------------------------------------------------------------------
@lru_cache(maxsize=None)
def package_share_dir(package: str = "example-robot-data") -> Path:
    """The ``share`` directory holding ``<package>/robots/...`` (the ``package://`` root).

    Looks in every ``sys.path`` entry's ``cmeel.prefix/share`` (where cmeel wheels install it),
    then in the package's installed-files record (``importlib.metadata``, loaded only then: it
    costs a cold process about 0.05 s).
    """
    for entry in sys.path:
        cand = Path(entry) / _PKG_SHARE
        if (cand / package / "robots").is_dir():
            return cand
    import importlib.metadata

    try:
        files = importlib.metadata.files(package) or []
    except importlib.metadata.PackageNotFoundError:
        files = []
    for f in files:
        parts = Path(str(f)).parts
        if package in parts and "robots" in parts:
            full = Path(f.locate()).resolve()
            idx = len(full.parts) - len(parts) + parts.index(package)
            share = Path(*full.parts[:idx])
            if (share / package / "robots").is_dir():
                return share
    raise ConfigError(f"package {package!r} with robot descriptions is not installed "
                      f"(pip install {package}); looked in sys.path's {_PKG_SHARE} and in its installed files")


# --------------------------------------------------------------------------------------------
# Small YAML helpers
# --------------------------------------------------------------------------------------------
def parse_srdf_disabled_pairs(srdf_path: Path) -> tuple[tuple[str, str], ...]:
    """``<disable_collisions link1 link2>`` entries of an SRDF, each pair sorted."""
    try:
        root = ET.parse(srdf_path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ConfigError(f"cannot read SRDF {srdf_path}: {exc}") from None
    pairs: set[tuple[str, str]] = set()
    for el in root.iter("disable_collisions"):
        a, b = el.get("link1"), el.get("link2")
        if a and b:
            pairs.add((a, b) if a <= b else (b, a))
    return tuple(sorted(pairs))


# --------------------------------------------------------------------------------------------
# Robot geometry
# --------------------------------------------------------------------------------------------
#: the most triangles one robot's meshes of one kind (collision, or visual) may hold in all:
#: Pinocchio/coal build about 1M triangles in 5 s of CPU (the shipped robots hold at most 135k)
MAX_ROBOT_TRIANGLES = 1_000_000
#: a URDF larger than this (bytes) is refused before it is parsed
MAX_URDF_BYTES = 50_000_000


def _ros_paths() -> list[str]:
    """The folders Pinocchio also looks in for ``package://`` meshes (``ROS_PACKAGE_PATH``, and
    ``AMENT_PREFIX_PATH`` entries + ``/share``), after the ones it is given."""
    ros = [p for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
    return ros + [p + "/share" for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]


def resolve_mesh_uri(uri: str, package_dirs: Sequence[str]) -> Path | None:
    """The file a URDF ``<mesh filename=...>`` names, found as Pinocchio finds it: ``package://``
    (or ``model://``) and relative paths in the first of ``package_dirs`` (then the ROS folders)
    that holds them, ``file://`` and absolute paths as they are; None when none holds it (or for
    a scheme Pinocchio refuses itself)."""
    dirs = [*package_dirs, *_ros_paths()]
    scheme, sep, rest = uri.partition("://")
    if sep and scheme == "file":
        return Path(rest)
    if sep and scheme not in ("package", "model"):
        return None
    rel = rest if sep else uri
    if not sep and Path(rel).is_absolute():
        return Path(rel)
    return next((Path(d + "/" + rel) for d in dirs if os.path.exists(d + "/" + rel)), None)


def urdf_meshes(urdf_path: Path, package_dirs: Sequence[str], kind: str) -> list[tuple[str, str, Path | None]]:
    """``(link, filename as written, file or None)`` of every ``<mesh>`` of the URDF's ``<collision>``
    (``kind="collision"``) or ``<visual>`` elements, resolved by :func:`resolve_mesh_uri`."""
    from ..config.inputs import read_input_bytes

    try:
        root = ET.fromstring(read_input_bytes(urdf_path, what="URDF", max_bytes=MAX_URDF_BYTES))
    except ET.ParseError as exc:
        raise ConfigError(f"URDF {urdf_path}: not valid XML ({exc}); fix or re-export the robot description") from None
    out = []
    for link in root.iter("link"):
        for el in link.iter(kind):
            for mesh in el.iter("mesh"):
                uri = str(mesh.get("filename") or "")
                out.append((str(link.get("name") or "?"), uri, resolve_mesh_uri(uri, package_dirs) if uri else None))
    return out


def check_robot_meshes(urdf_path: Path, package_dirs: Sequence[str], kind: str, where: Path | str) -> int:
    """Refuse, before Pinocchio loads them, the robot's ``kind`` meshes (``collision`` or ``visual``)
    that are missing, of a format whose triangles grasplan cannot count, larger than the part limits
    (:data:`grasplan.part.mesh.MAX_TRIANGLES` triangles, :data:`grasplan.part.mesh.MAX_FILE_BYTES` bytes:
    counted from the header or in one streaming pass, never loaded) or, together, above
    :data:`MAX_ROBOT_TRIANGLES`; ConfigError naming the mesh file, its triangles and the limit.
    Returns the meshes' triangles in all."""
    from ..errors import MeshError
    from ..part.mesh import MAX_FILE_BYTES, MAX_TRIANGLES
    from ..part.meshfile import COUNTED_SUFFIXES, ReadLimits, count_triangles

    lim = ReadLimits(MAX_TRIANGLES, MAX_FILE_BYTES)
    total, counts = 0, []
    for link, uri, path in urdf_meshes(urdf_path, package_dirs, kind):
        what = f"{where}: field 'urdf': link {link!r} {kind} mesh"
        if path is None:
            raise ConfigError(f"{what} {uri[:200]!r}: not found (looked in {', '.join(package_dirs)}); install the "
                              f"robot's meshes or fix the path in {urdf_path.name}")
        try:
            n = count_triangles(path, lim, suffixes=COUNTED_SUFFIXES)
        except MeshError as exc:
            raise ConfigError(f"{what}: {exc}") from None
        total += n
        counts.append((n, path.name))
    if total > MAX_ROBOT_TRIANGLES:
        big = ", ".join(f"{name} {n:,}" for n, name in sorted(counts, reverse=True)[:3])
        raise ConfigError(f"{where}: field 'urdf': the robot's {kind} meshes hold {total:,} triangles in all, more than "
                          f"grasplan loads for one robot ({MAX_ROBOT_TRIANGLES:,}, grasplan.robot.files.MAX_ROBOT_TRIANGLES; "
                          f"the largest: {big}); decimate them")
    return total
