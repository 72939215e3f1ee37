"""The FastAPI application of ``grasplan serve`` (:func:`create_app`). Routes, status codes and
bodies: docs/serve.md.

Every planning route takes ``Content-Type: application/json`` bodies only (415), reads its body
itself (at most ``--max-body`` bytes, counted while it arrives), parses it strictly (400), hands
the document to the first free of ``--workers`` planner processes
(:class:`~grasplan.serve.pool.PlannerPool`; with an already started in-process ``service``, as the
tests give, the planning thread of this process: :class:`~grasplan.serve.jobs.JobQueue`); one
request at a time per planner, a time limit each (503/504), where :mod:`grasplan.serve.handlers`
validates it (422 naming the field), plans and serialises. A client that hangs up is one info line.
Any other exception is a bug: logged with its traceback, answered 500 with one line, and the
service keeps serving. Every GET route answers HEAD too.
"""
from __future__ import annotations

import asyncio
import logging
import uuid
import zlib
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass, replace
from typing import Any

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse, PlainTextResponse, Response
from fastapi.routing import APIRoute
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.requests import ClientDisconnect

from .. import __version__
from ..errors import GrasplanError, InputError
from . import handlers
from .config import ServeConfig
from .guard import CLOSED_KEY, Guard
from .jobs import Busy, JobQueue, TimedOut
from .pool import PlannerError, PlannerPool
from .openapi import export_body, pick_body, plan_body
from .bodies import BadRequest, parse_json
from .state import Service, process_rss_mib

log = logging.getLogger("grasplan.serve")
#: bodies larger than this are parsed off the event loop
_BIG_BODY = 1 << 20


#: a gzip-compressed body may inflate to this many times --max-body
GZIP_FACTOR = 8


class TooLarge(Exception):
    pass


class Unsupported(Exception):
    """A Content-Encoding the service does not read (HTTP 415)."""


#: the charsets a JSON body may declare (bodies are UTF-8)
_UTF8 = ("utf-8", "utf8")


def media_type_problem(request: Request) -> str | None:
    """Why the request's ``Content-Type`` is not a JSON body's (None: it is ``application/json``,
    with parameters, charset UTF-8 if given). Any other type, form and multipart bodies included,
    is refused: a web page can send those to the service from a browser without asking
    (a cross-site request), a JSON body it cannot."""
    fix = "send the body as JSON with 'Content-Type: application/json'"
    given = request.headers.getlist("content-type")
    if not given:
        return f"Content-Type: missing; {fix}"
    if len(given) > 1:
        return f"Content-Type: given {len(given)} times; {fix}"
    media, _, params = given[0].partition(";")
    media = media.strip().lower()
    if media != "application/json":
        return f"Content-Type: {media[:60]!r} is not read; {fix}"
    for param in params.split(";"):
        name, _, value = param.partition("=")
        if name.strip().lower() == "charset" and value.strip().strip('"').lower() not in _UTF8:
            return (f"Content-Type: charset {value.strip()[:40]!r}: bodies are UTF-8; send 'Content-Type: "
                    "application/json' with charset=utf-8 or none")
    return None


def error(status: int, kind: str, detail: str) -> JSONResponse:
    """``{"error": kind, "detail": one line}`` with ``status``."""
    detail = " ".join(detail.split())
    detail = "".join(c if c.isprintable() else "?" for c in detail)[:2000]
    return JSONResponse({"error": kind, "detail": detail}, status_code=status)


