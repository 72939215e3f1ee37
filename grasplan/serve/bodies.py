"""Reading request bodies: strict JSON (:func:`parse_json`, HTTP 400 for what is not JSON) and the
documents of ``POST /plan``, ``/pick`` and ``/export`` (:class:`~grasplan.errors.InputError`
naming the field, HTTP 422). No request names a file: parts are names from the service's parts
folder, and every field that would read a file (a scene's ``grasps`` or ``cloud``, a plan option's
``scoring``, a plan document's robot) is refused or must match the service's own; a scene's
``mesh`` only names the part (its file is never read).

Plan options are the fields of :class:`~grasplan.config.params.CandidateParams`,
:class:`~grasplan.config.params.GraspParams` and :class:`~grasplan.config.params.PlanParams`, by field name or
CLI spelling (``thin_spacing`` or ``thin``), read by :func:`grasplan.config.option_kinds.read_value` (the
CLI's reading: ``"2mm"`` or 0.002) and validated by the dataclasses, so a value the CLI refuses is
refused here with the same message.
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ..errors import InputError
from ..config.jsontext import DuplicateKeyError, loads_strict
from ..config.option_kinds import KINDS, OptionSpec, check_fields, option_spec, read_value
from ..config.params import ALL_POSES, PARAM_CLASSES, PlanParams, option_fields
from ..geometry.transforms import MAX_CELL_COORD_M
from ..piles.scene_file import (MAX_INSTANCES, PART_NAME_RULE, SCENE_SCHEMA, SHA256_RE, Scene, part_name,
                                scene_from_dict, scene_part_material)
from ..results.compact import DEFAULT_KEEP, KEEP_CHOICES
from .state import BUDGET_SHARE, PartEntry, Service

#: the largest whole number a request may hold (digits); longer ones are refused as malformed
MAX_INT_DIGITS = 20
#: JSON nesting deeper than this is refused (a grasplan document is at most ~8 deep)
MAX_DEPTH = 64
PLAN_KEYS = ("part", "options", "part_pose", "keep")
PICK_OPTION_KEYS = ("max_picks", "seed", "sequence", "push")
EXPORT_KEYS = ("document", "format", "grasp", "instance", "max_accel", "velocity_scale", "program_name")
_PARAM_ATTRS = dict(zip(PARAM_CLASSES, ("candidates", "grasps", "planning")))
_SEED = OptionSpec("int", "seed", lo=0, hi=2**31 - 1)
_MAX_PICKS = OptionSpec("int", "max_picks", lo=1, hi=MAX_INSTANCES)
_POSE = OptionSpec("pose", "part pose")
#: the head of a parameter class's message: ``--top (top): ``
_CLI_NAMED = re.compile(r"^--[A-Za-z0-9-]+ \((\w+)\): ")


class BadRequest(Exception):
    """The body is not a JSON document (HTTP 400)."""


def _bad_number(text: str) -> Any:
    raise BadRequest(f"body: {text[:40]} is not a JSON number grasplan reads (NaN and Infinity are not JSON; "
                     f"numbers must be finite doubles and whole numbers at most {MAX_INT_DIGITS} digits)")


def _float(text: str) -> float:
    v = float(text)
    return v if math.isfinite(v) else _bad_number(text)


def _int(text: str) -> int:
    return int(text) if len(text.lstrip("-")) <= MAX_INT_DIGITS else _bad_number(text)


def _depth(doc: Any) -> int:
    """Nesting depth of a parsed document (iterative: a deep document cannot exhaust the stack)."""
    deepest, stack = 0, [(doc, 1)]
    while stack:
        d, k = stack.pop()
        if isinstance(d, dict):
            d = list(d.values())
        if isinstance(d, list):
            deepest = max(deepest, k)
            if k > MAX_DEPTH:
                return k
            stack.extend((x, k + 1) for x in d if isinstance(x, (dict, list)))
    return deepest


def parse_json(body: bytes) -> Any:
    """The JSON document of a request body; :class:`BadRequest` for an empty body, bytes that are
    not UTF-8, text that is not JSON, an object naming one key twice, NaN/Infinity, numbers out of
    range or absurd nesting."""
    if not body.strip():
        raise BadRequest("body: empty; send a JSON document (Content-Type: application/json)")
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise BadRequest(f"body: not UTF-8 text (byte {exc.start}); send a JSON document") from None
    try:
        doc = loads_strict(text, parse_float=_float, parse_int=_int, parse_constant=_bad_number)
    except json.JSONDecodeError as exc:
        raise BadRequest(f"body: not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    except DuplicateKeyError as exc:
        raise BadRequest(f"body: {exc}") from None
    except RecursionError:
        raise BadRequest(f"body: JSON nested too deeply (more than {MAX_DEPTH} levels)") from None
    except ValueError as exc:  # int digits beyond the interpreter's limit
        raise BadRequest(f"body: {str(exc)[:120]}") from None
    if _depth(doc) > MAX_DEPTH:
        raise BadRequest(f"body: JSON nested too deeply (more than {MAX_DEPTH} levels)")
    return doc


def _object(doc: Any, where: str, keys: tuple[str, ...]) -> dict[str, Any]:
    if not isinstance(doc, dict):
        raise InputError(f"{where}: expected a JSON object with {', '.join(keys)}, got {_type(doc)}")
    unknown = sorted(str(k) for k in doc if k not in keys)
    if unknown:
        raise InputError(f"{where}: unknown keys {_names(unknown)}; valid: {', '.join(keys)}")
    return doc


def _type(v: Any) -> str:
    return {dict: "an object", list: "an array", str: "a string", bool: "a boolean", type(None): "null"}.get(
        type(v), "a number")


def _names(items: list[str], limit: int = 5) -> str:
    return ", ".join(repr(s[:40]) for s in items[:limit]) + (" ..." if len(items) > limit else "")


def _checked(spec: OptionSpec, value: Any, name: str) -> Any:
    """``value`` read as an option of ``spec`` and range-checked (InputError naming ``name``)."""
    v = read_value(spec, value, name)
    why = KINDS[spec.kind].check(v, spec)
    if why is not None:
        raise InputError(f"{name}: {why}, got {v!r}")
    return v


def _bool(value: Any, name: str) -> bool:
    if not isinstance(value, bool):
        raise InputError(f"{name}: expected true or false, got {_type(value)}")
    return value


# ---------------------------------------------------------------------------------------- /plan
@dataclass(frozen=True)
class PlanRequest:
    part: PartEntry
    params: dict[str, Any]           #: candidates, grasps, planning (the dataclasses)
    T_world_part: np.ndarray | None  #: the part's pose instead of its resting pose
    keep: str = DEFAULT_KEEP          #: what the plan document keeps (grasplan.results.compact)


def read_options(options: Any, *, budget_cap_s: float | None = None) -> dict[str, Any]:
    """``{"candidates": CandidateParams, "grasps": GraspParams, "planning": PlanParams}`` from a
    request's ``options`` object. ``budget_cap_s``: the planning budget (``budget``) is at most this."""
    if options is None:
        options = {}
    if not isinstance(options, dict):
        raise InputError(f"options: expected an object of plan options (e.g. {{\"top\": 5}}), got {_type(options)}")
    known = option_fields()
    kw: dict[type, dict[str, Any]] = {cls: {} for cls in PARAM_CLASSES}
    for key, value in options.items():
        if key not in known:
            raise InputError(f"options.{str(key)[:40]}: unknown option; valid: "
                             f"{', '.join(sorted({f.name for _, f in known.values()}))}")
        cls, f = known[key]
        s = option_spec(f)
        assert s is not None
        if s.kind == "file":
            raise InputError(f"options.{key}: the service reads no file a client names; it scores with its own "
                             "weights (leave it out)")
        if f.name in kw[cls]:
            raise InputError(f"options.{key}: given twice (as {f.name} and its CLI spelling)")
        v = read_value(s, value, f"options.{key}")
        if f.name == "pose_index" and v == ALL_POSES:
            raise InputError("options.pose_index: 'all' writes one plan per resting pose; the service plans one "
                             "pose per request: give a pose index (0 = most probable)")
        kw[cls][f.name] = v
    out: dict[str, Any] = {}
    for cls, values in kw.items():
        try:
            out[_PARAM_ATTRS[cls]] = cls(**values)
        except InputError as exc:  # "--top (top): must be ..." -> "options.top: must be ..."
            raise InputError(_CLI_NAMED.sub(r"options.\1: ", str(exc), count=1)) from None
    if budget_cap_s is not None:
        pp: PlanParams = out["planning"]
        if pp.budget_s is None or pp.budget_s > budget_cap_s:
            out["planning"] = _replace_checked(pp, budget_s=budget_cap_s)
    return out


