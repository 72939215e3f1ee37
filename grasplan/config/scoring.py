"""The grasp score: a weighted sum of registered terms, each in [0, 1] (higher is better).

``score = sum_k w_k * term_k / sum_k w_k``. The weights and the normalisation of the physical
terms are defined in exactly one place, the scoring YAML ``configs/scoring.yaml`` (packaged; a user
file replaces it with ``--scoring FILE``; :func:`load_scoring`). ``DEFAULT_SCORING`` is that file,
read once; ``GraspParams.score_weights`` / ``score_refs`` default to it and are recorded in every
output. A term is a function ``term(ctx: ScoreContext) -> (M,) float in [0, 1]`` registered with
:func:`register_term`; adding one is a function plus one registration (and a weight in the YAML).
The terms: ``center``, ``top``, ``width`` (geometric) and ``gravity_margin``, ``epsilon`` (physical:
:func:`gravity_margin_term`, :func:`epsilon_term`).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, TypeVar

import numpy as np

from .lookup import config_number, packaged_file
from ..errors import ConfigError, InputError
from ..geometry.meshdata import TriangleMesh

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

#: a parameter dataclass with score_weights/score_refs (:class:`grasplan.config.params.GraspParams`)
_Params = TypeVar("_Params", bound="DataclassInstance")

#: scoring configuration shipped with grasplan (the one definition of the default weights)
SCORING_FILE = packaged_file("configs", "scoring.yaml")
#: normalisation keys of the scoring YAML (a user file that omits one gets the packaged file's)
REF_KEYS = ("gravity_margin_ref", "epsilon_ref")


def _ref_fallback() -> dict:
    """The references a scoring YAML may omit: the packaged file's (none while that one loads)."""
    d = globals().get("DEFAULT_SCORING")
    return dict(d.refs) if d is not None else {}


@dataclass(frozen=True)
class ScoringConfig:
    """A scoring YAML: ``weights`` ((term, weight), ...), the normalisation references and the file."""

    weights: tuple[tuple[str, float], ...]
    gravity_margin_ref: float
    epsilon_ref: float
    source: str = ""

    @property
    def refs(self) -> tuple[tuple[str, float], ...]:
        return (("gravity_margin_ref", self.gravity_margin_ref), ("epsilon_ref", self.epsilon_ref))

    @classmethod
    def from_params(cls, weights: Iterable[tuple[str, float]], refs: Iterable[tuple[str, float]]) -> ScoringConfig:
        r = {**_ref_fallback(), **dict(refs)}
        return cls(weights=tuple((str(n), float(w)) for n, w in weights),
                   gravity_margin_ref=float(r["gravity_margin_ref"]), epsilon_ref=float(r["epsilon_ref"]))


class GraspQualities(Protocol):
    """What the physical terms read of a :class:`grasplan.grasps.quality.Quality` of ``M`` grasps (a
    Protocol: scoring sits below the quality computations and does not import them)."""

    @property
    def gravity_margin(self) -> np.ndarray: ...    # (M,)

    @property
    def epsilon(self) -> np.ndarray: ...           # (M,)

    def __len__(self) -> int: ...


@dataclass(frozen=True)
class ScoreContext:
    """What a score term may read: ``T_part_tcp`` (M, 4, 4), ``width`` (M,) m, the part's mesh (part
    frame, metres), ``T_world_part`` (4, 4), the gripper's ``max_opening`` (m), and optionally the
    grasps' ``quality`` (:class:`grasplan.grasps.quality.Quality`, M rows) with the ``scoring`` config
    (normalisation references) and the part's centre of mass ``com`` (3,) m."""

    part_mesh: TriangleMesh
    T_world_part: np.ndarray
    T_part_tcp: np.ndarray
    width: np.ndarray
    max_opening: float
    quality: GraspQualities | None = None
    scoring: ScoringConfig | None = None
    com: np.ndarray | None = None


#: a score term: ``fn(ctx) -> (M,) in [0, 1]``
ScoreTerm = Callable[[ScoreContext], np.ndarray]
TERMS: dict[str, ScoreTerm] = {}
#: terms that read ``ScoreContext.quality``
PHYSICAL_TERMS = ("gravity_margin", "epsilon")


def register_term(name: str) -> Callable[[ScoreTerm], ScoreTerm]:
    """Decorator: register ``fn(ctx) -> (M,) in [0, 1]`` as score term ``name``."""
    def deco(fn: ScoreTerm) -> ScoreTerm:
        TERMS[name] = fn
        return fn
    return deco


