"""Request-body schemas shown at ``/docs`` (OpenAPI). The service reads bodies itself
(:mod:`grasplan.serve.bodies`), so these describe the documents; they do not validate them.
The plan options are listed from the parameter dataclasses (one definition)."""
from __future__ import annotations

from dataclasses import MISSING, fields
from typing import Any

from ..config.option_kinds import option_spec
from ..config.params import PARAM_CLASSES

_KIND_TYPES = {"length": ["number", "string"], "length0": ["number", "string"], "angle": ["number", "string"],
               "float": "number", "seconds": "number", "int": "integer", "bool": "boolean", "choice": "string",
               "pose": ["string", "array"]}


def plan_options_schema() -> dict[str, Any]:
    props: dict[str, Any] = {}
    for cls in PARAM_CLASSES:
        for f in fields(cls):
            s = option_spec(f)
            if s is None or s.kind not in _KIND_TYPES:
                continue
            p: dict[str, Any] = {"type": _KIND_TYPES[s.kind], "description": s.help}
            if s.choices:
                p["enum"] = list(s.choices)
            if f.default is not MISSING and isinstance(f.default, (int, float, str, bool)):
                p["default"] = f.default
            props[f.name] = p
    return {"type": "object", "properties": props, "additionalProperties": False,
            "description": "Plan options by field name or CLI spelling (thin_spacing or thin); lengths in m or "
                           "with a unit ('2mm'), angles in degrees; the same ranges as the CLI."}


def _body(schema: dict[str, Any], example: dict[str, Any]) -> dict[str, Any]:
    return {"requestBody": {"required": True, "content": {"application/json": {"schema": schema,
                                                                                "example": example}}}}


def plan_body() -> dict[str, Any]:
    schema = {"type": "object", "required": ["part"], "additionalProperties": False, "properties": {
        "part": {"type": "string", "description": "A part name from GET /parts (its mesh file's stem)."},
        "options": plan_options_schema(),
        "part_pose": {"description": "The part's pose instead of its resting pose: 'x,y,z,roll,pitch,yaw' "
                                     "(m, degrees) or a 4x4 T_world_part."}}}
    return _body(schema, {"part": "bracket", "options": {"top": 5, "seed": 1}})


def pick_body() -> dict[str, Any]:
    pose = {"description": "T_world_part: {xyz: [m], rpy_deg: [deg]} (R = Rz(yaw) Ry(pitch) Rx(roll)) or a "
                           "4x4 row-major matrix"}
    schema = {"type": "object", "required": ["schema", "instances"], "properties": {
        "schema": {"const": "grasplan.scene/1"},
        "cell": {"type": "string", "description": "Optional; must be the service's cell (GET /health)."},
        "parts": {"type": "object", "description": "Optional: {name: {units}} or, as `scene drop` writes it, "
                                                   "{name: {mesh, units}}; names from GET /parts. A mesh is never "
                                                   "read: its file's stem must be the part's name. No grasps or "
                                                   "cloud files: the service reads none a client names."},
        "instances": {"type": "array", "items": {"type": "object", "required": ["id", "part", "T"],
                                                 "properties": {"id": {"type": "string"},
                                                                "part": {"type": "string"}, "T": pose}}},
        "options": {"type": "object", "additionalProperties": False, "properties": {
            "max_picks": {"type": "integer", "minimum": 1, "description": "Stop after this many picks (default: "
                                                                          "every instance that has one)."},
            "seed": {"type": "integer", "minimum": 0, "description": "Seed of IK and OMPL."},
            "sequence": {"type": "boolean", "description": "Pick, remove the instance, plan the next."},
            "push": {"type": "boolean", "description": "When nothing can be picked, plan a push of a part a wall "
                                                       "or a neighbour boxes in (the document's push entry)."}}}}}
    example = {"schema": "grasplan.scene/1", "instances": [
        {"id": "a", "part": "bracket", "T": {"xyz": [0.45, 0.0, 0.02], "rpy_deg": [0, 0, 30]}}],
        "options": {"max_picks": 1, "seed": 0}}
    return _body(schema, example)


def export_body() -> dict[str, Any]:
    schema = {"type": "object", "required": ["document", "format"], "additionalProperties": False, "properties": {
        "document": {"type": "object", "description": "A grasplan.plan/1 document from POST /plan."},
        "format": {"type": "string", "description": "An export format (grasplan export --help): urscript, "
                                                    "joint-trajectory, csv, krl, rapid, ..."},
        "grasp": {"type": "integer", "minimum": 0, "description": "The planned grasp (default: the best)."},
        "instance": {"type": "string", "description": "For a picks document: the instance to export."},
        "max_accel": {"type": "number", "description": "joint-trajectory: rad/s^2."},
        "velocity_scale": {"type": "number", "description": "joint-trajectory: fraction of the velocity limits."},
        "program_name": {"type": "string", "description": "KRL/RAPID routine name."}}}
    return _body(schema, {"document": {"schema": "grasplan.plan/1", "...": "..."}, "format": "urscript"})
