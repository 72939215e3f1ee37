"""The HTTP connections of ``grasplan serve``: uvicorn's h11 protocol with the limits a service left
running needs (reference: docs/serve.md, "Connections"). uvicorn is given this class (``http=``),
whichever HTTP parsers are installed. It enforces: the header timeout (a request's headers complete
within ``--header-timeout`` of the connection's opening or previous response, not reset by each
byte: idle connections are closed, begun requests answered 408); the body timeout (a body pauses
at most ``--body-timeout`` and arrives within ``--time-limit``, else 408); connection caps per
client address and in all (a new connection replaces the oldest idle one, or is answered 503 when
every one is busy); malformed HTTP (400; over-long headers 431; a chunk beyond any body 400, beyond
``--max-body`` 413); a response sent before the body was read closes the connection after a short
linger (:data:`LINGER_S`) discarding further body bytes. Each is one log line on
``grasplan.serve``, never a traceback, rate-limited per kind (:data:`LOG_EVERY_S`). Nothing here is
FastAPI's: the limits hold for every route and before any route runs.
"""
from __future__ import annotations

import asyncio
import json
import logging
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

from .guard import CLOSED_KEY

if TYPE_CHECKING:
    from .config import ServeConfig

log = logging.getLogger("grasplan.serve")
#: request line and headers larger than this are answered 431
MAX_HEADER_BYTES = 16 * 1024
#: a chunk size above this (2 GiB, the largest --max-body) is no size a body can have: 400
MAX_CHUNK = 2**31
#: seconds a connection answered before its body was read stays open for the client to read the answer
LINGER_S = 2.0
#: at most one log line of a kind (a refusal, a 408, a 400, ...) per this many seconds, with the
#: count of those not logged since
LOG_EVERY_S = 10.0


@dataclass(frozen=True)
class Limits:
    """What one HTTP connection may hold (module docstring)."""

    header_timeout_s: float
    body_timeout_s: float
    body_deadline_s: float
    max_body: int
    max_connections: int
    max_connections_per_client: int

    @classmethod
    def from_config(cls, config: ServeConfig, max_connections: int | None = None) -> Limits:
        return cls(header_timeout_s=float(config.header_timeout_s), body_timeout_s=float(config.body_timeout_s),
                   body_deadline_s=float(config.time_limit_s), max_body=int(config.max_body),
                   max_connections=int(max_connections or config.max_connections),
                   max_connections_per_client=min(config.max_connections_per_client,
                                                  int(max_connections or config.max_connections)))


class Registry:
    """The open connections of one server: in all and per client address, each ordered by when it
    last began a request (or opened), least recent first."""

    def __init__(self, limits: Limits):
        self.limits = limits
        self.all: dict[GuardedH11Protocol, None] = {}
        self.by_client: dict[str, dict[GuardedH11Protocol, None]] = {}
        self.refused = 0  #: connections refused (every one of the address's or all busy)
        self.replaced = 0  #: idle connections closed to make room for a new one
        self._logged: dict[str, tuple[float, int]] = {}  # kind: (when last logged, how many since)

    def __len__(self) -> int:
        return len(self.all)

    def admit(self, conn: GuardedH11Protocol) -> bool:
        """Room for ``conn``, replacing the least recently active idle connection of its address,
        then of all, where it is needed; False (refuse it) when every one there is busy."""
        mine = self.by_client.get(conn.peer, {})
        if len(mine) >= self.limits.max_connections_per_client and not self._replace(mine):
            self._refuse(conn, f"{len(mine)} connections from {conn.peer} are busy with requests "
                               f"(--max-connections-per-client {self.limits.max_connections_per_client})")
            return False
        if len(self.all) >= self.limits.max_connections and not self._replace(self.all):
            self._refuse(conn, f"{len(self.all)} connections are busy with requests (--max-connections "
                               f"{self.limits.max_connections})")
            return False
        self.all[conn] = None
        self.by_client.setdefault(conn.peer, {})[conn] = None
        return True

    def _replace(self, conns: dict[GuardedH11Protocol, None]) -> bool:
        victim = next((c for c in conns if c.idle), None)
        if victim is None:
            return False
        self.replaced += 1
        victim.close_idle("replaced by a newer connection")
        return True

    def _refuse(self, conn: GuardedH11Protocol, why: str) -> None:
        self.refused += 1
        self.log(logging.WARNING, "refused", f"connection from {conn.peer} refused (503): {why}; "
                                             f"{self.refused} refused so far")

    def log(self, level: int, kind: str, line: str) -> None:
        """``line`` on the log unless a line of ``kind`` was logged within :data:`LOG_EVERY_S`
        (then it is counted, and the count joins the next line of that kind)."""
        now = time.monotonic()
        last, skipped = self._logged.get(kind, (-LOG_EVERY_S, 0))
        if now - last < LOG_EVERY_S:
            self._logged[kind] = (last, skipped + 1)
            return
        self._logged[kind] = (now, 0)
        log.log(level, "%s%s", line, f" ({skipped} more like it not logged)" if skipped else "")

    def touch(self, conn: GuardedH11Protocol) -> None:
        """``conn`` began a request: it becomes the most recently active."""
        for d in (self.all, self.by_client.get(conn.peer)):
            if d is not None and conn in d:
                del d[conn]
                d[conn] = None

    def remove(self, conn: GuardedH11Protocol) -> None:
        self.all.pop(conn, None)
        mine = self.by_client.get(conn.peer)
        if mine is not None:
            mine.pop(conn, None)
            if not mine:
                del self.by_client[conn.peer]


