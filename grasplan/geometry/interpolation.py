"""Joint-path interpolation: the one densifier every path check uses (:func:`interpolate_path`)
and its default resolution :data:`STEP`. One compiled loop (:func:`_densify`): the collision
scene, the planners, the exports and the viewer all densify here.

Joint vectors are ``(n,)`` float64 radians; paths are ``(k, n)`` arrays, first row the start.
"""
from __future__ import annotations

from typing import Literal, overload

import numpy as np

from ..compiled.jit import kernel

#: default interpolation resolution (rad, per joint) of every path check
STEP = 0.01


@overload
def interpolate_path(path: np.ndarray, *, step: float = ..., return_index: Literal[False] = ...) -> np.ndarray: ...
@overload
def interpolate_path(path: np.ndarray, *, step: float = ...,
                     return_index: Literal[True]) -> tuple[np.ndarray, np.ndarray]: ...

def interpolate_path(path: np.ndarray, *, step: float = STEP, return_index: bool = False
                     ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """The one joint-path densifier: every segment of a ``(k, n)`` path split into
    ``ceil(max|dq| / step)`` equal parts (a repeated waypoint adds no point).

    Returns ``(m, n)`` with the original waypoints included (first and last rows unchanged); the
    largest per-joint change between consecutive rows is ``<= step``. With ``return_index`` also
    the row of each original waypoint in the output, ``(k,)``.
    """
    path = np.asarray(path, dtype=np.float64)
    if path.ndim != 2 or len(path) == 0:
        raise ValueError(f"path must have shape (k, n) with k >= 1, got {path.shape}")
    if not step > 0:
        raise ValueError(f"step must be > 0 rad, got {step!r}")
    out, rows = _densify(np.ascontiguousarray(path), float(step))
    return (out, rows) if return_index else out


@kernel(cache=True, nogil=True)
def _densify(path: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`interpolate_path` of a C-contiguous float64 ``path`` (k >= 1, n): ``(dense (m, n), row of
    each waypoint in it (k,))``. Waypoints within 1e-12 rad (every joint) of the previous one are
    dropped; each remaining segment ``d`` is split into ``p = max(1, ceil(max|d| / step -
    1e-12))`` parts, row ``i`` of it ``start + (i / p + 1 / p) d`` (the NumPy form's operations, in
    its order)."""
    k, n = path.shape
    keep = np.zeros(k, dtype=np.bool_)
    pieces = np.zeros(k, dtype=np.int64)  # pieces[i]: the parts of the segment ending at kept waypoint i
    keep[0] = True
    last = 0
    total = 1
    for i in range(1, k):
        moved = 0.0  # from the previous waypoint: within 1e-12 rad it is a repeat
        jump = 0.0  # from the last kept one: the segment's largest joint change
        for j in range(n):
            moved = max(moved, abs(path[i, j] - path[i - 1, j]))
            jump = max(jump, abs(path[i, j] - path[last, j]))
        if moved > 1e-12:
            keep[i] = True
            p = max(1, int(np.ceil(jump / step - 1e-12)))
            pieces[i] = p
            total += p
            last = i
    out = np.empty((total, n))
    rows = np.zeros(k, dtype=np.int64)
    for j in range(n):
        out[0, j] = path[0, j]
    r = 1
    last = 0
    for i in range(1, k):
        if not keep[i]:
            rows[i] = r - 1
            continue
        p = pieces[i]
        inv = 1.0 / p
        for q in range(p):
            f = q / p + inv
            for j in range(n):
                out[r, j] = path[last, j] + f * (path[i, j] - path[last, j])
            r += 1
        rows[i] = r - 1
        last = i
    return out, rows
