"""Stage 3: convex/concave classification per triangle (Vogt et al. 2021, Sec. III-B).

(Implementation in progress: see ``classify_convexity``.)
"""
from __future__ import annotations

import numpy as np
import trimesh

from .tolerance import Tolerance


def classify_convexity(mesh: trimesh.Trimesh, *, d_shift: float = 1e-5, tol: Tolerance | None = None) -> np.ndarray:
    """Return ``(m,) bool``: True where face is convex."""
    raise NotImplementedError("convexity: being implemented")
