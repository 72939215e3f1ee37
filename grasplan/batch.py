"""``grasplan batch``: plan a whole catalogue of parts, resumable, on a local process pool or on Ray.

Inputs (:func:`discover_parts`): mesh files, folders (searched recursively for STL/OBJ/PLY, sorted)
and manifests (``.csv`` with a header row, or ``.yaml``) naming one part per row with optional
per-part options: ``units``, ``robot``, ``gripper``, ``cell`` and any field of
:class:`~grasplan.params.CandidateParams`, :class:`~grasplan.params.GraspParams` or
:class:`~grasplan.params.PlanParams`, by field name (``pose_index``, ``thin_spacing``) or CLI
spelling (``pose-index``, ``thin``). Lengths accept unit suffixes (``2mm``), angles are degrees.
Relative paths in a manifest are relative to the manifest's folder.

Outputs, in ``OUTDIR``::

    <stem>-<sha8>/plan.json       grasplan.plan/1 (identical to `grasplan plan` with the same options)
    <stem>-<sha8>/<exports>       one file per --export format (plan.script, plan.csv, ...)
    <stem>-<sha8>/view.html       the offline viewer
    <stem>-<sha8>/log.txt         what happened (units, warnings, counts, seconds, errors)
    <stem>-<sha8>/done.json       written last: sha256 of the part, options hash, status, summary row
    summary.csv, summary.json     one row per part
    index.html                    offline page linking every part's viewer, sortable

``<sha8>`` is the first 8 hex digits of the part file's sha256; when one file is planned with
different per-part options in the same batch, ``-<options hash 8>`` is appended.

Resuming: a part whose folder holds a ``done.json`` with the same part sha256 and options hash,
and a finished status (``planned``, ``nothing_planned``, ``bad_input``), is not planned again.
Every part is produced in ``OUTDIR/.staging/`` and renamed into place complete, so an interrupted
batch (Ctrl-C, a killed worker or machine) leaves no half-written result; rerunning the same
command finishes the rest. Parts that hit an internal error (status ``error``) are retried.

Engines (:func:`run_batch`): ``local`` (a spawn process pool, one worker per core) and ``ray``
(Ray tasks; the part's bytes are shipped to the task, which writes nothing on the worker's disk
but its own temporary folder and returns the result files' bytes, zlib-compressed; the driver
writes them). Both call the same :func:`run_part`, so results are identical (same seed) across
engines and to single-part ``grasplan plan`` runs; only ``timing_s`` differs.

Exit code (:attr:`BatchSummary.exit_code`): 0 when at least one part has a planned grasp, 4 when
no part has any; bad batch inputs (no parts found, a bad manifest, unknown option) raise
:class:`~grasplan.errors.InputError` (exit 3) before anything is written.
"""
from __future__ import annotations

import contextlib
import csv
import dataclasses
import fcntl
import hashlib
import html
import io
import json
import os
import shutil
import tempfile
import time
import traceback
import uuid
import warnings
import zlib
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any
from urllib.parse import quote

from .errors import GrasplanError, InputError
from .io import (
    read_json,
    sha256_file,
    write_atomic_bytes,
    write_atomic_text,
    write_json,
)
from .mesh import UNIT_CHOICES
from .meshfile import SUPPORTED_SUFFIXES
from .params import (
    DEFAULT_CELL,
    DEFAULT_GRIPPER,
    DEFAULT_ROBOT,
    PARAM_CLASSES,
    CandidateParams,
    GraspParams,
    PlanParams,
    option_name,
)
from .units import parse_angle_deg, parse_length

SUMMARY_SCHEMA = "grasplan.batch-summary/1"
DONE_SCHEMA = "grasplan.batch-done/1"
OPTIONS_SCHEMA = "grasplan.batch-options/1"
#: suffixes a folder is searched for (files named on the command line may be any mesh grasplan reads)
FOLDER_SUFFIXES = (".stl", ".obj", ".ply")
MANIFEST_SUFFIXES = (".csv", ".yaml", ".yml")
ENGINES = ("local", "ray")
#: part statuses; the first three are final (a rerun skips them), ``error`` is retried
STATUS_PLANNED, STATUS_NOTHING, STATUS_BAD, STATUS_ERROR = "planned", "nothing_planned", "bad_input", "error"
FINAL_STATUSES = (STATUS_PLANNED, STATUS_NOTHING, STATUS_BAD)
#: file names inside a part's folder
PLAN_FILE, VIEW_FILE, LOG_FILE, DONE_FILE = "plan.json", "view.html", "log.txt", "done.json"
STAGING_DIR, LOCK_FILE = ".staging", ".grasplan-batch.lock"
#: a part that was in flight when a worker process died this many times is recorded as ``error``
MAX_CRASHES = 2
#: manifest keys that are not parameter fields
_ENTRY_KEYS = ("path", "units", "robot", "gripper", "cell", "part_pose")


