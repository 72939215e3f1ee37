"""Grasp databases: a part's grasps computed once, in the part frame, reused wherever it lies.

A bin-picking cell sees the same part many times at poses a pose estimator reports. Everything of
a grasp that does not depend on that pose is computed once (:func:`build_database`): the
candidates, the gripper poses ``T_part_tcp``, the full-jaw collision check against the part alone
(cell ``none``: no table, no obstacles), the contact patches and the Ferrari-Canny epsilon. What
depends on the pose is cheap and recomputed per instance: the gravity margin
(:meth:`GraspDatabase.quality_at`) and the score's ``top`` term (:meth:`GraspDatabase.score_at`);
collisions with the bin and the neighbours are the picker's (:mod:`grasplan.pick`).

File: ``*.graspdb.npz`` (``grasplan database PART -o PART.graspdb.npz``), its arrays and record:
:class:`GraspDatabase`. A database is refused (exit 3, both named) for another part (sha256 or
scale) or gripper. :func:`database_for` keeps databases in the cache folder
(:func:`grasplan.cache.cache_dir`, ``graspdb/``), keyed by the part, the gripper and the options.
"""
from __future__ import annotations

import io
import json
import time
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from ..cache import CACHE_ENV, cache_dir
from ..cell.model import NO_CELL
from ..errors import InputError
from .pipeline import compute_grasps
from ..gripper.load import gripper_from_json, load_gripper
from ..gripper.model import Gripper
from ..config.inputs import check_input_file
from ..io import sha256_doc, show_path, write_atomic_bytes
from ..part.mass import MassProperties
from ..part.mesh import Part
from ..part.stability import stable_poses
from ..geometry.meshdata import TriangleMesh
from ..config.params import CandidateParams, GraspParams
from .quality import Quality
from ..config.scoring import PHYSICAL_TERMS, ScoringConfig, score_grasps
from ..status import Status
from ..geometry.transforms import check_transform
from .wrench import CONTACTS_PER_GRIP, gravity_margin, margin_summary_of, pressure_widths

#: what a margin function of :meth:`GraspDatabase._margins` returns
_M = TypeVar("_M")

DB_SCHEMA = "grasplan.graspdb/1"
#: the file name ending `grasplan database` and the cache use
DB_SUFFIX = ".graspdb.npz"
#: largest database file read, bytes (10k grasps take ~3 MB)
MAX_DB_BYTES = 1 << 30
#: bumped when the computation behind a database changes: cached databases of another version are
#: recomputed, files of another version are refused
DB_VERSION = 3  # 3: pose ids, rolls, the part's rejected poses per candidate and resting poses
_ARRAYS = ("T_part_tcp", "width", "contacts", "normals", "candidate", "region", "contact_area", "contact_type",
           "contact_width", "epsilon", "score", "pose", "roll")
_SHAPES: dict[str, tuple[int, ...]] = {"T_part_tcp": (4, 4), "width": (), "contacts": (2, 3), "normals": (2, 3),
                                       "candidate": (), "region": (), "contact_area": (2,), "contact_type": (2,),
                                       "contact_width": (2, 2), "epsilon": (), "score": (), "pose": (), "roll": ()}
_DTYPES = {"candidate": np.int64, "region": np.int64, "contact_type": np.int8, "pose": np.int64}
#: the arrays of the poses that hit the part, one row per candidate (K rows, candidates increasing)
_REJECTED = ("rejected_candidate", "rejected_part")
#: the part's resting poses on a plane (grasplan.part.stability.stable_poses): R_world_part, probability
_RESTING = ("rest_R", "rest_prob")


def gripper_key(gripper: Gripper) -> str:
    """sha256 of the gripper's full definition (shapes, opening, force, TCP): what its grasps depend on."""
    return sha256_doc(gripper.to_json(definition=True))


def params_key(candidates: CandidateParams, grasps: GraspParams) -> str:
    """sha256 of the options a database is computed with (and the database version)."""
    return sha256_doc({"candidates": candidates.options_json(), "grasps": grasps.options_json(), "version": DB_VERSION})


