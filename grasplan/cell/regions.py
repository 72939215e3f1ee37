"""Where a part may go in a cell: the straight retreat after a grasp (``retreat:`` of a cell YAML)
and the workspace the parts must stay in while a pile is cleared (``workspace:``): a push does not
move a part's centre of mass out of it (:mod:`grasplan.pick.push`). docs/cells.md."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config.lookup import config_number, config_vector
from ..errors import ConfigError
from ..geometry.transforms import MAX_CELL_COORD_M

DEFAULT_RETREAT_DIRECTION = (0.0, 0.0, 1.0)
DEFAULT_RETREAT_DISTANCE = 0.10


def retreat_from(r: Any, where: str) -> tuple[tuple[float, float, float], float]:
    """``(unit direction, distance m)`` of a ``retreat: {direction: [x, y, z], distance: m}`` block."""
    if not isinstance(r, dict):
        raise ConfigError(f"{where}: expected {{direction: [x, y, z], distance: m}}, got {str(r)[:60]!r}")
    unknown = set(r) - {"direction", "distance"}
    if unknown:
        raise ConfigError(f"{where}: unknown keys {sorted(map(str, unknown))}; valid: ['direction', 'distance']")
    d = config_vector(r.get("direction", list(DEFAULT_RETREAT_DIRECTION)), f"{where}.direction")
    n = float(np.linalg.norm(d))
    if not n > 1e-9:
        raise ConfigError(f"{where}.direction: must not be zero (a world direction, e.g. [0, 0, 1] = straight up)")
    dist = config_number(r.get("distance", DEFAULT_RETREAT_DISTANCE), f"{where}.distance", nonneg=True, max_abs=2.0)
    if not 0.0 <= dist <= 2.0:
        raise ConfigError(f"{where}.distance: expected 0..2 m, got {dist}")
    u = d / n
    return (float(u[0]), float(u[1]), float(u[2])), float(dist)


@dataclass(frozen=True)
class Workspace:
    """The rectangle of world x, y (m) ``lo`` .. ``hi`` the parts' centres of mass must stay in."""

    lo: tuple[float, float]
    hi: tuple[float, float]

    @classmethod
    def from_config(cls, v: Any, where: str) -> Workspace:
        """From ``{min: [x, y], max: [x, y]}`` (a cell YAML or a result's cell block); ConfigError
        naming the field otherwise."""
        if not isinstance(v, dict) or set(v) != {"min", "max"}:
            raise ConfigError(f"{where}: expected {{min: [x, y], max: [x, y]}} (world, m), got {str(v)[:60]!r}")
        lo: list[float] = []
        hi: list[float] = []
        for key, out in (("min", lo), ("max", hi)):
            xy = v[key]
            if not isinstance(xy, (list, tuple)) or len(xy) != 2:
                raise ConfigError(f"{where}.{key}: expected [x, y] in metres, got {str(xy)[:40]!r}")
            out.extend(config_number(c, f"{where}.{key}[{i}]", max_abs=MAX_CELL_COORD_M) for i, c in enumerate(xy))
        if not (lo[0] < hi[0] and lo[1] < hi[1]):
            raise ConfigError(f"{where}: min {lo} must be below max {hi} in x and y")
        return cls((lo[0], lo[1]), (hi[0], hi[1]))

    def contains(self, xy: np.ndarray) -> bool:
        """Whether the world point ``xy`` (2+,) lies inside (the boundary included)."""
        return bool(self.lo[0] <= xy[0] <= self.hi[0] and self.lo[1] <= xy[1] <= self.hi[1])

    def travel_inside(self, xy: np.ndarray, direction: np.ndarray) -> float:
        """How far (m) the point ``xy`` (inside) may move along the world ``direction`` (its x, y)
        and stay inside; ``inf`` along a direction with no horizontal part."""
        t = math.inf
        for k in range(2):
            d = float(direction[k])
            if d > 1e-12:
                t = min(t, (self.hi[k] - float(xy[k])) / d)
            elif d < -1e-12:
                t = min(t, (self.lo[k] - float(xy[k])) / d)
        return max(t, 0.0)

    def to_json(self) -> dict:
        return {"min": [float(self.lo[0]), float(self.lo[1])], "max": [float(self.hi[0]), float(self.hi[1])]}