# ------------------------------------------------------------------------------------------ options
@dataclass(frozen=True, kw_only=True)
class BatchOptions:
    """Everything that decides a part's result (the options hash is computed from it).

    ``robot``, ``gripper``, ``cell``: names or YAML paths; ``units``: of the mesh files (see
    :func:`grasplan.mesh.load_part`); ``T_world_part``: 4x4 row-major nested tuple (m), the part's
    pose instead of its stable resting pose (``--part-pose``), or None; ``exports``:
    :data:`grasplan.export.FORMATS` names written next to ``plan.json``; ``view``: write ``view.html``.
    """

    robot: str = DEFAULT_ROBOT
    gripper: str = DEFAULT_GRIPPER
    cell: str = DEFAULT_CELL
    units: str = "auto"
    candidates: CandidateParams = field(default_factory=CandidateParams)
    grasps: GraspParams = field(default_factory=GraspParams)
    planning: PlanParams = field(default_factory=PlanParams)
    T_world_part: tuple[tuple[float, ...], ...] | None = None
    exports: tuple[str, ...] = ()
    view: bool = True

    def __post_init__(self):
        if self.units not in UNIT_CHOICES:
            raise InputError(f"units {self.units!r}: use one of {', '.join(UNIT_CHOICES)}")
        if self.T_world_part is not None:
            from .transforms import check_transform

            T = check_transform(self.T_world_part, "part pose T_world_part")
            object.__setattr__(self, "T_world_part", tuple(tuple(float(x) for x in r) for r in T))
        check_exports(self.exports)

    def to_json(self) -> dict:
        return {"robot": self.robot, "gripper": self.gripper, "cell": self.cell, "units": self.units,
                "candidates": self.candidates.to_json(), "grasps": self.grasps.to_json(),
                "planning": self.planning.to_json(),
                "T_world_part": None if self.T_world_part is None else [list(r) for r in self.T_world_part],
                "exports": list(self.exports), "view": self.view}

    @classmethod
    def from_json(cls, data: dict) -> BatchOptions:
        return cls(robot=data["robot"], gripper=data["gripper"], cell=data["cell"], units=data["units"],
                   candidates=CandidateParams.from_json(data["candidates"]),
                   grasps=GraspParams.from_json(data["grasps"]), planning=PlanParams.from_json(data["planning"]),
                   T_world_part=data.get("T_world_part"), exports=tuple(data["exports"]), view=bool(data["view"]))


def export_formats() -> dict[str, Any]:
    """The export registry, name -> format (``.extension``, ``.per_grasp``): :data:`grasplan.export.FORMATS`."""
    from .export import load_builtin_formats

    return load_builtin_formats()


def export_file(fmt) -> str:
    """The file a format is written to in a part's folder: ``export-<name><extension>`` (never
    ``plan.json``, whatever the format's extension)."""
    return f"export-{fmt.name}{fmt.extension}"


def check_exports(names: Iterable[str]) -> tuple[str, ...]:
    """Validate export names against the registry; InputError listing the available ones."""
    names = tuple(names)
    if not names:
        return names
    available = export_formats()
    unknown = [n for n in names if n not in available]
    if unknown:
        raise InputError(f"--export: unknown format(s) {', '.join(unknown)}; available: {', '.join(available)}")
    if len(set(names)) != len(names):
        raise InputError(f"--export: format listed twice in {','.join(names)}")
    return names


def _config_fingerprint(kind: str, name: str) -> str:
    """sha256 of the YAML a name resolves to on this machine (so editing a gripper redoes its parts)."""
    from .config_files import resolve_yaml

    return sha256_file(resolve_yaml(kind, name))


def options_hash(options: BatchOptions) -> str:
    """sha256 (hex) of the canonical JSON of ``options``, the grasplan version and the robot,
    gripper and cell YAML contents. Raises ConfigError for an unknown robot/gripper/cell."""
    from . import __version__

    doc = {"schema": OPTIONS_SCHEMA, "grasplan": __version__, "options": options.to_json(),
           "configs": {k: _config_fingerprint(k, getattr(options, k)) for k in ("robot", "gripper", "cell")}}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


# ---------------------------------------------------------------------------------------- discovery
@dataclass(frozen=True)
class PartEntry:
    """One part to plan: ``path`` as it will be recorded (relative paths stay relative to the
    current folder), ``overrides`` (manifest options, already converted), ``origin`` (where it was
    named, for messages)."""

    path: str
    overrides: tuple[tuple[str, Any], ...] = ()
    origin: str = ""


def _param_fields() -> dict[str, tuple[type, Any]]:
    """Accepted manifest key -> (param class, dataclass field); field names and CLI spellings."""
    out: dict[str, tuple[type, Any]] = {}
    for cls in PARAM_CLASSES:
        for f in fields(cls):
            if f.metadata.get("kind") in (None, "internal"):
                continue
            out[f.name] = (cls, f)
            out[option_name(f).lstrip("-").replace("-", "_")] = (cls, f)
    return out


def _convert(f, value: Any, where: str) -> Any:
    """A manifest value for param field ``f`` (strings as on the command line) -> the field's type."""
    kind = f.metadata["kind"]
    optional = kind.startswith("optional_")
    base = kind.removeprefix("optional_")
    name = f"{where}: {option_name(f)}"
    if isinstance(value, str):
        value = value.strip()
        if optional and value.lower() in ("none", "null"):
            return None
    if base in ("length", "length0"):
        return parse_length(value, name=name, allow_zero=True)  # the range check is the param class's
    if base == "angle":
        return parse_angle_deg(value, name=name)
    if base == "bool":
        if isinstance(value, bool):
            return value
        text = str(value).lower()
        if text in ("1", "true", "yes", "on"):
            return True
        if text in ("0", "false", "no", "off"):
            return False
        raise InputError(f"{name}: expected true or false, got {value!r}")
    if base == "int":
        try:
            if isinstance(value, float) and not value.is_integer():
                raise ValueError
            return int(value)
        except (TypeError, ValueError):
            raise InputError(f"{name}: expected a whole number, got {value!r}") from None
    if base in ("float", "seconds"):
        try:
            return float(value)
        except (TypeError, ValueError):
            raise InputError(f"{name}: expected a number, got {value!r}") from None
    return value  # a choice: validated by the param class


