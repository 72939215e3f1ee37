"""Stages 2-4: the boundary layer mesher (Vogt et al. 2021), convexity and the antipodal contact
candidates (sampled regions or the paper's face pairs), composed by :mod:`.pipeline`.

Every name below is imported from its module on first use (:mod:`grasplan._lazy`).
"""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "compute_candidates": ".pipeline", "find_candidates": ".pipeline", "CandidateResult": ".pipeline",
    "boundary_layer": ".blm", "BLMResult": ".blm",
    "classify_convexity": ".convexity",
    "Candidates": ".antipodal_base",
    "thin_candidates": ".thinning",
})
