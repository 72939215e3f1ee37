"""``--workers N``: N planner processes (one or more) behind the one HTTP process, each request
handed to a free planner (reference: docs/serve.md, "Planners").

The HTTP process reads, checks and parses every body and answers ``/health``, ``/parts``,
``/robots``, ``/grippers`` itself; ``/plan``, ``/pick`` and ``/export`` documents go, in arrival
order, to the first free planner process (:class:`PlannerPool`), which validates, plans and
serialises them with its own warm :class:`~grasplan.serve.state.Service` (started from the files
the HTTP process resolved the robot, gripper and cell to) and sends the body back over a socket
pair. The time limit counts from a request's arrival: still waiting past it -> 503
(:class:`~grasplan.serve.jobs.Busy`); planning past it -> 504 (:class:`~grasplan.serve.jobs.TimedOut`),
the planner killed and replaced. A planner's exception comes back as its kind (422, 507, a bug
500); one that dies is replaced. Planners are fresh interpreters that ignore Ctrl-C and SIGTERM
(the HTTP process finishes the requests in progress, then stops them) and exit when their socket closes.
"""
from __future__ import annotations

import asyncio
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from ..compiled.threads import one_thread
from ..errors import GrasplanError, InputError
from .config import ServeConfig, config_from_json, config_to_json
from .jobs import Busy, TimedOut

log = logging.getLogger("grasplan.serve")
#: seconds a planner process may take to start (robot, parts, databases from the cache)
START_TIMEOUT_S = 900.0
#: seconds a planner is given to exit after being asked to, before it is killed
STOP_TIMEOUT_S = 5.0
JOBS = ("plan", "pick", "export")


class PlannerError(Exception):
    """A bug in a planner process (HTTP 500): ``type_name`` of its exception, its ``traceback``."""

    def __init__(self, type_name: str, traceback_text: str):
        super().__init__(type_name)
        self.type_name = type_name
        self.traceback = traceback_text


# ------------------------------------------------------------------------------- planner process
def planner_entry(fd: int) -> None:
    """A planner process (:class:`_Planner` starts it): read the settings from the socket ``fd``,
    start the warm state, then answer ``(job, document)`` messages until ``None`` or the socket
    closes (the HTTP process is gone)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole process group: the parent stops us
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # so may SIGTERM: the parent finishes the request, then stops us
    from . import handlers
    from .state import Service

    conn = Connection(fd)
    try:
        config_json = conn.recv()
        service = Service.start(config_from_json(config_json), lambda line: conn.send(("progress", line)))
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, which stops the start
        try:
            conn.send(("failed", f"{type(exc).__name__}: {exc}"))
        except (EOFError, OSError):  # the parent is gone
            pass
        return
    fns: dict[str, Callable[[Any, Any], Any]] = {"plan": handlers.plan, "pick": handlers.pick,
                                                 "export": handlers.export}
    try:
        conn.send(("ready", service.picker is not None))
    except (EOFError, OSError):  # the parent is gone
        return
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return
        if msg is None:
            return
        job, doc = msg
        try:
            reply: tuple[Any, ...] = ("ok", fns[job](service, doc))
        except InputError as exc:
            reply = ("input", str(exc))
        except GrasplanError as exc:
            reply = ("grasplan", str(exc))
        except MemoryError:
            reply = ("memory",)
        except Exception as exc:  # a bug: its type to the client, its traceback to the log
            reply = ("internal", type(exc).__name__, traceback.format_exc())
        try:
            conn.send(reply)
        except (EOFError, OSError):
            return


def _unpack(reply: tuple[Any, ...]) -> Any:
    """A planner's reply as the result, or the exception the app maps to a status."""
    kind = reply[0]
    if kind == "ok":
        return reply[1]
    if kind == "input":
        raise InputError(reply[1])
    if kind == "grasplan":
        raise GrasplanError(reply[1])
    if kind == "memory":
        raise MemoryError()
    raise PlannerError(reply[1], reply[2])