async def read_body(request: Request, limit: int) -> bytes:
    """The request body, at most ``limit`` bytes as sent (:class:`TooLarge` as soon as it passes
    them); a ``Content-Encoding: gzip`` body is inflated to at most :data:`GZIP_FACTOR` x ``limit``."""
    encoding = request.headers.get("content-encoding", "identity").strip().lower()
    if encoding not in ("identity", "gzip"):
        raise Unsupported(f"Content-Encoding {encoding[:40]!r}: send the body as is or gzip-compressed")
    chunks, n = [], 0
    async for chunk in request.stream():
        n += len(chunk)
        if n > limit:
            raise TooLarge(f"request body larger than the service's limit of {limit} bytes (--max-body)")
        chunks.append(chunk)
    body = b"".join(chunks)
    if encoding == "gzip":  # inflated off the event loop
        return await asyncio.to_thread(gunzip, body, GZIP_FACTOR * limit)
    return body


def gunzip(data: bytes, limit: int) -> bytes:
    """``data`` inflated (gzip), at most ``limit`` bytes (:class:`TooLarge` beyond: a compressed
    body cannot expand without bound); :class:`BadRequest` for data that is not gzip."""
    d = zlib.decompressobj(wbits=16 + zlib.MAX_WBITS)
    try:
        out = d.decompress(data, limit + 1)
    except zlib.error as exc:
        raise BadRequest(f"body: Content-Encoding gzip, but not gzip data ({exc})") from None
    if len(out) > limit or d.unconsumed_tail:
        raise TooLarge(f"gzip body inflates to more than {limit} bytes ({GZIP_FACTOR} x --max-body)")
    if not d.eof:
        raise BadRequest("body: Content-Encoding gzip, but the gzip data is truncated")
    return out


@dataclass(frozen=True)
class _Serving:
    """What the routes answer from: the settings, the warm state of this process, the planning
    thread's queue, the planner processes (None: plans run on the planning thread) and whether
    ``POST /pick`` can be served."""

    config: ServeConfig
    service: Service
    jobs: JobQueue
    pool: PlannerPool | None
    can_pick: bool


def create_app(config: ServeConfig, *, service: Service | None = None,
               progress: Callable[[str], None] | None = None) -> FastAPI:
    """The service's app (OpenAPI at ``/docs``), behind the token and body-size guard.

    ``service``: an already started :class:`Service` whose warm state to use with this config's
    limits, planned on this process's planning thread (tests share one; a plan past the time limit
    is answered 504 but cannot be stopped, and later requests wait for it); by default the warm
    state is started here in ``config.workers`` planner processes
    (:class:`~grasplan.serve.pool.PlannerPool`: robot, gripper, cell, parts, grasp databases:
    seconds to minutes, reported on ``progress``; a plan past the time limit is stopped with its
    process; stopped when the app's lifespan ends). Raises InputError/ConfigError for a
    configuration that cannot start."""
    serving = _start(config, service, progress or log.info)
    api = _application(serving)
    _add_error_handlers(api)
    _add_info_routes(api, serving)
    _add_planning_routes(api, serving)
    _answer_head(api)
    return api


def _start(config: ServeConfig, service: Service | None, progress: Callable[[str], None]) -> _Serving:
    """The warm state: ``service`` with this config's limits, or one started here (robot, gripper
    and cell resolved once, by this process) and the planner processes, which load the very files
    it resolved them to."""
    pool: PlannerPool | None = None
    if service is not None:
        service = service.with_config(config)
    else:  # planner processes; this one parses, checks and answers
        service = Service.start(replace(config, databases=False))
        pool = PlannerPool(service.resolved_config(config), config.workers, progress)
    jobs = JobQueue(time_limit_s=config.time_limit_s, max_queue=config.max_queue)
    can_pick = service.picker is not None if pool is None else pool.picks
    return _Serving(config, service, jobs, pool, can_pick)


def _application(serving: _Serving) -> FastAPI:
    """The FastAPI app holding ``serving`` (``app.state``), its lifespan (the queue and the planner
    processes stopped at its end) and the token and body-size guard."""

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        yield
        serving.jobs.close()
        if serving.pool is not None:
            serving.pool.close()

    api = FastAPI(title="grasplan", version=__version__, lifespan=lifespan,
                  description="Grasps, plans and picks for the parts in this service's parts folder "
                              "(docs/serve.md). Bodies are JSON; errors are {error, detail}.")
    api.state.config = serving.config
    api.state.service = serving.service
    api.state.jobs = serving.jobs
    api.state.pool = serving.pool
    api.add_middleware(Guard, token=serving.config.token, max_body=serving.config.max_body)
    return api