@dataclass(frozen=True, eq=False)
class GraspDatabase:
    """The collision-free grasps of one part with one gripper, in the part frame.

    File: a NumPy archive of plain arrays (no pickles) plus a ``meta`` JSON record: schema
    ``grasplan.graspdb/1``, the part's path, sha256, scale and triangle count, the gripper's full
    definition and its key (sha256 of that definition), the candidate and grasp options and their
    key, the mass properties, counts and timings. Arrays are read-only; rows (N grasps, only the
    collision-free ones) are sorted by ``score`` (the score with the part upright in its own
    frame), best first:

    ===============  ==============  =================================================
    ``T_part_tcp``   (N, 4, 4)       TCP pose in the part frame
    ``width``        (N,)            contact distance, m
    ``contacts``     (N, 2, 3)       contact points, part frame, m (0: the -x jaw's)
    ``normals``      (N, 2, 3)       outward unit surface normals at the contacts
    ``candidate``    (N,) int64      candidate index (the candidate stage's order)
    ``region``       (N,) int64      region of the candidate (-1: none)
    ``contact_area`` (N, 2)          patch area per jaw, m^2
    ``contact_type`` (N, 2) int8     0 point, 1 line, 2 surface
    ``contact_width`` (N, 2, 2)      equivalent (min, max) widths of each patch, m
    ``epsilon``      (N,)            Ferrari-Canny L1 quality
    ``score``        (N,)            score with the part upright in its frame
    ``pose``         (N,) int64      pose id: the index of the pose among every posed
                                     (candidate, roll), the grasp id plans use
    ``roll``         (N,)            roll about the closing axis, rad (roll 0: the
                                     approach closest to the part frame's -z)
    ===============  ==============  =================================================

    The poses that hit the part are counted, not stored: ``rejected_candidate`` (K,) int64
    (increasing) and ``rejected_part`` (K,) int64, how many poses of that candidate hit the part.
    The part's resting poses (:func:`grasplan.part.stability.stable_poses`, pose-independent like
    the rest): ``rest_R`` (P, 3, 3) and ``rest_prob`` (P,) (P = 0: none could be computed).
    """

    part_path: str
    part_sha256: str
    scale_to_m: float
    triangles: int
    gripper: Gripper
    gripper_key: str
    params_key: str
    candidates: CandidateParams
    grasps: GraspParams
    mass_props: MassProperties | None
    T_part_tcp: np.ndarray
    width: np.ndarray
    contacts: np.ndarray
    normals: np.ndarray
    candidate: np.ndarray
    region: np.ndarray
    contact_area: np.ndarray
    contact_type: np.ndarray
    contact_width: np.ndarray
    epsilon: np.ndarray
    score: np.ndarray
    pose: np.ndarray
    roll: np.ndarray
    rejected_candidate: np.ndarray
    rejected_part: np.ndarray
    rest_R: np.ndarray
    rest_prob: np.ndarray
    counts: dict[str, int] = field(default_factory=dict)
    timing_s: dict[str, float] = field(default_factory=dict)
    #: what the candidate and pose stages did to bound their work (one line each; usually none)
    notes: tuple[str, ...] = ()
    #: the file it was read from ("": computed in this process)
    origin: str = ""

    def __post_init__(self) -> None:
        n = len(self.width)
        for name in _ARRAYS:
            a = np.ascontiguousarray(getattr(self, name), dtype=_DTYPES.get(name, np.float64))
            if a.shape != (n, *_SHAPES[name]):
                raise InputError(f"grasp database: {name} has shape {a.shape}, expected {(n, *_SHAPES[name])}")
            a.flags.writeable = False
            object.__setattr__(self, name, a)
        k = len(self.rejected_candidate)
        for name in _REJECTED:
            a = np.ascontiguousarray(getattr(self, name), dtype=np.int64)
            if a.shape != (k,):
                raise InputError(f"grasp database: {name} has shape {a.shape}, expected ({k},)")
            a.flags.writeable = False
            object.__setattr__(self, name, a)
        for name, shape in (("rest_R", (3, 3)), ("rest_prob", ())):
            a = np.ascontiguousarray(getattr(self, name), dtype=np.float64)
            if a.shape[1:] != shape or len(a) != len(self.rest_prob):
                raise InputError(f"grasp database: {name} has shape {a.shape}, expected (P, {shape})")
            a.flags.writeable = False
            object.__setattr__(self, name, a)
        if n > 1 and _repeats(self.pose):
            raise InputError("grasp database: a pose id appears twice")
        if k and (np.any(np.diff(self.rejected_candidate) <= 0) or np.any(self.rejected_part < 0)):
            raise InputError("grasp database: rejected_candidate must increase and rejected_part be >= 0")

    def __len__(self) -> int:
        return len(self.width)

    @property
    def mu(self) -> float:
        return float(self.candidates.mu)

    @property
    def scoring(self) -> ScoringConfig:
        return ScoringConfig.from_params(self.grasps.score_weights, self.grasps.score_refs)

    def _rows(self, rows: np.ndarray | None) -> np.ndarray:
        return np.arange(len(self)) if rows is None else np.asarray(rows, dtype=np.int64).reshape(-1)

    def quality_at(self, T_world_part: np.ndarray, rows: np.ndarray | None = None) -> Quality | None:
        """The :class:`~grasplan.grasps.quality.Quality` of ``rows`` (default all) with the part at
        ``T_world_part``: patches and epsilon as stored, the gravity margin for gravity's direction
        at that pose. None when the part has no mass properties (no volume)."""
        if self.mass_props is None:
            return None
        r = self._rows(rows)
        gm = self._margins(gravity_margin, T_world_part, r)
        return Quality(contact_area=self.contact_area[r], contact_type=self.contact_type[r],
                       contact_width=self.contact_width[r], gravity_margin=gm, epsilon=self.epsilon[r],
                       grip_force=float(self.gripper.grip_force), mu=self.mu)

    def holding_at(self, T_world_part: np.ndarray, rows: np.ndarray | None = None) -> tuple[int, float]:
        """``(rows predicted to hold, largest gravity_margin)`` of ``rows`` (default all) with the part
        at ``T_world_part``: the count of :meth:`quality_at`'s ``gravity_margin >= 1`` and its
        maximum (0 and 0.0 without mass properties or rows), without computing every margin."""
        r = self._rows(rows)
        if self.mass_props is None or not len(r):
            return 0, 0.0
        return self._margins(margin_summary_of, T_world_part, r)

    def _margins(self, fn: Callable[..., _M], T_world_part: np.ndarray, r: np.ndarray) -> _M:
        """``fn`` (:func:`~grasplan.grasps.wrench.gravity_margin` or
        :func:`~grasplan.grasps.wrench.margin_summary_of`) of rows ``r`` with the part at
        ``T_world_part``: the stored patches, the gripper's force on each contact."""
        assert self.mass_props is not None
        T = check_transform(T_world_part, "T_world_part")
        return fn(self.mass_props, T, self.T_part_tcp[r], self.width[r], self.contact_area[r], mu=self.mu,
                  normal_force=float(self.gripper.grip_force) / CONTACTS_PER_GRIP,
                  patch_width=pressure_widths(self.contact_type[r], self.contact_width[r]))

    def score_at(self, part_mesh: TriangleMesh, T_world_part: np.ndarray, rows: np.ndarray | None = None,
                 quality: Quality | None = None) -> np.ndarray:
        """(k,) score of ``rows`` (default all) with the part at ``T_world_part``, with the weights
        the database was computed with (:mod:`grasplan.config.scoring`). ``quality``: :meth:`quality_at`
        of the same rows and pose when the caller has it."""
        r = self._rows(rows)
        T = check_transform(T_world_part, "T_world_part")
        cfg = self.scoring
        q = quality if quality is not None else self.quality_at(T, r)
        weights = cfg.weights if q is not None else tuple((n, w) for n, w in cfg.weights if n not in PHYSICAL_TERMS)
        if not len(r):
            return np.zeros(0)
        return score_grasps(part_mesh, T, self.T_part_tcp[r], self.width[r], float(self.gripper.max_opening),
                            weights, quality=q, scoring=cfg,
                            com=None if self.mass_props is None else self.mass_props.com)

    def prime_resting_poses(self, part: Part) -> None:
        """Give ``part``'s mesh the resting poses stored here, so that placing the part in a cell
        (:func:`grasplan.cell.resting.stable_pose`) computes no convex hull. ``part`` must be this
        database's (:meth:`check_for`)."""
        derived = getattr(part.mesh, "derived", None)
        if derived is not None and len(self.rest_prob):
            derived("stable_poses", lambda: (np.array(self.rest_R), np.array(self.rest_prob)))

    def check_for(self, part: Part | None = None, gripper: Gripper | None = None, *, source: str = "") -> None:
        """InputError (exit 3) naming both when this database belongs to another part (sha256 or
        scale) or gripper."""
        src = f"grasp database {source}: " if source else "grasp database: "
        if part is not None and (part.sha256 != self.part_sha256 or not np.isclose(part.scale_to_m, self.scale_to_m,
                                                                                rtol=1e-9, atol=0)):
            raise InputError(
                f"{src}it was computed for part {self.part_path} (sha256 {self.part_sha256[:12]}..., scale "
                f"{self.scale_to_m:g} m per unit), not for {part.path} (sha256 {part.sha256[:12]}..., scale "
                f"{part.scale_to_m:g}); compute one for this part: grasplan database {part.path} -o "
                f"{Path(part.path).stem}{DB_SUFFIX}")
        if gripper is not None and gripper_key(gripper) != self.gripper_key:
            raise InputError(f"{src}it was computed for gripper {self.gripper.name!r}, not for {gripper.name!r} "
                             f"(or that gripper's definition changed); compute one with --gripper {gripper.name}")

    # -- file ------------------------------------------------------------------------------------
    def meta(self) -> dict[str, Any]:
        return {"schema": DB_SCHEMA, "version": DB_VERSION,
                "part": {"path": self.part_path, "sha256": self.part_sha256, "scale_to_m": self.scale_to_m,
                         "triangles": self.triangles},
                "gripper": self.gripper.to_json(definition=True), "gripper_key": self.gripper_key,
                "params_key": self.params_key, "candidates": self.candidates.options_json(),
                "grasps": self.grasps.options_json(),
                "mass": None if self.mass_props is None else self.mass_props.to_json(),
                "counts": dict(self.counts), "timing_s": dict(self.timing_s), "notes": list(self.notes)}

    def to_bytes(self) -> bytes:
        buf = io.BytesIO()
        meta = np.frombuffer(json.dumps(self.meta(), allow_nan=False).encode(), dtype=np.uint8)
        np.savez(buf, meta=meta, **{n: getattr(self, n) for n in (*_ARRAYS, *_REJECTED, *_RESTING)})
        return buf.getvalue()