class _Connection(h11.Connection):
    """h11's connection, keeping the reason of the last request it refused (uvicorn's answer does not
    name it)."""

    refusal: str = ""
    refusal_status: int = 400

    def next_event(self) -> Any:
        try:
            return super().next_event()
        except h11.RemoteProtocolError as exc:
            self.refusal, self.refusal_status = str(exc), exc.error_status_hint
            raise


def _declared_chunk_left(conn: h11.Connection) -> int:
    """Bytes the chunk being read has announced and not yet delivered (0 outside a chunked body).
    h11 has no public accessor for it: its chunked reader's count is read, 0 if it is not there."""
    return int(getattr(getattr(conn, "_reader", None), "_bytes_in_chunk", 0) or 0)


class _QuietLog(logging.LoggerAdapter):
    """uvicorn's ``uvicorn.error`` logger without its lines for a malformed request (without its
    reason: :meth:`GuardedH11Protocol.send_400_response` logs one naming it) and for an ``Upgrade``
    request (the service has no WebSocket routes: such a request is served as plain HTTP), which a
    client could otherwise repeat into the log at will."""

    @property
    def level(self) -> int:
        return self.logger.level

    def warning(self, msg: Any, *args: Any, **kwargs: Any) -> None:
        if msg == "Invalid HTTP request received." or "upgrade" in str(msg).lower() \
                or "WebSocket" in str(msg):
            return
        self.logger.warning(msg, *args, **kwargs)


def _answer(status: int, reason: str, kind: str, detail: str) -> bytes:
    """A whole HTTP response ``{"error": kind, "detail": detail}`` that closes the connection."""
    body = json.dumps({"error": kind, "detail": detail}).encode("utf-8")
    return (f"HTTP/1.1 {status} {reason}\r\ncontent-type: application/json\r\ncontent-length: {len(body)}\r\n"
            "connection: close\r\n\r\n").encode("ascii") + body


