"""Which instance to try first and which of its grasps (the accessibility rule, docs/pick.md).

Instances: fewest neighbours on top first, then highest first. A neighbour is *on top* of an
instance when their world boxes overlap in x and y and the neighbour's box centre is higher; ties
by the top of the box (higher first), then scene order. So of a stacked pair the upper part is
tried first, and a part under another is tried last (it is usually blocked by it).

Grasps of an instance: the part-frame grasps posed in the world (``T_world_part @ T_part_tcp``);
those whose approach (the TCP's z axis) is more than ``max_tilt_deg`` from straight down are not
tried (the gripper would come from below or through the bin's side); the rest are ranked by
``score + vertical_weight * cos(tilt)`` (descending, ties by row), ``score`` being the database's
(:mod:`grasplan.grasps.graspdb`: the part upright in its own frame; recomputing it per pose costs ~20 us
a grasp, too much for every grasp of every instance; the chosen pick records the score and the
gravity margin at its instance's pose).
"""
from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence

import numpy as np

from .params import PickParams

#: grasps gripper-checked per step while looking for collision-free ones
CHECK_CHUNK = 256
#: the first steps are smaller (the best-ranked grasps are often free, and a pick waits for its
#: step's check: 32 grasps take ~1.5 ms, 256 ~12 ms); then CHECK_CHUNK
FIRST_CHUNKS = (32, 32, 64, 128)


def instance_order(ids: Sequence[str], boxes: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> list[str]:
    """``ids`` in trying order; ``boxes[id] = (centre (3,), half extents (3,))`` world boxes."""
    c = np.array([boxes[i][0] for i in ids]).reshape(-1, 3)
    h = np.array([boxes[i][1] for i in ids]).reshape(-1, 3)
    overlap_xy = np.all(np.abs(c[:, None, :2] - c[None, :, :2]) < h[:, None, :2] + h[None, :, :2], axis=2)
    higher = c[None, :, 2] > c[:, None, 2]  # [i, j]: j's centre above i's
    on_top = (overlap_xy & higher).sum(axis=1)
    top = c[:, 2] + h[:, 2]
    order = np.lexsort((np.arange(len(ids)), -top, on_top))
    return [ids[k] for k in order]


def on_top_counts(ids: Sequence[str], boxes: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> dict[str, int]:
    """How many neighbours lie on top of each instance (the first key of :func:`instance_order`)."""
    c = np.array([boxes[i][0] for i in ids]).reshape(-1, 3)
    h = np.array([boxes[i][1] for i in ids]).reshape(-1, 3)
    overlap_xy = np.all(np.abs(c[:, None, :2] - c[None, :, :2]) < h[:, None, :2] + h[None, :, :2], axis=2)
    return {i: int(n) for i, n in zip(ids, (overlap_xy & (c[None, :, 2] > c[:, None, 2])).sum(axis=1))}


def rank_grasps(T_world_part: np.ndarray, T_part_tcp: np.ndarray, score: np.ndarray, params: PickParams
                ) -> tuple[np.ndarray, np.ndarray]:
    """``(rows in trying order (k,), T_world_tcp (k, 4, 4))`` of the grasps an instance tries."""
    R = T_world_part[:3, :3]
    down = -(R[2] @ T_part_tcp[:, :3, 2].T)  # cos of the approach's angle to straight down
    keep = np.flatnonzero(down >= params.cos_max_tilt - 1e-12)
    key = score[keep] + params.vertical_weight * down[keep]
    rows = keep[np.lexsort((keep, -key))]
    return rows, T_world_part @ T_part_tcp[rows]


def check_chunks(n: int) -> Iterator[tuple[int, int]]:
    """``(start, end)`` of the gripper-check steps over ``n`` ranked grasps: FIRST_CHUNKS, then CHECK_CHUNK."""
    c0, sizes = 0, iter(FIRST_CHUNKS)
    while c0 < n:
        c1 = c0 + next(sizes, CHECK_CHUNK)
        yield c0, min(c1, n)
        c0 = c1
