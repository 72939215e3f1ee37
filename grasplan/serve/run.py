"""Running the service under uvicorn (``grasplan serve``).

One worker: the app is built in this process (robot, parts and grasp databases load with progress
lines), then uvicorn serves it. ``--workers N``: this process first fills the grasp-database cache
(so the workers load instead of computing), then uvicorn starts N worker processes, each building
its own warm app from the settings passed in :data:`CONFIG_ENV` (:func:`app_from_env`).
"""
from __future__ import annotations

import gc
import json
import logging
import os
from collections.abc import Callable
from typing import Any

from .config import ServeConfig, config_from_json, config_to_json

#: how the settings reach uvicorn's worker processes
CONFIG_ENV = "GRASPLAN_SERVE_CONFIG"
#: seconds an idle keep-alive connection stays open
KEEP_ALIVE_S = 5
log = logging.getLogger("grasplan.serve")


def uvicorn_options(config: ServeConfig) -> dict[str, Any]:
    """uvicorn's settings: the address, and a connection limit above which uvicorn answers 503
    itself (the planner's queue refuses earlier, with a message)."""
    return {"host": config.host, "port": config.port, "log_level": "info", "timeout_keep_alive": KEEP_ALIVE_S,
            "limit_concurrency": config.max_queue + 64, "server_header": False}


def serve(config: ServeConfig, progress: Callable[[str], None]) -> None:
    """Start the service and serve until interrupted (Ctrl-C or SIGTERM)."""
    import uvicorn

    from .app import create_app
    from .state import Service

    if config.workers == 1:
        app = create_app(config, progress=progress)
        progress(f"listening on http://{config.host}:{config.port} (OpenAPI: /docs)")
        uvicorn.run(app, **uvicorn_options(config))
        return
    progress(f"{config.workers} workers: filling the grasp-database cache first")
    Service.start(config, progress)  # the workers then load the databases from the cache
    gc.collect()
    os.environ[CONFIG_ENV] = json.dumps(config_to_json(config))
    progress(f"listening on http://{config.host}:{config.port} with {config.workers} workers (OpenAPI: /docs)")
    uvicorn.run("grasplan.serve.run:app_from_env", factory=True, workers=config.workers, **uvicorn_options(config))


def app_from_env() -> Any:
    """The app of one uvicorn worker (``--workers N``), from :data:`CONFIG_ENV`."""
    from .app import create_app

    return create_app(config_from_json(json.loads(os.environ[CONFIG_ENV])), progress=log.info)
