"""Every option of the pipeline, defined once: three frozen, keyword-only dataclasses.

``CandidateParams`` (stages 2-4), ``GraspParams`` (stages 5-6) and ``PlanParams`` (stages 7-8)
validate themselves in ``__post_init__`` and raise :class:`~grasplan.errors.InputError` naming
the CLI option, the value and the range that would pass; :class:`RunParams` holds the three for a
run. Each field carries its CLI spelling, kind, range and help in ``metadata``
(:func:`grasplan.config.option_kinds.spec`), read by the one interpreter of option kinds
(:mod:`grasplan.config.option_kinds`): the CLI options and the batch manifests' columns.

Besides the stages' numbers they hold what to plan: the place (``PlanParams.place``), the scoring
file (``GraspParams.scoring``, read into ``score_weights`` / ``score_refs``) and every resting pose
(``GraspParams.pose_index = "all"``). ``to_json`` (the record in output files) leaves out what an
output records elsewhere; ``options_json`` (the batch's options hash) keeps the place. Units:
lengths in metres, user-facing angles in degrees and named so (``gamma_deg``), times in seconds.
"""
from __future__ import annotations

import math
from dataclasses import MISSING, Field, dataclass, field, fields
from typing import Any, ClassVar, TypeVar

import numpy as np

from ..errors import InputError
from .option_kinds import check_fields, is_option, option_name, option_spec, spec

#: the default gripper, cell and robot (names looked up by grasplan.config.lookup): the SCHUNK
#: Co-act EGP-C 40 with its 2 x 6 mm stroke and fingers for the demo bracket (30-42 mm)
DEFAULT_GRIPPER = "schunk_egp_c_40"
DEFAULT_CELL = "table"
DEFAULT_ROBOT = "ur5"
#: the gripper as Vogt et al. 2021 modelled it (the EGP-C 40's boxes, jaws closing fully from 50 mm):
#: the paper's figures, and mixed piles (grasplan clutter), whose parts no single short stroke holds
PAPER_GRIPPER = "long_stroke_50"
#: contact distance searched when no gripper says otherwise: PAPER_GRIPPER's 50 mm opening
DEFAULT_MAX_OPENING = 0.05
#: candidate methods: regions (sampled contact regions, the default) or the paper's face pairs
METHODS = ("regions", "paper")
#: score terms of :mod:`grasplan.config.scoring` with their default weights, and the normalisation of the
#: physical terms: read from the packaged ``configs/scoring.yaml``, their one definition
from .scoring import DEFAULT_SCORING as _DEFAULT_SCORING
from .scoring import SCORING_HELP

DEFAULT_SCORE_WEIGHTS: tuple[tuple[str, float], ...] = _DEFAULT_SCORING.weights
DEFAULT_SCORE_REFS: tuple[tuple[str, float], ...] = _DEFAULT_SCORING.refs
#: the default part material and its density, kg/m^3 (steel; grasplan.config.materials)
from .materials import CUSTOM, DEFAULT_DENSITY, DEFAULT_MATERIAL, MATERIAL_HELP, MATERIAL_NAMES, resolve_material
#: ``pose_index="all"``: plan every stable pose (grasplan.motion.planning.plan_poses), one plan per pose
ALL_POSES = "all"
#: PlanParams.grasp_db: place the part's cached grasp database, or compute the grasp stage in the cell
GRASP_DB_CACHE, GRASP_DB_OFF = "cache", "off"
GRASP_DB_CHOICES = (GRASP_DB_CACHE, GRASP_DB_OFF)


_Set = TypeVar("_Set", bound="OptionSet")


