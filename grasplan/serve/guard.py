"""The ASGI layer in front of the service's routes: the bearer token and the body-size limit,
both decided before a request's body is read.

- ``--token``: every path but :data:`OPEN_PATHS` needs ``Authorization: Bearer <token>``, compared
  with :func:`hmac.compare_digest` (constant time); otherwise 401.
- ``--max-body``: a ``Content-Length`` above the limit is answered 413 at once, without reading the
  body; a malformed ``Content-Length`` is 400. A body without a length (chunked) is refused by
  the connection layer from a chunk size over the limit (:mod:`grasplan.serve.protocol`) and
  counted while it arrives by the routes' reader (:func:`grasplan.serve.app.read_body`), 413 as
  soon as it passes the limit.
"""
from __future__ import annotations

import hmac
import json
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

#: paths anyone may read without the token: liveness and the API description (no data)
OPEN_PATHS = frozenset({"/health", "/docs", "/docs/oauth2-redirect", "/openapi.json", "/redoc"})
#: a key of a request's ASGI scope, set by the connection layer (:mod:`grasplan.serve.protocol`)
#: when it answered the request itself and closed the connection: the route then does not log the
#: closed connection again
CLOSED_KEY = "grasplan.closed"


async def send_error(send: Send, status: int, error: str, detail: str,
                     headers: tuple[tuple[bytes, bytes], ...] = ()) -> None:
    """A JSON error response ``{"error": ..., "detail": ...}`` straight on the ASGI channel."""
    body = json.dumps({"error": error, "detail": detail}).encode("utf-8")
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                            *headers]})
    await send({"type": "http.response.body", "body": body})


class Guard:
    """Wraps the FastAPI app: token and body limit (module docstring)."""

    def __init__(self, app: ASGIApp, *, token: str | None, max_body: int):
        self.app = app
        self.token = None if token is None else token.encode("utf-8")
        self.max_body = int(max_body)

    def _authorised(self, scope: Scope) -> bool:
        if self.token is None or scope.get("path") in OPEN_PATHS:
            return True
        given = b""
        for k, v in scope.get("headers") or ():
            if k.lower() == b"authorization":
                given = v
                break
        scheme, _, value = given.partition(b" ")
        ok = scheme.lower() == b"bearer"
        # compared in constant time whatever the scheme, so timing says nothing about the token
        return hmac.compare_digest(value.strip(), self.token) and ok

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        if not self._authorised(scope):
            await send_error(send, 401, "unauthorized", "this service needs 'Authorization: Bearer <token>' "
                             "(the token grasplan serve was started with, --token or $GRASPLAN_TOKEN)",
                             ((b"www-authenticate", b"Bearer"),))
            return
        length = None
        for k, v in scope.get("headers") or ():
            if k.lower() == b"content-length":
                try:
                    length = int(v)
                except ValueError:
                    length = -1
                if length < 0:
                    await send_error(send, 400, "bad_request", "Content-Length: not a byte count")
                    return
        if length is not None and length > self.max_body:
            await send_error(send, 413, "too_large", f"request body of {length} bytes is larger than the service's "
                             f"limit of {self.max_body} bytes (--max-body)")
            return
        await self.app(scope, receive, send)
