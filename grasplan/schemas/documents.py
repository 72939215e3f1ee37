"""JSON Schemas (draft 2020-12) of every JSON file grasplan writes, shipped with the package
(:data:`SCHEMA_FILES`: each document's ``"schema"`` field, its schema file and the command that
writes it).

>>> from grasplan.schemas import validate
>>> validate(json.load(open("plan.json")))        # doctest: +SKIP

``validate`` raises :class:`grasplan.errors.InputError` naming the first problem (its JSON path),
so a CLI command that reads a file the user gave exits with code 3.
"""
from __future__ import annotations

import json
from functools import lru_cache
from importlib import resources
from typing import Any

import jsonschema

from ..errors import InputError

#: schema name (the ``"schema"`` field of a document) -> schema file in this package
SCHEMA_FILES: dict[str, str] = {
    "grasplan.candidates/1": "candidates.schema.json",                # written by grasplan candidates
    "grasplan.grasps/1": "grasps.schema.json",                        # grasplan grasps
    "grasplan.plan/1": "plan.schema.json",                            # grasplan plan
    "grasplan.joint_trajectory/1": "joint_trajectory.schema.json",    # grasplan export --format joint-trajectory
    "grasplan.picks/1": "picks.schema.json",                          # grasplan pick
    "grasplan.scene/1": "scene.schema.json",                          # grasplan scene drop (read by grasplan pick)
}


def available_schemas() -> list[str]:
    return sorted(SCHEMA_FILES)


@lru_cache(maxsize=None)
def load_schema(name: str) -> dict:
    """The JSON Schema (a dict) for the schema name ``name`` (e.g. ``"grasplan.plan/1"``)."""
    if name not in SCHEMA_FILES:
        raise InputError(f"unknown schema {name!r}; available: {', '.join(available_schemas())}")
    text = resources.files(__package__).joinpath(SCHEMA_FILES[name]).read_text(encoding="utf-8")
    return json.loads(text)


@lru_cache(maxsize=None)
def _validator(name: str) -> jsonschema.Draft202012Validator:
    schema = load_schema(name)
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def errors(doc: Any, name: str | None = None) -> list[str]:
    """All validation problems of ``doc`` as ``"<json path>: <message>"`` strings (empty when valid).

    ``name`` defaults to ``doc["schema"]``.
    """
    if name is None:
        if not isinstance(doc, dict) or not isinstance(doc.get("schema"), str):
            return ["$: not a grasplan document (no \"schema\" field; expected one of "
                    f"{', '.join(available_schemas())})"]
        name = doc["schema"]
    if name not in SCHEMA_FILES:
        return [f"$.schema: unknown schema {name!r}; available: {', '.join(available_schemas())}"]
    out = []
    for err in sorted(_validator(name).iter_errors(doc), key=lambda e: list(e.absolute_path)):
        out.append(f"{err.json_path}: {err.message}")
    return out


def validate(doc: Any, name: str | None = None) -> str:
    """Validate ``doc`` against the schema named by ``doc["schema"]`` (or ``name``).

    Returns the schema name; raises :class:`~grasplan.errors.InputError` listing the first problems.
    """
    problems = errors(doc, name)
    if problems:
        shown = "; ".join(problems[:3])
        more = f" (and {len(problems) - 3} more)" if len(problems) > 3 else ""
        label = name or (doc.get("schema") if isinstance(doc, dict) else None) or "grasplan document"
        raise InputError(f"invalid {label}: {shown}{more}")
    return name or doc["schema"]