def _entry_from_mapping(row: dict, base_dir: Path, where: str) -> PartEntry:
    keys = {str(k).strip().lower().replace("-", "_"): v for k, v in row.items() if k is not None}
    raw_path = keys.pop("path", None)
    if raw_path is None or str(raw_path).strip() == "":
        raise InputError(f"{where}: no 'path'; every manifest row needs the part's mesh file in a 'path' column")
    p = Path(str(raw_path).strip()).expanduser()
    path = p if p.is_absolute() else Path(os.path.normpath(base_dir / p))
    if not path.is_file():
        raise InputError(f"{where}: part file {path} not found (relative paths are relative to the manifest's folder)")
    known = _param_fields()
    overrides: dict[str, Any] = {}
    for key, value in keys.items():
        if value is None or (isinstance(value, str) and value.strip() == ""):
            continue  # an empty cell: the batch's option
        if key in ("units", "robot", "gripper", "cell"):
            text = str(value).strip()
            if key == "units" and text not in UNIT_CHOICES:
                raise InputError(f"{where}: units {text!r}; use one of {', '.join(UNIT_CHOICES)}")
            overrides[key] = text
        elif key == "part_pose":
            from .transforms import parse_part_pose

            pose = str(value).strip()
            pp = Path(pose).expanduser()
            if pp.suffix.lower() in (".json", ".yaml", ".yml") and not pp.is_absolute():
                pose = str(base_dir / pp)
            try:
                overrides["T_world_part"] = tuple(tuple(r) for r in parse_part_pose(pose).tolist())
            except InputError as exc:
                raise InputError(f"{where}: {exc}") from None
        elif key in known:
            _, f = known[key]
            overrides[f.name] = _convert(f, value, where)
        else:
            accepted = sorted({*_ENTRY_KEYS, *(f.name for _, f in known.values())})
            raise InputError(f"{where}: unknown column {key!r}; accepted: {', '.join(accepted)}")
    return PartEntry(path=str(path), overrides=tuple(sorted(overrides.items())), origin=where)


def read_manifest(path: str | os.PathLike) -> list[PartEntry]:
    """Parts named by a CSV (header row with a ``path`` column) or YAML manifest.

    YAML: a list of mappings (or of bare paths), or ``{"defaults": {...}, "parts": [...]}`` where
    ``defaults`` applies to every part that does not set the key itself."""
    path = Path(path)
    base = path.parent
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read the manifest ({exc})") from None
    entries: list[PartEntry] = []
    if path.suffix.lower() == ".csv":
        reader = csv.DictReader(io.StringIO(text))
        if not reader.fieldnames or "path" not in [h.strip().lower() for h in reader.fieldnames]:
            raise InputError(f"{path}: a CSV manifest needs a header row with a 'path' column "
                             f"(e.g. 'path,units,pose_index'); got {reader.fieldnames}")
        for row in reader:
            if None in row:
                raise InputError(f"{path}:{reader.line_num}: more values than header columns")
            if all((v or "").strip() == "" for v in row.values()):
                continue
            entries.append(_entry_from_mapping(row, base, f"{path}:{reader.line_num}"))
    else:
        import yaml

        try:
            doc = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise InputError(f"{path}: not valid YAML ({exc})") from None
        defaults: dict = {}
        if isinstance(doc, dict):
            defaults = doc.get("defaults") or {}
            if not isinstance(defaults, dict):
                raise InputError(f"{path}: 'defaults' must be a mapping of option -> value")
            doc = doc.get("parts")
        if not isinstance(doc, list):
            raise InputError(f"{path}: a YAML manifest is a list of parts (or a mapping with a 'parts' list); "
                             "each part is a path or a mapping with 'path' and optional options")
        for i, item in enumerate(doc):
            row = {"path": item} if isinstance(item, str) else item
            if not isinstance(row, dict):
                raise InputError(f"{path}: parts[{i}] must be a path or a mapping with 'path', got {item!r}")
            entries.append(_entry_from_mapping({**defaults, **row}, base, f"{path}: parts[{i}]"))
    if not entries:
        raise InputError(f"{path}: the manifest lists no parts")
    return entries


def discover_parts(inputs: Sequence[str | os.PathLike]) -> list[PartEntry]:
    """Expand files, folders (recursive, sorted) and manifests into parts, in the order given.

    Raises InputError when an input does not exist, a manifest is malformed, or nothing is found."""
    if not inputs:
        raise InputError("no parts given; name mesh files, folders or a CSV/YAML manifest")
    out: list[PartEntry] = []
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            found = sorted(q for q in p.rglob("*") if q.is_file() and q.suffix.lower() in FOLDER_SUFFIXES
                           and not any(part.startswith(".") for part in q.relative_to(p).parts))
            out += [PartEntry(path=str(q), origin=str(p)) for q in found]
        elif p.is_file() and p.suffix.lower() in MANIFEST_SUFFIXES:
            out += read_manifest(p)
        elif p.is_file() and p.suffix.lower() in SUPPORTED_SUFFIXES:
            out.append(PartEntry(path=str(p), origin="command line"))
        elif p.is_file():
            raise InputError(f"{p}: not a mesh ({', '.join(SUPPORTED_SUFFIXES)}) or a manifest "
                             f"({', '.join(MANIFEST_SUFFIXES)})")
        else:
            raise InputError(f"{p}: no such file or folder")
    if not out:
        raise InputError(f"no parts found in {', '.join(map(str, inputs))} (folders are searched recursively "
                         f"for {', '.join(FOLDER_SUFFIXES)})")
    return out


def apply_overrides(options: BatchOptions, overrides: Iterable[tuple[str, Any]]) -> BatchOptions:
    """``options`` with a manifest row's overrides (each param class re-validates itself)."""
    overrides = dict(overrides)
    if not overrides:
        return options
    top = {k: overrides.pop(k) for k in ("units", "robot", "gripper", "cell", "T_world_part") if k in overrides}
    groups = {"candidates": CandidateParams, "grasps": GraspParams, "planning": PlanParams}
    new = dict(top)
    for attr, cls in groups.items():
        names = {f.name for f in fields(cls)}
        mine = {k: v for k, v in overrides.items() if k in names}
        if mine:
            new[attr] = dataclasses.replace(getattr(options, attr), **mine)
    return dataclasses.replace(options, **new)