class OptionSet:
    """Shared behaviour: validation, JSON (lengths m, angles *_deg), defaults by name."""

    __dataclass_fields__: ClassVar[dict[str, Field[Any]]]

    def __post_init__(self) -> None:
        check_fields(self)
        self._check()

    def _check(self) -> None:  # cross-field checks, overridden where needed
        pass

    def _json(self, records: tuple[str, ...]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for f in fields(self):
            s = option_spec(f)
            record = s.record if s is not None else "always"
            if record not in records or (record == "elsewhere" and getattr(self, f.name) == f.default):
                continue
            v = getattr(self, f.name)
            out[f.name] = [list(x) if isinstance(x, tuple) else x for x in v] if isinstance(v, tuple) else v
        return out

    def to_json(self) -> dict[str, Any]:
        """The record of the options in an output file: every field but those the output records
        elsewhere (``record="elsewhere"``: the place is the plan's ``cell.place``) and the inputs read
        into other fields (``record="never"``: the scoring file, recorded as its weights)."""
        return self._json(("always",))

    def options_json(self) -> dict[str, Any]:
        """Every option that decides a result (the batch's options hash and its workers):
        :meth:`to_json` plus the ``record="elsewhere"`` options that are set."""
        return self._json(("always", "elsewhere"))

    @classmethod
    def from_json(cls: type[_Set], data: dict[str, Any]) -> _Set:
        """Rebuild from :meth:`to_json` or :meth:`options_json` output (unknown keys are ignored:
        older/newer files)."""
        kw = {}
        for f in fields(cls):
            if f.name in data:
                v = data[f.name]
                if isinstance(v, list):
                    v = tuple(tuple(x) if isinstance(x, list) else x for x in v)
                kw[f.name] = v
        return cls(**kw)

    @classmethod
    def default(cls, name: str) -> Any:
        f = next(f for f in fields(cls) if f.name == name)
        if f.default is not MISSING:
            return f.default
        assert f.default_factory is not MISSING
        return f.default_factory()


class MaterialOptions:
    """``material`` and ``density`` fields resolved before validation
    (:func:`grasplan.config.materials.resolve_material`): the material's density, or the density
    named by its material (``custom`` when none has it), or the default, steel; a ``mass`` (when
    the class has one) is recorded as ``custom`` unless a material was named. After
    ``__post_init__`` both are set."""

    material: str
    density: float

    def _resolve_material(self) -> None:
        material, density = resolve_material(self.material, self.density)
        if getattr(self, "mass", None) is not None and self.material is None:
            material = CUSTOM
        object.__setattr__(self, "material", material)
        object.__setattr__(self, "density", density)

    def with_material(self: _M, material: str | None = None, density: float | None = None) -> _M:
        """These options with another ``material`` or ``density`` (as given on the command line:
        None for not given; both None: the default)."""
        kw = {f.name: getattr(self, f.name) for f in fields(self)  # type: ignore[arg-type]
              if f.init and f.name not in ("material", "density")}
        cls: Any = type(self)  # a dataclass that has the two fields
        return cls(material=material, density=density, **kw)


_M = TypeVar("_M", bound=MaterialOptions)


@dataclass(frozen=True, kw_only=True)
class CandidateParams(OptionSet):
    """Stages 2-4: BLM, convexity, antipodal search. Lengths m, angles degrees."""

    blm: bool = spec(True, "bool", "Run the boundary layer mesher before the search (--no-blm: the part's own mesh).",
                     flag="--blm/--no-blm")
    alpha: float = spec(1e-4, "length", "BLM boundary-layer width.", hi=0.1, show="0.1mm")
    gamma_deg: float = spec(135.0, "angle", "BLM surface angle: facets join a surface when their normals differ "
                            "by at most 180 - gamma degrees.", cli="--gamma", lo=90.0, hi=180.0, lo_open=True)
    d_shift: float = spec(1e-5, "length", "Convexity: shift of the face centroid along its normal.", hi=0.01,
                          show="0.01mm")
    epsilon: float = spec(5e-3, "length", "Antipodal overlap threshold.", hi=0.5, show="5mm")
    max_opening: float | None = spec(None, "length", "Largest contact distance searched "
                                     "[default: the gripper's max_opening].", hi=2.0, optional=True)
    beta_deg: float = spec(2.0, "angle", "Normals anti-parallel within this angle.", cli="--beta", lo=0.0, hi=45.0)
    mu: float = spec(0.3, "float", "Friction coefficient (cone half-angle atan(mu)).", lo=0.0, hi=10.0)
    method: str = spec("regions", "choice", "Candidates: 'regions' samples opposing contact regions every --spacing "
                       "(independent of the tessellation); 'paper' is one pair per face pair (Vogt et al. 2021).",
                       choices=METHODS)
    spacing: float = spec(2e-3, "length", "regions: grid spacing of the contact samples.", lo=0.0, hi=0.1, show="2mm")


@dataclass(frozen=True, kw_only=True)
class GraspParams(MaterialOptions, OptionSet):
    """Stages 5-6: TCP frames rolled about each closing axis, full-jaw collision filter; the part's
    material (:class:`MaterialOptions`)."""

    roll_step_deg: float = spec(15.0, "float", "Roll step of the TCP about the closing axis, degrees "
                                "(poses at 0, step, ... < 360).", cli="--roll-step", lo=1.0, hi=360.0)
    thin_spacing: float = spec(0.0, "length0", "Pose one candidate per cluster (grasp-centre grid of this pitch x "
                               "closing axis in --thin-axis steps); 0 poses every candidate.", cli="--thin",
                               hi=0.5, show="0 (off)")
    thin_axis_deg: float = spec(10.0, "float", "Thinning: closing-axis direction step, degrees.", cli="--thin-axis",
                                lo=0.5, hi=90.0)
    merge_distance: float = spec(0.0, "length0", "Also skip a candidate whose contacts fall in the same grid cells of "
                                 "this size as an earlier candidate's; 0 = off.", hi=0.5)
    pose_index: int | str | None = spec(None, "int", "Rest the part in this stable pose (0 = most probable) "
                                        "instead of the cell's pose_index; 'all' (plan, batch): plan every stable "
                                        "pose of probability >= 2 %, write OUT.pose<k>.json "
                                        "per pose and OUT.json = the pose with the most planned grasps predicted to "
                                        "hold (then the most planned) plus a "
                                        "'poses' block with the counts per pose.", lo=0, hi=10000, optional=True,
                                        words=(ALL_POSES,), metavar="INDEX|all")
    # grasp quality (grasplan.grasps.quality): mass properties and the score
    material: str = spec(None, "choice", MATERIAL_HELP, choices=(*MATERIAL_NAMES, CUSTOM), record="never",
                         show=DEFAULT_MATERIAL, metavar="NAME")
    density: float = spec(None, "float", "Part density, kg/m^3 (uniform; 7850 steel, 2700 aluminium, "
                          "~1200 plastic): mass and centre of mass for the grasp quality; by default --material's.",
                          lo=0.0, lo_open=True, hi=1e5, show=f"{DEFAULT_DENSITY:g}")
    mass: float | None = spec(None, "float", "Part mass, kg (overrides --density).", lo=0.0, lo_open=True,
                              hi=1e4, optional=True)
    # a scoring YAML: its weights and normalisation replace score_weights and score_refs (the outputs
    # record those, not the file name)
    scoring: str | None = spec(None, "file", SCORING_HELP, optional=True, record="never")
    score_weights: tuple[tuple[str, float], ...] = spec(DEFAULT_SCORE_WEIGHTS, "internal",
                                                         "Score terms and weights (configs/scoring.yaml or --scoring).")
    score_refs: tuple[tuple[str, float], ...] = spec(DEFAULT_SCORE_REFS, "internal",
                                                      "Normalisation of the physical score terms (scoring YAML).")

    def __post_init__(self) -> None:
        self._resolve_material()
        super().__post_init__()

    def single_pose_index(self) -> int | None:
        """:attr:`pose_index` as the one resting pose a grasp stage or a plan uses (None: the cell's);
        InputError for ``"all"``, which plans every pose (:func:`grasplan.motion.planning.plan_poses`)."""
        if isinstance(self.pose_index, str):
            raise InputError("--pose-index all (pose_index='all') plans every resting pose: use `grasplan plan "
                             "--pose-index all`, `grasplan batch --pose-index all` or grasplan.motion.planning.plan_poses; "
                             "this step takes one pose index (0 = most probable)")
        return self.pose_index

    def _check(self) -> None:
        from .scoring import REF_KEYS, check_weights, load_scoring

        if self.scoring is not None:  # the file's weights and references replace the fields (outputs record those)
            cfg = load_scoring(self.scoring)
            object.__setattr__(self, "score_weights", cfg.weights)
            object.__setattr__(self, "score_refs", cfg.refs)
        check_weights(self.score_weights)
        if not all(isinstance(p, (tuple, list)) and len(p) == 2 and isinstance(p[0], str) for p in self.score_refs):
            raise InputError(f"score_refs: expected (name, value) pairs of {', '.join(REF_KEYS)}, "
                             f"got {self.score_refs!r}")
        refs = dict(self.score_refs)
        if set(refs) - set(REF_KEYS) or not all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0
                                                 for v in refs.values()) or refs.get("gravity_margin_ref", 2) <= 1:
            raise InputError(f"score_refs: expected {', '.join(REF_KEYS)} > 0 (gravity_margin_ref > 1), got {refs!r}")


