"""Every option of the pipeline, defined once: three frozen, keyword-only dataclasses.

``CandidateParams`` (stages 2-4), ``GraspParams`` (stages 5-6) and ``PlanParams`` (stages 7-8)
validate themselves in ``__post_init__`` and raise :class:`~grasplan.errors.InputError` naming
the CLI option, the value and the range that would pass. Each field carries its CLI spelling, kind
and range in ``metadata`` (:func:`spec`); ``grasplan.cli.options`` builds every command's options
from these fields, so a default or a range exists in exactly one place.

Units: lengths in metres (the CLI accepts suffixes: ``2mm``), user-facing angles in degrees and
named so (``gamma_deg``), times in seconds.
"""
from __future__ import annotations

import math
from dataclasses import MISSING, asdict, dataclass, field, fields
from typing import Any

from .errors import InputError

#: the default gripper, cell and robot (names looked up by grasplan.config_files)
DEFAULT_GRIPPER = "schunk_egp_c_40"
DEFAULT_CELL = "table"
DEFAULT_ROBOT = "ur5"
#: contact distance searched when no gripper says otherwise: the paper's Schunk Co-act EGP-C 40
#: with fingers for a 50 mm opening
DEFAULT_MAX_OPENING = 0.05
#: the largest length any option accepts, m (a cell is a few metres; 1e308 is refused)
MAX_LENGTH = 10.0
#: candidate methods: regions (sampled contact regions, the default) or the paper's face pairs
METHODS = ("regions", "paper")
#: score terms of :mod:`grasplan.scoring` with their default weights, and the normalisation of the
#: physical terms: read from the packaged ``configs/scoring.yaml``, their one definition
from .scoring import DEFAULT_SCORING as _DEFAULT_SCORING

DEFAULT_SCORE_WEIGHTS: tuple[tuple[str, float], ...] = _DEFAULT_SCORING.weights
DEFAULT_SCORE_REFS: tuple[tuple[str, float], ...] = _DEFAULT_SCORING.refs
#: default part density, kg/m^3 (steel)
DEFAULT_DENSITY = 7850.0


def spec(default: Any, kind: str, help: str, *, cli: str | None = None, lo: float | None = None,
         hi: float | None = None, lo_open: bool = False, choices: tuple = (), flag: str | None = None,
         show: str | None = None, cli_hidden: bool = False):
    """A dataclass field with its CLI description.

    kind: ``length`` (m, > 0), ``length0`` (m, >= 0, 0 = off), ``angle`` (deg), ``int``, ``float``,
    ``bool``, ``choice``, ``seconds`` (> 0 s), ``optional_length`` / ``optional_seconds`` / ``optional_int``
    (None allowed), ``internal`` (no CLI option)."""
    md = {"kind": kind, "help": help, "cli": cli, "lo": lo, "hi": hi, "lo_open": lo_open, "choices": choices,
          "flag": flag, "show": show, "cli_hidden": cli_hidden}
    return field(default=default, metadata=md)


def option_name(f) -> str:
    """The CLI spelling of a dataclass field (``--roll-step`` for ``roll_step_deg``)."""
    return f.metadata.get("cli") or "--" + f.name.replace("_", "-")


def _fail(f, value, why: str) -> InputError:
    return InputError(f"{option_name(f)} ({f.name}): {why}, got {value!r}")


def _validate(obj) -> None:
    for f in fields(obj):
        md = f.metadata
        kind = md.get("kind")
        if kind is None or kind == "internal":
            continue
        v = getattr(obj, f.name)
        if v is None and kind.startswith("optional_"):
            continue
        base = kind.removeprefix("optional_")
        if base == "bool":
            if not isinstance(v, bool):
                raise _fail(f, v, "expected true or false")
            continue
        if base == "choice":
            if v not in md["choices"]:
                raise _fail(f, v, f"expected one of {', '.join(map(str, md['choices']))}")
            continue
        if base == "int":
            if isinstance(v, bool) or not isinstance(v, int):
                raise _fail(f, v, "expected a whole number")
        elif isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise _fail(f, v, "expected a finite number")
        lo, hi = md.get("lo"), md.get("hi")
        if base == "length":
            lo, hi = (lo if lo is not None else 0.0), (hi if hi is not None else MAX_LENGTH)
            if not (lo < v <= hi):
                raise _fail(f, v, f"expected a length in ({lo:g}, {hi:g}] m (e.g. 2mm)")
            continue
        if base == "length0":
            hi = hi if hi is not None else MAX_LENGTH
            if not (0.0 <= v <= hi):
                raise _fail(f, v, f"expected a length in [0, {hi:g}] m (0 = off)")
            continue
        if base == "seconds":
            hi = hi if hi is not None else 86400.0
            if not (0.0 < v <= hi):
                raise _fail(f, v, f"expected seconds in (0, {hi:g}]")
            continue
        if lo is not None and (v < lo or (md.get("lo_open") and v == lo)):
            raise _fail(f, v, f"must be {'>' if md.get('lo_open') else '>='} {lo:g}" + (f" and <= {hi:g}" if hi is not None else ""))
        if hi is not None and v > hi:
            raise _fail(f, v, f"must be <= {hi:g}" + (f" and >= {lo:g}" if lo is not None else ""))


