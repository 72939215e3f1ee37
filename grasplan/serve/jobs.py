"""One request planned at a time per worker, each within a time limit.

:class:`JobQueue` runs every planning job (plan, pick, export) on one thread of its own, in
arrival order, so the warm planner is never used by two requests at once and the event loop stays
free for ``/health`` and for refusing bad requests. A request's time limit counts from its
arrival: still waiting when it runs out -> :class:`Busy` (HTTP 503, the job is dropped before it
starts); planning when it runs out -> :class:`TimedOut` (HTTP 504). A job cannot be stopped
half-way (a plan is C++ inside), so a timed-out job finishes in the background and later requests
wait for it; ``POST /plan`` caps the planning budget at the time limit so that rarely matters.
More than ``max_queue`` requests waiting -> :class:`Busy` at once.
"""
from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable
from concurrent.futures import CancelledError, Future, ThreadPoolExecutor
from typing import Any, TypeVar

from ..compiled.jit import prefer_jit

T = TypeVar("T")


class Busy(Exception):
    """The request could not start within its time limit, or the queue is full (HTTP 503)."""


class TimedOut(Exception):
    """The request's planning ran past its time limit (HTTP 504)."""


def _retrieve(fut: asyncio.Future) -> None:
    if not fut.cancelled():
        fut.exception()


class JobQueue:
    """A single planning thread with a bounded queue and per-request time limits."""

    def __init__(self, *, time_limit_s: float, max_queue: int):
        prefer_jit()  # kernels through numba, which releases the GIL: the event loop serves while one runs
        self.time_limit_s = float(time_limit_s)
        self.max_queue = int(max_queue)
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="grasplan-plan")
        self._lock = threading.Lock()
        self._pending = 0  # submitted and not finished (the running one included)
        self._closed = False

    @property
    def pending(self) -> int:
        """Jobs queued or running."""
        return self._pending

    def _done(self, fut: Future) -> None:
        with self._lock:
            self._pending -= 1

    async def run(self, fn: Callable[..., T], *args: Any, what: str = "request") -> T:
        """``fn(*args)`` on the planning thread; its result, or its exception re-raised here."""
        t0 = time.monotonic()
        with self._lock:
            if self._closed:
                raise Busy("the service is shutting down; retry on another instance")
            if self._pending > self.max_queue:
                raise Busy(f"the service is busy: {self._pending} requests are queued or planning (at most "
                           f"{self.max_queue} wait); retry shortly")
            self._pending += 1
        started = threading.Event()
        abandoned = threading.Event()

        def job() -> T:
            if abandoned.is_set():  # its client was already answered 503
                raise CancelledError()
            started.set()
            return fn(*args)

        try:
            fut = self._executor.submit(job)
        except RuntimeError:  # the executor was shut down
            self._done(Future())
            raise Busy("the service is shutting down; retry on another instance") from None
        fut.add_done_callback(self._done)
        afut = asyncio.wrap_future(fut)
        afut.add_done_callback(_retrieve)  # a timed-out job's late error is not "never retrieved"
        try:
            return await asyncio.wait_for(asyncio.shield(afut), self.time_limit_s)
        except asyncio.TimeoutError:
            abandoned.set()
            fut.cancel()
            waited = time.monotonic() - t0
            if started.is_set():
                raise TimedOut(f"the {what} took longer than the service's time limit of {self.time_limit_s:g} s "
                               "(--time-limit); ask for less (e.g. a smaller top or max_picks) or raise the limit"
                               ) from None
            raise Busy(f"the {what} waited {waited:.1f} s for the planner, which was busy with earlier requests, "
                       f"past the time limit of {self.time_limit_s:g} s; retry shortly") from None

    def close(self) -> None:
        """Refuse new jobs, drop the queued ones (the running one finishes)."""
        with self._lock:
            self._closed = True
        self._executor.shutdown(wait=False, cancel_futures=True)