@dataclass(frozen=True, kw_only=True)
class PlanParams(OptionSet):
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
    budget_s: float | None = spec(100.0, "seconds", "Wall-clock budget of the planning loop, seconds; "
                                  "later grasps are not_tried.", cli="--budget", hi=86400.0, optional=True)
    distinct_distance: float = spec(0.005, "length0", "Ranking: a grasp within this distance and --distinct-angle "
                                    "of a better one ranks after every distinct grasp; 0 = off.", hi=0.5, show="5mm")
    distinct_angle_deg: float = spec(15.0, "float", "Ranking: angle for --distinct-distance, degrees.",
                                     cli="--distinct-angle", lo=0.0, hi=180.0)
    score_weights: tuple[tuple[str, float], ...] | None = spec(None, "internal",
                                                                "Re-score the grasps with these weights before "
                                                                "ranking; None: the grasp stage's score "
                                                                "(GraspParams.score_weights, the scoring YAML).")
    min_gravity_margin: float = spec(0.0, "float", "Plan only grasps whose gravity margin is at least this (1: those "
                                     "predicted to hold the part's weight and the shared load at the gripper's "
                                     "force and the part's density; 0: off); the others stay not_tried, the reason "
                                     "saying so. docs/quality.md.", lo=0.0, hi=100.0)
    simulate: int = spec(0, "int", "After planning, simulate the top N planned grasps (MuJoCo lift and shake, "
                         "grasplan simulate) and rank those that held first; 0 = off.", lo=0, hi=1000)
    grasp_db: str = spec(GRASP_DB_CACHE, "choice", "Where the grasp stage comes from: 'cache' places the part's "
                         "grasp database (computed on the first plan of a part with this gripper and these options, "
                         "then read from the cache folder); 'off' computes the stage in the cell, every pose "
                         "(--keep all implies it). Same grasps either way (docs/plan.md).",
                         choices=GRASP_DB_CHOICES, cli="--grasp-db")
    place: tuple[tuple[float, ...], ...] | None = spec(
        None, "pose", "Pick-and-place: the part's pose after release, 'x,y,z,roll,pitch,yaw' (lengths m or with "
        "units, angles deg, R = Rz(yaw) Ry(pitch) Rx(roll)); overrides the cell's place. Every plan lifts the part "
        "along the cell's retreat; with a place it is carried there, released and the gripper retreats.",
        optional=True, record="elsewhere")

    def _check(self) -> None:
        if self.score_weights is not None:
            from .scoring import check_weights

            check_weights(self.score_weights)

    def place_matrix(self) -> np.ndarray | None:
        """:attr:`place` as the (4, 4) float64 ``T_world_part`` :func:`grasplan.motion.planning.plan` takes
        as ``place`` (None: the cell's place, if any)."""
        return None if self.place is None else np.asarray(self.place, dtype=np.float64)