class _Planner:
    """One planner process and the parent's end of its socket pair. The process is a fresh
    interpreter (``python -c``; nothing is inherited, the caller's ``__main__`` is not imported)
    that imports this grasplan and gets its settings as the first message."""

    def __init__(self, config_json: dict[str, Any], index: int):
        self.index = index
        ours, theirs = socket.socketpair()
        root = str(Path(__file__).resolve().parents[2])  # the folder holding this grasplan package
        # one planner per core, each planning one request at a time: one BLAS thread each
        env = dict(one_thread({**os.environ,
                               "PYTHONPATH": os.pathsep.join([root, *filter(None, [os.environ.get("PYTHONPATH")])])}))
        try:
            self.proc = subprocess.Popen(
                [sys.executable, "-c", f"from grasplan.serve.pool import planner_entry; planner_entry({theirs.fileno()})"],
                pass_fds=(theirs.fileno(),), env=env, stdin=subprocess.DEVNULL)
        finally:
            theirs.close()
        self.conn = Connection(ours.detach())
        self.conn.send(config_json)
        self.picks = False

    def wait_ready(self, progress: Callable[[str], None], timeout_s: float = START_TIMEOUT_S) -> None:
        """Until the process has started its warm state (its progress lines to ``progress``);
        InputError when it could not."""
        t_end = time.monotonic() + timeout_s
        while True:
            left = t_end - time.monotonic()
            try:
                if left <= 0 or not self.conn.poll(left):
                    self.kill()
                    raise InputError(f"planner process {self.index} did not start within {timeout_s:g} s")
                msg = self.conn.recv()
            except (EOFError, OSError):
                self.kill()
                raise InputError(f"planner process {self.index} exited while starting (exit code "
                                 f"{self.proc.returncode}); see the lines above") from None
            if msg[0] == "progress":
                progress(msg[1])
            elif msg[0] == "ready":
                self.picks = bool(msg[1])
                return
            else:
                self.kill()
                raise InputError(f"planner process {self.index}: {msg[1]}")

    def call(self, job: str, doc: Any) -> tuple[Any, ...]:
        """Send one job and wait for its reply (on a thread of the pool's executor)."""
        self.conn.send((job, doc))
        reply: tuple[Any, ...] = self.conn.recv()
        return reply

    def stop(self) -> None:
        try:
            self.conn.send(None)
        except (EOFError, OSError):
            pass
        try:
            self.proc.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            pass
        self.kill()

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(STOP_TIMEOUT_S)
        self.conn.close()


def _retrieve(fut: asyncio.Future) -> None:
    if not fut.cancelled():
        fut.exception()