# --------------------------------------------------------------------------------------------- jobs
@dataclass(frozen=True)
class PartJob:
    """A part with everything needed to plan it: ``dir_name`` under OUTDIR, its options and hash."""

    path: str
    sha256: str
    dir_name: str
    options: BatchOptions
    options_hash: str
    duplicate_of: str | None = None  #: path of an earlier part with the same file and options


def make_jobs(entries: Sequence[PartEntry], options: BatchOptions) -> list[PartJob]:
    """Hash every part file (streamed) and every option set; name the output folders.

    Raises InputError / ConfigError for a bad per-part option or an unknown robot/gripper/cell."""
    hashes: dict[BatchOptions, str] = {}
    pre = []
    for e in entries:
        try:
            opts = apply_overrides(options, e.overrides)
        except GrasplanError as exc:
            raise type(exc)(f"{e.origin}: {exc}") from None
        if opts not in hashes:
            hashes[opts] = options_hash(opts)
        try:
            sha = sha256_file(e.path)
        except OSError as exc:
            raise InputError(f"{e.path}: cannot read the part ({exc.strerror})") from None
        pre.append((e, opts, sha))
    # folder names: <stem>-<sha8>, plus -<opt8> where one file meets several option sets
    option_sets: dict[tuple[str, str], set[str]] = {}
    for e, opts, sha in pre:
        option_sets.setdefault((Path(e.path).stem, sha[:8]), set()).add(hashes[opts])
    jobs: list[PartJob] = []
    first: dict[tuple[str, str], str] = {}
    for e, opts, sha in pre:
        stem = _safe_stem(Path(e.path).stem)
        h = hashes[opts]
        name = f"{stem}-{sha[:8]}"
        if len(option_sets[(Path(e.path).stem, sha[:8])]) > 1:
            name += f"-{h[:8]}"
        key = (sha, h)
        jobs.append(PartJob(path=e.path, sha256=sha, dir_name=name, options=opts, options_hash=h,
                            duplicate_of=first.get(key)))
        first.setdefault(key, e.path)
    return jobs


def _safe_stem(stem: str) -> str:
    keep = "".join(c if c.isalnum() or c in "-_." else "_" for c in stem).strip(".") or "part"
    return keep[:80]


# ------------------------------------------------------------------------------------ one part (worker)
def _job_payload(job: PartJob, *, ship_bytes: bool, config_dirs: Sequence[str]) -> dict:
    """Plain data for a worker (picklable, no shared filesystem needed when ``ship_bytes``)."""
    payload = {"path": job.path, "sha256": job.sha256, "options": job.options.to_json(),
               "options_hash": job.options_hash, "config_dirs": list(config_dirs), "data": None}
    if ship_bytes:
        payload["data"] = Path(job.path).read_bytes()
    return payload


def run_part(payload: dict, out_dir: str | None = None) -> dict:
    """Plan one part; never raises for a bad part (the outcome records it).

    ``payload``: from :func:`_job_payload` (``data`` holds the mesh bytes when the worker has no
    access to ``path``). With ``out_dir`` the files are written there (plan.json, exports,
    view.html, log.txt); without, they are written to a private temporary folder and returned as
    ``{"files": {name: zlib-compressed bytes}}`` (the Ray engine). The returned ``row`` is the
    summary row (see :func:`summary_row_fields`)."""
    if out_dir is not None:
        return _run_part_in(payload, Path(out_dir))
    with tempfile.TemporaryDirectory(prefix="grasplan-batch-") as tmp:
        outcome = _run_part_in(payload, Path(tmp) / "out")
        files = {}
        for p in sorted((Path(tmp) / "out").iterdir()):
            files[p.name] = zlib.compress(p.read_bytes(), 3)
        outcome["files"] = files
        return outcome


def _run_part_in(payload: dict, out: Path) -> dict:
    from .config_files import use_config_dirs

    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    log: list[str] = [f"part: {payload['path']}", f"sha256: {payload['sha256']}",
                      f"options_hash: {payload['options_hash']}"]
    row: dict[str, Any] = {"status": STATUS_ERROR, "exit_code": 1, "planned": 0, "grasps": 0, "best_score": None,
                           "timing_s": {}, "error": ""}
    local = Path(payload["path"])
    try:
        with contextlib.ExitStack() as stack:
            if payload["config_dirs"]:
                stack.enter_context(use_config_dirs(*payload["config_dirs"]))
            if payload["data"] is not None:
                tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="grasplan-part-")))
                local = tmp / Path(payload["path"]).name
                local.write_bytes(payload["data"])
            _plan_one(payload, local, out, row, log)
    except GrasplanError as exc:
        msg = str(exc).replace(str(local), payload["path"])  # name the part, not the worker's copy
        row.update(status=STATUS_BAD if exc.exit_code == 3 else STATUS_NOTHING, exit_code=exc.exit_code, error=msg)
        log.append(f"error (exit {exc.exit_code}): {msg}")
    except Exception as exc:  # noqa: BLE001 - isolate the part: the batch goes on, the log keeps the traceback
        row.update(status=STATUS_ERROR, exit_code=1, error=f"internal error: {type(exc).__name__}: {exc}")
        log.append("internal error (a bug; please report it with this log):")
        log.append(traceback.format_exc())
    row["timing_s"]["total"] = time.perf_counter() - t0
    log.append(f"status: {row['status']} (exit code {row['exit_code']}), {row['timing_s']['total']:.2f} s")
    write_atomic_text(out / LOG_FILE, "\n".join(log) + "\n")
    return {"row": row}