PARAM_CLASSES = (CandidateParams, GraspParams, PlanParams)


@dataclass(frozen=True, kw_only=True)
class RunParams:
    """The option sets of one run, built once (by the CLI from its options, by a batch from a
    manifest row) and handed on as its parts: ``grasplan.plan(part, robot, candidates=p.candidates,
    grasps=p.grasps, planning=p.planning)``."""

    candidates: CandidateParams = field(default_factory=CandidateParams)
    grasps: GraspParams = field(default_factory=GraspParams)
    planning: PlanParams = field(default_factory=PlanParams)

    #: the field of each parameter class
    FIELDS: ClassVar[dict[type, str]] = {CandidateParams: "candidates", GraspParams: "grasps", PlanParams: "planning"}

    @classmethod
    def from_options(cls, options: dict[str, Any], classes: tuple[type, ...] = PARAM_CLASSES) -> RunParams:
        """Pop the fields of ``classes`` from ``options`` (a command's keyword arguments, by field
        name) and build those sets (the others keep their defaults); the sets validate the values."""
        sets: dict[str, Any] = {}
        for set_cls in classes:
            names = {f.name for f in fields(set_cls)}
            sets[cls.FIELDS[set_cls]] = set_cls(**{k: options.pop(k) for k in list(options) if k in names})
        return cls(**sets)


def option_fields() -> dict[str, tuple[type, Field[Any]]]:
    """Every option of the three classes by field name and by CLI spelling without dashes
    (``thin_spacing`` and ``thin``, ``pose_index``): ``key -> (class, field)`` (batch manifests)."""
    out: dict[str, tuple[type, Field[Any]]] = {}
    for cls in PARAM_CLASSES:
        for f in fields(cls):
            if is_option(f):
                out[f.name] = (cls, f)
                out[option_name(f).lstrip("-").replace("-", "_")] = (cls, f)
    return out