def _replace_checked(obj: Any, **changes: Any) -> Any:
    from dataclasses import replace

    new = replace(obj, **changes)
    check_fields(new)
    return new


def plan_request(doc: Any, service: Service) -> PlanRequest:
    """A ``POST /plan`` body: ``{"part": NAME, "options": {...}, "part_pose": ..., "keep": ...}``."""
    d = _object(doc, "body", PLAN_KEYS)
    if "part" not in d:
        raise InputError(f"part: missing; name one of the service's parts: {', '.join(service.parts)}")
    entry = service.part(d["part"], "part")
    params = read_options(d.get("options"), budget_cap_s=BUDGET_SHARE * service.config.time_limit_s)
    T = None
    if d.get("part_pose") is not None:
        T = np.asarray(_checked(_POSE, d["part_pose"], "part_pose"), dtype=np.float64)
        if np.abs(T[:3, 3]).max() > MAX_CELL_COORD_M:
            raise InputError(f"part_pose: the position is beyond {MAX_CELL_COORD_M:g} m of the world origin; give the "
                             "part's pose in the cell (m)")
    keep = d.get("keep", DEFAULT_KEEP)
    if keep not in KEEP_CHOICES:
        raise InputError(f"keep: {str(keep)[:40]!r} is not one of {', '.join(KEEP_CHOICES)}")
    return PlanRequest(entry, params, T, keep)