def _plan_one(payload: dict, local: Path, out: Path, row: dict, log: list[str]) -> None:
    import numpy as np

    from .mesh import load_part
    from .planning import plan

    o = BatchOptions.from_json(payload["options"])
    t = time.perf_counter()
    part = load_part(local, units=o.units)
    load_s = time.perf_counter() - t
    if str(local) != payload["path"]:
        # the worker's copy: record the path the part was named by, as `grasplan plan` would
        part = dataclasses.replace(part, path=payload["path"],
                                   warnings=tuple(w.replace(str(local), payload["path"]) for w in part.warnings))
    log.append(f"{part.triangles} triangles ({part.units_note})")
    log += [f"warning: {w}" for w in part.warnings]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        T = None if o.T_world_part is None else np.asarray(o.T_world_part, dtype=np.float64)
        result = plan(part, robot=o.robot, gripper=o.gripper, cell=o.cell, candidates=o.candidates,
                      grasps=o.grasps, planning=o.planning, T_world_part=T, load_s=load_s)
    log += [f"warning: {w.message}" for w in caught]
    result.write(out / PLAN_FILE)
    counts = result.counts()
    scores = [e["score"] for e in result.planned() if e.get("score") is not None]
    timing = {"load": load_s, **{k: float(v) for k, v in result.timing_s.items()}}  # the same load_s
    row.update(planned=int(counts["planned"]), grasps=int(counts["grasps"]),
               best_score=max(scores) if scores else None, timing_s=timing)
    log.append("counts: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    notes = []
    if o.exports:
        t = time.perf_counter()
        registry = export_formats()
        for name in o.exports:
            fmt = registry[name]
            if counts["planned"] == 0 and fmt.per_grasp:
                notes.append(f"export {name}: skipped, nothing planned")
                continue
            try:
                result.export(name, out / export_file(fmt), source=PLAN_FILE)
                log.append(f"export {name}: {export_file(fmt)}")
            except GrasplanError as exc:  # e.g. urscript for a non-UR robot: the part's plan still stands
                notes.append(f"export {name} failed: {exc}")
        timing["exports"] = time.perf_counter() - t
    if o.view:
        from .viewer import write_viewer

        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            write_viewer(result, out / VIEW_FILE)
        timing["view"] = time.perf_counter() - t
    log += notes
    log.append("seconds: " + ", ".join(f"{k} {v:.3f}" for k, v in timing.items()))
    if counts["planned"]:
        row.update(status=STATUS_PLANNED, exit_code=0, error="; ".join(notes))
    else:
        row.update(status=STATUS_NOTHING, exit_code=4,
                   error="; ".join([f"no grasp could be planned for {o.robot} (plan.json lists every grasp's "
                                    "status and reason)", *notes]))


# ---------------------------------------------------------------------------------------- engines
def _iter_local(jobs: Sequence[PartJob], *, workers: int, staging: Path, config_dirs: Sequence[str]
                ) -> Iterator[tuple[PartJob, dict, Path | None]]:
    """Run ``jobs`` on a spawn process pool; yields (job, outcome, folder the files are in).

    At most ``2 * workers`` parts are in flight. A worker that dies (killed, out of memory) breaks
    the pool: a new pool is started and the parts that were in flight are resubmitted; a part in
    flight during :data:`MAX_CRASHES` deaths is recorded as ``error``."""
    import concurrent.futures as cf
    import multiprocessing as mp
    from concurrent.futures.process import BrokenProcessPool

    pending = list(reversed(jobs))
    crashes: dict[int, int] = {}
    while pending:
        pool = cf.ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"))
        in_flight: dict[cf.Future, tuple[PartJob, Path]] = {}
        broken = finished = False
        try:
            while pending or in_flight:
                while pending and len(in_flight) < 2 * workers and not broken:
                    job = pending.pop()
                    d = staging / f"{job.dir_name}.{uuid.uuid4().hex[:8]}"
                    try:
                        fut = pool.submit(run_part, _job_payload(job, ship_bytes=False, config_dirs=config_dirs),
                                          str(d))
                    except BrokenProcessPool:
                        pending.append(job)
                        broken = True
                        break
                    in_flight[fut] = (job, d)
                if not in_flight:
                    break
                done, _ = cf.wait(in_flight, return_when=cf.FIRST_COMPLETED)
                for fut in done:
                    job, d = in_flight.pop(fut)
                    try:
                        outcome = fut.result()
                    except BrokenProcessPool:
                        broken = True
                        crashes[id(job)] = crashes.get(id(job), 0) + 1
                        shutil.rmtree(d, ignore_errors=True)
                        if crashes[id(job)] >= MAX_CRASHES:
                            yield job, _died_outcome(crashes[id(job)]), None
                        else:
                            pending.append(job)
                        continue
                    yield job, outcome, d
                if broken and not in_flight:
                    break
            finished = True
        finally:
            if not finished:  # Ctrl-C or the caller stopped: do not wait for the parts in flight
                _terminate_workers(pool)
            pool.shutdown(wait=True, cancel_futures=True)
            for _, d in in_flight.values():
                shutil.rmtree(d, ignore_errors=True)


def _terminate_workers(pool) -> None:
    """Stop a process pool's workers now (Python >= 3.14 has ``terminate_workers``; before, the
    executor keeps its processes in ``_processes``)."""
    terminate = getattr(pool, "terminate_workers", None)
    if terminate is not None:
        terminate()
        return
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        if proc.is_alive():
            proc.terminate()


def _died_outcome(n: int) -> dict:
    return {"row": {"status": STATUS_ERROR, "exit_code": 1, "planned": 0, "grasps": 0, "best_score": None,
                    "timing_s": {}, "error": f"the worker process died {n} times while planning this part "
                                             "(killed, or out of memory); rerun the batch to retry it"}}


def _iter_ray(jobs: Sequence[PartJob], *, workers: int | None, address: str | None, config_dirs: Sequence[str]
              ) -> Iterator[tuple[PartJob, dict, Path | None]]:
    """Run ``jobs`` as Ray tasks (bytes in, bytes out); yields (job, outcome with ``files``, None).

    With no ``address`` a private local Ray runtime with ``workers`` CPUs (default: all) is started
    (an already initialised Ray in this process is used as is); with an address (``HOST:6379``,
    ``ray://HOST:10001`` or ``auto``) the driver joins that cluster. In flight: twice the
    cluster's CPUs, so the driver holds a bounded number of parts' bytes."""
    try:
        import ray
    except ImportError:
        raise InputError("--engine ray needs Ray: pip install 'grasplan[ray]' (or use --engine local)") from None

    started = False
    if not ray.is_initialized():
        kwargs = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
        try:
            if address:
                ray.init(address=address, **kwargs)
            else:  # "local": a new runtime even when RAY_ADDRESS or a `ray start` cluster exists
                ray.init(address="local", num_cpus=workers, **kwargs)
        except (ConnectionError, ValueError, RuntimeError) as exc:
            if address:
                raise InputError(f"--ray-address {address}: cannot join the Ray cluster ({exc}); start it with "
                                 "`ray start --head` and pass the address it prints") from None
            raise InputError(f"--engine ray: cannot start a local Ray runtime ({exc}); try --engine local") from None
        started = True
    in_flight: dict[Any, PartJob] = {}
    finished = False
    try:
        from ray.exceptions import RayError

        remote = ray.remote(num_cpus=1, max_retries=MAX_CRASHES - 1)(run_part)
        cpus = int(ray.cluster_resources().get("CPU", 1))
        limit = 2 * max(1, cpus if workers is None or address else workers)
        pending = list(reversed(jobs))
        while pending or in_flight:
            while pending and len(in_flight) < limit:
                job = pending.pop()
                in_flight[remote.remote(_job_payload(job, ship_bytes=True, config_dirs=config_dirs))] = job
            ready, _ = ray.wait(list(in_flight), num_returns=1)
            for ref in ready:
                job = in_flight.pop(ref)
                try:
                    outcome = ray.get(ref)
                except RayError as exc:
                    outcome = _died_outcome(MAX_CRASHES)
                    outcome["row"]["error"] = f"Ray task failed ({type(exc).__name__}); rerun the batch to retry it"
                yield job, outcome, None
        finished = True
    finally:
        if not finished:  # Ctrl-C or the caller stopped: free the cluster's CPUs
            for ref in in_flight:
                ray.cancel(ref, force=True)
        if started:
            ray.shutdown()


# ------------------------------------------------------------------------------------------- driver
@dataclass
class BatchSummary:
    """Rows (one per part, in input order), the output folder, and the exit code."""

    out_dir: Path
    rows: list[dict]
    interrupted: bool = False

    @property
    def counts(self) -> dict[str, int]:
        out = {s: 0 for s in (*FINAL_STATUSES, STATUS_ERROR, "pending")}
        for r in self.rows:
            out[r["status"]] = out.get(r["status"], 0) + 1
        out["resumed"] = sum(1 for r in self.rows if r.get("resumed"))
        return out

    @property
    def exit_code(self) -> int:
        """0 when some part has a planned grasp, else 4."""
        return 0 if any(r["status"] == STATUS_PLANNED for r in self.rows) else 4


def _read_done(folder: Path, job: PartJob) -> dict | None:
    """The finished row in ``folder/done.json`` when it matches ``job`` (sha256 and options hash)."""
    try:
        done = read_json(folder / DONE_FILE)
    except (OSError, ValueError):
        return None
    if (isinstance(done, dict) and done.get("schema") == DONE_SCHEMA and done.get("sha256") == job.sha256
            and done.get("options_hash") == job.options_hash and done.get("status") in FINAL_STATUSES
            and isinstance(done.get("row"), dict)):
        return done["row"]
    return None


def _finalise(out_dir: Path, staging: Path, job: PartJob, outcome: dict, files_dir: Path | None) -> dict:
    """Move a part's files into ``out_dir/<dir_name>`` complete (done.json last, then one rename)."""
    row = _row(job, outcome["row"])
    work = files_dir if files_dir is not None else staging / f"{job.dir_name}.{uuid.uuid4().hex[:8]}"
    if files_dir is None:
        for name, blob in outcome.get("files", {}).items():
            if "/" in name or name.startswith("."):
                raise RuntimeError(f"unexpected result file name {name!r}")
            write_atomic_bytes(work / name, zlib.decompress(blob))
    write_json(work / DONE_FILE, {"schema": DONE_SCHEMA, "sha256": job.sha256, "options_hash": job.options_hash,
                                  "status": row["status"], "options": job.options.to_json(), "row": row}, indent=1)
    final = out_dir / job.dir_name
    if final.exists():
        trash = staging / f"{job.dir_name}.old.{uuid.uuid4().hex[:8]}"
        os.replace(final, trash)
        os.replace(work, final)
        shutil.rmtree(trash, ignore_errors=True)
    else:
        os.replace(work, final)
    return row


def _row(job: PartJob, r: dict) -> dict:
    return {"part": job.path, "dir": job.dir_name, "status": r["status"], "exit_code": r["exit_code"],
            "planned": r["planned"], "grasps": r["grasps"], "best_score": r["best_score"],
            "seconds": r["timing_s"].get("total"), "timing_s": r["timing_s"], "error": r["error"],
            "resumed": False, "sha256": job.sha256, "options_hash": job.options_hash}


def _pending_row(job: PartJob) -> dict:
    return _row(job, {"status": "pending", "exit_code": None, "planned": 0, "grasps": 0, "best_score": None,
                      "timing_s": {}, "error": "not run (the batch was interrupted); rerun to finish"})


def _file_size(path: str) -> int:
    try:
        return os.stat(path).st_size
    except OSError:
        return 0


@contextlib.contextmanager
def _lock(out_dir: Path) -> Iterator[None]:
    with open(out_dir / LOCK_FILE, "w") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(f"{out_dir}: another grasplan batch is writing to this folder; wait for it or "
                             "choose another -o") from None
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def run_batch(parts: Sequence[str | os.PathLike], out_dir: str | os.PathLike, *,
              options: BatchOptions = BatchOptions(), engine: str = "local", workers: int | None = None,
              ray_address: str | None = None, config_dirs: Sequence[str | os.PathLike] = (),
              progress: Callable[[dict], None] | None = None) -> BatchSummary:
    """Plan every part of ``parts`` (files, folders, manifests) into ``out_dir``; see the module doc.

    Parameters
    ----------
    options
        The batch's options; manifest rows override them per part.
    engine
        ``"local"`` (process pool of ``workers``, default one per core) or ``"ray"``.
    workers
        Local: pool size. Ray without address: CPUs of the local runtime (default: all).
    ray_address
        Join this Ray cluster instead of starting a local runtime (engine ``ray`` only).
    config_dirs
        Looked in first for robot/gripper/cell names (``--config-dir``); they must exist on every
        Ray node.
    progress
        Called after every part with ``{"done", "total", "failed", "planned", "skipped", "row",
        "elapsed_s"}``.

    Raises InputError (nothing written) for bad inputs; KeyboardInterrupt after writing the summary
    of what finished (the interrupted parts are left out of ``out_dir``).
    """
    if engine not in ENGINES:
        raise InputError(f"--engine {engine!r}: use one of {', '.join(ENGINES)}")
    if ray_address and engine != "ray":
        raise InputError("--ray-address needs --engine ray")
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be >= 1, got {workers}")
    cdirs = [str(Path(d).expanduser().resolve()) for d in config_dirs]
    from .config_files import use_config_dirs

    with use_config_dirs(*cdirs):
        jobs = make_jobs(discover_parts(parts), options)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"-o {out}: exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    with _lock(out):
        staging = out / STAGING_DIR
        shutil.rmtree(staging, ignore_errors=True)  # left by an interrupted batch: never a finished result
        staging.mkdir()
        rows: dict[int, dict] = {}
        todo: list[PartJob] = []
        for i, job in enumerate(jobs):
            if job.duplicate_of is not None:
                continue
            row = _read_done(out / job.dir_name, job)
            if row is not None:
                rows[i] = {**row, "part": job.path, "resumed": True}
            else:
                todo.append(job)
        # largest files first: the long parts do not end up alone at the tail (rows keep input order)
        todo.sort(key=lambda j: -_file_size(j.path))
        position = {id(j): i for i, j in enumerate(jobs)}
        t0 = time.perf_counter()
        state = {"done": len(rows), "failed": sum(r["status"] in (STATUS_BAD, STATUS_ERROR) for r in rows.values()),
                 "planned": sum(r["status"] == STATUS_PLANNED for r in rows.values()), "skipped": len(rows)}
        n_unique = sum(j.duplicate_of is None for j in jobs)
        interrupted = False
        if todo:
            workers_n = workers or os.cpu_count() or 1
            it = (_iter_local(todo, workers=min(workers_n, len(todo)), staging=staging, config_dirs=cdirs)
                  if engine == "local" else
                  _iter_ray(todo, workers=workers, address=ray_address, config_dirs=cdirs))
            try:
                for job, outcome, files_dir in it:
                    row = _finalise(out, staging, job, outcome, files_dir)
                    rows[position[id(job)]] = row
                    state["done"] += 1
                    state["failed"] += row["status"] in (STATUS_BAD, STATUS_ERROR)
                    state["planned"] += row["status"] == STATUS_PLANNED
                    if progress is not None:
                        progress({**state, "total": n_unique, "row": row, "elapsed_s": time.perf_counter() - t0})
            except KeyboardInterrupt:
                interrupted = True
            finally:
                if hasattr(it, "close"):
                    it.close()
        # duplicates share the first occurrence's result
        first_row = {}
        for i, job in enumerate(jobs):
            if job.duplicate_of is None and i in rows:
                first_row[(job.sha256, job.options_hash)] = rows[i]
        for i, job in enumerate(jobs):
            if job.duplicate_of is not None and (job.sha256, job.options_hash) in first_row:
                src = first_row[(job.sha256, job.options_hash)]
                rows[i] = {**src, "part": job.path,
                           "error": (src["error"] + "; " if src["error"] else "") + f"same file and options as "
                                                                                     f"{job.duplicate_of}"}
        final_rows = [rows.get(i) or _pending_row(job) for i, job in enumerate(jobs)]
        summary = BatchSummary(out_dir=out, rows=final_rows, interrupted=interrupted)
        write_summary(summary, options=options, engine=engine)
        shutil.rmtree(staging, ignore_errors=True)
    if interrupted:
        raise KeyboardInterrupt
    return summary


# ------------------------------------------------------------------------------------------ summary
#: fixed summary columns; one ``s_<stage>`` column per stage timing follows, then ``error``
SUMMARY_COLUMNS = ("part", "dir", "status", "exit_code", "planned", "grasps", "best_score", "seconds", "resumed",
                   "sha256", "options_hash")


def _stage_names(rows: Sequence[dict]) -> list[str]:
    names: list[str] = []
    for r in rows:
        for k in r.get("timing_s", {}):
            if k != "total" and k not in names:
                names.append(k)
    return names


def write_summary(summary: BatchSummary, *, options: BatchOptions, engine: str) -> None:
    """``summary.csv``, ``summary.json`` and ``index.html`` in ``summary.out_dir`` (atomic writes)."""
    rows = summary.rows
    stages = _stage_names(rows)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([*SUMMARY_COLUMNS, *(f"s_{s}" for s in stages), "error"])
    for r in rows:
        vals = []
        for c in SUMMARY_COLUMNS:
            v = r.get(c)
            vals.append("" if v is None else (f"{v:.6g}" if isinstance(v, float) else str(v).lower()
                                               if isinstance(v, bool) else v))
        t = r.get("timing_s", {})
        vals += [f"{t[s]:.4f}" if s in t else "" for s in stages]
        vals.append(r.get("error", ""))
        w.writerow(vals)
    write_atomic_text(summary.out_dir / "summary.csv", buf.getvalue())
    write_json(summary.out_dir / "summary.json",
               {"schema": SUMMARY_SCHEMA, "engine": engine, "options": options.to_json(),
                "interrupted": summary.interrupted, "exit_code": summary.exit_code, "counts": summary.counts,
                "parts": rows}, indent=1)
    write_atomic_text(summary.out_dir / "index.html", index_html(summary))


_STATUS_ORDER = {STATUS_PLANNED: 0, STATUS_NOTHING: 1, STATUS_BAD: 2, STATUS_ERROR: 3, "pending": 4}


def index_html(summary: BatchSummary) -> str:
    """An offline page (no network request): one table row per part linking its view.html;
    columns sort on click (status by default, planned parts first)."""
    e = html.escape
    trs = []
    for r in summary.rows:
        has_view = (summary.out_dir / r["dir"] / VIEW_FILE).is_file() if r["status"] != "pending" else False
        name = e(r["part"])
        link = f'<a href="{e(quote(r["dir"]))}/{VIEW_FILE}">{name}</a>' if has_view else name
        log = (f' <a class="log" href="{e(quote(r["dir"]))}/{LOG_FILE}">log</a>'
               if (summary.out_dir / r["dir"] / LOG_FILE).is_file() else "")
        score = "" if r["best_score"] is None else f"{r['best_score']:.3f}"
        secs = "" if r.get("seconds") is None else f"{r['seconds']:.2f}"
        trs.append(
            f'<tr class="{e(r["status"])}"><td>{link}{log}</td>'
            f'<td data-v="{_STATUS_ORDER.get(r["status"], 9)}">{e(r["status"])}</td>'
            f'<td data-v="{r["planned"]}">{r["planned"]}</td><td data-v="{r["grasps"]}">{r["grasps"]}</td>'
            f'<td data-v="{score or -1}">{score}</td><td data-v="{secs or -1}">{secs}</td>'
            f'<td>{e(r.get("error") or "")}</td></tr>')
    c = summary.counts
    head = ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in c.items() if v)
    return _INDEX_TEMPLATE.format(title=e(f"grasplan batch: {len(summary.rows)} parts"), counts=e(head),
                                  rows="\n".join(trs))


