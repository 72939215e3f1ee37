"""The robot cell around the part: a table top and where the part rests on it.

World frame: z up. The table top is the plane ``z = table_z`` (default 0) and the table fills
``z < table_z`` (a half-space: it is infinite in x and y). The part rests on the table in a
stable pose (:func:`stable_pose`: the most probable one unless ``pose_index`` says otherwise),
its lowest point on the table top and its centre of mass above ``part_xy`` (default (0.45, 0) m).

YAML schema (``configs/cells/<name>.yaml``; metres)::

    name: table
    table_z: 0.0
    part_xy: [0.45, 0.0]
    pose_index: 0          # which stable pose, 0 = most probable

``--part-pose`` overrides the resting pose: :func:`parse_part_pose`.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
import yaml

from .config_files import CONFIG_DIR, available, config_number, resolve_yaml
from .errors import ConfigError, InputError
from .gripper import rpy_matrix
from .units import parse_angle_deg, parse_length
from .transforms import check_transform

CELL_DIR = CONFIG_DIR / "cells"


@dataclass(frozen=True)
class Cell:
    """A table cell. ``table_z``: height of the table top (m); ``part_xy``: where the part's centre
    of mass rests (m); ``pose_index``: which stable pose (0 = most probable)."""

    name: str
    table_z: float = 0.0
    part_xy: tuple[float, float] = (0.45, 0.0)
    pose_index: int = 0
    source: str = ""

    def to_json(self) -> dict:
        """The ``cell`` block of the grasps output: the name and what defines the cell."""
        return {
            "name": self.name,
            "up": [0.0, 0.0, 1.0],
            "table": {"type": "half_space", "normal": [0.0, 0.0, 1.0], "z": float(self.table_z),
                      "fills": "z < table_z"},
            "part_xy": [float(self.part_xy[0]), float(self.part_xy[1])],
            "pose_index": int(self.pose_index),
        }


def available_cells() -> list[str]:
    """Names of the cells shipped in ``configs/cells/*.yaml``."""
    return available(CELL_DIR)


def cell_from_dict(data, *, name: str, source: str = "") -> Cell:
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: a cell file must be a YAML mapping")
    allowed = {"name", "table_z", "part_xy", "pose_index", "description"}
    unknown = set(data) - allowed
    if unknown:
        raise ConfigError(f"{source}: unknown cell fields {sorted(unknown)}; allowed: {sorted(allowed)}")
    cname = data.get("name", name)
    if not isinstance(cname, str) or not cname:
        raise ConfigError(f"{source}: name: expected a non-empty string")
    table_z = config_number(data.get("table_z", 0.0), "table_z")
    xy = data.get("part_xy", [0.45, 0.0])
    if not isinstance(xy, (list, tuple)) or len(xy) != 2:
        raise ConfigError(f"{source}: part_xy: expected [x, y] in metres, got {xy!r}")
    part_xy = (config_number(xy[0], "part_xy[0]"), config_number(xy[1], "part_xy[1]"))
    pi = data.get("pose_index", 0)
    if isinstance(pi, bool) or not isinstance(pi, int) or pi < 0:
        raise ConfigError(f"{source}: pose_index: expected an integer >= 0, got {pi!r}")
    return Cell(name=cname, table_z=table_z, part_xy=part_xy, pose_index=pi, source=source)


def load_cell(name_or_path: str | os.PathLike = "table") -> Cell:
    """A cell by name (``configs/cells/<name>.yaml``) or path to a YAML file."""
    if isinstance(name_or_path, Cell):
        return name_or_path
    p = resolve_yaml("cell", name_or_path, CELL_DIR)
    try:
        data = yaml.safe_load(p.read_text())
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: not valid YAML: {exc}") from exc
    try:
        return cell_from_dict(data, name=p.stem, source=str(p))
    except ConfigError as exc:
        msg = str(exc)
        raise ConfigError(msg if msg.startswith(str(p)) else f"{p}: {msg}") from None


# -- stable poses ----------------------------------------------------------------------------

def stable_poses(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """Quasi-static resting poses of ``mesh`` on a plane: trimesh's implementation of the toppling
    model (Goldberg et al.; ``trimesh.poses.compute_stable_poses``) with ``sigma = 0``, so no random
    perturbation of the centre of mass: deterministic.

    Returns ``(R (k, 3, 3), prob (k,))``, most probable first (ties: by the resting normal in the
    part frame, so the order is deterministic). ``R`` is ``R_world_part``: it turns the part so
    that it rests on its face; the translation is left to :func:`stable_pose`.
    """
    com = mesh.center_mass if mesh.is_watertight and mesh.volume > 0 else mesh.convex_hull.center_mass
    transforms, probs = trimesh.poses.compute_stable_poses(mesh, center_mass=com, sigma=0.0, n_samples=1, threshold=0.0)
    if len(transforms) == 0:
        return np.zeros((0, 3, 3)), np.zeros(0)
    R = np.asarray(transforms, dtype=np.float64)[:, :3, :3]
    probs = np.asarray(probs, dtype=np.float64)
    down = np.round(np.einsum("kji,j->ki", R, [0.0, 0.0, -1.0]), 6) + 0.0  # resting normal, part frame
    order = np.lexsort((down[:, 2], down[:, 1], down[:, 0], -np.round(probs, 9)))
    return R[order], probs[order] / probs.sum()


def stable_pose(part_mesh: trimesh.Trimesh, cell: Cell | None = None) -> np.ndarray:
    """``T_world_part`` (4, 4): the part resting on the table in stable pose ``cell.pose_index``
    (0 = most probable), lowest point on ``z = table_z``, centre of mass above ``cell.part_xy``."""
    cell = cell or Cell("table")
    R, prob = stable_poses(part_mesh)
    if len(R) == 0:
        raise InputError("the part has no stable resting pose on a plane (is the mesh degenerate?)")
    if cell.pose_index >= len(R):
        raise ConfigError(f"pose_index {cell.pose_index}: the part has only {len(R)} stable poses (0..{len(R) - 1})")
    return place_on_table(part_mesh, R[cell.pose_index], cell)


def place_on_table(part_mesh: trimesh.Trimesh, R_world_part: np.ndarray, cell: Cell) -> np.ndarray:
    """``T_world_part`` with rotation ``R_world_part``, lowest point at ``table_z``, centre of mass
    above ``part_xy``."""
    hull = part_mesh.convex_hull
    com = part_mesh.center_mass if part_mesh.is_watertight and part_mesh.volume > 0 else hull.center_mass
    T = np.eye(4)
    T[:3, :3] = R_world_part
    v = hull.vertices @ R_world_part.T
    c = R_world_part @ com
    T[:3, 3] = [cell.part_xy[0] - c[0], cell.part_xy[1] - c[1], cell.table_z - v[:, 2].min()]
    return T


_POSE_SPLIT = re.compile(r"\s*,\s*")


def parse_part_pose(text: str | os.PathLike) -> np.ndarray:
    """``T_world_part`` from ``--part-pose``.

    Either ``"x,y,z,roll,pitch,yaw"`` (lengths with optional units, bare = metres; angles in
    degrees; R = R_z(yaw) R_y(pitch) R_x(roll)) or a JSON/YAML file holding a 4x4 row-major
    matrix (top level, or under the key ``T_world_part``). The pose is used as given: the part
    may float above or sink into the table (the collision check does not move it)."""
    s = str(text)
    p = Path(s)
    if p.suffix.lower() in (".json", ".yaml", ".yml") or p.is_file():
        if not p.is_file():
            raise InputError(f"--part-pose: file {p} not found")
        try:
            data = yaml.safe_load(p.read_text())  # YAML is a superset of JSON
        except yaml.YAMLError as exc:
            raise InputError(f"--part-pose: {p} is not valid JSON/YAML: {exc}") from exc
        if isinstance(data, dict):
            if "T_world_part" not in data:
                raise InputError(f"--part-pose: {p} has no key 'T_world_part' (a 4x4 row-major matrix)")
            data = data["T_world_part"]
        return check_transform(data, f"--part-pose {p}")
    parts = _POSE_SPLIT.split(s.strip())
    if len(parts) != 6:
        raise InputError(f"--part-pose: expected 'x,y,z,roll,pitch,yaw' (m or with units; degrees) or a JSON/YAML file, got {s!r}")
    xyz = [parse_length(v, name=f"--part-pose {n}", allow_negative=True) for v, n in zip(parts[:3], "xyz")]
    rpy = [math.radians(parse_angle_deg(v, name=f"--part-pose {n}")) for v, n in zip(parts[3:], ("roll", "pitch", "yaw"))]
    T = np.eye(4)
    T[:3, :3] = rpy_matrix(*rpy)
    T[:3, 3] = xyz
    return T
