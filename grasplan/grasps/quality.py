"""Physical grasp quality: the :class:`Quality` of parallel-jaw grasps and the grasp
stage's quality step.

:func:`grasp_quality` computes each grasp's contact patches, gravity margin and Ferrari-Canny
epsilon, :func:`quality_and_score` is the grasp stage's step (mass properties, quality of the
collision-free poses, score with :mod:`grasplan.config.scoring`), :func:`holding_warning` says when
no grasp holds.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError
from ..gripper.model import Gripper
from ..part.mass import MassProperties, mass_properties
from ..geometry.meshdata import TriangleMesh
from .patches import contact_patches, pad_rectangle
from ..results.quality_json import CONTACT_TYPES, hold_force
from ..config.scoring import (
    DEFAULT_SCORING, PHYSICAL_TERMS, ScoringConfig, epsilon_term, gravity_margin_term, score_grasps
)
from ..status import Status
from ..geometry.transforms import check_transform
from .wrench import CONTACTS_PER_GRIP, LOAD, epsilon_dedup, gravity_margin, pressure_widths

if TYPE_CHECKING:
    from ..candidates.antipodal_base import Candidates
    from ..config.params import GraspParams


@dataclass(frozen=True)
class Quality:
    """Quality of ``M`` grasps.

    Attributes
    ----------
    contact_area : (M, 2) float64
        Patch area per jaw (jaw 0 touches contact 0, on the TCP's -x side), m^2.
    contact_type : (M, 2) int8
        Index into ``CONTACT_TYPES`` ("point", "line", "surface").
    contact_width : (M, 2, 2) float64
        Equivalent (min, max) widths of each patch, m.
    gravity_margin : (M,) float64
        Friction available / friction needed under the lift and shake (``wrench.LOAD``); < 1 slips.
    epsilon : (M,) float64
        Ferrari-Canny L1 quality (wrench units: N per N of normal force), >= 0.
    grip_force : float
        The gripping force used, N (sum of both jaws; each contact is pressed with half of it).
    mu : float
        Friction coefficient used.
    """

    contact_area: np.ndarray
    contact_type: np.ndarray
    contact_width: np.ndarray
    gravity_margin: np.ndarray
    epsilon: np.ndarray
    grip_force: float
    mu: float

    def __len__(self) -> int:
        return len(self.epsilon)

    @property
    def hold_force(self) -> np.ndarray:
        """(M,) grip force (N, both jaws) at which each grasp just holds under the shared load
        (:func:`grasplan.results.quality_json.hold_force`: ``grip_force / gravity_margin``; NaN:
        no force holds it)."""
        return hold_force(self.gravity_margin, self.grip_force)

    def to_json(self, i: int, *, score: float | None = None) -> dict:
        """The ``quality`` object of grasp ``i`` (areas m^2; ``score`` added when given)."""
        out = {
            "contact": [{"area_m2": float(self.contact_area[i, j]),
                         "type": CONTACT_TYPES[int(self.contact_type[i, j])]}
                        for j in range(2)],
            "gravity_margin": float(self.gravity_margin[i]),
            "epsilon": float(self.epsilon[i]),
        }
        if score is not None:
            out["score"] = float(score)
        return out


def part_radius(part_mesh: TriangleMesh, com: np.ndarray) -> float:
    """Largest distance of the part's (hull) vertices from ``com``, m: the torque scale of epsilon."""
    v = np.asarray(part_mesh.convex_hull.vertices if len(part_mesh.vertices) > 64 else part_mesh.vertices)
    return float(np.linalg.norm(v - com, axis=1).max())


def grasp_quality(part_mesh: TriangleMesh, mass_props: MassProperties, gripper: Gripper,
                  T_part_tcp: np.ndarray, contacts: np.ndarray, normals: np.ndarray, width: np.ndarray, *,
                  T_world_part: np.ndarray, mu: float, grip_force: float | None = None,
                  timing: dict[str, float] | None = None) -> Quality:
    """Contact patches, gravity margin and epsilon of ``M`` grasps:

    - the **contact patch** of each finger pad (area, type point / line / surface, equivalent widths):
      :func:`grasplan.grasps.patches.contact_patches`;
    - the **gravity margin** (soft-finger friction and pad pressure available / needed under the lift
      and shake of :data:`grasplan.grasps.wrench.LOAD`, the profile the MuJoCo check applies; below 1
      the part slips) and the **Ferrari-Canny epsilon** (L1, two soft-finger contacts):
      :mod:`grasplan.grasps.wrench`, which gives the models; each contact is pressed with
      ``grip_force / CONTACTS_PER_GRIP`` (the datasheet gripping force is the sum of both jaws).

    Parameters
    ----------
    part_mesh : TriangleMesh
        Part frame, metres (a MeshData or a trimesh).
    mass_props : MassProperties
        From :func:`grasplan.part.mass.mass_properties`.
    gripper : Gripper
        Its finger gives the pad; its ``grip_force`` (N, sum of both jaws) is used unless ``grip_force``.
    T_part_tcp : (M, 4, 4)
    contacts, normals : (M, 2, 3)
        Contact points (m) and outward unit surface normals, part frame; contact 0 on the TCP's -x side.
    width : (M,)
        Contact distance, m.
    T_world_part : (4, 4)
        The part's pose (gives the direction of gravity).
    mu : float
        Friction coefficient (>= 0).
    grip_force : float, optional
        Gripping force, N (sum of both jaws: each contact is pressed with half); default
        ``gripper.grip_force``.
    timing : dict, optional
        Seconds of the three steps are added to it: ``quality_patches``, ``quality_margin``,
        ``quality_epsilon``.
    """
    T = check_transform(T_part_tcp, "T_part_tcp", batch=True) if len(np.shape(T_part_tcp)) == 3 else \
        check_transform(T_part_tcp, "T_part_tcp")[None]
    Twp = check_transform(T_world_part, "T_world_part")
    M = len(T)
    C = np.asarray(contacts, dtype=np.float64)
    N = np.asarray(normals, dtype=np.float64)
    w = np.asarray(width, dtype=np.float64).reshape(-1)
    if C.shape != (M, 2, 3) or N.shape != (M, 2, 3) or w.shape != (M,):
        raise InputError(f"grasp quality: expected contacts and normals (M, 2, 3) and width (M,) for M = {M} "
                         f"grasps, got {C.shape}, {N.shape}, {w.shape}")
    if not (np.all(np.isfinite(C)) and np.all(np.isfinite(N)) and np.all(np.isfinite(w))):
        raise InputError("grasp quality: contacts, normals or widths hold NaN or infinite values")
    if not (math.isfinite(mu) and mu >= 0):
        raise InputError(f"grasp quality: mu must be a finite number >= 0, got {mu!r}")
    F = float(gripper.grip_force if grip_force is None else grip_force)
    if not (math.isfinite(F) and F > 0):
        raise InputError(f"grasp quality: grip_force must be > 0 N, got {grip_force!r} (gripper YAML grip_force)")
    if M == 0:
        z2 = np.zeros((0, 2))
        return Quality(contact_area=z2, contact_type=np.zeros((0, 2), dtype=np.int8), contact_width=np.zeros((0, 2, 2)),
                       gravity_margin=np.zeros(0), epsilon=np.zeros(0), grip_force=F, mu=float(mu))
    t0 = time.perf_counter()
    area, kind, widths = contact_patches(part_mesh, gripper, T, C)
    t1 = time.perf_counter()
    margin = gravity_margin(mass_props, Twp, T, w, area, mu=mu, normal_force=F / CONTACTS_PER_GRIP,
                            patch_width=pressure_widths(kind, widths))
    t2 = time.perf_counter()
    eps = epsilon_dedup(C, N, area, mass_props.com, max(part_radius(part_mesh, mass_props.com), 1e-9), mu)
    if timing is not None:
        for key, dt in (("quality_patches", t1 - t0), ("quality_margin", t2 - t1),
                        ("quality_epsilon", time.perf_counter() - t2)):
            timing[key] = timing.get(key, 0.0) + dt
    return Quality(contact_area=area, contact_type=kind, contact_width=widths, gravity_margin=margin,
                   epsilon=eps, grip_force=F, mu=float(mu))


def stage_warnings(notes: tuple[str, ...] | list[str], quality: Quality | None, mass_props: MassProperties | None,
                   quality_note: str, *, part: str) -> list[str]:
    """What a grasp stage tells the user: ``notes`` (the work bounds the candidate and pose stages
    applied), the mass properties' warnings (or ``quality_note``, why there is no quality) and
    :func:`holding_warning`."""
    out = list(notes)
    out += list(mass_props.warnings) if mass_props is not None else [quality_note] if quality_note else []
    w = holding_warning(quality, mass_props, part=part)
    return out + [w] if w else out


def holding_warning(quality: Quality | None, mass_props: MassProperties | None, *, part: str = "the part") -> str:
    """A warning when no grasp of ``quality`` reaches ``gravity_margin >= 1`` ("" otherwise): the
    best margin, what would have held: the largest density (or mass) the best grasp holds (the
    loads are proportional to the mass, so the margin to its inverse) and the lighter materials
    within it, and the grip force that would (the margin is proportional to the gripping force:
    friction and soft-finger torsion both scale with it)."""
    from ..config.materials import CUSTOM, MATERIALS

    if quality is None or mass_props is None or len(quality) == 0:
        return ""
    best = float(np.max(quality.gravity_margin))
    if not np.isfinite(best) or best >= 1.0:
        return ""
    need = quality.grip_force / max(best, 1e-12)
    limit = mass_props.density * best
    lighter = [n for n, d in sorted(MATERIALS.items(), key=lambda kv: -kv[1]) if d <= limit]
    what = f"{mass_props.material} at " if mass_props.material and mass_props.material != CUSTOM else ""
    if mass_props.material == CUSTOM and lighter == []:
        would = f"it would hold at <= {mass_props.mass * best:.3g} kg"
    else:
        would = f"it would hold at <= {limit:.4g} kg/m^3"
        if lighter:
            hint = "--material plastic if it is plastic" if "plastic" in lighter else f"--material {lighter[0]}"
            would += f" ({', '.join(lighter)}: give {hint}, or --density, --mass)"
        else:
            would += " (lighter than any --material: give the real --density or --mass)"
    return (f"no collision-free grasp is predicted to hold {part} ({mass_props.mass:.3g} kg, {what}"
            f"{mass_props.density:.4g} kg/m^3) through the lift and shake (peak {LOAD.peak_g():.2f} g): the best "
            f"gravity_margin is {best:.2f} (< 1: it slips); {would}, or with about {need:.0f} N of grip force at "
            f"mu {quality.mu:g} (the gripper gives {quality.grip_force:g} N; grip_force in its YAML); the ranking "
            f"leads with the grasps closest to holding (check them with grasplan simulate)")


# ------------------------------------------------------------------------------------------------
# the grasp stage's quality step: columns, score
# ------------------------------------------------------------------------------------------------
def quality_columns(quality: Quality, rows: np.ndarray, M: int) -> dict:
    """Per-pose arrays of :class:`grasplan.results.plan_result.GraspTable` for ``M`` poses whose rows ``rows``
    have ``quality`` (the others NaN, type -1): contact_area (M, 2), contact_type (M, 2) int8,
    gravity_margin (M,), epsilon (M,)."""
    rows = np.asarray(rows, dtype=np.int64)
    area = np.full((M, 2), np.nan)
    kind = np.full((M, 2), -1, dtype=np.int8)
    gm = np.full(M, np.nan)
    eps = np.full(M, np.nan)
    area[rows], kind[rows], gm[rows], eps[rows] = quality.contact_area, quality.contact_type, \
        quality.gravity_margin, quality.epsilon
    return {"contact_area": area, "contact_type": kind, "gravity_margin": gm, "epsilon": eps}


def quality_and_score(part_mesh: TriangleMesh, gripper: Gripper, T_world_part: np.ndarray, T_part_tcp: np.ndarray,
                      candidate: np.ndarray, candidates: Candidates, status: np.ndarray, mu: float, params: GraspParams, *,
                      mass_props: MassProperties | None = None, timing: dict[str, float] | None = None,
                      ) -> tuple[Quality | None, MassProperties | None, np.ndarray, str]:
    """The grasp stage's quality step: mass properties at ``params.density`` / ``params.mass``, the
    quality of the ``ok`` poses and the score of every pose (NaN where not ``ok``) with the weights
    ``params.score_weights`` / ``params.score_refs`` (a :class:`grasplan.config.params.GraspParams`).

    Returns ``(Quality of the ok rows, MassProperties, score (M,), note)``. A part without volume
    (flat, degenerate: no mass properties) has no quality: ``(None, None, score, note)`` with the
    score of the other terms and ``note`` saying why; ``note`` is "" otherwise. ``mass_props``: the
    part's mass properties at ``params`` when the caller already has them (chunked callers);
    ``timing``: the quality's split is added to it (:func:`grasp_quality`)."""
    T = np.asarray(T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    M = len(T)
    ok = np.flatnonzero(np.asarray(status).astype(str) == Status.OK.value)
    ci = np.asarray(candidate, dtype=np.int64)[ok]
    width = np.asarray(candidates.width, dtype=np.float64)[ci]
    note = ""
    mp = mass_props
    if mp is None:
        mp, note = mass_or_note(part_mesh, params)
    q = None if mp is None else grasp_quality(part_mesh, mp, gripper, T[ok], candidates.contacts[ci],
                                              candidates.normals[ci], width, T_world_part=T_world_part, mu=mu,
                                              timing=timing)
    score = np.full(M, np.nan)
    score[ok] = stage_score(part_mesh, gripper, T_world_part, T[ok], width, params, q, mp)
    return q, mp, score, note


def mass_or_note(part_mesh: TriangleMesh, params: GraspParams) -> tuple[MassProperties | None, str]:
    """``(mass properties at params.density / params.mass, "")``, or ``(None, why)`` for a part
    without volume (flat, degenerate) at the default density: its grasps get no quality and the
    score only the other terms. InputError when the user asked for a density or mass."""
    try:
        return mass_properties(part_mesh, density=params.density, mass=params.mass, material=params.material), ""
    except InputError as exc:
        if params.mass is not None or params.density != type(params)().density:
            raise  # the user asked for a mass: say why there is none
        return None, f"no grasp quality: {exc}; the score uses only the other terms"


def stage_score(part_mesh: TriangleMesh, gripper: Gripper, T_world_part: np.ndarray, T_part_tcp: np.ndarray,
                width: np.ndarray, params: GraspParams, quality: Quality | None, mass_props: MassProperties | None
                ) -> np.ndarray:
    """(k,) the grasp stage's score of ``k`` collision-free poses (:func:`grasplan.config.scoring.score_grasps`,
    weights ``params.score_weights``): with ``quality`` (and ``mass_props``) every term, without
    only the terms that need no quality (NaN when those weigh nothing)."""
    cfg = ScoringConfig.from_params(params.score_weights, params.score_refs)
    k = len(width)
    if quality is None or mass_props is None:
        weights = tuple((n, w) for n, w in cfg.weights if n not in PHYSICAL_TERMS)
        if not k or sum(w for _, w in weights) <= 0:
            return np.full(k, np.nan)
        return score_grasps(part_mesh, T_world_part, T_part_tcp, width, float(gripper.max_opening), weights,
                            scoring=cfg)
    if not k:
        return np.zeros(0)
    return score_grasps(part_mesh, T_world_part, T_part_tcp, width, float(gripper.max_opening), cfg.weights,
                        quality=quality, scoring=cfg, com=mass_props.com)


def score_quality_terms(quality: Quality, config: ScoringConfig | None = None) -> dict[str, np.ndarray]:
    """Normalised quality terms, each (M,) in [0, 1], higher is better: the score's own
    :func:`grasplan.config.scoring.gravity_margin_term` and :func:`grasplan.config.scoring.epsilon_term`."""
    cfg = config if config is not None else DEFAULT_SCORING
    return {"gravity_margin": gravity_margin_term(quality.gravity_margin, cfg.gravity_margin_ref),
            "epsilon": epsilon_term(quality.epsilon, cfg.epsilon_ref)}
