"""Joint-path interpolation: the one densifier every path check uses (:func:`interpolate_path`)
and its default resolution :data:`STEP`. Plain NumPy: the collision scene, the planners, the
exports and the viewer all densify here.

Joint vectors are ``(n,)`` float64 radians; paths are ``(k, n)`` arrays, first row the start.
"""
from __future__ import annotations

from typing import Literal, overload

import numpy as np

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
    d = path[1:] - path[:-1]
    jump = np.abs(d).max(axis=1) if len(d) else np.zeros(0)
    moved = jump > 1e-12
    kept, keep = path, None
    if not moved.all():  # repeated waypoints dropped
        keep = np.concatenate([[True], moved])
        kept = path[keep]
        if len(kept) < 2:
            out = kept.copy()
            return (out, np.zeros(len(path), dtype=np.int64)) if return_index else out
        d = kept[1:] - kept[:-1]
        jump = np.abs(d).max(axis=1)
    pieces = np.maximum(1, np.ceil(jump / step - 1e-12).astype(np.int64))
    out = np.empty((int(pieces.sum()) + 1, path.shape[1]))
    out[0] = kept[0]
    if len(d) == 1:  # one segment (a transit): row i is kept[0] + (i / p + 1 / p) d
        p = int(pieces[0])
        out[1:] = kept[0] + ((np.arange(p) / p + 1.0 / p)[:, None]) * d[0]
    else:
        seg = np.repeat(np.arange(len(d)), pieces)
        start = np.repeat(np.cumsum(pieces) - pieces, pieces)
        frac = (np.arange(len(seg)) - start) / pieces[seg]
        out[1:] = kept[seg] + ((frac + 1.0 / pieces[seg])[:, None]) * d[seg]
    if not return_index:
        return out
    row_of_kept = np.concatenate([[0], np.cumsum(pieces)])
    return out, (row_of_kept if keep is None else row_of_kept[np.cumsum(keep) - 1])