def _add_error_handlers(api: FastAPI) -> None:
    """404/405 as ``{error, detail}``; any exception outside the planning routes a logged 500."""

    @api.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        kinds = {404: "not_found", 405: "method_not_allowed"}
        response = error(exc.status_code, kinds.get(exc.status_code, "http_error"),
                         f"{request.method} {request.url.path}: {exc.detail}; see /docs")
        response.headers.update(exc.headers or {})  # a 405's Allow
        return response

    @api.exception_handler(Exception)
    async def unexpected(request: Request, exc: Exception) -> JSONResponse:  # outside the planning routes
        log.exception("%s %s: internal error", request.method, request.url.path)
        return error(500, "internal", f"internal error ({type(exc).__name__}); it is logged")


def _add_info_routes(api: FastAPI, serving: _Serving) -> None:
    """``GET /health``, ``/robots``, ``/grippers``, ``/parts``: answered by this process."""
    service, jobs, pool = serving.service, serving.jobs, serving.pool

    @api.get("/health", summary="Liveness: status, robot, gripper, cell, parts, queue, memory (no token needed)")
    async def health() -> dict[str, Any]:
        return {"status": "ok", "version": __version__, **service.info(), "pick": serving.can_pick,
                "queued": jobs.pending if pool is None else pool.pending, "planners": 1 if pool is None else pool.n,
                "rss_mib": {"http": process_rss_mib(None),
                            "planners": [] if pool is None else [process_rss_mib(p) for p in pool.pids()]}}

    @api.get("/robots", summary="The robot this service plans for, and the robots grasplan knows")
    async def robots() -> dict[str, Any]:
        return {"robot": service.robot.to_json(), "available": service.available["robots"]}

    @api.get("/grippers", summary="The gripper this service plans with, and the grippers grasplan knows")
    async def grippers() -> dict[str, Any]:
        return {"gripper": service.gripper.to_json(), "available": service.available["grippers"]}

    @api.get("/parts", summary="The parts a request may name (mesh file stems in --parts)")
    async def parts() -> dict[str, Any]:
        return {"parts": [e.to_json() for e in service.parts.values()]}


def _add_planning_routes(api: FastAPI, serving: _Serving) -> None:
    """``POST /plan``, ``/pick`` and ``/export``: each body run by :func:`_run`."""

    def json_bytes(out: Any) -> Response:
        return out if isinstance(out, Response) else Response(out, media_type="application/json")

    @api.post("/plan", summary="Plan grasps of a part: grasplan.plan/1", openapi_extra=plan_body(),
              responses={200: {"description": "A grasplan.plan/1 document"}})
    async def plan(request: Request) -> Response:
        return json_bytes(await _run(serving, request, handlers.plan, "plan"))

    @api.post("/pick", summary="Plan picks from a scene: grasplan.picks/1", openapi_extra=pick_body(),
              responses={200: {"description": "A grasplan.picks/1 document"}})
    async def pick(request: Request) -> Response:
        return json_bytes(await _run(serving, request, handlers.pick, "pick"))

    @api.post("/export", summary="A robot program of a plan: {format, extension, text, files}",
              openapi_extra=export_body(),
              responses={200: {"description": "JSON {format, extension, text, files}; with 'Accept: text/plain' "
                                              "the program text alone (single-file formats)"}})
    async def export(request: Request) -> Response:
        out = await _run(serving, request, handlers.export, "export")
        if isinstance(out, Response):
            return out
        if _wants_text(request):
            if len(out["files"]) != 1:
                return error(406, "not_acceptable", f"format {out['format']} writes {len(out['files'])} files "
                                                    f"({', '.join(out['files'])}); ask for application/json")
            return PlainTextResponse(out["text"])
        return JSONResponse(out)


