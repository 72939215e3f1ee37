"""Running the service under uvicorn (``grasplan serve``): one process serves HTTP through
:mod:`grasplan.serve.protocol` (timeouts and connection limits) and hands the planning to
``--workers`` planner processes (:class:`grasplan.serve.pool.PlannerPool`).

SIGTERM and Ctrl-C stop it the same way: no new connections, idle ones closed, every request in
progress answered (its planning bounded by ``--time-limit``; the wait by :func:`shutdown_grace_s`),
the planners stopped, exit 0. A SIGTERM while it starts stops the planners started so far and
exits 0 too.
"""
from __future__ import annotations

import logging
import os
import signal
import threading
from collections.abc import Callable
from types import FrameType
from typing import Any

from .config import MAX_AUTO_WORKERS, ServeConfig

log = logging.getLogger("grasplan.serve")
#: file descriptors kept for everything but client connections (planner sockets, files, the listener)
RESERVED_FDS = 64
#: seconds, beyond the time limit, a stopping service waits for the requests in progress
SHUTDOWN_GRACE_S = 10.0


def default_workers() -> int:
    """``--workers`` when not given: one planner per core, at most :data:`MAX_AUTO_WORKERS`
    (each holds its own warm planner: docs/serve.md gives its memory)."""
    return max(1, min(os.cpu_count() or 1, MAX_AUTO_WORKERS))


def shutdown_grace_s(config: ServeConfig) -> float:
    """How long a stopping service waits for the requests in progress (then they are cancelled)."""
    return float(config.time_limit_s) + SHUTDOWN_GRACE_S


def raise_fd_limit(wanted: int) -> int:
    """Raise this process's soft limit of open files towards its hard limit so that ``wanted``
    connections fit beside :data:`RESERVED_FDS`; the connections that fit (at most ``wanted``)."""
    try:
        import resource
    except ImportError:  # not a POSIX system: nothing to raise
        return wanted
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    need = wanted + RESERVED_FDS
    if soft != resource.RLIM_INFINITY and soft < need:
        target = need if hard == resource.RLIM_INFINITY else min(need, hard)
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
            soft = target
        except (ValueError, OSError):
            pass
    if soft == resource.RLIM_INFINITY:
        return wanted
    return max(1, min(wanted, soft - RESERVED_FDS))


def uvicorn_config(app: Any, config: ServeConfig, *, log_level: str = "info",
                   max_connections: int | None = None) -> Any:
    """uvicorn's settings for ``app``: the address, the connection protocol of
    :mod:`grasplan.serve.protocol` (h11 with the timeouts and connection limits; uvicorn's own
    ``limit_concurrency``, which counts idle sockets, is not used; no WebSockets: the service has
    no such routes), the shutdown's bound."""
    import uvicorn

    from .protocol import Limits, protocol_class

    limits = Limits.from_config(config, max_connections)
    return uvicorn.Config(app, host=config.host, port=config.port, log_level=log_level, lifespan="on",
                          http=protocol_class(limits), ws="none", limit_concurrency=None, server_header=False,
                          timeout_keep_alive=config.header_timeout_s + 1,  # type: ignore[arg-type]
                          timeout_graceful_shutdown=shutdown_grace_s(config))  # type: ignore[arg-type]


class _Terminated(BaseException):
    """SIGTERM while the service starts."""


def serve(config: ServeConfig, progress: Callable[[str], None]) -> None:
    """Start the service and serve until Ctrl-C or SIGTERM (module docstring)."""
    import uvicorn

    from .app import create_app

    server: uvicorn.Server | None = None

    def on_sigterm(sig: int, frame: FrameType | None) -> None:
        if server is None:
            raise _Terminated()
        server.should_exit = True  # uvicorn's own handler replaces this one while it serves

    main = threading.current_thread() is threading.main_thread()
    if main:
        signal.signal(signal.SIGTERM, on_sigterm)
    connections = raise_fd_limit(config.max_connections)
    if connections < config.max_connections:
        progress(f"warning: the open-file limit allows {connections} connections, not {config.max_connections} "
                 "(--max-connections); raise it with ulimit -n")
    try:
        app = create_app(config, progress=progress)
    except _Terminated:
        progress("stopped while starting (SIGTERM)")
        return
    server = uvicorn.Server(uvicorn_config(app, config, max_connections=connections))
    planners = f"{config.workers} planner process{'es' if config.workers > 1 else ''}"
    progress(f"listening on http://{config.host}:{config.port} with {planners} (OpenAPI: /docs)")
    try:
        # uvicorn stops gracefully on SIGINT/SIGTERM, then re-delivers the signal to the handler it
        # replaced: on_sigterm (nothing left to do) or Python's, which raises KeyboardInterrupt
        server.run()
    except KeyboardInterrupt:
        pass
    progress("stopped")
