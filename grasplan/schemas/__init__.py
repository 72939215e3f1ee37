"""The JSON Schemas of grasplan's documents and their validation (:mod:`.documents`)."""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "SCHEMA_FILES": ".documents",
    "available_schemas": ".documents",
    "load_schema": ".documents",
    "errors": ".documents",
    "validate": ".documents",
})