def write_database(db: GraspDatabase, path: str | Path) -> Path:
    """Write ``db`` to ``path`` atomically (nothing is left half-written)."""
    return write_atomic_bytes(path, db.to_bytes())


def _mass_from_json(d: Any, src: str) -> MassProperties | None:
    if d is None:
        return None
    try:
        return MassProperties(mass=float(d["mass"]), com=np.asarray(d["com"], dtype=np.float64).reshape(3),
                              inertia=np.asarray(d["inertia"], dtype=np.float64).reshape(3, 3),
                              volume=float(d["volume"]), density=float(d["density"]),
                              watertight_used=bool(d["watertight_used"]), material=str(d.get("material", "")))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{src}: meta.mass is malformed ({exc}); recompute the database") from None


def _repeats(ids: np.ndarray) -> bool:
    """Whether an id of ``ids`` (int64) appears twice: counted in a table when their range is
    small (the database's pose ids are), else by sorting."""
    lo, hi = int(ids.min()), int(ids.max())
    if hi - lo < 8 * len(ids):
        return bool(np.bincount(ids - lo).max() > 1)
    return len(np.unique(ids)) != len(ids)


def load_database(path: str | Path, *, part: Part | None = None, gripper: Gripper | None = None) -> GraspDatabase:
    """Read a ``*.graspdb.npz`` file; with ``part`` / ``gripper`` also check that it belongs to
    them (:meth:`GraspDatabase.check_for`). InputError (exit 3) for anything else than a grasp
    database of this version."""
    src = show_path(path)
    check_input_file(path, what="grasp database", max_bytes=MAX_DB_BYTES)
    try:
        with np.load(Path(path), allow_pickle=False) as z:
            names = set(z.files)
            missing = sorted({"meta", *_ARRAYS, *_REJECTED, *_RESTING} - names)
            if missing:
                raise InputError(f"grasp database {src}: not a grasplan grasp database (missing {', '.join(missing)}); "
                                 f"write one with grasplan database PART -o FILE{DB_SUFFIX}")
            meta = json.loads(bytes(z["meta"]).decode("utf-8"))
            arrays = {n: z[n] for n in (*_ARRAYS, *_REJECTED, *_RESTING)}
    except InputError:
        raise
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, UnicodeDecodeError, EOFError) as exc:
        raise InputError(f"grasp database {src}: cannot read it ({type(exc).__name__}: {str(exc)[:120]}); "
                         f"write one with grasplan database PART -o FILE{DB_SUFFIX}") from None
    if not isinstance(meta, dict) or meta.get("schema") != DB_SCHEMA:
        raise InputError(f"grasp database {src}: schema {str(meta.get('schema') if isinstance(meta, dict) else meta)[:40]!r}"
                         f", expected {DB_SCHEMA!r}")
    if meta.get("version") != DB_VERSION:
        raise InputError(f"grasp database {src}: version {meta.get('version')!r} of the computation, this grasplan "
                         f"computes version {DB_VERSION}; recompute it with grasplan database")
    try:
        p = meta["part"]
        db = GraspDatabase(
            part_path=str(p["path"]), part_sha256=str(p["sha256"]), scale_to_m=float(p["scale_to_m"]),
            triangles=int(p["triangles"]), gripper=gripper_from_json(meta["gripper"], where=f"{src}: meta.gripper"),
            gripper_key=str(meta["gripper_key"]), params_key=str(meta["params_key"]),
            candidates=CandidateParams.from_json(meta["candidates"]), grasps=GraspParams.from_json(meta["grasps"]),
            mass_props=_mass_from_json(meta.get("mass"), src), counts=dict(meta.get("counts", {})),
            timing_s=dict(meta.get("timing_s", {})), notes=tuple(str(n) for n in meta.get("notes", [])),
            origin=str(path), **arrays)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"grasp database {src}: meta record is malformed ({type(exc).__name__}: {exc}); "
                         f"recompute it with grasplan database") from None
    if not all(np.all(np.isfinite(getattr(db, n))) for n in ("T_part_tcp", "width", "contacts", "normals")):
        raise InputError(f"grasp database {src}: poses, widths or contacts hold NaN or infinite values")
    db.check_for(part, gripper, source=src)
    return db


