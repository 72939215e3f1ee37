"""The ``parallel_linkage`` gripper kind: parallel pads carried by a four-bar linkage (Robotiq 2F-85,
2F-140, OnRobot RG2 and RG6).

The pads stay parallel to each other, but each pad's carrier link swings about a pivot in the
gripper body, so the pad moves on a circular arc: as the jaws close, the fingertips also move along
the approach axis z (:class:`LinkageGripper`). YAML: the ``parallel_jaw`` fields
(:mod:`grasplan.gripper.parallel_jaw`) plus, required (:func:`from_yaml`)::

    kind: parallel_linkage
    arc: {radius: 0.05715, center_x: 0.005342}   # m; |opening/2 - center_x| <= radius over the stroke
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from ..config.lookup import config_number
from ..errors import ConfigError
from ..geometry.meshdata import convex_hull
from . import parallel_jaw
from .model import Box, Gripper, MeshShape, Shape, rz180
from .registry import GripperKind, register

#: the kind's name (the YAML / JSON ``kind``)
PARALLEL_LINKAGE = "parallel_linkage"
#: openings sampled along a closing sweep (their fingers' convex hull is the swept volume)
SWEEP_SAMPLES = 9


@dataclass(frozen=True, eq=False)
class LinkageGripper(Gripper):
    """A :class:`~grasplan.gripper.model.Gripper` whose pads move on an arc: ``arc_radius`` and
    ``arc_center_x`` in metres. Model (+x pad; the -x pad is it turned 180 deg about z)::

        inner face x = opening / 2 = center_x + radius * sin(theta)
        tcp_offset(opening) = radius * (cos(theta(opening)) - cos(theta(max_opening)))

    ``theta`` is the link's angle from the approach axis; ``tcp_offset`` is how far (m, along +z, away
    from the flange) the pads are beyond their place at ``max_opening``. The YAML's ``T_flange_tcp``,
    ``body`` and ``fingers`` describe the gripper at ``max_opening`` (the frame the shapes are given in);
    a grasp of contact width ``w`` has its TCP between the contacts, at
    :meth:`~grasplan.gripper.model.Gripper.T_flange_tcp_at` ``(w)`` = ``T_flange_tcp`` moved by
    ``tcp_offset(w)`` along z. The stages place the gripper for a grasp with
    :meth:`~grasplan.gripper.model.Gripper.T_tcp_gripper` (grasp collision check, planning, the FK check
    of plans, the robot programs' TCP)."""

    kind: ClassVar[str] = PARALLEL_LINKAGE
    moving_tcp: ClassVar[bool] = True

    arc_radius: float = 0.0
    arc_center_x: float = 0.0

    def theta(self, opening: float | np.ndarray) -> np.ndarray:
        """The link angle (rad, from the approach axis, outwards positive) at ``opening``."""
        s = (0.5 * np.asarray(opening, dtype=np.float64) - self.arc_center_x) / self.arc_radius
        return np.arcsin(np.clip(s, -1.0, 1.0))

    def tcp_offset(self, opening: float | np.ndarray) -> np.ndarray:
        c_open = np.cos(self.theta(self.max_opening))
        return self.arc_radius * (np.cos(self.theta(opening)) - c_open)

    def fingers(self, opening: float) -> tuple[Shape, Shape]:
        o = float(opening)
        T = np.eye(4)
        T[0, 3] = 0.5 * o
        T[2, 3] = float(self.tcp_offset(o))
        right = self.finger.moved(T)
        return right.moved(rz180()), right

    def offset_range(self, lo: float, hi: float) -> tuple[float, float]:
        """``(min, max)`` of :meth:`tcp_offset` over openings in [lo, hi] (cos theta peaks where the
        link points straight along z, theta = 0)."""
        cands = [lo, hi]
        o0 = 2.0 * self.arc_center_x  # theta = 0
        if lo < o0 < hi:
            cands.append(o0)
        z = self.tcp_offset(np.array(cands))
        return float(z.min()), float(z.max())

    def swept_boxes(self, open_from: np.ndarray, close_to: np.ndarray) -> None:
        """None: a sweep along the arc is not :class:`Gripper`'s box (:meth:`swept_fingers`, per pair)."""
        return None

    def swept_fingers(self, open_from: float, close_to: float) -> tuple[Shape, Shape]:
        """The volume each jaw sweeps between two openings. A box finger: one axis-aligned box
        spanning its x travel and its z travel along the arc (a superset of the arc sweep, as tight
        as the z travel over the interval: 0.2 mm for a 10 mm closing sweep of the 2F-85); a mesh
        finger: the convex hull of :data:`SWEEP_SAMPLES` placements along the arc (the chord between
        samples cuts the arc by at most radius * (1 - cos(dtheta / 2)): 0.07 mm for the 2F-85's 0.8 rad
        travel)."""
        lo, hi = sorted((float(open_from), float(close_to)))
        if isinstance(self.finger, Box):
            f = self.finger
            ext = np.array(f.extents, dtype=np.float64)
            z0, z1 = self.offset_range(lo, hi)
            x0 = f.T_tcp_box[0, 3] - ext[0] / 2 + lo / 2
            x1 = f.T_tcp_box[0, 3] + ext[0] / 2 + hi / 2
            T = f.T_tcp_box.copy()
            T[0, 3], T[2, 3] = 0.5 * (x0 + x1), f.T_tcp_box[2, 3] + 0.5 * (z0 + z1)
            ext[0], ext[2] = x1 - x0, ext[2] + (z1 - z0)
            box = Box(ext, T)
            return box.moved(rz180()), box
        pts = np.vstack([self.fingers(o)[1].corners() for o in np.linspace(lo, hi, SWEEP_SAMPLES)])
        hull = convex_hull(pts)
        right = MeshShape(np.asarray(hull.vertices, dtype=np.float64), np.asarray(hull.faces, dtype=np.int64),
                          "finger sweep hull (arc)")
        return right.moved(rz180()), right

    def to_json(self, *, definition: bool = False) -> dict[str, Any]:
        out = super().to_json(definition=definition)
        out["arc"] = {"radius": float(self.arc_radius), "center_x": float(self.arc_center_x)}
        return out


def _arc(spec: object, where: str, max_opening: float) -> tuple[float, float]:
    if not isinstance(spec, dict) or set(spec) != {"radius", "center_x"}:
        raise ConfigError(f"{where}: expected {{radius: m, center_x: m}} (the pad's arc), got {str(spec)[:80]!r}")
    r = config_number(spec["radius"], f"{where}.radius", positive=True, max_abs=1.0)
    cx = config_number(spec["center_x"], f"{where}.center_x", max_abs=1.0)
    far = max(abs(0.0 - cx), abs(0.5 * max_opening - cx))
    if far > r + 1e-12:
        raise ConfigError(f"{where}: radius {r} m is shorter than the pad's reach |opening/2 - center_x| = "
                          f"{far:.6g} m over the stroke [0, {max_opening}] m; the arc must span the stroke")
    return r, cx


def _with_arc(base: Gripper, arc: tuple[float, float]) -> LinkageGripper:
    kw: dict[str, Any] = {f.name: getattr(base, f.name) for f in fields(base)}
    kw["arc_radius"], kw["arc_center_x"] = arc
    return LinkageGripper(**kw)


def from_yaml(data: dict[str, Any], *, base: Path, name: str, source: str = "") -> Gripper:
    """A :class:`LinkageGripper` from its YAML: the ``parallel_jaw`` fields and ``arc``."""
    if "arc" not in data:
        raise ConfigError(f"{source}: arc: missing (kind {PARALLEL_LINKAGE} needs {{radius, center_x}} in metres)")
    rest = {k: v for k, v in data.items() if k != "arc"}
    g = parallel_jaw.from_yaml(rest, base=base, name=name, source=source)
    return _with_arc(g, _arc(data["arc"], "arc", g.max_opening))


def from_json(d: dict[str, Any], *, where: str) -> Gripper:
    """A :class:`LinkageGripper` from its ``to_json(definition=True)`` block."""
    g = parallel_jaw.from_json(d, where=where)
    return _with_arc(g, _arc(d.get("arc"), f"{where}.arc", g.max_opening))


KIND = register(GripperKind(
    name=PARALLEL_LINKAGE, model=LinkageGripper, from_yaml=from_yaml, from_json=from_json,
    description="parallel pads on a four-bar linkage (Robotiq 2F): the TCP moves along z with the opening"))
