"""The work of ``POST /plan``, ``/pick`` and ``/export``, run on the planning thread
(:class:`grasplan.serve.jobs.JobQueue`): parse the request, plan with the warm state, render the
response body. Pure functions of a :class:`~grasplan.serve.state.Service` and the parsed JSON
document; they raise :class:`~grasplan.errors.InputError` (HTTP 422) naming the field.

Responses never show the server's file paths: a plan's ``part.path`` is the mesh's file name.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..io import to_json_text
from .bodies import export_request, pick_request, plan_request
from .state import Service

PLAN_SCHEMA = "grasplan.plan/1"
PICKS_SCHEMA = "grasplan.picks/1"


def plan(service: Service, doc: Any) -> bytes:
    """``grasplan.plan/1`` JSON for a ``POST /plan`` body (see :func:`~grasplan.serve.bodies.plan_request`)."""
    from ..motion.planning import plan as plan_part
    from ..motion.planning import planning_for_keep
    from ..results.writer import stream_document

    req = plan_request(doc, service)
    params = dict(req.params)
    if "planning" in params:
        params["planning"] = planning_for_keep(params["planning"], req.keep)
    result = plan_part(req.part.part, service.robot, gripper=service.gripper, cell=service.cell,
                       T_world_part=req.T_world_part, **params)
    result = replace(result, part=replace(result.part, path=req.part.path.name))
    chunks = stream_document(result, keep=req.keep)
    if chunks is None:  # a value the fast writer cannot encode: through the dict (refuses NaN)
        return to_json_text(result.to_json(keep=req.keep)).encode("utf-8")
    return "".join(chunks).encode("utf-8")


def pick(service: Service, doc: Any) -> bytes:
    """``grasplan.picks/1`` JSON for a ``POST /pick`` body (a scene plus ``options``)."""
    req = pick_request(doc, service)
    if service.picker is None:
        raise RuntimeError("pick requested from a service without a picker")  # the app answers 503 before
    result = service.picker.plan(req.scene, max_picks=req.max_picks, sequence=req.sequence, seed=req.seed,
                                 push=req.push)
    if req.notes:
        result = replace(result, warnings=(*req.notes, *result.warnings))
    return result.to_json_text(parts=public_parts(result.parts, service)).encode("utf-8")


def public_parts(parts: dict[str, dict[str, Any]], service: Service) -> dict[str, dict[str, Any]]:
    """A picks document's part records with each recorded path reduced to its file name."""
    out = {}
    for name, rec in parts.items():
        rec = dict(rec)
        if "path" in rec and name in service.parts:
            rec["path"] = service.parts[name].path.name
        out[name] = rec
    return out


def export(service: Service, doc: Any) -> dict[str, Any]:
    """``{"format", "extension", "text", "files": {extension: text}}`` for a ``POST /export`` body:
    the program of a plan document's grasp, or of a picks document's pick (``instance``, default
    the first pick), rendered in memory (no file is written)."""
    from ..results.export_registry import get_format, render_export

    req = export_request(doc)
    schema = req.document.get("schema")
    if schema == PLAN_SCHEMA:
        if req.instance is not None:
            raise InputError("instance: a plan document has no instances (instance is for a picks document)")
        res = _plan_result(service, req.document)
    elif schema == PICKS_SCHEMA:
        if req.grasp is not None:
            raise InputError("grasp: a picks document has one grasp per pick; choose the pick with instance")
        res = _pick_plan(service, req.document, req.instance)
    else:
        raise InputError(f"document.schema: expected {PLAN_SCHEMA!r} or {PICKS_SCHEMA!r}, got {str(schema)[:40]!r}")
    files = render_export(res, req.format, grasp_id=req.grasp, **req.options)
    f = get_format(req.format)
    return {"format": req.format, "extension": f.extension, "text": files[f.extension], "files": files}


def _check_robot(service: Service, doc: dict[str, Any]) -> None:
    """The document's robot must be the service's: a robot's description names URDF files to read."""
    robot = doc.get("robot")
    src = robot.get("source") if isinstance(robot, dict) else None
    if not isinstance(src, dict) or src.get("yaml") != service.robot.source_yaml:
        name = robot.get("name") if isinstance(robot, dict) else None
        raise InputError(f"document.robot: the document is for robot {str(name)[:40]!r}, not this service's robot "
                         f"{service.robot.name!r} (as loaded by the service); export documents made by this service")


def _pick_plan(service: Service, doc: dict[str, Any], instance: str | None) -> Any:
    """One pick of a client's picks document as a one-grasp plan (:func:`grasplan.pick.reader.pick_as_plan`):
    its robot must be the service's and each of its parts one of the service's (by sha256; the
    meshes are read from the parts folder, never from a path the document names)."""
    from ..pick.reader import pick_as_plan, result_from_picks

    _check_robot(service, doc)
    parts = doc.get("parts")
    if not isinstance(parts, dict) or not parts:
        raise InputError("document.parts: expected the picks document's parts ({name: {path, sha256, scale_to_m}})")
    local: dict[str, Any] = {}
    for name, rec in parts.items():
        entry = service.part_by_sha256(rec.get("sha256") if isinstance(rec, dict) else None)
        if entry is None or not isinstance(rec, dict):
            raise InputError(f"document.parts.{str(name)[:40]}.sha256: none of the service's parts "
                             f"({', '.join(service.parts)}); export picks made by this service")
        local[name] = {**rec, "path": str(entry.path)}
    res = result_from_picks({**doc, "parts": local}, where="document")
    plan = pick_as_plan(res, instance)
    return replace(plan, part=replace(plan.part, path=Path(plan.part.path).name))


def _plan_result(service: Service, doc: dict[str, Any]) -> Any:
    """The typed plan of a client's plan document: its robot must be the service's (a robot's
    description names URDF files to read) and its part one of the service's (by sha256; the mesh
    comes from the parts folder, at the scale the plan records)."""
    from ..part.mesh import load_recorded_part
    from ..results.reader import result_from_document

    _check_robot(service, doc)
    part = doc.get("part")
    sha = part.get("sha256") if isinstance(part, dict) else None
    entry = service.part_by_sha256(sha)
    if entry is None:
        raise InputError(f"document.part.sha256: {str(sha)[:16]!r}... is none of the service's parts "
                         f"({', '.join(service.parts)}); export plans of the service's parts")
    scale = part.get("scale_to_m") if isinstance(part, dict) else None
    mesh = entry.part.mesh
    if scale != entry.part.scale_to_m:
        if isinstance(scale, bool) or not isinstance(scale, (int, float)):
            raise InputError(f"document.part.scale_to_m: expected a number, got {str(scale)[:40]!r}")
        mesh = load_recorded_part({"path": str(entry.path), "scale_to_m": float(scale)}, path=entry.path).mesh
    res = result_from_document(doc, where="document", part_mesh=mesh)
    return replace(res, part=replace(res.part, path=entry.path.name))
