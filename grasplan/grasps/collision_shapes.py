"""The gripper's shapes per pose for the collision filter (:class:`grasplan.grasps.collision.GripperCollider`):
one :class:`ShapeSet` per gripper element (each body shape, each swept jaw), its variants' coal
geometry built on first use (:class:`Geoms`), and the jaws' sweeps met so far (:class:`Sweeps`),
one table per gripper shared by its colliders (:func:`shared_sweeps`).
"""
from __future__ import annotations

import bisect
import threading
import weakref
from typing import Any

import coal
import numpy as np

from ..cell.shapes import bvh
from ..gripper.model import Box, Gripper, rz180


class Geoms:
    """The coal geometry of each variant of a shape, built when first asked for (most variants never
    reach coal): ``geoms[k]``."""

    def __init__(self, variants: list | ShapeRows):
        self.variants = variants  # may grow (the swept jaws met so far, :class:`Sweeps`)
        self._built: dict[int, Any] = {}

    def __len__(self) -> int:
        return len(self.variants)

    def __getitem__(self, k: int) -> Any:
        g = self._built.get(k)
        if g is None:
            v = self.variants[k]
            g = self._built[k] = (coal.Box(*np.asarray(v.extents, dtype=np.float64)) if isinstance(v, Box)
                                  else bvh(v.vertices, v.faces))
        return g


class ShapeSet:
    """One gripper shape per pose: coal geometry per unique variant, ``T_tcp_shape`` per pose."""

    def __init__(self, variants: list, index: np.ndarray):
        self.variants: list | ShapeRows = variants  # Box | MeshShape per variant
        self.index = index  # (M,) variant per pose
        self.is_box = isinstance(variants[0], Box)
        self.geoms = Geoms(variants)
        # per variant: the geometry's placement and its local bounding box in the TCP frame (for the
        # prefilter), :func:`shape_frames` of each variant
        frames = [shape_frames(v) for v in variants]
        self.T_tcp_geom = np.array([f[0] for f in frames])
        self.T_tcp_bb = np.array([f[1] for f in frames])
        self.half_bb = np.array([f[2] for f in frames])


class ShapeRows:
    """A jaw's sweeps in row order, as :class:`Geoms` and :class:`ShapeSet` index them: box sweeps
    kept as the arrays they were made from and turned into a :class:`~grasplan.gripper.model.Box`
    when first asked for (most are only placed, never handed to coal), other shapes as given."""

    def __init__(self) -> None:
        self._starts: list[int] = []
        self._chunks: list[Any] = []  # a list of shapes, or the (extents (n, 3), T (n, 4, 4)) of n boxes
        self._made: dict[int, Box] = {}
        self._n = 0

    def __len__(self) -> int:
        return self._n

    def add_boxes(self, extents: np.ndarray, T: np.ndarray) -> None:
        """Append boxes of ``extents (n, 3)`` at ``T (n, 4, 4)`` (TCP frame)."""
        if len(extents):
            self._starts.append(self._n)
            self._chunks.append((extents, T))
            self._n += len(extents)

    def append(self, shape: Any) -> None:
        self._starts.append(self._n)
        self._chunks.append([shape])
        self._n += 1

    def __getitem__(self, k: int) -> Any:
        k = int(k)
        if not 0 <= k < self._n:
            raise IndexError(f"shape row {k} of {self._n}")
        c = bisect.bisect_right(self._starts, k) - 1
        chunk, i = self._chunks[c], k - self._starts[c]
        if isinstance(chunk, list):
            return chunk[i]
        box = self._made.get(k)
        if box is None:
            box = self._made[k] = Box(chunk[0][i], chunk[1][i])
        return box


