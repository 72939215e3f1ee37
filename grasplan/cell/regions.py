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
    """The rectangle of world x, y (m) the parts' centres of mass must stay in: ``lo`` .. ``hi``,
    turned by ``yaw_deg`` about its centre (a yawed bin's floor)."""

    lo: tuple[float, float]
    hi: tuple[float, float]
    yaw_deg: float = 0.0

    @classmethod
    def from_config(cls, v: Any, where: str) -> Workspace:
        """From ``{min: [x, y], max: [x, y], yaw_deg: a}`` (``yaw_deg`` optional; a cell YAML or a
        result's cell block); ConfigError naming the field otherwise."""
        if not isinstance(v, dict) or not {"min", "max"} <= set(v) or set(v) - {"min", "max", "yaw_deg"}:
            raise ConfigError(f"{where}: expected {{min: [x, y], max: [x, y]}} (world, m; optional yaw_deg about "
                              f"its centre), got {str(v)[:60]!r}")
        lo: list[float] = []
        hi: list[float] = []
        for key, out in (("min", lo), ("max", hi)):
            xy = v[key]
            if not isinstance(xy, (list, tuple)) or len(xy) != 2:
                raise ConfigError(f"{where}.{key}: expected [x, y] in metres, got {str(xy)[:40]!r}")
            out.extend(config_number(c, f"{where}.{key}[{i}]", max_abs=MAX_CELL_COORD_M) for i, c in enumerate(xy))
        if not (lo[0] < hi[0] and lo[1] < hi[1]):
            raise ConfigError(f"{where}: min {lo} must be below max {hi} in x and y")
        yaw = config_number(v.get("yaw_deg", 0.0), f"{where}.yaw_deg", max_abs=360.0)
        return cls((lo[0], lo[1]), (hi[0], hi[1]), float(yaw))

    def _local(self, v: np.ndarray, *, point: bool) -> tuple[float, float]:
        """World x, y of a point (or a direction) in the rectangle's frame (centre, turned by the yaw)."""
        a = math.radians(self.yaw_deg)
        x = float(v[0]) - (0.5 * (self.lo[0] + self.hi[0]) if point else 0.0)
        y = float(v[1]) - (0.5 * (self.lo[1] + self.hi[1]) if point else 0.0)
        return math.cos(a) * x + math.sin(a) * y, -math.sin(a) * x + math.cos(a) * y

    def contains(self, xy: np.ndarray) -> bool:
        """Whether the world point ``xy`` (2+,) lies inside (the boundary included, 1 nm)."""
        p = self._local(xy, point=True)
        return all(abs(p[k]) <= 0.5 * (self.hi[k] - self.lo[k]) + 1e-9 for k in range(2))

    def travel_inside(self, xy: np.ndarray, direction: np.ndarray) -> float:
        """How far (m) the point ``xy`` (inside) may move along the world ``direction`` (its x, y)
        and stay inside; ``inf`` along a direction with no horizontal part."""
        p, d = self._local(xy, point=True), self._local(direction, point=False)
        t = math.inf
        for k in range(2):
            h = 0.5 * (self.hi[k] - self.lo[k])
            if d[k] > 1e-12:
                t = min(t, (h - p[k]) / d[k])
            elif d[k] < -1e-12:
                t = min(t, (-h - p[k]) / d[k])
        return max(t, 0.0)

    def to_json(self) -> dict:
        out: dict[str, Any] = {"min": [float(self.lo[0]), float(self.lo[1])],
                               "max": [float(self.hi[0]), float(self.hi[1])]}
        if self.yaw_deg:
            out["yaw_deg"] = float(self.yaw_deg)
        return out