class GuardedH11Protocol(H11Protocol):
    """uvicorn's h11 protocol with the limits of the module docstring (one instance per connection;
    :func:`protocol_class` makes the class of one server, sharing its :class:`Registry`)."""

    registry: ClassVar[Registry]

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._h11 = _Connection(h11.SERVER, MAX_HEADER_BYTES)
        self.conn = self._h11
        self.logger = _QuietLog(self.logger, {})  # type: ignore[assignment]
        self.limits = self.registry.limits
        self.peer = "unknown"
        self._timer: asyncio.TimerHandle | None = None
        self._closing = False      # refused, answered here or lingering: what arrives is discarded
        self._seen_cycle: Any = None
        self._sent_since_response = False
        self._body_deadline = 0.0

    # -- state ---------------------------------------------------------------------------------
    @property
    def idle(self) -> bool:
        """No request in progress (nothing sent, headers arriving, between requests, closing)."""
        return self._closing or self.cycle is None or self.cycle.response_complete

    def _arm(self, delay_s: float, callback: Any) -> None:
        self._cancel_timer()
        self._timer = self.loop.call_later(max(delay_s, 0.0), callback)

    def _cancel_timer(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    # -- asyncio.Protocol --------------------------------------------------------------------------
    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self.peer = str(self.client[0]) if self.client else "unknown"
        if not self.registry.admit(self):
            self._closing = True
            transport.write(_answer(503, "Service Unavailable", "busy", "too many connections from this address or "
                                    "in all, each busy with a request; retry shortly"))
            transport.close()
            return
        self._arm(self.limits.header_timeout_s, self._header_timed_out)

    def connection_lost(self, exc: Exception | None) -> None:
        self._cancel_timer()
        self.registry.remove(self)
        super().connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        if self._closing:
            return
        if self.idle:
            self._sent_since_response = True
        super().data_received(data)

    def handle_events(self) -> None:
        try:
            super().handle_events()
        except h11.ProtocolError as exc:  # h11 refused what uvicorn did not expect it to
            self._answer_and_close(400, "Bad Request", "bad_request", f"malformed HTTP request: {exc}")
            return
        self._watch()

    def on_response_complete(self) -> None:
        if self._closing:  # answered here already: nothing follows on this connection
            return
        if self.transport.is_closing():
            super().on_response_complete()
            return
        if self.conn.their_state is h11.SEND_BODY:  # answered before the body was read
            self.server_state.total_requests += 1
            self._linger()
            return
        self._sent_since_response = False
        self._arm(self.limits.header_timeout_s, self._header_timed_out)
        super().on_response_complete()

    def send_400_response(self, msg: str) -> None:
        why = self._h11.refusal or msg
        if self._h11.refusal_status == 431:
            self._answer_and_close(431, "Request Header Fields Too Large", "bad_request",
                                   f"the request line, headers or a chunk-size line are larger than {MAX_HEADER_BYTES} "
                                   f"bytes ({why})")
        else:
            self._answer_and_close(400, "Bad Request", "bad_request", f"malformed HTTP request: {why}")

    def shutdown(self) -> None:
        """The server is stopping: idle connections close now, one with a request in progress after
        its response."""
        if self._closing or self.idle:
            self._cancel_timer()
            self.transport.close()
            return
        try:
            super().shutdown()
        except h11.ProtocolError:
            self.transport.close()

    # -- the limits ------------------------------------------------------------------------------
    def _watch(self) -> None:
        """After the events of newly arrived data: a request whose headers just completed stops the
        header timer; a body being read restarts the body timer (or is refused by its chunk size)."""
        if self._closing or self.transport.is_closing():
            return
        cycle = self.cycle
        if cycle is not None and cycle is not self._seen_cycle:  # a new request's headers are complete
            self._seen_cycle = cycle
            self._cancel_timer()
            self.registry.touch(self)
            self._body_deadline = time.monotonic() + self.limits.body_deadline_s
        if cycle is None or cycle.response_complete or self.conn.their_state is not h11.SEND_BODY:
            if cycle is not None and not cycle.response_complete:
                self._cancel_timer()  # the body is whole: the route's time limit takes over
            return
        left = _declared_chunk_left(self.conn)
        if left > MAX_CHUNK:
            self._answer_and_close(400, "Bad Request", "bad_request", f"malformed chunked body: a chunk size over "
                                   f"{MAX_CHUNK} bytes (more than the largest body any service reads)")
            return
        if left > self.limits.max_body:
            limit = self.limits.max_body
            self._answer_and_close(413, "Content Too Large", "too_large", f"a chunk of over {limit} bytes: larger "
                                   f"than the service's limit of {limit} bytes (--max-body)")
            return
        self._arm(min(self.limits.body_timeout_s, self._body_deadline - time.monotonic()), self._body_timed_out)

    def _header_timed_out(self) -> None:
        self._timer = None
        if self._closing or self.transport.is_closing() or not self.idle:
            return
        if not self._sent_since_response:
            self.close_idle(f"idle for {self.limits.header_timeout_s:g} s, --header-timeout")
            return
        self._answer_and_close(408, "Request Timeout", "timeout", f"the request's headers did not arrive within "
                               f"{self.limits.header_timeout_s:g} s (--header-timeout); send them at once")

    def _body_timed_out(self) -> None:
        self._timer = None
        if self._closing or self.transport.is_closing() or self.cycle is None or self.cycle.response_complete:
            return
        if self.flow.read_paused:  # the route has not taken what arrived yet: not the client's delay
            self._arm(self.limits.body_timeout_s, self._body_timed_out)
            return
        if time.monotonic() >= self._body_deadline - 1e-3:
            why = f"the request body did not arrive within the time limit of {self.limits.body_deadline_s:g} s " \
                  "(--time-limit)"
        else:
            why = f"the request body paused for more than {self.limits.body_timeout_s:g} s (--body-timeout)"
        self._answer_and_close(408, "Request Timeout", "timeout", f"{why}; send the body without pauses")

    def close_idle(self, why: str) -> None:
        """Close an idle connection (no answer: no request is in progress)."""
        log.debug("%s: idle connection closed (%s)", self.peer, why)
        self._closing = True
        self._cancel_timer()
        self.registry.remove(self)
        self.transport.close()

    def _answer_and_close(self, status: int, reason: str, kind: str, detail: str) -> None:
        """Answer ``status`` here (unless the route's response has begun) and close the connection; the
        route, if one is reading the body, sees the client gone and does not answer."""
        detail = " ".join(detail.split())[:500]
        self.registry.log(logging.INFO, f"{status} {kind}", f"{self.peer}: {status} {detail}; connection closed")
        cycle = self.cycle if self.cycle is not None and not self.cycle.response_complete else None
        answered = cycle is None or not cycle.response_started
        if cycle is not None:
            cycle.scope[CLOSED_KEY] = detail  # type: ignore[literal-required]
            cycle.disconnected = True
            cycle.message_event.set()
        if answered and not self.transport.is_closing():
            self.transport.write(_answer(status, reason, kind, detail))
        self._linger()

    def _linger(self) -> None:
        """Close after the answer is sent: the write side at once, the socket when the client closes
        its side or after :data:`LINGER_S` (what it still sends is discarded)."""
        self._closing = True
        self._cancel_timer()
        if self.transport.is_closing():
            return
        self.flow.resume_reading()
        try:
            if self.transport.can_write_eof():
                self.transport.write_eof()
                self._timer = self.loop.call_later(LINGER_S, self.transport.close)
                return
        except OSError:  # the client is already gone
            pass
        self.transport.close()


def protocol_class(limits: Limits) -> type[GuardedH11Protocol]:
    """The protocol class of one server: its connections share one :class:`Registry`."""
    return type("GrasplanH11Protocol", (GuardedH11Protocol,), {"registry": Registry(limits)})