class Sweeps:
    """The two jaws' sweeps met so far by one collider, one row per distinct (pre-grasp opening,
    closed opening) pair: the shapes (:meth:`Gripper.swept_fingers`), their coal geometry (on first
    use) and their :func:`shape_frames` as arrays, so that a batch of poses only looks its pairs up."""

    def __init__(self, gripper: Gripper):
        self.gripper = gripper
        self.ids: dict[tuple[float, float], int] = {}
        self.shapes = (ShapeRows(), ShapeRows())
        self.geoms = (Geoms(self.shapes[0]), Geoms(self.shapes[1]))
        self.frames = [(np.zeros((0, 4, 4)), np.zeros((0, 4, 4)), np.zeros((0, 3))) for _ in range(2)]
        self._lock = threading.Lock()
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # the last widths and their rows

    def __len__(self) -> int:
        return len(self.ids)

    def rows_for(self, width: np.ndarray) -> np.ndarray:
        """(M,) read-only: the row of each contact width's sweep, from the pre-grasp opening to the
        closed one (:meth:`Gripper.pregrasp_opening`, :meth:`Gripper.close_to_opening`); the last
        call's answer when the widths are the same (a database placed in pose after pose)."""
        w = np.asarray(width, dtype=np.float64).reshape(-1)
        last = self._last
        if last is not None and last[0].shape == w.shape and np.array_equal(last[0], w):
            return last[1]
        g = self.gripper
        key = np.round(np.stack([g.pregrasp_opening(w), g.close_to_opening(w)], axis=1), 12)
        uk, inv = unique_rows(key)
        index = self.rows(uk)[inv]
        index.flags.writeable = False
        self._last = (w.copy(), index)
        return index

    def rows(self, pairs: np.ndarray) -> np.ndarray:
        """The row of each ``(o_pre, o_close)`` pair of ``pairs`` (n, 2), new pairs added."""
        with self._lock:
            return self._rows(pairs)

    def _rows(self, pairs: np.ndarray) -> np.ndarray:
        out = np.empty(len(pairs), dtype=np.int64)
        fresh: list[int] = []
        for i, key in enumerate(map(tuple, pairs.tolist())):
            r = self.ids.get(key)
            if r is None:
                r = self.ids[key] = len(self.shapes[0]) + len(fresh)
                fresh.append(i)
            out[i] = r
        if fresh:
            self._add(pairs[fresh, 0], pairs[fresh, 1])
        return out

    def _add(self, o_pre: np.ndarray, o_close: np.ndarray) -> None:
        """Append the sweeps of these pairs (in order) to both jaws' shapes and frames: a box
        finger's all at once (:meth:`Gripper.swept_boxes`), others one :meth:`Gripper.swept_fingers`
        each (a mesh finger's hull, a linkage's arc)."""
        g = self.gripper
        new: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        boxes = g.swept_boxes(o_pre, o_close)
        if boxes is not None:
            ext, T = boxes
            for side, Ts in enumerate((rz180() @ T, T)):
                self.shapes[side].add_boxes(ext, Ts)
                new.append((Ts, Ts, 0.5 * ext))  # shape_frames of a box, all rows at once
        else:
            got: tuple[list, list] = ([], [])
            for a, b in zip(o_pre.tolist(), o_close.tolist()):
                for side, shape in enumerate(g.swept_fingers(a, b)):
                    self.shapes[side].append(shape)
                    got[side].append(shape_frames(shape))
            new = [tuple(np.array([f[j] for f in got[side]]) for j in range(3))  # type: ignore[misc]
                   for side in range(2)]
        for side in range(2):
            old = self.frames[side]
            self.frames[side] = tuple(np.concatenate([old[j], new[side][j]]) for j in range(3))  # type: ignore[assignment]

    def shape_set(self, side: int, index: np.ndarray) -> ShapeSet:
        """The ``side`` (0: -x, 1: +x) jaw's sweeps for poses of rows ``index`` (M,)."""
        s = ShapeSet.__new__(ShapeSet)
        s.variants, s.index, s.geoms = self.shapes[side], index, self.geoms[side]
        s.is_box = isinstance(self.shapes[side][0], Box) if self.shapes[side] else isinstance(self.gripper.finger, Box)
        s.T_tcp_geom, s.T_tcp_bb, s.half_bb = self.frames[side]
        return s


#: sweeps a gripper's shared table holds before it starts again (bounds a long-lived process;
#: about 1-2 kB each); colliders already holding the full table keep it
MAX_SHARED_SWEEPS = 50_000
_SHARED: weakref.WeakKeyDictionary[Gripper, Sweeps] = weakref.WeakKeyDictionary()
_SHARED_LOCK = threading.Lock()


def shared_sweeps(gripper: Gripper) -> Sweeps:
    """The sweeps table of ``gripper`` (this object) shared by every collider of it: the colliders
    of one database placed in many poses (``--pose-index all``, the other poses' hints) build each
    jaw sweep once. Kept while the gripper lives, and replaced by an empty table once it holds
    :data:`MAX_SHARED_SWEEPS`."""
    with _SHARED_LOCK:
        table = _SHARED.get(gripper)
        if table is None or len(table) >= MAX_SHARED_SWEEPS:
            table = _SHARED[gripper] = Sweeps(gripper)
        return table


def shape_frames(v: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(T_tcp_geom, T_tcp_bb, half_bb)`` of a shape: where its coal geometry sits in the TCP frame
    (a box's own frame; a mesh's vertices are in the TCP frame), the centre frame and half extents
    of its local bounding box (a box: itself)."""
    if isinstance(v, Box):
        return v.T_tcp_box, v.T_tcp_box, 0.5 * np.asarray(v.extents, dtype=np.float64)
    lo, hi = v.vertices.min(axis=0), v.vertices.max(axis=0)
    T = np.eye(4)
    T[:3, 3] = 0.5 * (lo + hi)
    return np.eye(4), T, 0.5 * (hi - lo)


def unique_rows(key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(key, axis=0, return_inverse=True)`` of the (M, 2) float rows (no NaN): the
    distinct rows in lexicographic order and each row's index among them, by one lexsort."""
    if not len(key):
        return key[:0], np.zeros(0, dtype=np.int64)
    o = np.lexsort((key[:, 1], key[:, 0]))
    k = key[o]
    new = np.ones(len(k), dtype=bool)
    new[1:] = np.any(k[1:] != k[:-1], axis=1)
    inv = np.empty(len(k), dtype=np.int64)
    inv[o] = np.cumsum(new) - 1
    return k[new], inv
