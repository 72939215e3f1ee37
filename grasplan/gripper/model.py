"""The gripper model: shapes in the TCP frame and :class:`Gripper`, two jaws closing along x.

TCP frame: origin at the midpoint of the two contacts; x = closing axis (contact 0 ->
contact 1); z = approach direction, from the gripper towards the part (the fingers point along
+z); y = z cross x.

A gripper is a fixed ``body`` (boxes and meshes in the TCP frame) and two jaws: ``finger`` is the
+x jaw at opening 0 (its inner face on the plane x = 0); at opening ``o`` it sits at x = +o/2
and the -x jaw is it turned 180 deg about z (:meth:`Gripper.fingers`, :meth:`Gripper.swept_fingers`).

:class:`Gripper` is the model of the ``parallel_jaw`` kind (:mod:`grasplan.gripper.parallel_jaw`
reads it from YAML and JSON); another kind subclasses it, sets :attr:`Gripper.kind` and
overrides what differs (see :mod:`grasplan.gripper.registry`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, overload

import numpy as np

from ..config.lookup import config_vector
from ..errors import ConfigError
from ..geometry.meshdata import convex_hull
from ..config.poses import parse_pose

#: the kind of a gripper whose YAML / JSON names none: two jaws moving apart along x
PARALLEL_JAW = "parallel_jaw"

#: grip force when the YAML gives none, N (Schunk EGP-C 40: 140 N)
DEFAULT_GRIP_FORCE = 140.0
#: pre-grasp opening = min(max_opening, width + PREGRASP_CLEARANCE)
PREGRASP_CLEARANCE = 0.010
#: the closing sweep stops at width + CLOSE_CLEARANCE (1 mm per side before touching)
CLOSE_CLEARANCE = 0.002


def rz180() -> np.ndarray:
    """(4, 4) rotation by 180 deg about the TCP z axis (maps one jaw onto the other)."""
    T = np.eye(4)
    T[0, 0] = T[1, 1] = -1.0
    return T


@dataclass(frozen=True, eq=False)
class Box:
    """A box with full side lengths ``extents`` (3,) whose centre pose in the TCP frame is
    ``T_tcp_box`` (4, 4)."""

    extents: np.ndarray
    T_tcp_box: np.ndarray

    def corners(self) -> np.ndarray:
        """(8, 3) corners in the TCP frame."""
        s = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=np.float64)
        local = s * (0.5 * np.asarray(self.extents))
        return local @ self.T_tcp_box[:3, :3].T + self.T_tcp_box[:3, 3]

    def moved(self, T: np.ndarray) -> "Box":
        """This box after the rigid motion ``T`` (4, 4) of the TCP frame."""
        return Box(np.asarray(self.extents, dtype=np.float64), np.asarray(T, dtype=np.float64) @ self.T_tcp_box)


@dataclass(frozen=True, eq=False)
class MeshShape:
    """A triangle mesh: ``vertices (n, 3)`` already expressed in the TCP frame, ``faces (m, 3)``."""

    vertices: np.ndarray
    faces: np.ndarray
    source: str = ""

    def corners(self) -> np.ndarray:
        return self.vertices

    def moved(self, T: np.ndarray) -> "MeshShape":
        T = np.asarray(T, dtype=np.float64)
        return MeshShape(self.vertices @ T[:3, :3].T + T[:3, 3], self.faces, self.source)


Shape = Box | MeshShape


@dataclass(frozen=True, eq=False)
class Gripper:
    """A two-jaw gripper (the ``parallel_jaw`` kind). ``finger`` is the +x jaw at opening 0 (inner
    face on x = 0); ``body`` is fixed in the TCP frame."""

    #: the registered kind (:mod:`grasplan.gripper.registry`) whose reader builds this class
    kind: ClassVar[str] = PARALLEL_JAW

    name: str
    max_opening: float
    T_flange_tcp: np.ndarray
    body: tuple[Shape, ...]
    finger: Shape
    symmetric: bool = True
    source: str = ""
    grip_force: float = DEFAULT_GRIP_FORCE  #: N, datasheet gripping force = sum of both jaws (each contact: half)
    #: m, how far the jaws travel together (both jaws): they close to ``max_opening - stroke`` at the
    #: narrowest (:attr:`min_opening`); None: they close fully (stroke = max_opening)
    stroke: float | None = None
    #: kg, the gripper with its fingers (datasheet); None when the file gives none
    mass: float | None = None
    #: (3,) centre of mass in the FLANGE frame, m (what RAPID's ``tload.cog`` and a UR payload take)
    com: np.ndarray | None = None

    @property
    def min_opening(self) -> float:
        """The narrowest jaw opening (m): ``max_opening - stroke`` (0 when the jaws close fully);
        narrower candidates are not posed (:func:`grasplan.grasps.frames.grasp_frames`)."""
        return 0.0 if self.stroke is None else max(0.0, float(self.max_opening) - float(self.stroke))

    # -- the TCP at an opening ------------------------------------------------------------------
    #: True for a kind whose fingertips move along the approach axis as the jaws open (Robotiq 2F
    #: linkages); the stages then ask :meth:`T_flange_tcp_at` instead of reading ``T_flange_tcp``
    moving_tcp: ClassVar[bool] = False

    def tcp_offset(self, opening: float | np.ndarray) -> np.ndarray:
        """How far (m, along +z) the fingertips are beyond their place at ``max_opening`` when the
        jaws stand at ``opening``: 0 for jaws that slide straight; shape of ``opening``."""
        return np.zeros_like(np.asarray(opening, dtype=np.float64))

    def T_flange_tcp_at(self, width: float) -> np.ndarray:
        """(4, 4) flange -> TCP with the jaws closed on ``width``: ``T_flange_tcp`` moved by
        :meth:`tcp_offset` along its z (the grasp's TCP, between the contacts)."""
        T = np.array(self.T_flange_tcp, dtype=np.float64)
        T[:3, 3] += T[:3, 2] * float(self.tcp_offset(float(width)))
        return T

    def T_tcp_gripper(self, width: float | np.ndarray) -> np.ndarray:
        """(4, 4), or (n, 4, 4) for n widths: the grasp TCP of contact width ``width`` -> the frame
        the gripper's shapes are given in (the TCP at ``max_opening``): a move by
        ``-tcp_offset(width)`` along z. Identity for jaws that slide straight."""
        w = np.asarray(width, dtype=np.float64)
        T = np.broadcast_to(np.eye(4), w.shape + (4, 4)).copy()
        T[..., 2, 3] = -self.tcp_offset(w)
        return T

    # -- finger geometry -------------------------------------------------------------------
    def fingers(self, opening: float) -> tuple[Shape, Shape]:
        """The two jaws at ``opening`` (m): inner faces at x = -opening/2 (first) and +opening/2."""
        o = float(opening)
        T = np.eye(4)
        T[0, 3] = 0.5 * o
        right = self.finger.moved(T)
        return right.moved(rz180()), right

    def swept_fingers(self, open_from: float, close_to: float) -> tuple[Shape, Shape]:
        """The volume each jaw sweeps while the opening moves between ``open_from`` and
        ``close_to`` (either order): (-x jaw, +x jaw). The sweep of a box finger is exactly one box;
        the sweep of a mesh finger is the convex hull of its two end placements (exact for a convex
        finger, a superset otherwise)."""
        lo, hi = sorted((float(open_from), float(close_to)))
        boxes = self.swept_boxes(np.array([lo]), np.array([hi]))
        if boxes is not None:
            right = Box(boxes[0][0], boxes[1][0])
            return right.moved(rz180()), right
        return self._hull_sweep(lo, hi)

    def swept_boxes(self, open_from: np.ndarray, close_to: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """A box finger's sweeps for many ``(open_from, close_to)`` pairs (n,) at once: ``(extents
        (n, 3), T_tcp_box (n, 4, 4))`` of the +x jaw's box (the -x jaw's is ``rz180() @ T_tcp_box``);
        None when a sweep is not one box (a mesh finger: :meth:`swept_fingers` per pair). At
        opening ``o`` the jaw spans x in ``[cx - ex/2 + o/2, cx + ex/2 + o/2]``; the sweep is that
        union over ``o`` between the pair (the finger is axis-aligned: the loader enforces it)."""
        f = self.finger
        if not isinstance(f, Box):
            return None
        a, b = np.asarray(open_from, dtype=np.float64), np.asarray(close_to, dtype=np.float64)
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        ext = np.tile(np.asarray(f.extents, dtype=np.float64), (len(lo), 1))
        cx = f.T_tcp_box[0, 3]
        x0 = cx - ext[:, 0] / 2 + lo / 2
        x1 = cx + ext[:, 0] / 2 + hi / 2
        ext[:, 0] = x1 - x0
        T = np.tile(np.asarray(f.T_tcp_box, dtype=np.float64), (len(lo), 1, 1))
        T[:, 0, 3] = 0.5 * (x0 + x1)
        return ext, T

    def _hull_sweep(self, lo: float, hi: float) -> tuple[Shape, Shape]:
        a = self.fingers(lo)[1].corners()
        b = self.fingers(hi)[1].corners()
        hull = convex_hull(np.vstack([a, b]))
        right = MeshShape(np.asarray(hull.vertices, dtype=np.float64), np.asarray(hull.faces, dtype=np.int64), "finger sweep hull")
        return right.moved(rz180()), right

    @overload
    def pregrasp_opening(self, width: float) -> float: ...
    @overload
    def pregrasp_opening(self, width: np.ndarray) -> np.ndarray: ...

    def pregrasp_opening(self, width: float | np.ndarray) -> float | np.ndarray:
        """``min(max_opening, width + 0.010)``; scalar (a NumPy float) or (n,) array."""
        return np.minimum(self.max_opening, np.asarray(width, dtype=np.float64) + PREGRASP_CLEARANCE)

    @overload
    def close_to_opening(self, width: float) -> float: ...
    @overload
    def close_to_opening(self, width: np.ndarray) -> np.ndarray: ...

    def close_to_opening(self, width: float | np.ndarray) -> float | np.ndarray:
        """Where the checked closing sweep stops: ``min(width + 0.002, pregrasp_opening(width))``."""
        w = np.asarray(width, dtype=np.float64)
        return np.minimum(w + CLOSE_CLEARANCE, self.pregrasp_opening(w))

    def to_json(self, *, definition: bool = False) -> dict[str, Any]:
        """The ``gripper`` block of the grasps and plan outputs; with ``definition`` also the
        resolved shapes (boxes, mesh vertices in the TCP frame), so a result file rebuilds the
        gripper without its YAML (:func:`grasplan.gripper.gripper_from_json`). Only a kind other
        than the default names itself (``kind``), so default-kind files read as before kinds."""
        out: dict[str, Any] = {"name": self.name, "max_opening": float(self.max_opening),
                               "T_flange_tcp": self.T_flange_tcp.tolist(), "grip_force": float(self.grip_force)}
        if self.stroke is not None:
            out["stroke"] = float(self.stroke)
        if self.mass is not None:
            out["mass"] = float(self.mass)
            out["com"] = [float(c) for c in (self.com if self.com is not None else np.zeros(3))]
        if definition:
            out["definition"] = {"body": [shape_to_json(b) for b in self.body], "finger": shape_to_json(self.finger),
                                 "symmetric": bool(self.symmetric)}
        if self.kind != PARALLEL_JAW:
            out["kind"] = self.kind
        return out


# -- shapes in JSON ------------------------------------------------------------------------
def shape_to_json(shape: Shape) -> dict[str, Any]:
    """``{box: {extents, T}}`` or ``{mesh: {vertices, faces}}`` (TCP frame; vertices rounded to 1 nm)."""
    if isinstance(shape, Box):
        return {"box": {"extents": np.asarray(shape.extents, dtype=float).tolist(), "T": shape.T_tcp_box.tolist()}}
    return {"mesh": {"vertices": np.round(shape.vertices, 9).tolist(), "faces": np.asarray(shape.faces).tolist()}}


def shape_from_json(d: object, where: str) -> Shape:
    """The shape :func:`shape_to_json` wrote; ConfigError naming ``where`` for anything else."""
    if not isinstance(d, dict) or len(d) != 1 or next(iter(d)) not in ("box", "mesh"):
        raise ConfigError(f"{where}: expected {{box: {{extents, T}}}} or {{mesh: {{vertices, faces}}}}")
    kind, spec = next(iter(d.items()))
    if not isinstance(spec, dict):
        raise ConfigError(f"{where}.{kind}: expected a mapping")
    if kind == "box":
        ext = config_vector(spec.get("extents"), f"{where}.box.extents", positive=True)
        T = parse_pose(spec.get("T"), f"{where}.box.T")
        return Box(ext, T)
    try:
        V = np.asarray(spec.get("vertices"), dtype=np.float64)
        F = np.asarray(spec.get("faces"), dtype=np.int64)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(f"{where}.mesh: vertices and faces must be numeric arrays") from None
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(F) == 0 or len(V) > 10**6:
        raise ConfigError(f"{where}.mesh: expected vertices (n, 3) and faces (m, 3)")
    if not np.all(np.isfinite(V)) or np.abs(V).max() > 10 or F.min() < 0 or F.max() >= len(V):
        raise ConfigError(f"{where}.mesh: vertices must be finite (|v| <= 10 m) and faces index them")
    return MeshShape(V, F, "embedded")
