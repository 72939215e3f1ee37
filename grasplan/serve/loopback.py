"""The service on this machine only, in a background thread, and a small keep-alive HTTP client:
what the tests and ``benchmarks/bench_serve.py`` talk to (real HTTP over 127.0.0.1, no network).

    with LoopbackServer(create_app(config)) as srv:
        c = Client(srv.port, token="...")
        status, doc = c.json("GET", "/health")
"""
from __future__ import annotations

import http.client
import json
import socket
import threading
import time
from typing import Any


class LoopbackServer:
    """uvicorn serving ``app`` on 127.0.0.1 at a free port, in a daemon thread, until the ``with``
    block ends (then it stops and the thread is joined). An app of :func:`grasplan.serve.create_app`
    is served as ``grasplan serve`` serves it (:func:`grasplan.serve.run.uvicorn_config`)."""

    def __init__(self, app: Any, *, start_timeout_s: float = 30.0):
        import uvicorn

        # proto IPPROTO_TCP (not 0): asyncio sets TCP_NODELAY only on such sockets (and the connections
        # they accept); without it every response waited ~40 ms for the client's delayed ACK (Nagle)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM, socket.IPPROTO_TCP)
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._sock.bind(("127.0.0.1", 0))
        self.port: int = self._sock.getsockname()[1]
        config = getattr(getattr(app, "state", None), "config", None)
        if config is not None:  # the service's app: its connection protocol, timeouts and limits
            from .run import uvicorn_config

            uv = uvicorn_config(app, config, log_level="warning")
        else:
            uv = uvicorn.Config(app, log_level="warning", lifespan="on", timeout_keep_alive=30)
        self.server = uvicorn.Server(uv)
        self._thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self._sock]},
                                        name="grasplan-serve-loopback", daemon=True)
        self._timeout = start_timeout_s

    def __enter__(self) -> LoopbackServer:
        self._thread.start()
        t_end = time.monotonic() + self._timeout
        while not self.server.started:
            if not self._thread.is_alive() or time.monotonic() > t_end:
                raise RuntimeError("the loopback server did not start")
            time.sleep(0.01)
        return self

    def __exit__(self, *exc: Any) -> None:
        self.server.should_exit = True
        self._thread.join(timeout=30)
        self._sock.close()


class Client:
    """One keep-alive HTTP/1.1 connection to ``127.0.0.1:port`` (reconnects when the server closed it)."""

    def __init__(self, port: int, *, token: str | None = None, timeout_s: float = 120.0, host: str = "127.0.0.1"):
        self.host, self.port, self.token, self.timeout_s = host, port, token, timeout_s
        self._conn: http.client.HTTPConnection | None = None

    def _connection(self) -> http.client.HTTPConnection:
        if self._conn is None:
            self._conn = http.client.HTTPConnection(self.host, self.port, timeout=self.timeout_s)
        return self._conn

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    def request(self, method: str, path: str, body: bytes | None = None, *,
                headers: dict[str, str] | None = None) -> tuple[int, bytes]:
        """``(status, body)``; a ``token`` is sent unless ``headers`` has an Authorization."""
        h = {"Content-Type": "application/json"} if body is not None else {}
        if self.token is not None:
            h["Authorization"] = f"Bearer {self.token}"
        h.update(headers or {})
        for attempt in (0, 1):  # a keep-alive connection the server closed: reconnect once
            conn = self._connection()
            try:
                conn.request(method, path, body=body, headers=h)
                resp = conn.getresponse()
                data = resp.read()
                if resp.getheader("connection", "").lower() == "close":
                    self.close()
                return resp.status, data
            except (ConnectionError, http.client.RemoteDisconnected, http.client.CannotSendRequest,
                    http.client.BadStatusLine):
                self.close()
                if attempt:
                    raise
        raise AssertionError("unreachable")

    def json(self, method: str, path: str, doc: Any = None, **kw: Any) -> tuple[int, Any]:
        """``(status, parsed JSON body)``; ``doc`` (not None) is sent as the JSON body."""
        status, data = self.request(method, path, None if doc is None else json.dumps(doc).encode("utf-8"), **kw)
        try:
            return status, json.loads(data)
        except ValueError:
            return status, data.decode("utf-8", "replace")
