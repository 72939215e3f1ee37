"""``grasplan.pick.lift.inside_walls`` (a lifted part stays within the bin's walls) skips the hull
points that no shift can carry past a wall; its verdict must be the one of moving every point."""
from __future__ import annotations

import math

import numpy as np

from grasplan.cell.model import BinSpec
from grasplan.pick.lift import WALL_SLACK, inside_walls


def _every_point(hull_world: np.ndarray, shifts: np.ndarray, b: BinSpec) -> bool:
    """The reference: every hull point moved by every shift, in the bin frame."""
    T = np.asarray(b.T_world_bin, dtype=np.float64)
    p0 = (hull_world - T[:3, 3]) @ T[:3, :3]
    s = shifts @ T[:3, :3]
    half = 0.5 * np.asarray(b.inner)
    out0 = np.maximum(np.abs(p0[:, :2]) - half, 0.0)
    for sk in s:
        p = p0 + sk
        beyond = np.abs(p[:, :2]) - half - out0 - WALL_SLACK
        if np.any((beyond > 0).any(axis=1) & (p[:, 2] < b.height)):
            return False
    return True


def test_inside_walls_matches_moving_every_point():
    rng = np.random.default_rng(7)
    seen = {True: 0, False: 0}
    for _ in range(600):
        yaw = rng.uniform(-math.pi, math.pi)
        T = np.eye(4)
        T[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
        T[:3, 3] = [rng.uniform(0.3, 0.6), rng.uniform(-0.2, 0.2), 0.01]
        b = BinSpec(inner=(0.30, 0.20), wall=0.01, height=0.15, T_world_bin=T)
        # a part's hull: points around a centre anywhere in the bin, some already past a wall
        c = np.array([rng.uniform(-0.17, 0.17), rng.uniform(-0.12, 0.12), rng.uniform(0.0, 0.05)])
        pts = c + rng.normal(scale=rng.uniform(0.005, 0.03), size=(rng.integers(4, 200), 3))
        hull_world = pts @ T[:3, :3].T + T[:3, 3]
        # a lift: a direction tilted up to 60 deg from straight up, steps up to 0.1 m
        tilt, az = rng.uniform(0, math.radians(60)), rng.uniform(-math.pi, math.pi)
        d = np.array([math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az), math.cos(tilt)])
        steps = np.sort(rng.uniform(0, 0.1, rng.integers(1, 30)))
        shifts = steps[:, None] * d
        got, want = inside_walls(hull_world, shifts, b), _every_point(hull_world, shifts, b)
        assert got == want, (got, want, c, d, steps)
        seen[want] += 1
    assert min(seen.values()) > 50, seen  # both verdicts were exercised
    assert inside_walls(np.zeros((3, 3)), np.zeros((1, 3)), None)
    assert inside_walls(np.zeros((3, 3)), np.zeros((0, 3)), b)  # no shift: nothing moves