_INDEX_TEMPLATE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>
body {{ font: 14px system-ui, sans-serif; margin: 1.5em; }}
table {{ border-collapse: collapse; }}
th, td {{ padding: .25em .7em; border-bottom: 1px solid #ddd; text-align: left; }}
th {{ cursor: pointer; user-select: none; background: #f4f4f4; }} th:after {{ content: " \\2195"; color: #aaa; }}
tr.planned td:nth-child(2) {{ color: #1a7f37; }} tr.nothing_planned td:nth-child(2) {{ color: #9a6700; }}
tr.bad_input td:nth-child(2), tr.error td:nth-child(2) {{ color: #cf222e; }}
a.log {{ font-size: 85%; color: #666; }}
</style></head><body>
<h1>{title}</h1><p>{counts}</p>
<table id="parts"><thead><tr><th>part</th><th>status</th><th>planned</th><th>grasps</th><th>best score</th>
<th>seconds</th><th>error</th></tr></thead>
<tbody>
{rows}
</tbody></table>
<script>
(function () {{
  var table = document.getElementById("parts"), body = table.tBodies[0], dir = {{}};
  function key(tr, i) {{
    var td = tr.cells[i], v = td.getAttribute("data-v");
    return v === null ? td.textContent.toLowerCase() : parseFloat(v);
  }}
  function sort(i, asc) {{
    var rows = Array.prototype.slice.call(body.rows);
    rows.sort(function (a, b) {{
      var x = key(a, i), y = key(b, i);
      return (x < y ? -1 : x > y ? 1 : 0) * (asc ? 1 : -1);
    }});
    rows.forEach(function (r) {{ body.appendChild(r); }});
  }}
  Array.prototype.forEach.call(table.tHead.rows[0].cells, function (th, i) {{
    th.addEventListener("click", function () {{ dir[i] = !dir[i]; sort(i, dir[i]); }});
  }});
  sort(1, true);
}})();
</script>
</body></html>
"""


def format_row(row: dict) -> str:
    """One plain progress line for a finished part."""
    score = "" if row["best_score"] is None else f", best score {row['best_score']:.3f}"
    secs = "" if row.get("seconds") is None else f" in {row['seconds']:.1f} s"
    err = f": {row['error']}" if row["status"] not in (STATUS_PLANNED,) and row.get("error") else ""
    return f"{row['part']}: {row['status']}, {row['planned']} planned{score}{secs}{err}"


__all__ = ["BatchOptions", "BatchSummary", "PartEntry", "PartJob", "discover_parts", "read_manifest", "make_jobs",
           "apply_overrides", "options_hash", "run_part", "run_batch", "write_summary", "index_html",
           "check_exports", "export_formats", "FINAL_STATUSES", "ENGINES", "format_row"]
