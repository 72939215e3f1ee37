"""One tolerance object, scaled to the part (in the spirit of trimesh's ``constants.tol``).

Every geometric comparison in grasplan takes its epsilon from a :class:`Tolerance` built from the
part's size, never from a literal in the stage code.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Tolerance:
    """Tolerances for a part whose bounding-box diagonal is ``scale`` metres.

    Attributes
    ----------
    scale : float
        Bounding-box diagonal of the part, metres.
    merge : float
        Vertices closer than this are the same vertex (metres).
    distance : float
        Generic "on the surface / on the plane" distance (metres).
    area : float
        Faces with less area are degenerate (square metres).
    planar_deg : float
        Faces whose normals differ by less than this are coplanar (one facet).
    """

    scale: float
    merge: float
    distance: float
    area: float
    planar_deg: float = 0.5

    @classmethod
    def for_scale(cls, scale: float) -> "Tolerance":
        scale = float(scale)
        if not np.isfinite(scale) or scale <= 0:
            raise ValueError(f"tolerance scale must be a positive length, got {scale!r}")
        # STL stores float32 (about 7 significant digits): vertices written twice agree to ~1e-7
        # of the part size, so that is the merge distance; "on the surface" is checked 10x looser.
        return cls(
            scale=scale,
            merge=1e-8 * scale,
            distance=1e-6 * scale,
            area=(1e-7 * scale) ** 2,
        )

    @classmethod
    def for_mesh(cls, vertices: np.ndarray) -> "Tolerance":
        """Tolerance for vertices ``(n, 3)`` in metres."""
        v = np.asarray(vertices, dtype=np.float64)
        diag = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0))) if len(v) else 0.0
        return cls.for_scale(diag if diag > 0 else 1.0)
