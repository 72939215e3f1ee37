"""Running the service under uvicorn (``grasplan serve``): one process serves HTTP; with
``--workers N`` (N >= 2) it hands the planning to N planner processes
(:class:`grasplan.serve.pool.PlannerPool`), with one worker it plans on a thread of its own.
"""
from __future__ import annotations

import logging
import os
from collections.abc import Callable
from typing import Any

from .config import MAX_AUTO_WORKERS, ServeConfig

#: seconds an idle keep-alive connection stays open
KEEP_ALIVE_S = 5
log = logging.getLogger("grasplan.serve")


def default_workers() -> int:
    """``--workers`` when not given: one planner per core, at most :data:`MAX_AUTO_WORKERS`
    (each holds its own warm planner: docs/serve.md gives its memory)."""
    return max(1, min(os.cpu_count() or 1, MAX_AUTO_WORKERS))


def uvicorn_options(config: ServeConfig) -> dict[str, Any]:
    """uvicorn's settings: the address, and a connection limit above which uvicorn answers 503
    itself (the planners' queue refuses earlier, with a message)."""
    return {"host": config.host, "port": config.port, "log_level": "info", "timeout_keep_alive": KEEP_ALIVE_S,
            "limit_concurrency": config.max_queue + 64, "server_header": False}


def serve(config: ServeConfig, progress: Callable[[str], None]) -> None:
    """Start the service and serve until interrupted (Ctrl-C or SIGTERM)."""
    import uvicorn

    from .app import create_app

    app = create_app(config, progress=progress)
    planners = f" with {config.workers} planner processes" if config.workers > 1 else ""
    progress(f"listening on http://{config.host}:{config.port}{planners} (OpenAPI: /docs)")
    uvicorn.run(app, **uvicorn_options(config))