class PlannerPool:
    """``n`` planner processes started from ``config`` (module docstring). The first one starts
    alone (it computes any grasp database missing from the cache, with progress lines), the others
    then together (they load them from the cache)."""

    def __init__(self, config: ServeConfig, n: int, progress: Callable[[str], None] = lambda s: None):
        self.n = int(n)
        self.time_limit_s = float(config.time_limit_s)
        self.max_queue = int(config.max_queue)
        self._config_json = config_to_json(replace(config, token=None))  # the HTTP process checks the token
        self._planners: list[_Planner] = []
        try:
            first = _Planner(self._config_json, 0)
            self._planners.append(first)
            first.wait_ready(lambda line: progress(f"planner 0: {line}"))
            rest = [_Planner(self._config_json, k) for k in range(1, self.n)]
            self._planners.extend(rest)
            for p in rest:
                p.wait_ready(lambda line: None)
        except BaseException:
            self.close()
            raise
        progress(f"{self.n} planner process{'es' if self.n > 1 else ''} ready")
        self.picks = first.picks
        self._idle: deque[_Planner] = deque(self._planners)
        self._waiters: deque[asyncio.Future] = deque()
        self._executor = ThreadPoolExecutor(max_workers=self.n, thread_name_prefix="grasplan-planner")
        self._lock = threading.Lock()
        self._pending = 0
        self._closed = False
        self._loop: asyncio.AbstractEventLoop | None = None

    @property
    def pending(self) -> int:
        """Requests waiting for a planner or planning."""
        return self._pending

    def pids(self) -> list[int]:
        """The planner processes' ids (the benchmark reads their CPU time and memory)."""
        return [p.proc.pid for p in self._planners]

    # -- handing planners out (on the event loop) -------------------------------------------------
    def _release(self, planner: _Planner) -> None:
        while self._waiters:
            w = self._waiters.popleft()
            if not w.done():
                w.set_result(planner)
                return
        self._idle.append(planner)

    async def _acquire(self, timeout_s: float) -> _Planner | None:
        if self._idle and not self._waiters:
            return self._idle.popleft()
        assert self._loop is not None
        fut: asyncio.Future = self._loop.create_future()
        self._waiters.append(fut)
        try:
            await asyncio.wait({fut}, timeout=max(timeout_s, 0.0))
        except BaseException:  # the request was cancelled: a planner handed to it goes to the next
            if fut.done() and not fut.cancelled():
                self._release(fut.result())
            fut.cancel()
            raise
        if fut.done():
            planner: _Planner = fut.result()
            return planner
        fut.cancel()
        return None

    def _replace(self, planner: _Planner, why: str) -> None:
        """Kill ``planner`` and start a fresh one in its place (in a thread: seconds)."""
        loop = self._loop

        def work() -> None:
            planner.kill()
            if self._closed:
                return
            try:
                new = _Planner(self._config_json, planner.index)
                new.wait_ready(lambda line: None)
            except Exception as exc:  # the pool serves on with one planner less
                log.error("planner %d could not be restarted (%s); %d planners serve on", planner.index, exc,
                          len(self._planners) - 1)
                with self._lock:
                    self._planners.remove(planner)
                return
            with self._lock:
                self._planners[self._planners.index(planner)] = new
            log.info("planner %d restarted (%s)", planner.index, why)
            if loop is not None and not self._closed:
                loop.call_soon_threadsafe(self._release, new)

        threading.Thread(target=work, name=f"grasplan-restart-{planner.index}", daemon=True).start()

    async def run(self, job: str, doc: Any, *, what: str = "request") -> Any:
        """``job`` (plan, pick, export) of ``doc`` on a free planner: its result, or the exception
        of its kind (module docstring)."""
        t0 = time.monotonic()
        self._loop = asyncio.get_running_loop()
        if self._closed:
            raise Busy("the service is shutting down; retry on another instance")
        if self._pending - self.n >= self.max_queue:
            raise Busy(f"the service is busy: {self._pending} requests are queued or planning ({self.n} planners, "
                       f"at most {self.max_queue} wait); retry shortly")
        self._pending += 1
        try:
            while True:
                planner = await self._acquire(self.time_limit_s - (time.monotonic() - t0))
                if planner is None or planner.proc.poll() is None:
                    break
                self._replace(planner, f"it had exited with code {planner.proc.poll()}")  # died while idle
            if planner is None:
                raise Busy(f"the {what} waited {time.monotonic() - t0:.1f} s for a planner, all busy with earlier "
                           f"requests, past the time limit of {self.time_limit_s:g} s; retry shortly")
            fut = self._loop.run_in_executor(self._executor, planner.call, job, doc)
            fut.add_done_callback(_retrieve)
            try:
                await asyncio.wait({fut}, timeout=max(self.time_limit_s - (time.monotonic() - t0), 0.0))
            except BaseException:  # the request was cancelled: the planner is free when its job ends
                fut.add_done_callback(lambda f: self._release(planner) if f.exception() is None
                                      else self._replace(planner, "its connection broke"))
                raise
            if not fut.done():
                self._replace(planner, "time limit")
                raise TimedOut(f"the {what} took longer than the service's time limit of {self.time_limit_s:g} s "
                               "(--time-limit); ask for less (e.g. a smaller top or max_picks) or raise the limit")
            exc = fut.exception()
            if exc is not None:  # the pipe broke: the process died (a crash, the OOM killer)
                code = planner.proc.poll()
                self._replace(planner, f"it exited with code {code}")
                raise PlannerError("PlannerExited", f"planner {planner.index} exited (code {code}) during a {what}: "
                                                    f"{type(exc).__name__}")
            self._release(planner)
            return _unpack(fut.result())
        finally:
            self._pending -= 1

    def close(self) -> None:
        """Stop every planner (each finishes the job it has, for at most a few seconds)."""
        self._closed = True
        planners = list(self._planners)
        for p in planners:  # all asked first, then each waited for
            try:
                p.conn.send(None)
            except (EOFError, OSError):
                pass
        for p in planners:
            p.stop()
        if hasattr(self, "_executor"):
            self._executor.shutdown(wait=False, cancel_futures=True)