@register_term("center")
def _center(ctx: ScoreContext) -> np.ndarray:
    """``1 - min(1, |c_grasp - c_mass| / r_part)``: the grasp centre (TCP origin) close to the centre
    of mass (of the watertight part, else its mesh centroid); ``r_part`` = half the part's
    bounding-box diagonal."""
    m = ctx.part_mesh
    if ctx.com is not None:
        com = np.asarray(ctx.com, dtype=np.float64)
    else:
        com = np.asarray(m.center_mass if m.is_watertight else m.centroid, dtype=np.float64)
    r = 0.5 * float(np.linalg.norm(m.extents))
    d = np.linalg.norm(ctx.T_part_tcp[:, :3, 3] - com, axis=1)
    return 1.0 - np.minimum(1.0, d / max(r, 1e-12))


@register_term("top")
def _top(ctx: ScoreContext) -> np.ndarray:
    """``max(0, -z_tcp . z_world)``: approach from above (1: TCP z straight down)."""
    z_world = np.einsum("ij,mj->mi", ctx.T_world_part[:3, :3], ctx.T_part_tcp[:, :3, 2])
    return np.maximum(0.0, -z_world[:, 2])


@register_term("width")
def _width(ctx: ScoreContext) -> np.ndarray:
    """``(max_opening - width) / max_opening``: margin to the gripper's maximum opening."""
    return np.clip((ctx.max_opening - ctx.width) / ctx.max_opening, 0.0, 1.0)


def _quality_of(ctx: ScoreContext, term: str) -> tuple[GraspQualities, ScoringConfig]:
    """The physical terms read ``ScoreContext.quality`` (a :class:`grasplan.grasps.quality.Quality` of
    the same grasps); scoring with a non-zero weight on them and no quality is an InputError."""
    q = ctx.quality
    if q is None or len(q) != len(ctx.width):
        raise InputError(f"score term {term!r} needs the grasps' quality (grasplan.grasps.quality.grasp_quality); "
                         f"compute it, or give the term weight 0 in the scoring YAML")
    return q, ctx.scoring if ctx.scoring is not None else DEFAULT_SCORING


def gravity_margin_term(margin: np.ndarray, ref: float) -> np.ndarray:
    """The normalised gravity_margin term, (M,) in [0, 1]:
    ``clip((1 + log(margin) / log(gravity_margin_ref)) / 2, 0, 1)``, 1/2 at the slipping threshold
    (margin 1), 1 at the reference margin and above, 0 at its inverse and below. Log-symmetric about
    the threshold, so grasps that hold come first and margins below 1 still rank: where none holds
    (a part too heavy for the gripper, e.g. a steel one) the ones closest to holding lead, where a
    term flat at 0 left their order to the geometric terms (:mod:`grasplan.grasps.quality`)."""
    gm = np.maximum(np.asarray(margin, dtype=np.float64), 1e-300)
    return np.clip(0.5 * (1.0 + np.log(gm) / math.log(ref)), 0.0, 1.0)


def epsilon_term(epsilon: np.ndarray, ref: float) -> np.ndarray:
    """The normalised epsilon term, ``clip(epsilon / ref, 0, 1)``: the Ferrari-Canny L1 quality
    (:mod:`grasplan.grasps.quality`)."""
    return np.clip(np.asarray(epsilon, dtype=np.float64) / ref, 0.0, 1.0)


@register_term("gravity_margin")
def _gravity_margin(ctx: ScoreContext) -> np.ndarray:
    q, cfg = _quality_of(ctx, "gravity_margin")
    return gravity_margin_term(q.gravity_margin, cfg.gravity_margin_ref)


@register_term("epsilon")
def _epsilon(ctx: ScoreContext) -> np.ndarray:
    q, cfg = _quality_of(ctx, "epsilon")
    return epsilon_term(q.epsilon, cfg.epsilon_ref)


# ------------------------------------------------------------------------------------------------
# the scoring YAML
# ------------------------------------------------------------------------------------------------
#: a scoring file larger than this is refused before it is read
MAX_SCORING_BYTES = 1_000_000


