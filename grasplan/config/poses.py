"""Poses from configuration: a YAML field's pose (``{xyz, rpy_deg}`` or a 4x4 matrix,
:func:`parse_pose`) and ``--part-pose`` (a pose text or a JSON/YAML file, :func:`parse_part_pose`).
Poses on the command line alone: :func:`grasplan.geometry.transforms.parse_pose_text`."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, InputError
from ..geometry.transforms import check_transform, parse_pose_text, rpy_matrix
from .lookup import config_vector
from .yamlfile import read_yaml_file


def parse_pose(v: Any, where: str, *, matrix: bool = True, require_xyz: bool = False,
               max_coord: float | None = None, max_deg: float | None = None) -> np.ndarray:
    """A (4, 4) rigid transform from a config field: ``{xyz: [m], rpy_deg: [deg]}`` (R = Rz(yaw)
    Ry(pitch) Rx(roll); missing keys are zeros unless ``require_xyz``) or, with ``matrix``, a
    nested 4x4 row-major list. ``max_coord`` (m) / ``max_deg`` bound the position and the angles.
    ConfigError naming ``where`` and what would pass."""
    if matrix and isinstance(v, (list, tuple)) and len(v) == 4:
        T = np.array([config_vector(r, f"{where}[{i}]", 4) for i, r in enumerate(v)])
        return check_transform(T, where, error=ConfigError)
    if not isinstance(v, dict):
        forms = "a 4x4 matrix (list of 4 rows) or " if matrix else ""
        raise ConfigError(f"{where}: expected {forms}{{xyz: [x, y, z] (m), rpy_deg: [roll, pitch, yaw] (deg)}}, "
                          f"got {str(v)[:60]!r}")
    unknown = set(v) - {"xyz", "rpy_deg"}
    if unknown:
        raise ConfigError(f"{where}: unknown keys {sorted(map(str, unknown))}; valid: ['rpy_deg', 'xyz']")
    if require_xyz and "xyz" not in v:
        raise ConfigError(f"{where}.xyz: missing (the position [x, y, z] in metres)")
    T = np.eye(4)
    T[:3, 3] = config_vector(v.get("xyz", [0, 0, 0]), f"{where}.xyz")
    if max_coord is not None and np.abs(T[:3, 3]).max() > max_coord:
        raise ConfigError(f"{where}.xyz: coordinates must be within {max_coord} m of the origin")
    rpy = config_vector(v.get("rpy_deg", [0, 0, 0]), f"{where}.rpy_deg")
    if max_deg is not None and np.abs(rpy).max() > max_deg:
        raise ConfigError(f"{where}.rpy_deg: angles in degrees, at most {max_deg:g} in magnitude")
    T[:3, :3] = rpy_matrix(*np.radians(rpy))
    return T


def parse_part_pose(text: str | os.PathLike) -> np.ndarray:
    """``T_world_part`` from ``--part-pose``.

    Either ``"x,y,z,roll,pitch,yaw"`` (:func:`parse_pose_text`) or a JSON/YAML file holding a 4x4
    row-major matrix (top level, or under the key ``T_world_part``). The pose is used as given: the
    part may float above or sink into the table (the collision check does not move it)."""
    s = str(text)
    if len(s) > 4096 or "\x00" in s:
        raise InputError("--part-pose: expected 'x,y,z,roll,pitch,yaw' or a JSON/YAML file with T_world_part")
    p = Path(s)
    try:
        is_file = p.is_file()
    except OSError:  # e.g. a name too long for the file system: not a file
        is_file = False
    if p.suffix.lower() in (".json", ".yaml", ".yml") or is_file:
        if not is_file:
            raise InputError(f"--part-pose: file {p} not found")
        data = read_yaml_file(p, what="--part-pose file", max_bytes=1_000_000)  # YAML is a superset of JSON
        if isinstance(data, dict):
            if "T_world_part" not in data:
                raise InputError(f"--part-pose: {p} has no key 'T_world_part' (a 4x4 row-major matrix)")
            data = data["T_world_part"]
        return check_transform(data, f"--part-pose {p}")
    return parse_pose_text(s, "--part-pose", "or a JSON/YAML file")