def build_database(part: Part, gripper: Gripper | str, *, candidates: CandidateParams = CandidateParams(),
                   grasps: GraspParams = GraspParams()) -> GraspDatabase:
    """Compute the database of ``part`` with ``gripper`` (module docstring): the grasp stage in
    cell ``none`` (the part alone in its own frame), its collision-free poses sorted by score."""
    g = load_gripper(gripper)
    grasps = database_params(grasps)
    t = time.perf_counter()
    res = compute_grasps(part, gripper=g, cell=NO_CELL, candidates=candidates, grasps=grasps)
    ok = np.flatnonzero(np.asarray(res.status).astype(str) == Status.OK.value)
    score = np.asarray(res.score, dtype=np.float64)[ok] if res.score is not None else np.zeros(len(ok))
    order = ok[np.lexsort((ok, -score))] if len(ok) else ok
    tab = res.table()
    q = res.quality
    if q is not None:  # quality rows follow the ok poses in pose order
        pos = np.searchsorted(ok, order)
        area, kind, cw, eps = q.contact_area[pos], q.contact_type[pos], q.contact_width[pos], q.epsilon[pos]
    else:
        k = len(order)
        area, kind, cw, eps = np.full((k, 2), np.nan), np.full((k, 2), -1), np.full((k, 2, 2), np.nan), np.full(k, np.nan)
    counts = res.counts()
    st = np.asarray(res.status).astype(str)
    rej_cand, rej_n = np.unique(np.asarray(res.frames.candidate)[st == Status.COLLISION_PART.value], return_counts=True)
    try:
        rest_R, rest_prob = stable_poses(part.mesh)
    except InputError:  # a part without a resting pose on a plane: placed with --part-pose only
        rest_R, rest_prob = np.zeros((0, 3, 3)), np.zeros(0)
    timing = {**res.timing_s, "database": time.perf_counter() - t}
    return GraspDatabase(
        part_path=part.path, part_sha256=part.sha256, scale_to_m=float(part.scale_to_m), triangles=part.triangles,
        gripper=g, gripper_key=gripper_key(g), params_key=params_key(res.cand.params, grasps),
        candidates=res.cand.params, grasps=grasps, mass_props=res.mass_props,
        T_part_tcp=tab.T_part_tcp[order], width=tab.width[order], contacts=tab.contacts[order],
        normals=tab.normals[order], candidate=tab.candidate[order], region=tab.region[order],
        contact_area=area, contact_type=kind, contact_width=cw, epsilon=eps,
        score=np.nan_to_num(np.asarray(tab.score)[order], nan=0.0), pose=order, roll=tab.roll[order],
        rejected_candidate=rej_cand, rejected_part=rej_n, rest_R=rest_R, rest_prob=rest_prob,
        counts={"candidates": counts["candidates"], "posed_candidates": counts["posed_candidates"],
                "poses": counts["poses"], "ok": int(len(order)),
                "collision_part": counts.get(Status.COLLISION_PART.value, 0),
                **({"regions": counts["regions"]} if "regions" in counts else {})},
        timing_s=timing, notes=tuple(res.cand.notes))


