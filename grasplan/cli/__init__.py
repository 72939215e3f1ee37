"""The ``grasplan`` command line (:mod:`.group`); each command lives in its own module."""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "COMMANDS": ".group",
    "LazyGroup": ".group",
    "main": ".group",
})