# ---------------------------------------------------------------------------------------- /pick
@dataclass(frozen=True)
class PickRequest:
    scene: Scene
    max_picks: int | None
    seed: int | None
    sequence: bool
    notes: tuple[str, ...] = ()  #: warnings the picks document carries (a lighter material ranked as the service's)
    push: bool = False  #: when nothing can be picked, plan a push (grasplan pick --push)


def pick_request(doc: Any, service: Service) -> PickRequest:
    """A ``POST /pick`` body: a ``grasplan.scene/1`` document whose parts are the service's (by
    name, or a ``mesh`` field's file name: :func:`_service_parts`; no ``grasps`` or ``cloud``
    file is read), plus an optional ``options`` object ``{max_picks, seed, sequence, push}``."""
    if not isinstance(doc, dict):
        raise InputError(f"scene: expected a {SCENE_SCHEMA} document (a JSON object), got {_type(doc)}")
    doc = dict(doc)
    opts = doc.pop("options", None)
    opts = _object({} if opts is None else opts, "options", PICK_OPTION_KEYS)
    max_picks = None if opts.get("max_picks") is None else _checked(_MAX_PICKS, opts["max_picks"], "options.max_picks")
    seed = None if opts.get("seed") is None else _checked(_SEED, opts["seed"], "options.seed")
    sequence = _bool(opts.get("sequence", False), "options.sequence")
    push = _bool(opts.get("push", False), "options.push")
    notes: list[str] = []
    if isinstance(doc.get("parts"), dict):
        doc = _service_parts(doc, service, notes)
    if doc.get("cloud") is not None:
        raise InputError("scene: cloud: the service reads no file a client names (a cloud is a file path); "
                         "leave it out")
    cell = doc.get("cell")
    if cell is not None and cell != service.cell.name:
        raise InputError(f"scene: cell: this service plans in cell {service.cell.name!r} (grasplan serve --cell); "
                         f"got {str(cell)[:40]!r}: leave it out or give {service.cell.name!r}")
    doc["cell"] = service.cell.name
    scene = scene_from_dict(doc, source="scene")
    for k, inst in enumerate(scene.instances):
        service.part(inst.part, f"scene: instances[{k}].part")
    return PickRequest(scene, max_picks, seed, sequence, tuple(notes), push)


