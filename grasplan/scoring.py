"""The grasp score: a weighted sum of registered terms, each in [0, 1] (higher is better).

``score = sum_k w_k * term_k / sum_k w_k`` with the weights of ``PlanParams.score_weights``
(default ``center 0.4, top 0.4, width 0.2``). A term is a function
``term(ctx: ScoreContext) -> (M,) float in [0, 1]`` registered with :func:`register_term`;
adding one is a function plus one registration.

Default terms::

    center = 1 - min(1, |c_grasp - c_mass| / r_part)   grasp centre (TCP origin) close to the centre
             of mass (of the watertight part, else its mesh centroid); r_part = half the part's
             bounding-box diagonal
    top    = max(0, -z_tcp . z_world)                  approach from above (1: TCP z straight down)
    width  = (max_opening - width) / max_opening       margin to the gripper's maximum opening
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ScoreContext:
    """What a score term may read: ``T_part_tcp`` (M, 4, 4), ``width`` (M,) m, the part's mesh (part
    frame, metres), ``T_world_part`` (4, 4), the gripper's ``max_opening`` (m)."""

    part_mesh: object
    T_world_part: np.ndarray
    T_part_tcp: np.ndarray
    width: np.ndarray
    max_opening: float


TERMS: dict[str, Callable[[ScoreContext], np.ndarray]] = {}


def register_term(name: str):
    """Decorator: register ``fn(ctx) -> (M,) in [0, 1]`` as score term ``name``."""
    def deco(fn):
        TERMS[name] = fn
        return fn
    return deco


@register_term("center")
def _center(ctx: ScoreContext) -> np.ndarray:
    m = ctx.part_mesh
    com = np.asarray(m.center_mass if m.is_watertight else m.centroid, dtype=np.float64)
    r = 0.5 * float(np.linalg.norm(m.extents))
    d = np.linalg.norm(ctx.T_part_tcp[:, :3, 3] - com, axis=1)
    return 1.0 - np.minimum(1.0, d / max(r, 1e-12))


@register_term("top")
def _top(ctx: ScoreContext) -> np.ndarray:
    z_world = np.einsum("ij,mj->mi", ctx.T_world_part[:3, :3], ctx.T_part_tcp[:, :3, 2])
    return np.maximum(0.0, -z_world[:, 2])


@register_term("width")
def _width(ctx: ScoreContext) -> np.ndarray:
    return np.clip((ctx.max_opening - ctx.width) / ctx.max_opening, 0.0, 1.0)


def score_grasps(part_mesh, T_world_part, T_part_tcp, width, max_opening: float,
                 weights=None) -> np.ndarray:
    """Score in [0, 1] per grasp (higher is better). ``T_part_tcp`` (M, 4, 4), ``width`` (M,) m.

    ``weights``: ``((term, weight), ...)``; default ``PlanParams().score_weights``."""
    from .params import DEFAULT_SCORE_WEIGHTS

    T_part_tcp = np.asarray(T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    width = np.asarray(width, dtype=np.float64).reshape(-1)
    if len(width) != len(T_part_tcp):
        raise ValueError("T_part_tcp (M, 4, 4) and width (M,) disagree")
    ctx = ScoreContext(part_mesh, np.asarray(T_world_part, dtype=np.float64), T_part_tcp, width, float(max_opening))
    weights = tuple(weights if weights is not None else DEFAULT_SCORE_WEIGHTS)
    total = sum(w for _, w in weights)
    out = np.zeros(len(width))
    for name, w in weights:
        if w:
            out += w * TERMS[name](ctx)
    return out / total if total > 0 else out


def distinct_order(T_part_tcp: np.ndarray, order: np.ndarray, *, min_distance: float = 0.005,
                   min_angle_deg: float = 15.0) -> np.ndarray:
    """Reorder ``order`` (best first) so that no two of the leading grasps are within
    ``min_distance`` (TCP origins) **and** ``min_angle_deg`` (relative rotation of the TCP frames)
    of each other while distinct grasps remain: a near-duplicate of an already chosen grasp moves
    behind every distinct one (keeping its relative order). ``min_distance = 0`` keeps ``order``."""
    order = np.asarray(order, dtype=np.int64)
    if min_distance <= 0 or len(order) < 2:
        return order
    from scipy.spatial import cKDTree

    T = np.asarray(T_part_tcp, dtype=np.float64)[order]
    p = T[:, :3, 3]
    R = T[:, :3, :3]
    cos_min = np.cos(np.radians(min_angle_deg))
    tree = cKDTree(p)
    chosen = np.zeros(len(order), dtype=bool)
    dup = np.zeros(len(order), dtype=bool)
    # greedy in rank order; a grasp is a duplicate if a chosen grasp is close in position and rotation
    neighbours = tree.query_ball_point(p, r=min_distance)
    for k in range(len(order)):
        if dup[k]:
            continue
        chosen[k] = True
        nb = np.asarray([j for j in neighbours[k] if j > k and not dup[j] and not chosen[j]], dtype=np.int64)
        if len(nb):
            # angle of R_k^T R_j: trace = 1 + 2 cos(theta)
            tr = np.einsum("ij,nij->n", R[k], R[nb])
            close = (tr - 1.0) / 2.0 >= cos_min - 1e-9  # a roll of exactly the angle counts as close
            dup[nb[close]] = True
    return np.concatenate([order[chosen], order[dup]])