class _Params:
    """Shared behaviour: validation, JSON (lengths m, angles *_deg), defaults by name."""

    def __post_init__(self):
        _validate(self)
        self._check()

    def _check(self) -> None:  # cross-field checks, overridden where needed
        pass

    def to_json(self) -> dict:
        out = asdict(self)
        for k, v in out.items():
            if isinstance(v, tuple):
                out[k] = [list(x) if isinstance(x, tuple) else x for x in v]
        return out

    @classmethod
    def from_json(cls, data: dict):
        """Rebuild from :meth:`to_json` output (unknown keys are ignored: older/newer files)."""
        kw = {}
        for f in fields(cls):
            if f.name in data:
                v = data[f.name]
                if isinstance(v, list):
                    v = tuple(tuple(x) if isinstance(x, list) else x for x in v)
                kw[f.name] = v
        return cls(**kw)

    @classmethod
    def default(cls, name: str):
        f = next(f for f in fields(cls) if f.name == name)
        return f.default if f.default is not MISSING else f.default_factory()


@dataclass(frozen=True, kw_only=True)
class CandidateParams(_Params):
    """Stages 2-4: BLM, convexity, antipodal search. Lengths m, angles degrees."""

    blm: bool = spec(True, "bool", "Run the boundary layer mesher before the search (--no-blm: the part's own mesh).",
                     flag="--blm/--no-blm")
    alpha: float = spec(1e-4, "length", "BLM boundary-layer width.", hi=0.1, show="0.1mm")
    gamma_deg: float = spec(135.0, "angle", "BLM surface angle: facets join a surface when their normals differ "
                            "by at most 180 - gamma degrees.", cli="--gamma", lo=90.0, hi=180.0, lo_open=True)
    d_shift: float = spec(1e-5, "length", "Convexity: shift of the face centroid along its normal.", hi=0.01,
                          show="0.01mm")
    epsilon: float = spec(5e-3, "length", "Antipodal overlap threshold.", hi=0.5, show="5mm")
    max_opening: float | None = spec(None, "optional_length", "Largest contact distance searched "
                                     "[default: the gripper's max_opening].", hi=2.0)
    beta_deg: float = spec(2.0, "angle", "Normals anti-parallel within this angle.", cli="--beta", lo=0.0, hi=45.0)
    mu: float = spec(0.3, "float", "Friction coefficient (cone half-angle atan(mu)).", lo=0.0, hi=10.0)
    method: str = spec("regions", "choice", "Candidates: 'regions' samples opposing contact regions every --spacing "
                       "(independent of the tessellation); 'paper' is one pair per face pair (Vogt et al. 2021).",
                       choices=METHODS)
    spacing: float = spec(2e-3, "length", "regions: grid spacing of the contact samples.", lo=0.0, hi=0.1, show="2mm")


