"""Stage 2: boundary layer mesher (Vogt et al. 2021, Sec. III-A).

(Implementation in progress: see ``boundary_layer``.)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from .tolerance import Tolerance


@dataclass(frozen=True)
class BLMResult:
    """The remeshed part and what the BLM found.

    mesh : trimesh.Trimesh, metres, same geometry as the input
    surface : (m_out,) int64, surface id of each output face
    facets : int, surfaces : int, shifted_vertices : int
    """

    mesh: trimesh.Trimesh
    surface: np.ndarray
    facets: int
    surfaces: int
    shifted_vertices: int


def boundary_layer(mesh: trimesh.Trimesh, *, alpha: float = 1e-4, gamma_deg: float = 135.0, tol: Tolerance | None = None) -> BLMResult:
    raise NotImplementedError("BLM: being implemented")