def _answer_head(api: FastAPI) -> None:
    """Every GET route answers HEAD too (the OpenAPI description, made first, lists GET only)."""
    api.openapi()
    for route in api.routes:
        if isinstance(route, APIRoute) and route.methods and "GET" in route.methods:
            route.methods.add("HEAD")


async def _run(serving: _Serving, request: Request, fn: Callable[[Service, Any], Any], what: str) -> Any:
    """Body -> JSON document -> ``fn(service, doc)`` on the planning thread or a planner process;
    errors mapped to responses (the caller gets either the result or a Response)."""
    rid = uuid.uuid4().hex[:12]
    problem = media_type_problem(request)
    if problem is not None:
        return error(415, "unsupported_media_type", problem)
    try:
        body = await read_body(request, serving.config.max_body)
        doc = await asyncio.to_thread(parse_json, body) if len(body) > _BIG_BODY else parse_json(body)
        if what == "pick" and not serving.can_pick:
            return error(503, "unavailable", "this service has no picker (started without grasp databases, or "
                                             "this build has no grasplan.pick); POST /plan still works")
        if serving.pool is not None:
            return await serving.pool.run(what, doc, what=what)
        return await serving.jobs.run(fn, serving.service, doc, what=what)
    except ClientDisconnect:  # the client hung up (or the connection layer answered and closed it)
        if CLOSED_KEY not in request.scope:
            log.info("%s %s [%s]: the client closed the connection before its body arrived", request.method,
                     request.url.path, rid)
        return error(400, "bad_request", "the connection closed before the body arrived")
    except asyncio.CancelledError:  # the service stopped before this request could finish
        log.info("%s %s [%s]: cancelled: the service is stopping", request.method, request.url.path, rid)
        return error(503, "unavailable", "the service is stopping; retry on another instance")
    except MemoryError:
        log.error("%s %s [%s]: out of memory", request.method, request.url.path, rid)
        return error(507, "out_of_memory", f"the request needs more memory than this machine has [{rid}]")
    except Exception as exc:  # noqa: BLE001 - every kind is answered (and a bug logged) by _failure
        return _failure(request, rid, exc)


#: the exceptions a planning request ends with that are answers, not bugs: (class, status, kind)
_ANSWERS: tuple[tuple[type[BaseException], int, str], ...] = (
    (TooLarge, 413, "too_large"), (Unsupported, 415, "unsupported_encoding"), (BadRequest, 400, "bad_request"),
    (InputError, 422, "invalid"), (GrasplanError, 422, "unprocessable"),  # an impossible request, not a bug
    (Busy, 503, "busy"), (TimedOut, 504, "time_limit"))


def _failure(request: Request, rid: str, exc: Exception) -> JSONResponse:
    """The response for a planning request that raised ``exc`` (after read and parse)."""
    for cls, status, kind in _ANSWERS:
        if isinstance(exc, cls):
            return error(status, kind, str(exc))
    if isinstance(exc, PlannerError):  # a bug in a planner process: its traceback to the log
        log.error("%s %s [%s]: internal error in a planner process:\n%s", request.method, request.url.path, rid,
                  exc.traceback)
        return error(500, "internal", f"internal error ({exc.type_name}) [{rid}]; it is logged and the "
                                      "service keeps serving; please report it with the request")
    # a bug: one line to the client, the traceback in the log
    log.exception("%s %s [%s]: internal error", request.method, request.url.path, rid)
    return error(500, "internal", f"internal error ({type(exc).__name__}) [{rid}]; it is logged and the "
                                  "service keeps serving; please report it with the request")


def _wants_text(request: Request) -> bool:
    accept = request.headers.get("accept", "")
    return "text/plain" in accept and "application/json" not in accept
