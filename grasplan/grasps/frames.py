"""Stage 5: TCP poses from contact pairs, rolled about the closing axis.

:func:`grasp_frames` poses every candidate at every roll angle (:func:`roll_angles`); the frame is
defined in :class:`GraspFrames`. Repeated and swapped contact pairs are dropped first
(:func:`unique_pairs`), so every ``(contact pair, roll)`` is emitted exactly once.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..candidates.antipodal_base import Candidates
from ..config.params import GraspParams


@dataclass(frozen=True)
class GraspFrames:
    """TCP poses in the part frame.

    For candidate ``i`` with contacts ``c0, c1`` (part frame):

    * origin = (c0 + c1) / 2;
    * x = (c1 - c0) / |c1 - c0| (closing axis, contact 0 -> contact 1);
    * z (approach, the fingers point along +z) turns about x: ``z(roll) = cos(roll) z0 + sin(roll) (x cross z0)``
      for ``roll = 0, step, 2 step, ... < 360 deg``;
    * y = z cross x (right-handed).

    Roll 0 (``z0``) is the direction closest to ``reference`` (default: part-frame -z, i.e. an
    approach from above when the part frame's z is up; :func:`grasplan.grasps.pipeline.compute_grasps` passes
    the world's down direction in the part frame) that is perpendicular to x. When x is within
    about 0.06 deg of ``reference`` the fallback reference is ``-e_k`` with ``k`` the axis of the
    smallest ``|x_k|``.

    T_part_tcp : (M, 4, 4) float64
    candidate : (M,) int64, index into the candidates the frames were built from
    roll : (M,) float64, radians in [0, 2 pi)
    """

    T_part_tcp: np.ndarray
    candidate: np.ndarray
    roll: np.ndarray

    def __post_init__(self) -> None:
        m = len(self.candidate)
        if self.T_part_tcp.shape != (m, 4, 4) or self.roll.shape != (m,):
            raise ValueError(f"GraspFrames: shapes {self.T_part_tcp.shape}, {self.candidate.shape}, {self.roll.shape} disagree")

    def __len__(self) -> int:
        return int(len(self.candidate))

    def subset(self, index: np.ndarray | slice) -> "GraspFrames":
        return GraspFrames(self.T_part_tcp[index], self.candidate[index], self.roll[index])


def roll_angles(roll_step_deg: float) -> np.ndarray:
    """Roll angles (rad): ``k * step`` for every k with ``k * step < 360 deg``."""
    step = float(roll_step_deg)
    if not (math.isfinite(step) and 0.0 < step <= 360.0):
        raise ValueError(f"roll_step_deg must be in (0, 360], got {roll_step_deg!r}")
    n = int(math.ceil(360.0 / step - 1e-9))
    return np.radians(np.arange(n, dtype=np.float64) * step)


def unique_pairs(candidates: Candidates, *, resolution: float = 1e-9) -> np.ndarray:
    """(n,) bool: True for the first occurrence of each unordered contact pair.

    For a gripper that is symmetric under a 180 deg turn about its z axis, the pose ``(x, z)`` and
    ``(-x, z)`` are the same grasp. The roll sweep of one candidate never repeats a z, so duplicates
    only come from a candidate listed twice with its contacts swapped (or listed twice outright):
    :func:`grasp_frames` drops such candidates (keeping the first one in the list).

    Contacts are compared on a grid of ``resolution`` metres (``floor(c / resolution)``): the
    default 1e-9 m finds exact repeats; a coarser grid (``merge_distance``) also merges
    near-identical candidates (contacts in the same grid cells, in either order)."""
    n = len(candidates)
    if n == 0:
        return np.zeros(0, dtype=bool)
    c = np.floor(candidates.contacts / float(resolution)).astype(np.int64)
    a, b = c[:, 0], c[:, 1]
    # order the two contacts lexicographically so that (a, b) and (b, a) give the same key
    swap = np.zeros(n, dtype=bool)
    undecided = np.ones(n, dtype=bool)
    for k in range(3):
        lt, gt = a[:, k] < b[:, k], a[:, k] > b[:, k]
        swap |= undecided & gt
        undecided &= ~(lt | gt)
    first = np.where(swap[:, None], b, a)
    second = np.where(swap[:, None], a, b)
    key = np.concatenate([first, second], axis=1)
    _, idx = np.unique(key, axis=0, return_index=True)
    keep = np.zeros(n, dtype=bool)
    keep[idx] = True  # np.unique returns the first index of each key
    return keep


def grasp_frames(
    candidates: Candidates,
    *,
    roll_step_deg: float = GraspParams.default("roll_step_deg"),
    reference: np.ndarray | None = None,
    max_width: float | None = None,
    min_width: float = 0.0,
    dedupe_swapped: bool = True,
    merge_distance: float = 0.0,
    select: np.ndarray | None = None,
) -> GraspFrames:
    """TCP poses for every candidate and roll angle (vectorised).

    Parameters
    ----------
    candidates : Candidates, n pairs in the part frame
    roll_step_deg : roll step about the closing axis, degrees (0, 360]
    reference : (3,) direction (part frame) that roll 0 approaches along as closely as possible
    max_width : candidates wider than this (m) are not posed (``None``: all)
    min_width : candidates narrower than this (m) are not posed (the jaws close no further:
        ``Gripper.min_opening``)
    dedupe_swapped : drop repeated / swapped contact pairs (right for a symmetric gripper)
    merge_distance : > 0: also drop a candidate whose two contacts fall in the same
        ``merge_distance`` grid cells as an earlier candidate's (in either order when
        ``dedupe_swapped``); 0 drops exact repeats only
    select : optional (k,) int indices of the candidates that may be posed (e.g. from
        :func:`grasplan.candidates.thinning.thin_candidates`); the others are not posed

    Returns
    -------
    GraspFrames with M = (posed candidates) x (roll steps) poses, candidate-major order.
    """
    rolls = roll_angles(roll_step_deg)
    n = len(candidates)
    use = np.ones(n, dtype=bool)
    if max_width is not None:
        use &= candidates.width <= float(max_width)
    if min_width > 0:
        use &= candidates.width >= float(min_width)
    if select is not None:
        allowed = np.zeros(n, dtype=bool)
        allowed[np.asarray(select, dtype=np.int64)] = True
        use &= allowed
    if n and (dedupe_swapped or merge_distance > 0):
        res = float(merge_distance) if merge_distance > 0 else 1e-9
        if dedupe_swapped:
            use &= unique_pairs(candidates, resolution=res)
        else:
            key = np.floor(candidates.contacts.reshape(n, 6) / res).astype(np.int64)
            _, first = np.unique(key, axis=0, return_index=True)
            keep = np.zeros(n, dtype=bool)
            keep[first] = True
            use &= keep
    idx = np.flatnonzero(use).astype(np.int64)
    if len(idx) == 0:
        return GraspFrames(np.zeros((0, 4, 4)), np.zeros(0, dtype=np.int64), np.zeros(0))
    c = candidates.contacts[idx]
    d = c[:, 1] - c[:, 0]
    length = np.linalg.norm(d, axis=1)
    if np.any(length <= 0):
        raise ValueError("a candidate has coincident contacts (zero width): no closing axis")
    x = d / length[:, None]
    mid = 0.5 * (c[:, 0] + c[:, 1])

    r = np.array([0.0, 0.0, -1.0]) if reference is None else np.asarray(reference, dtype=np.float64).reshape(3)
    r = r / np.linalg.norm(r)
    ref = np.broadcast_to(r, x.shape).copy()
    near = np.abs(x @ r) > 1.0 - 5e-7  # x within ~0.06 deg of the reference
    if near.any():
        k = np.argmin(np.abs(x[near]), axis=1)
        alt = np.zeros((int(near.sum()), 3))
        alt[np.arange(len(k)), k] = -1.0
        ref[near] = alt
    z0 = ref - np.sum(ref * x, axis=1, keepdims=True) * x
    z0 /= np.linalg.norm(z0, axis=1, keepdims=True)
    w = np.cross(x, z0)

    cr, sr = np.cos(rolls), np.sin(rolls)
    z = cr[None, :, None] * z0[:, None, :] + sr[None, :, None] * w[:, None, :]  # (n, K, 3)
    xx = np.broadcast_to(x[:, None, :], z.shape)
    y = np.cross(z, xx)
    T = np.zeros((len(idx), len(rolls), 4, 4))
    T[..., :3, 0] = xx
    T[..., :3, 1] = y
    T[..., :3, 2] = z
    T[..., :3, 3] = mid[:, None, :]
    T[..., 3, 3] = 1.0
    M = len(idx) * len(rolls)
    return GraspFrames(
        T.reshape(M, 4, 4),
        np.repeat(idx, len(rolls)),
        np.tile(rolls, len(idx)),
    )