@dataclass(frozen=True, kw_only=True)
class GraspParams(_Params):
    """Stages 5-6: TCP frames rolled about each closing axis, full-jaw collision filter."""

    roll_step_deg: float = spec(15.0, "float", "Roll step of the TCP about the closing axis, degrees "
                                "(poses at 0, step, ... < 360).", cli="--roll-step", lo=1.0, hi=360.0)
    thin_spacing: float = spec(0.0, "length0", "Pose one candidate per cluster (grasp-centre grid of this pitch x "
                               "closing axis in --thin-axis steps); 0 poses every candidate.", cli="--thin",
                               hi=0.5, show="0 (off)")
    thin_axis_deg: float = spec(10.0, "float", "Thinning: closing-axis direction step, degrees.", cli="--thin-axis",
                                lo=0.5, hi=90.0)
    merge_distance: float = spec(0.0, "length0", "Also skip a candidate whose contacts fall in the same grid cells of "
                                 "this size as an earlier candidate's; 0 = off.", hi=0.5)
    pose_index: int | None = spec(None, "optional_int", "Rest the part in this stable pose (0 = most probable) "
                                  "instead of the cell's pose_index.", lo=0, hi=10000)
    # grasp quality (issue 11, grasplan.quality): mass properties and the score
    density: float = spec(DEFAULT_DENSITY, "float", "Part density, kg/m^3 (uniform; 7850 steel, 2700 aluminium, "
                          "~1200 plastic): mass and centre of mass for the grasp quality.", lo=0.0, lo_open=True,
                          hi=1e5)
    mass: float | None = spec(None, "optional_float", "Part mass, kg (overrides --density).", lo=0.0, lo_open=True,
                              hi=1e4)
    score_weights: tuple[tuple[str, float], ...] = spec(DEFAULT_SCORE_WEIGHTS, "internal",
                                                         "Score terms and weights (configs/scoring.yaml or --scoring).")
    score_refs: tuple[tuple[str, float], ...] = spec(DEFAULT_SCORE_REFS, "internal",
                                                      "Normalisation of the physical score terms (scoring YAML).")

    def _check(self) -> None:
        from .scoring import REF_KEYS, check_weights

        check_weights(self.score_weights)
        refs = dict(self.score_refs)
        if set(refs) - set(REF_KEYS) or not all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0
                                                 for v in refs.values()) or refs.get("gravity_margin_ref", 2) <= 1:
            raise InputError(f"score_refs: expected {', '.join(REF_KEYS)} > 0 (gravity_margin_ref > 1), got {refs!r}")


@dataclass(frozen=True, kw_only=True)
class PlanParams(_Params):
    """Stages 7-8: ranking, IK, straight approach, OMPL path. Lengths m, times s."""

    top: int = spec(20, "int", "Plan at most this many grasps, best score first; other ok grasps are not_tried.",
                    lo=1, hi=100000)
    seed: int = spec(0, "int", "Seed of IK and OMPL (same seed, same result).", lo=0, hi=2**31 - 1)
    backoff: float = spec(0.05, "length", "Pre-grasp back-off along the TCP's -z (the straight approach).",
                          lo=0.0, hi=0.5, show="50mm")
    max_dev: float = spec(0.002, "length", "Approach: largest TCP distance from the straight line.", hi=0.05,
                          show="2mm")
    time_limit_per_query: float = spec(1.0, "seconds", "RRTConnect time per attempt, seconds.", cli="--time-limit",
                                       hi=600.0)
    path_attempts: int = spec(2, "int", "RRTConnect attempts per query (new seed, finer checks).", lo=1, hi=20)
    max_ik_solutions: int = spec(8, "int", "IK solutions tried per grasp (closest to q_home first).", lo=1, hi=64)
    max_path_queries: int = spec(2, "int", "RRTConnect queries per grasp (distinct IK solutions).", lo=1, hi=64)
    budget_s: float | None = spec(100.0, "optional_seconds", "Wall-clock budget of the planning loop, seconds; "
                                  "later grasps are not_tried.", cli="--budget", hi=86400.0)
    distinct_distance: float = spec(0.005, "length0", "Ranking: a grasp within this distance and --distinct-angle "
                                    "of a better one ranks after every distinct grasp; 0 = off.", hi=0.5, show="5mm")
    distinct_angle_deg: float = spec(15.0, "float", "Ranking: angle for --distinct-distance, degrees.",
                                     cli="--distinct-angle", lo=0.0, hi=180.0)
    score_weights: tuple[tuple[str, float], ...] | None = spec(None, "internal",
                                                                "Re-score the grasps with these weights before "
                                                                "ranking; None: the grasp stage's score "
                                                                "(GraspParams.score_weights, the scoring YAML).")
    simulate: int = spec(0, "int", "After planning, simulate the top N planned grasps (MuJoCo lift and shake, "
                         "grasplan simulate) and rank those that held first; 0 = off.", lo=0, hi=1000)
    check_all: bool = spec(True, "bool", "Collision-check and score every pose before planning; --no-check-all: "
                           "only the poses whose score bound can reach the planned ranks, the rest are not_checked "
                           "(docs/plan.md).", flag="--check-all/--no-check-all")

    def _check(self) -> None:
        if self.score_weights is not None:
            from .scoring import check_weights

            check_weights(self.score_weights)


PARAM_CLASSES = (CandidateParams, GraspParams, PlanParams)
