"""The part-frame grasps a pick starts from: one set per (part, gripper), computed once.

:func:`part_grasps` is the one place the picker gets them. It computes the grasps of the part
alone (no table, no obstacle: a cell whose table lies far below the part) with
:func:`grasplan.grasps.compute_grasps` and keeps the collision-free poses, best score first, as a
:class:`PartGrasps` (the fields of the grasp database of issue 20, ``grasplan.graspdb``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..cell import Cell
from ..gripper.model import Gripper
from ..mesh import Part
from ..params import CandidateParams, GraspParams
from ..status import Status

#: the table of the part-alone cell lies this far (m) below the part frame's origin
_FAR_BELOW = 100.0
#: grasp sets kept in memory per process (most recently used), keyed by part, gripper and options
_MEMORY: dict[tuple, PartGrasps] = {}
MEMORY_SETS = 8


@dataclass(frozen=True, eq=False)
class PartGrasps:
    """Part-frame grasps checked against the part alone, rows sorted by score (descending).

    ``T_part_tcp`` (N, 4, 4), ``width`` (N,) contact distance m, ``contacts`` / ``normals`` (N, 2, 3)
    part frame, ``score`` (N,) in [0, 1], ``quality`` per-row columns (``gravity_margin``,
    ``epsilon``, ...), ``part_sha256`` and ``gripper`` they belong to."""

    part_sha256: str
    gripper: Gripper
    T_part_tcp: np.ndarray
    width: np.ndarray
    contacts: np.ndarray
    normals: np.ndarray
    score: np.ndarray
    quality: dict[str, np.ndarray]

    def __len__(self) -> int:
        return int(len(self.width))


def part_grasps(part: Part, gripper: Gripper, *, candidates: CandidateParams = CandidateParams(),
                grasps: GraspParams = GraspParams()) -> PartGrasps:
    """The collision-free grasps of ``part`` alone for ``gripper`` (see the module docstring);
    the last :data:`MEMORY_SETS` sets computed in this process are reused."""
    import json

    key = (part.sha256, part.scale_to_m, json.dumps(gripper.to_json(definition=True), sort_keys=True, default=str),
           json.dumps(candidates.to_json(), sort_keys=True), json.dumps(grasps.to_json(), sort_keys=True))
    hit = _MEMORY.pop(key, None)
    if hit is None:
        hit = _compute(part, gripper, candidates, grasps)
    _MEMORY[key] = hit
    while len(_MEMORY) > MEMORY_SETS:
        _MEMORY.pop(next(iter(_MEMORY)))
    return hit


def _compute(part: Part, gripper: Gripper, candidates: CandidateParams, grasps: GraspParams) -> PartGrasps:
    from ..grasps import compute_grasps

    alone = Cell(name="none", table_z=-_FAR_BELOW, part_xy=(0.0, 0.0))
    gr = compute_grasps(part, gripper=gripper, cell=alone, candidates=candidates, grasps=grasps,
                        T_world_part=np.eye(4))
    table = gr.table()
    ok = np.flatnonzero(np.asarray(table.status).astype(str) == Status.OK.value)
    score = np.nan_to_num(np.asarray(table.score, dtype=np.float64)[ok], nan=0.0)
    order = ok[np.lexsort((ok, -score))]
    quality: dict[str, np.ndarray] = {}
    for name in ("gravity_margin", "epsilon", "contact_area", "contact_type"):
        col = getattr(table, name)
        if col is not None:
            quality[name] = np.asarray(col)[order]
    return PartGrasps(part_sha256=part.sha256, gripper=gripper,
                      T_part_tcp=np.ascontiguousarray(table.T_part_tcp[order]),
                      width=np.asarray(table.width, dtype=np.float64)[order],
                      contacts=np.asarray(table.contacts, dtype=np.float64)[order],
                      normals=np.asarray(table.normals, dtype=np.float64)[order],
                      score=np.nan_to_num(np.asarray(table.score, dtype=np.float64)[order], nan=0.0),
                      quality=quality)