def _by_sha256(name: Any, sha: Any, service: Service, where: str) -> str:
    """The service's part whose mesh has sha256 ``sha``; InputError naming ``where.sha256`` when
    the service's part called ``name`` has another mesh (the meshes differ) or no part has it
    (listing the parts and their sha256 prefixes)."""
    if not isinstance(sha, str) or not SHA256_RE.match(sha):
        raise InputError(f"{where}.sha256: expected the mesh file's sha256 (64 lowercase hex digits), "
                         f"got {str(sha)[:70]!r}")
    served = ", ".join(f"{n} ({e.part.sha256[:12]})" for n, e in service.parts.items())
    if isinstance(name, str) and name in service.parts and service.parts[name].part.sha256 != sha:
        raise InputError(f"{where}.sha256: the scene's mesh of {name} ({sha[:12]}...) differs from the service's "
                         f"{service.parts[name].path.name} ({service.parts[name].part.sha256[:12]}...): the meshes "
                         f"differ; write the scene with the service's mesh or serve this one")
    entry = service.part_by_sha256(sha)
    if entry is None:
        raise InputError(f"{where}.sha256: {sha[:12]}... is none of the service's parts (name (sha256)): {served}")
    return entry.name


def _service_material(spec: dict[str, Any], name: str, service: Service, where: str, notes: list[str]) -> None:
    """Check a scene part's ``material`` / ``density`` against the density the service's grasp
    database of part ``name`` was computed at, and leave them out of ``spec``: a lighter part is
    ranked with it (a grasp that holds the heavier part holds it) and ``notes`` says so; a heavier
    one is refused (InputError naming the field), as a material and a density that disagree."""
    material, density = spec.pop("material", None), spec.pop("density", None)
    if (material is None and density is None) or service.picker is None:
        return
    m, d = scene_part_material(material, density, where)
    served = service.picker.material_of(name)
    if d > served["density"] * (1 + 1e-9):
        raise InputError(f"{where}.{'material' if material is not None else 'density'}: the service ranks "
                         f"{name}'s grasps for {served['material']} ({served['density']:g} kg/m^3); a heavier part "
                         f"({m}, {d:g} kg/m^3) needs its own grasp databases: plan it with grasplan pick, or leave "
                         f"material and density out to rank it as {served['material']}")
    if d < served["density"] * (1 - 1e-9):
        notes.append(f"part {name}: {m} ({d:g} kg/m^3) ranked with the service's grasp databases for "
                     f"{served['material']} ({served['density']:g} kg/m^3): a grasp that holds the heavier part "
                     f"holds it too")


