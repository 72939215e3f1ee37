"""What the planner of a clutter round sees: the parts' poses as a pose estimator would give them
(off by a pose error drawn once per part and round, :func:`draw_errors`) and only the parts a
camera above the bin sees enough of (:func:`visible`; :mod:`grasplan.clutter.occlusion`).
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..errors import InputError
from ..geometry.units import parse_angle_deg, parse_length
from ..part.mesh import Part


def parse_pose_noise(text: str) -> tuple[float, float]:
    """``--pose-noise 2mm,2deg`` -> (0.002 m, 2.0 deg); InputError naming what would pass."""
    parts = [p.strip() for p in str(text).split(",")]
    example = "e.g. --pose-noise 2mm,2deg (a position error and an angle; 0,0 for ground truth)"
    if len(parts) != 2 or not all(parts):
        raise InputError(f"--pose-noise {text!r}: expected LENGTH,ANGLE, {example}")
    try:
        m = parse_length(parts[0], name="length", allow_zero=True)
        deg = parse_angle_deg(parts[1])
    except (InputError, ValueError) as exc:
        raise InputError(f"--pose-noise {text!r}: {exc}; {example}") from None
    if not (math.isfinite(m) and 0.0 <= m <= 0.05):
        raise InputError(f"--pose-noise {text!r}: the position error must be 0..50 mm, got {m * 1e3:g} mm")
    if not (math.isfinite(deg) and 0.0 <= deg <= 45.0):
        raise InputError(f"--pose-noise {text!r}: the angle must be 0..45 deg, got {deg:g} deg")
    return float(m), float(deg)


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.standard_normal(3)
    return v / np.linalg.norm(v)


def draw_error(noise_m: float, noise_deg: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One pose error: a shift (3,) of length ``noise_m`` (m) in a uniformly random direction and
    a turn R (3, 3) by ``noise_deg`` about a uniformly random axis. Draws 6 normals from ``rng``."""
    from scipy.spatial.transform import Rotation

    d = _unit(rng) * noise_m
    R = Rotation.from_rotvec(_unit(rng) * math.radians(noise_deg)).as_matrix()
    return d, R


def apply_error(T_world_part: np.ndarray, com: np.ndarray, d: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``T_world_part`` turned by ``R`` about its centre of mass ``com`` (3, part frame) and moved
    by ``d`` (3, world): the pose estimate of a part whose estimator is off by (d, R)."""
    T = np.array(T_world_part, dtype=np.float64)
    c = T[:3, :3] @ com + T[:3, 3]
    out = np.eye(4)
    out[:3, :3] = R @ T[:3, :3]
    out[:3, 3] = c + R @ (T[:3, 3] - c) + d
    return out


def perturb(T_world_part: np.ndarray, com: np.ndarray, noise_m: float, noise_deg: float,
            rng: np.random.Generator) -> np.ndarray:
    """``T_world_part`` moved ``noise_m`` (m) in a uniformly random direction and turned
    ``noise_deg`` about a uniformly random axis through the part's centre of mass ``com`` (3,
    part frame): a pose estimate off by exactly that much. Draws 6 normals from ``rng``."""
    d, R = draw_error(noise_m, noise_deg, rng)
    return apply_error(T_world_part, com, d, R)


def draw_errors(ids: Sequence[str], noise: tuple[float, float],
                rng: np.random.Generator) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """One pose error per instance for a whole round (:func:`draw_error`, in the order of
    ``ids``): the estimator is off the same way each time it sees a part, as a real one is for a
    part that has not moved (a new draw per planning call would let a planner average it away)."""
    return {k: draw_error(noise[0], noise[1], rng) for k in ids}


def noise_reach(parts: Sequence[Part], noise: tuple[float, float]) -> float:
    """How far (m) the pose noise moves any point of these parts: ``noise_m`` plus the chord the
    turn sweeps at the point farthest from its centre of mass (bounded here by the farthest vertex
    from the vertex centroid, doubled: a safe bound for any centre inside the part's hull). A
    planner that refuses parts below the bin floor beyond a tolerance needs that much more."""
    if noise[0] <= 0 and noise[1] <= 0:
        return 0.0
    reach = max(2.0 * float(np.linalg.norm(p.vertices - p.vertices.mean(axis=0), axis=1).max()) for p in parts)
    return float(noise[0] + 2.0 * reach * math.sin(0.5 * math.radians(noise[1])))
