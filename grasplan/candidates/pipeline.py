"""Stages 1-4 composed: part -> (BLM) -> convexity -> antipodal candidates, and their JSON.

``compute_candidates(part, params)`` is the pure function behind ``grasplan candidates``; the
grasps and plan pipelines start from its result. :func:`find_candidates` is stage 4's entry: it
validates the search parameters and chooses the method, the sampled contact regions
(:mod:`grasplan.candidates.regions`) or the paper's face pairs (:mod:`grasplan.candidates.antipodal`); both build on
:mod:`grasplan.candidates.antipodal_base`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Literal, cast

import numpy as np

from .antipodal import find_face_pairs
from .antipodal_base import Candidates, FaceGeometry
from .blm import BLMResult, boundary_layer
from .convexity import classify_convexity
from ..errors import InputError
from ..part.mesh import Part
from ..config.params import DEFAULT_MAX_OPENING, CandidateParams
from .regions import find_regions
from ..geometry.tolerance import Tolerance

if TYPE_CHECKING:
    from ..geometry.meshdata import MeshData, TriangleMesh

SCHEMA = "grasplan.candidates/1"
#: the candidate methods of :func:`find_candidates`
Method = Literal["regions", "paper"]


def find_candidates(
    mesh: TriangleMesh,
    convex: np.ndarray,
    *,
    max_opening: float = 0.05,
    beta_deg: float = 2.0,
    epsilon: float = 5e-3,
    mu: float = 0.3,
    tol: Tolerance | None = None,
    search: Literal["index", "brute"] = "index",
    method: Method = "paper",
    spacing: float = 0.002,
    notes: list[str] | None = None,
) -> Candidates:
    """Antipodal candidates among the convex faces of ``mesh`` by either method.

    Parameters
    ----------
    mesh : TriangleMesh
        Metres, outward winding.
    convex : (m,) bool
        Per face of ``mesh`` (from :func:`grasplan.candidates.convexity.classify_convexity`).
    max_opening, epsilon : float
        Metres.
    beta_deg : float
        Degrees.
    mu : float
        Friction coefficient (cone half-angle ``atan(mu)``).
    tol : Tolerance, optional
        Part tolerance (default: from the mesh).
    search : {"index", "brute"}
        ``method="paper"`` only. ``"index"``: the sub-quadratic 6D grid search, streamed in
        bounded chunks; ``"brute"``: every pair of convex faces (O(m^2) time, chunked; reference
        for tests and benchmarks).
    method : {"regions", "paper"}
        ``"paper"``: one contact pair per face pair (the rules of :mod:`grasplan.candidates.antipodal`, Vogt
        et al. 2021); ``"regions"``: sampled contact regions (:mod:`grasplan.candidates.regions`).
    spacing : float
        ``method="regions"``: lattice pitch of the samples, metres.
    notes : list of str, optional
        ``method="regions"``: receives a line when the search bounded its work
        (:func:`grasplan.candidates.regions.find_regions`; a part over its limits raises an InputError).

    Returns
    -------
    Candidates
        ``"paper"``: sorted by face pair ``(i, j)``, ``i < j``, contact 0 on face i, ``region`` -1.
        ``"regions"``: sorted by region, ``region`` set (see :mod:`grasplan.candidates.regions`).
    """
    F = np.asarray(mesh.faces, dtype=np.int64)
    convex = np.asarray(convex, dtype=bool)
    if convex.shape != (len(F),):
        raise ValueError(f"convex must have shape ({len(F)},), got {convex.shape}")
    for name, v in (("max_opening", max_opening), ("epsilon", epsilon)):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a positive length in metres, got {v!r}")
    if not 0.0 <= beta_deg < 90.0:
        raise ValueError(f"beta_deg must be in [0, 90), got {beta_deg!r}")
    if not (np.isfinite(mu) and mu >= 0):
        raise ValueError(f"mu must be >= 0, got {mu!r}")
    if search not in ("index", "brute"):
        raise ValueError(f"search must be 'index' or 'brute', got {search!r}")
    if method not in ("regions", "paper"):
        raise ValueError(f"method must be 'regions' or 'paper', got {method!r}")
    if method == "regions" and not (np.isfinite(spacing) and spacing > 0):
        raise ValueError(f"spacing must be a positive length in metres, got {spacing!r}")
    V = np.asarray(mesh.vertices, dtype=np.float64)
    if tol is None:
        tol = Tolerance.for_mesh(V)
    geo = FaceGeometry.of(V, F)
    ids = np.flatnonzero(convex & geo.valid)
    if len(ids) < 2:
        return Candidates.empty()
    if method == "regions":
        contacts, normals, width, faces, region = find_regions(
            mesh, convex, geo, max_opening=max_opening, beta_deg=beta_deg, mu=mu, spacing=spacing, tol=tol,
            notes=notes)
        return Candidates(contacts, normals, width, faces, region)
    return find_face_pairs(geo, ids, max_opening=max_opening, beta_deg=beta_deg, epsilon=epsilon, mu=mu, tol=tol,
                           search=search)


@dataclass(frozen=True)
class CandidateResult:
    part: Part
    params: CandidateParams
    mesh: MeshData                     #: the mesh the candidates index into (BLM output or the part's)
    blm: BLMResult | None
    convex: np.ndarray                 #: (m,) bool, per face of ``mesh``
    candidates: Candidates
    timing_s: dict = field(default_factory=dict)
    #: what the search did to bound its work (one line each; empty for almost every part)
    notes: tuple[str, ...] = ()

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
    max_opening = params.max_opening
    if max_opening is None:
        max_opening = DEFAULT_MAX_OPENING
        params = replace(params, max_opening=max_opening)
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
    notes: list[str] = []
    try:
        cands = find_candidates(
            mesh,
            convex,
            max_opening=max_opening,
            beta_deg=params.beta_deg,
            epsilon=params.epsilon,
            mu=params.mu,
            tol=part.tol,
            method=cast(Method, params.method),   # a valid name: CandidateParams validates its choices
            spacing=params.spacing,
            notes=notes,
        )
    except InputError as e:  # a work limit of the search: name the part
        raise InputError(f"{part.path}: {e}") from None
    timing["antipodal"] = time.perf_counter() - t
    return CandidateResult(part=part, params=params, mesh=mesh, blm=blm_result, convex=convex, candidates=cands,
                           timing_s=timing, notes=tuple(notes))
