"""Stages 1-4 composed: part -> (BLM) -> convexity -> antipodal candidates, and their JSON.

``compute_candidates(part, params)`` is the pure function behind ``grasplan candidates``; the
grasps and plan pipelines start from its result.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from .antipodal import Candidates, find_candidates
from .blm import BLMResult, boundary_layer
from .convexity import classify_convexity
from .mesh import Part
from .params import DEFAULT_MAX_OPENING, CandidateParams

if TYPE_CHECKING:  # trimesh (and scipy) load with the first mesh; importing this module stays cheap
    import trimesh

SCHEMA = "grasplan.candidates/1"
@dataclass(frozen=True)
class CandidateResult:
    part: Part
    params: CandidateParams
    mesh: trimesh.Trimesh              #: the mesh the candidates index into (BLM output or the part's)
    blm: BLMResult | None
    convex: np.ndarray                 #: (m,) bool, per face of ``mesh``
    candidates: Candidates
    timing_s: dict = field(default_factory=dict)

    def counts(self) -> dict:
        return {
            "triangles_in": self.part.triangles,
            "triangles_blm": int(len(self.blm.mesh.faces)) if self.blm is not None else None,
            "convex_faces": int(np.count_nonzero(self.convex)),
            "candidates": len(self.candidates),
        }

    def to_json(self) -> dict:
        return {
            "schema": SCHEMA,
            "part": self.part.to_json(),
            "params": self.params.to_json(),
            "counts": self.counts(),
            "timing_s": dict(self.timing_s),
            "candidates": self.candidates.to_json(),
        }


def compute_candidates(part: Part, params: CandidateParams = CandidateParams(), *, load_s: float = 0.0) -> CandidateResult:
    """Run BLM (unless ``params.blm`` is False), convexity and the antipodal search on ``part``.

    ``params.max_opening = None`` searches up to :data:`DEFAULT_MAX_OPENING`; the result's
    ``params`` hold the value used."""
    if params.max_opening is None:
        params = replace(params, max_opening=DEFAULT_MAX_OPENING)
    timing = {"load": float(load_s)}
    t = time.perf_counter()
    blm_result = None
    mesh = part.mesh
    if params.blm:
        blm_result = boundary_layer(part.mesh, alpha=params.alpha, gamma_deg=params.gamma_deg, tol=part.tol)
        mesh = blm_result.mesh
    timing["blm"] = time.perf_counter() - t if params.blm else 0.0

    t = time.perf_counter()
    convex = classify_convexity(mesh, d_shift=params.d_shift, tol=part.tol)
    timing["convexity"] = time.perf_counter() - t

    t = time.perf_counter()
    cands = find_candidates(
        mesh,
        convex,
        max_opening=params.max_opening,
        beta_deg=params.beta_deg,
        epsilon=params.epsilon,
        mu=params.mu,
        tol=part.tol,
        method=params.method,
        spacing=params.spacing,
    )
    timing["antipodal"] = time.perf_counter() - t
    return CandidateResult(part=part, params=params, mesh=mesh, blm=blm_result, convex=convex, candidates=cands, timing_s=timing)