def database_params(grasps: GraspParams) -> GraspParams:
    """The options a database depends on: ``grasps`` without the resting pose (a database holds
    the part alone, in its own frame)."""
    return replace(grasps, pose_index=None) if grasps.pose_index is not None else grasps


def options_key(gripper: Gripper, candidates: CandidateParams, grasps: GraspParams) -> str:
    """:func:`params_key` of these options as a database computed with ``gripper`` records them
    (the candidate search reaching the gripper's ``max_opening`` unless set, no resting pose)."""
    if candidates.max_opening is None:  # as compute_grasps resolves it
        candidates = replace(candidates, max_opening=gripper.max_opening)
    return params_key(candidates, database_params(grasps))


def cache_path(part: Part, gripper: Gripper, candidates: CandidateParams, grasps: GraspParams) -> Path:
    """Where :func:`database_for` keeps the database of ``part`` with ``gripper`` and these options."""
    key = sha256_doc({"part": part.sha256, "scale": repr(float(part.scale_to_m)), "gripper": gripper_key(gripper),
                "params": options_key(gripper, candidates, grasps)})
    return cache_dir() / "graspdb" / f"{key}{DB_SUFFIX}"


def read_cached(part: Part, gripper: Gripper, *, candidates: CandidateParams, grasps: GraspParams
                ) -> tuple[GraspDatabase | None, str]:
    """``(database, "")`` read from the cache folder for exactly this part, gripper and options, its
    resting poses given to the part's mesh (:meth:`GraspDatabase.prime_resting_poses`); ``(None,
    "")`` when the cache holds none; ``(None, why)`` when its entry is unusable."""
    path = cache_path(part, gripper, candidates, grasps)
    if not path.is_file():
        return None, ""
    try:
        db = load_database(path, part=part, gripper=gripper)
    except InputError as exc:
        return None, str(exc)
    db.prime_resting_poses(part)
    return db, ""


