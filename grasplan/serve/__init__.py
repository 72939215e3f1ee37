"""``grasplan serve``: an HTTP JSON service holding a warm planner (docs/serve.md): ``POST /pick``
(a ``grasplan.scene/1`` document -> ``grasplan.picks/1``), ``POST /plan`` (a part by name ->
``grasplan.plan/1``), ``POST /export`` (a plan -> program text), ``GET /health``, ``/robots``,
``/grippers``, ``/parts``; OpenAPI at ``/docs``.

Modules: ``config`` (settings), ``state`` (the warm setup, parts and picker), ``bodies`` (request
bodies), ``handlers`` (the work), ``jobs`` (one request at a time on a thread, time limits),
``pool`` (``--workers N`` planner processes), ``guard`` (token, body limit), ``app`` (FastAPI),
``protocol`` (HTTP connections), ``run`` (uvicorn, signals). FastAPI and uvicorn are the optional
``serve`` extra: only ``app``, ``protocol``, ``run`` and ``loopback`` import them.

    from grasplan.serve import ServeConfig, create_app
    app = create_app(ServeConfig(parts_dir="parts", cell="bin"))    # any ASGI server runs it
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .config import ServeConfig

if TYPE_CHECKING:
    from fastapi import FastAPI

__all__ = ["ServeConfig", "create_app"]


def create_app(config: ServeConfig, **kwargs: Any) -> FastAPI:
    """:func:`grasplan.serve.app.create_app` (imports FastAPI; InputError naming the extra when it
    is not installed)."""
    from .config import require_serve_packages

    require_serve_packages()
    from .app import create_app as make

    return make(config, **kwargs)
