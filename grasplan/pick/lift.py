"""The lift of a pick from a pile: its direction and what it may touch (docs/pick.md, "The lift").

A pick lifts the part in the jaws along the cell's retreat (straight up in the bin cell) when it
can. When that straight lift is blocked (it drags the part through a neighbour, or no grasp's
gripper and arm can follow it), the planner tries the tilted lifts of :func:`lift_directions`:
:data:`LIFT_TILTS_DEG` from the retreat in :data:`LIFT_AZIMUTHS` azimuths, the smaller tilts first
and, per tilt, those leading farthest away from the neighbour the straight lift touched and from
the bin walls the part is near (``away``; those leading towards them are not tried). A lift is
still one straight TCP line of the retreat's distance (a 45 deg lift raises the part by 71 % of
it), planned and checked as the straight one is (the part alone against the pile, then the gripper
and the arm per grasp); a tilted lift must also keep the part inside the bin's walls until it is
above the rim (:func:`inside_walls`). The pick records its own lift (``Pick.T_world_lifted``, the
motion's ``lift`` segment). How deep the part may touch a neighbour: :class:`RestDepth`.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from ..cell.model import BinSpec
from .budget import UNLIMITED, Budget
from .depth import PartDepth, pair_depth

#: tilts (deg) of the lifts tried when the straight one is blocked, smallest first
LIFT_TILTS_DEG = (15.0, 30.0, 45.0)
#: azimuths per tilt (evenly spaced about the retreat; the first along the world x axis)
LIFT_AZIMUTHS = 8
#: lift directions (whose part-alone lift is free) motion-planned per grasp, best first
LIFTS_PER_GRASP = 3
#: :meth:`RestDepth.exceeds` looks at every COARSE-th surface sample first
COARSE = 8
#: a part this close (m) to a bin wall is "near" it: its tilted lifts lead away from the wall first
WALL_NEAR = 0.01
#: a tilted lift may take a point of the part at most this far (m) beyond where it already was
#: outside the bin's inner walls (the part slides along a wall it touches)
WALL_SLACK = 0.0005


def _basis(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to ``u`` and to each other (the first along world x when
    ``u`` is world z)."""
    ref = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = ref - (ref @ u) * u
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(u, e1)


def lift_directions(retreat: np.ndarray, away: np.ndarray | None = None, max_tilt_deg: float = 90.0
                    ) -> list[tuple[float, np.ndarray]]:
    """``[(tilt_deg, unit direction)]``: the straight lift (``retreat``, tilt 0) first, then per tilt
    of :data:`LIFT_TILTS_DEG` up to ``max_tilt_deg`` its :data:`LIFT_AZIMUTHS` directions, those most
    along ``away`` (a world vector; its part along the retreat is ignored) first, ties by azimuth;
    with a non-zero ``away`` only the azimuths within 90 deg of it (a lift leading towards what
    blocked the straight one is not tried)."""
    u = np.asarray(retreat, dtype=np.float64)
    u = u / np.linalg.norm(u)
    e1, e2 = _basis(u)
    a = np.zeros(3) if away is None else np.asarray(away, dtype=np.float64) - (np.asarray(away) @ u) * u
    n = float(np.linalg.norm(a))
    a = a / n if n > 1e-12 else np.zeros(3)
    out: list[tuple[float, np.ndarray]] = [(0.0, u)]
    phi = 2.0 * math.pi * np.arange(LIFT_AZIMUTHS) / LIFT_AZIMUTHS
    h = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    along = np.round(h @ a, 9)
    order = [int(k) for k in np.lexsort((np.arange(LIFT_AZIMUTHS), -along)) if n <= 1e-12 or along[k] >= 0.0]
    for tilt in LIFT_TILTS_DEG:
        if tilt > max_tilt_deg + 1e-9:
            break
        t = math.radians(tilt)
        out += [(float(tilt), math.cos(t) * u + math.sin(t) * h[k]) for k in order]
    return out


