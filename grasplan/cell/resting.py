"""The part resting in a cell: one of its stable poses (:func:`grasplan.part.stability.stable_poses`)
on the cell's support, lowest point on the table top (or the bin floor's top), centre of mass above
``cell.part_xy``. Lengths in metres."""
from __future__ import annotations

import numpy as np

from ..errors import ConfigError, InputError
from ..geometry.meshdata import TriangleMesh
from ..part.stability import part_centre_of_mass, stable_poses
from .model import Cell


def stable_pose(part_mesh: TriangleMesh, cell: Cell | None = None) -> np.ndarray:
    """``T_world_part`` (4, 4): the part resting on the table in stable pose ``cell.pose_index``
    (0 = most probable), lowest point on ``z = table_z``, centre of mass above ``cell.part_xy``."""
    cell = cell or Cell("table")
    R, prob = stable_poses(part_mesh)
    if len(R) == 0:
        raise InputError("the part has no stable resting pose on a plane (is the mesh degenerate?)")
    if cell.pose_index >= len(R):
        raise ConfigError(f"pose_index {cell.pose_index}: the part has only {len(R)} stable poses (0..{len(R) - 1})")
    return place_on_table(part_mesh, R[cell.pose_index], cell)


def place_on_table(part_mesh: TriangleMesh, R_world_part: np.ndarray, cell: Cell) -> np.ndarray:
    """``T_world_part`` (4, 4) with rotation ``R_world_part`` (3, 3), lowest point at ``cell.rest_z``
    (the table top, or the bin floor's top),
    centre of mass (:func:`part_centre_of_mass`) above ``part_xy`` (metres)."""
    com = part_centre_of_mass(part_mesh)
    T = np.eye(4)
    T[:3, :3] = R_world_part
    z_min = float((np.asarray(part_mesh.vertices) @ R_world_part[2]).min())  # lowest point of the turned part
    c = R_world_part @ com
    T[:3, 3] = [cell.part_xy[0] - c[0], cell.part_xy[1] - c[1], cell.rest_z - z_min]
    return T