def load_scoring(path: str | Path | None = None) -> ScoringConfig:
    """Read a scoring YAML (default: the packaged ``configs/scoring.yaml``); ConfigError naming the
    field and the fix."""
    p = Path(path) if path is not None else SCORING_FILE
    from .yamlfile import read_yaml_file

    try:  # the one YAML reader: a regular file of at most 1 MB, bounded aliases, each field constructible
        data = read_yaml_file(p, what="scoring file", max_bytes=MAX_SCORING_BYTES)
    except ConfigError:
        raise
    except InputError as exc:
        raise ConfigError(str(exc)) from None
    if not isinstance(data, dict) or not isinstance(data.get("weights"), dict) or not data["weights"]:
        raise ConfigError(f"scoring file {p}: expected a mapping with 'weights: {{term: weight, ...}}'")
    unknown = set(data) - {"weights", "normalisation"}
    if unknown:
        raise ConfigError(f"scoring file {p}: unknown fields {sorted(map(str, unknown))}; allowed: weights, normalisation")
    bad = sorted(str(k) for k in data["weights"] if k not in TERMS)
    if bad:
        raise ConfigError(f"scoring file {p}: weights: unknown term(s) {bad}; available: {', '.join(sorted(TERMS))}")
    weights = tuple((str(k), config_number(v, f"{p}: weights.{k}", nonneg=True)) for k, v in data["weights"].items())
    if sum(w for _, w in weights) <= 0:
        raise ConfigError(f"scoring file {p}: weights: at least one weight must be > 0")
    norm = data.get("normalisation") or {}
    if not isinstance(norm, dict) or set(norm) - set(REF_KEYS):
        raise ConfigError(f"scoring file {p}: normalisation: allowed keys {', '.join(REF_KEYS)}")
    fallback = _ref_fallback()
    missing = [k for k in REF_KEYS if k not in norm and k not in fallback]
    if missing:
        raise ConfigError(f"scoring file {p}: normalisation: {', '.join(missing)} missing")
    gm = config_number(norm.get("gravity_margin_ref", fallback.get("gravity_margin_ref")),
                       f"{p}: normalisation.gravity_margin_ref", positive=True)
    if gm <= 1:
        raise ConfigError(f"scoring file {p}: normalisation.gravity_margin_ref must be > 1, got {gm:g}")
    eps = config_number(norm.get("epsilon_ref", fallback.get("epsilon_ref")), f"{p}: normalisation.epsilon_ref",
                        positive=True)
    return ScoringConfig(weights=weights, gravity_margin_ref=gm, epsilon_ref=eps, source=str(p))


def load_score_weights(path: str | Path | None = None) -> tuple[tuple[str, float], ...]:
    """``((term, weight), ...)`` from a scoring YAML (default the packaged ``configs/scoring.yaml``)."""
    return load_scoring(path).weights


#: the packaged scoring YAML, read once at import: the default weights and references
DEFAULT_SCORING = load_scoring()


def check_weights(weights: Sequence[tuple[str, float]], where: str = "score_weights") -> None:
    """InputError unless ``weights`` is ((known term, finite weight >= 0), ...) with a positive one."""
    try:
        names = [n for n, _ in weights]
    except (TypeError, ValueError):
        raise InputError(f"{where}: expected ((term, weight), ...), got {weights!r}") from None
    unknown = sorted(set(map(str, names)) - set(TERMS))
    if unknown:
        raise InputError(f"{where}: unknown term(s) {unknown}; available: {', '.join(sorted(TERMS))}")
    for n, w in weights:
        if isinstance(w, bool) or not isinstance(w, (int, float)) or not math.isfinite(w) or w < 0:
            raise InputError(f"{where}: weight of {n!r} must be a finite number >= 0, got {w!r}")
    if not any(w > 0 for _, w in weights):
        raise InputError(f"{where}: at least one weight must be > 0")


def score_grasps(part_mesh: TriangleMesh, T_world_part: np.ndarray, T_part_tcp: np.ndarray, width: np.ndarray,
                 max_opening: float, weights: Sequence[tuple[str, float]] | None = None, *, quality: GraspQualities | None = None,
                 scoring: ScoringConfig | None = None, com: np.ndarray | None = None) -> np.ndarray:
    """Score in [0, 1] per grasp (higher is better). ``T_part_tcp`` (M, 4, 4), ``width`` (M,) m.

    ``weights``: ``((term, weight), ...)``; default those of ``scoring`` (default: the packaged
    ``configs/scoring.yaml``). ``quality`` (:class:`grasplan.grasps.quality.Quality` of the M grasps) is
    needed by the physical terms; ``com`` (3,) m: the part's centre of mass for ``center``."""
    T_part_tcp = np.asarray(T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    width = np.asarray(width, dtype=np.float64).reshape(-1)
    if len(width) != len(T_part_tcp):
        raise ValueError("T_part_tcp (M, 4, 4) and width (M,) disagree")
    cfg = scoring if scoring is not None else DEFAULT_SCORING
    ctx = ScoreContext(part_mesh, np.asarray(T_world_part, dtype=np.float64), T_part_tcp, width, float(max_opening),
                       quality=quality, scoring=cfg, com=com)
    weights = tuple(weights if weights is not None else cfg.weights)
    total = sum(w for _, w in weights)
    out = np.zeros(len(width))
    for name, w in weights:
        if w:
            out += w * TERMS[name](ctx)
    return out / total if total > 0 else out


def with_scoring_file(grasp_params: _Params, path: str | Path | None) -> _Params:
    """``grasp_params`` (a :class:`grasplan.config.params.GraspParams`) with the weights and references of
    the scoring YAML ``path`` (``--scoring FILE``); unchanged when ``path`` is None."""
    if path is None:
        return grasp_params
    from dataclasses import replace

    cfg = load_scoring(path)
    return replace(grasp_params, score_weights=cfg.weights, score_refs=cfg.refs)


#: help of the ``--scoring FILE`` option of grasps, plan and batch
SCORING_HELP = ("Score weights and normalisation: a YAML file like the packaged configs/scoring.yaml "
                "(docs/quality.md) [default: the packaged one].")