def wall_away(hull_world: np.ndarray, b: BinSpec | None) -> np.ndarray:
    """Sum of the inward normals (world) of the bin walls within :data:`WALL_NEAR` of the part's
    hull vertices ``hull_world`` (k, 3); zero without a bin."""
    if b is None:
        return np.zeros(3)
    p = b.to_bin(hull_world)
    ix, iy = 0.5 * b.inner[0], 0.5 * b.inner[1]
    out = np.zeros(3)
    for axis, half in ((0, ix), (1, iy)):
        if p[:, axis].max() > half - WALL_NEAR:
            out[axis] -= 1.0
        if p[:, axis].min() < -half + WALL_NEAR:
            out[axis] += 1.0
    return np.asarray(b.T_world_bin, dtype=np.float64)[:3, :3] @ out


def inside_walls(hull_world: np.ndarray, shifts: np.ndarray, b: BinSpec | None) -> bool:
    """True when the part (its hull vertices ``hull_world`` (k, 3)) moved by each shift (m, 3)
    stays within the bin's inner walls wherever it is below their top (each point at most
    :data:`WALL_SLACK` beyond where it already was outside them)."""
    if b is None or not len(shifts):
        return True
    p0 = b.to_bin(hull_world)
    T = np.asarray(b.T_world_bin, dtype=np.float64)
    s = np.asarray(shifts, dtype=np.float64).reshape(-1, 3) @ T[:3, :3]  # bin-frame shifts
    half = 0.5 * np.asarray(b.inner, dtype=np.float64)
    out0 = np.maximum(np.abs(p0[:, :2]) - half, 0.0)  # (k, 2) how far each point is already outside
    # a point moves towards a wall at most by the shifts' largest component that way: the points
    # that do not reach past a wall so (most of them) are not moved one by one
    room = half + out0 + WALL_SLACK - 1e-12
    near = np.any((p0[:, :2] + s[:, :2].max(axis=0) > room) | (p0[:, :2] + s[:, :2].min(axis=0) < -room), axis=1)
    p0, out0 = p0[near], out0[near]
    p = p0[None] + s[:, None]  # (m, k, 3)
    beyond = np.abs(p[..., :2]) - half - out0[None] - WALL_SLACK
    below = p[..., 2] < b.height
    return not bool(np.any((beyond > 0).any(axis=2) & below))