def database_for(part: Part, gripper: Gripper | str, *, candidates: CandidateParams = CandidateParams(),
                 grasps: GraspParams = GraspParams(), cache: bool = True,
                 progress: Callable[[str], None] | None = None) -> GraspDatabase:
    """The database of ``part`` with ``gripper``: from the cache folder when it holds one for
    exactly this part, gripper and options (:func:`read_cached`), else computed (and, with
    ``cache``, stored there; the computation leaves the part's resting poses on its mesh).
    ``progress`` gets a line before and after a computation."""
    g = load_gripper(gripper)
    path = cache_path(part, g, candidates, grasps)
    name = Path(part.path).name
    if cache:
        db, why = read_cached(part, g, candidates=candidates, grasps=grasps)
        if db is not None:
            return db
        if why and progress is not None:  # a damaged or foreign cache entry: say so, then recompute it
            progress(f"grasp database for {name}: cached copy unusable ({why}); recomputing")
    if progress is not None:
        progress(f"grasp database for {name} with {g.name}: computing (candidates, poses, collisions, quality) ...")
    db = build_database(part, g, candidates=candidates, grasps=grasps)
    where = ""
    if cache:
        try:
            write_database(db, path)
            where = f", cached in {show_path(path)}"
        except (OSError, InputError) as exc:  # a read-only or full cache folder costs the next run the computation
            where = f"; not cached ({exc}); set {CACHE_ENV} to a writable folder to keep it"
    if progress is not None:
        progress(f"grasp database for {name}: {len(db)} grasps in {db.timing_s.get('database', 0.0):.1f} s{where}")
    return db