def _service_parts(doc: dict[str, Any], service: Service, notes: list[str]) -> dict[str, Any]:
    """``doc`` with its ``parts`` matched to the service's: a part with a ``sha256`` (as ``scene
    drop`` writes it) by that sha256 (:func:`_by_sha256`); else by its name; one with a ``mesh``
    by that file's part name (:func:`grasplan.piles.scene_file.part_name`), which must be the
    part's own name or, for a name the service does not hold (a scene written with lower-cased
    names), replaces it in the parts and instances. The mesh is never read (the service's file
    is used) and is left out; ``material`` / ``density``: :func:`_service_material`. InputError
    naming the field and the service's parts when nothing matches, for a ``grasps`` file and for
    ``units`` other than those the service read the part in."""
    renamed: dict[str, str] = {}
    parts: dict[str, Any] = {}
    for name, spec in doc["parts"].items():
        where = f"scene: parts.{str(name)[:40]}"
        spec = dict(spec) if isinstance(spec, dict) else spec
        mesh = spec.pop("mesh", None) if isinstance(spec, dict) else None
        if isinstance(spec, dict) and "grasps" in spec:
            raise InputError(f"{where}.grasps: the service uses its own grasp databases and reads no file a client "
                             "names; leave it out")
        if isinstance(spec, dict) and spec.get("sha256") is not None:
            by_sha = _by_sha256(name, spec["sha256"], service, where)
            if by_sha != name:
                renamed[name] = by_sha
        elif mesh is not None:
            if not isinstance(mesh, str) or not mesh.strip() or "\x00" in mesh or len(mesh) > 4096:
                raise InputError(f"{where}.mesh: expected a mesh file path (only its file name is used)")
            by_file = part_name(mesh.replace("\\", "/"))
            if by_file not in service.parts:
                raise InputError(f"{where}.mesh: the file's part name {by_file!r} is none of the service's parts "
                                 f"({', '.join(service.parts)}); a part's name is {PART_NAME_RULE}")
            if by_file != name:
                if name in service.parts:
                    raise InputError(f"{where}.mesh: the file gives part name {by_file!r}, not {str(name)[:40]!r}; "
                                     "give the part its mesh file's name")
                renamed[name] = by_file
        entry = service.part(renamed.get(name, name), where)
        units = spec.get("units") if isinstance(spec, dict) else None
        if mesh is not None and units not in (None, "auto", entry.part.units):
            raise InputError(f"{where}.units: the service reads part {entry.name!r} in {entry.part.units}, the scene "
                             f"says {str(units)[:20]!r}; give {entry.part.units!r} or leave units out")
        if entry.name in parts:
            raise InputError(f"{where}: another scene part is also the service's part {entry.name!r}; give each part "
                             "once")
        if isinstance(spec, dict):
            _service_material(spec, entry.name, service, where, notes)
        parts[entry.name] = spec
    out = dict(doc, parts=parts)
    if renamed and isinstance(doc.get("instances"), list):
        out["instances"] = [dict(i, part=renamed.get(i["part"], i["part"]))
                            if isinstance(i, dict) and isinstance(i.get("part"), str) else i
                            for i in doc["instances"]]
    return out


# -------------------------------------------------------------------------------------- /export
@dataclass(frozen=True)
class ExportRequest:
    document: dict[str, Any]
    format: str
    grasp: int | None
    instance: str | None
    options: dict[str, Any]  #: ExportOptions keywords (max_accel, velocity_scale, program_name)


def export_request(doc: Any) -> ExportRequest:
    """A ``POST /export`` body: ``{"document": <plan or picks document>, "format": NAME, "grasp": ID,
    "instance": ID, "max_accel": ..., "velocity_scale": ..., "program_name": ...}``."""
    from ..results.export_registry import ExportOptions, get_format

    d = _object(doc, "body", EXPORT_KEYS)
    if not isinstance(d.get("document"), dict):
        raise InputError(f"document: expected a grasplan.plan/1 or grasplan.picks/1 document (an object), got "
                         f"{_type(d.get('document'))}")
    if not isinstance(d.get("format"), str):
        raise InputError(f"format: expected a format name, got {_type(d.get('format'))}")
    try:
        get_format(d["format"])
    except InputError as exc:
        raise InputError(f"format: {exc}") from None
    options = {k: d[k] for k in ("max_accel", "velocity_scale", "program_name") if d.get(k) is not None}
    grasp = d.get("grasp")
    try:
        ExportOptions(grasp_id=grasp, **options)  # every value checked here, before the document is read
    except InputError as exc:
        raise InputError(str(exc).replace("--grasp", "grasp").replace("--max-accel", "max_accel")
                         .replace("--velocity-scale", "velocity_scale")) from None
    except TypeError:
        raise InputError("max_accel, velocity_scale: expected numbers; program_name: a string") from None
    instance = d.get("instance")
    if instance is not None and not isinstance(instance, str):
        raise InputError(f"instance: expected an instance id (a string), got {_type(instance)}")
    return ExportRequest(d["document"], d["format"], grasp, instance, options)


def param_names() -> list[str]:
    """Every plan option a request may set (field names), for the docs and errors."""
    out = []
    for cls in PARAM_CLASSES:
        for f in fields(cls):
            s = option_spec(f)
            if s is not None and s.kind not in ("internal", "file"):
                out.append(f.name)
    return out