class RestDepth:
    """Depth of the carried part into its neighbours relative to their resting interpenetration:
    ``excess(T_world_part, names)`` = the largest ``depth(T) - rest`` over the neighbours
    ``names``, each rest depth measured once at the part's resting pose and counted up to ``cap``.
    ``depth_of(name) -> (PartDepth, T_world)`` gives a neighbour's probes and pose.

    Beyond ``lift_contact`` the part in the jaws may touch a neighbour only as deep as
    ``lift_depth`` (``tol``) measured this way: poses from a pose estimator put touching neighbours
    a little into each other, and a lift that does not push the part deeper into such a neighbour
    does not drag it through. The resting depth counted is at most the scene's ``overlap_tol``
    (``cap``; deeper is a warning of the scene checks: the poses are wrong there)."""

    def __init__(self, part: PartDepth, T_rest: np.ndarray, depth_of: Callable[[str], tuple[PartDepth, np.ndarray]],
                 *, tol: float, cap: float, budget: Budget = UNLIMITED):
        self.part, self.T_rest, self.depth_of = part, np.asarray(T_rest, dtype=np.float64), depth_of
        self.tol, self.cap, self.budget = float(tol), float(cap), budget
        self._rest: dict[str, float] = {}
        self._exceeds: dict[tuple[bytes, tuple[str, ...]], bool] = {}  # a lift raising a neighbour redoes a clean one's

    def rest(self, name: str) -> float:
        """How deep (m, at most ``cap``) the part at rest is in neighbour ``name``."""
        d = self._rest.get(name)
        if d is None:
            b, T_b = self.depth_of(name)
            # exact up to cap
            d = min(pair_depth(self.part, self.T_rest, b, T_b, cap=self.cap, budget=self.budget), self.cap)
            self._rest[name] = d
        return d

    def exceeds(self, T_world_part: np.ndarray, names: list[str]) -> bool:
        """``excess(T_world_part, names) > tol``, decided first on every :data:`COARSE`-th surface
        sample of both parts (a depth found among some samples is at most the one found among all,
        so "deeper" there is "deeper" for :meth:`excess` too; a deep contact is found in a fraction
        of the time), else by :meth:`excess` itself; remembered per pose and names."""
        key = (np.asarray(T_world_part, dtype=np.float64).tobytes(), tuple(names))
        v = self._exceeds.get(key)
        if v is None:
            v = self._exceeds[key] = self._exceeds_now(T_world_part, names)
        return v

    def _exceeds_now(self, T_world_part: np.ndarray, names: list[str]) -> bool:
        for n in names:
            r = self.rest(n)
            b, T_b = self.depth_of(n)
            if pair_depth(self.part, T_world_part, b, T_b, stop=self.tol + r, step=COARSE, budget=self.budget) - r \
                    > self.tol:
                return True
        return self.excess(T_world_part, names) > self.tol

    def excess(self, T_world_part: np.ndarray, names: list[str], *, exact: bool = False) -> float:
        """Largest depth beyond the resting one (m) of the part at ``T_world_part`` into ``names``;
        stops once above ``tol`` (the answer is then a lower bound) unless ``exact`` (for a report)."""
        out = -np.inf
        for n in names:
            r = self.rest(n)
            b, T_b = self.depth_of(n)
            out = max(out, pair_depth(self.part, T_world_part, b, T_b, stop=np.inf if exact else self.tol + r,
                                      budget=self.budget) - r)
            if out > self.tol and not exact:
                break
        return float(max(out, 0.0)) if names else 0.0


def free_to_rise(world: Any, part: str, T_world_part: np.ndarray, shifts: np.ndarray, pile: list[Any],
                 rest: RestDepth, neighbours: set[str]) -> bool:
    """Whether a part (``part`` at ``T_world_part``, in a :class:`grasplan.pick.world.PickWorld`)
    moved alone by each of ``shifts`` (its straight lift) touches none of ``pile`` (the other
    instances and the cloud) deeper than ``rest`` allows (the neighbours in ``neighbours``; any
    contact with the others): nothing lies on it or holds it down, so a part under it that rises
    raises it (``lift_carry``, docs/pick.md)."""
    hits = world.part_hits(part, T_world_part, shifts, pile,
                           lambda T, b: b.name in neighbours and not rest.exceeds(T, [b.name]), first_only=True)
    return not bool(np.any(np.asarray(hits) >= 0))


class Carry:
    """``lift_carry`` for one instance: while :attr:`on` (a lift tried after the clean ones), a
    neighbour the lifted part touches beyond ``lift_contact`` is raised, not dragged through, when
    it lies on the part (:meth:`free`: ``is_free(name)``, :func:`free_to_rise`, asked once per
    neighbour; ``known`` caches the answers, shared by the instances of one plan: it is the
    neighbour's alone); :attr:`raised` lists them per lift direction (:attr:`direction`)."""

    def __init__(self, is_free: Callable[[str], bool], known: dict[str, bool] | None = None):
        self.on, self.direction = False, 0
        self._is_free = is_free
        self._free: dict[str, bool] = {} if known is None else known
        self.raised: dict[int, set[str]] = {}

    def free(self, name: str) -> bool:
        """Whether neighbour ``name`` lies on the part, free to rise."""
        v = self._free.get(name)
        if v is None:
            v = self._free[name] = bool(self._is_free(name))
        return v

    def raises(self, name: str) -> bool:
        """:attr:`on` and :meth:`free`, recording ``name`` as raised by the lift along :attr:`direction`."""
        if self.on and self.free(name):
            self.raised.setdefault(self.direction, set()).add(name)
            return True
        return False
