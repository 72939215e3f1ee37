"""Where a batch's parts run: a local spawn process pool (:func:`iter_local`) or Ray tasks
(:func:`iter_ray`). Both run :func:`grasplan.batch.worker.run_part` per part and yield
``(job, outcome, folder holding the part's files or None)`` as parts finish."""
from __future__ import annotations

import contextlib
import os
import shutil
import uuid
from collections.abc import Callable, Generator, Sequence
from pathlib import Path
from typing import Any

from ..errors import InputError
from .layout import MAX_CRASHES
from .lifeline import bind_to_parent
from .manifest import PartJob
from .worker import died_outcome, job_payload, ray_failed_outcome, run_part

#: what an engine yields per part: (job, outcome, folder its files are in or None when they came back as bytes)
Outcomes = Generator[tuple[PartJob, dict[str, Any], Path | None], None, None]
#: an engine runs jobs: ``run(jobs, *, workers, address, staging, config_dirs) -> Outcomes``
Engine = Callable[..., Outcomes]
#: the engines ``grasplan batch --engine`` offers, by name: adding one is a function plus one registration
ENGINES: dict[str, Engine] = {}


def register_engine(name: str) -> Callable[[Engine], Engine]:
    """Decorator: register an engine under ``name``."""
    def deco(fn: Engine) -> Engine:
        ENGINES[name] = fn
        return fn
    return deco


@register_engine("local")
def iter_local(jobs: Sequence[PartJob], *, workers: int | None, staging: Path, config_dirs: Sequence[str],
               address: str | None = None) -> Outcomes:
    """Run ``jobs`` on a spawn process pool of ``workers`` processes (default: one per CPU, at most
    one per job); yields (job, outcome, folder the files are in). ``address`` is not used.

    The workers end with this process, ``kill -9`` included (:func:`~grasplan.batch.lifeline.bind_to_parent`).
    At most ``2 * workers`` parts are in flight. A worker that dies (killed, out of memory) breaks
    the pool: a new pool is started and the parts that were in flight are resubmitted; a part in
    flight during :data:`~grasplan.batch.layout.MAX_CRASHES` deaths is recorded as ``error``."""
    workers = max(1, min(workers or os.cpu_count() or 1, len(jobs)))
    import concurrent.futures as cf
    import multiprocessing as mp
    from concurrent.futures.process import BrokenProcessPool

    pending = list(reversed(jobs))
    crashes: dict[int, int] = {}
    while pending:
        pool = cf.ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"),
                                      initializer=bind_to_parent, initargs=(os.getpid(),))
        in_flight: dict[cf.Future, tuple[PartJob, Path]] = {}
        broken = finished = False
        try:
            while pending or in_flight:
                while pending and len(in_flight) < 2 * workers and not broken:
                    job = pending.pop()
                    d = staging / f"{job.dir_name}.{uuid.uuid4().hex[:8]}"
                    try:
                        fut = pool.submit(run_part, job_payload(job, ship_bytes=False, config_dirs=config_dirs),
                                          str(d))
                    except BrokenProcessPool:
                        pending.append(job)
                        broken = True
                        break
                    in_flight[fut] = (job, d)
                if not in_flight:
                    break
                done, _ = cf.wait(in_flight, return_when=cf.FIRST_COMPLETED)
                for fut in done:
                    job, d = in_flight.pop(fut)
                    try:
                        outcome = fut.result()
                    except BrokenProcessPool:
                        broken = True
                        crashes[id(job)] = crashes.get(id(job), 0) + 1
                        shutil.rmtree(d, ignore_errors=True)
                        if crashes[id(job)] >= MAX_CRASHES:
                            yield job, died_outcome(crashes[id(job)]), None
                        else:
                            pending.append(job)
                        continue
                    yield job, outcome, d
                if broken and not in_flight:
                    break
            finished = True
        finally:
            if not finished:  # Ctrl-C or the caller stopped: do not wait for the parts in flight
                _terminate_workers(pool)
            pool.shutdown(wait=True, cancel_futures=True)
            for _, d in in_flight.values():
                shutil.rmtree(d, ignore_errors=True)


def _terminate_workers(pool: Any) -> None:
    """Stop a process pool's workers now (Python >= 3.14 has ``terminate_workers``; before, the
    executor keeps its processes in ``_processes``)."""
    terminate = getattr(pool, "terminate_workers", None)
    if terminate is not None:
        terminate()
        return
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        if proc.is_alive():
            proc.terminate()


@register_engine("ray")
def iter_ray(jobs: Sequence[PartJob], *, workers: int | None, address: str | None, config_dirs: Sequence[str],
             staging: Path | None = None) -> Outcomes:
    """Run ``jobs`` as Ray tasks (bytes in, bytes out); yields (job, outcome with ``files``, None).

    With no ``address`` a private local Ray runtime with ``workers`` CPUs (default: all) is started
    (an already initialised Ray in this process is used as is); with an address (``HOST:6379``,
    ``ray://HOST:10001`` or ``auto``) the driver joins that cluster. In flight: twice the
    cluster's CPUs, so the driver holds a bounded number of parts' bytes."""
    try:
        import ray
    except ImportError:
        raise InputError("--engine ray needs Ray: pip install 'grasplan[ray]' (or use --engine local)") from None
    except (OSError, MemoryError) as exc:  # e.g. an address-space limit too small for Ray's libraries
        raise InputError(f"--engine ray: cannot load Ray ({type(exc).__name__}); raise the memory limit or use "
                         "--engine local") from None

    started = False
    if not ray.is_initialized():
        try:
            if address:
                ray.init(address=address, include_dashboard=False, log_to_driver=False, configure_logging=False)
            else:  # "local": a new runtime even when RAY_ADDRESS or a `ray start` cluster exists
                ray.init(address="local", num_cpus=workers, include_dashboard=False, log_to_driver=False,
                         configure_logging=False)
        except Exception as exc:  # noqa: BLE001 - any start failure (no memory, no port, no /dev/shm) is the setup's
            if address:
                raise InputError(f"--ray-address {address}: cannot join the Ray cluster ({exc}); start it with "
                                 "`ray start --head` and pass the address it prints") from None
            raise InputError(f"--engine ray: cannot start a local Ray runtime ({exc}); try --engine local") from None
        started = True
    in_flight: dict[Any, PartJob] = {}
    finished = False
    try:
        from ray.exceptions import RayError

        remote = ray.remote(num_cpus=1, max_retries=MAX_CRASHES - 1)(run_part)
        cpus = int(ray.cluster_resources().get("CPU", 1))
        limit = 2 * max(1, cpus if workers is None or address else workers)
        pending = list(reversed(jobs))
        while pending or in_flight:
            while pending and len(in_flight) < limit:
                job = pending.pop()
                in_flight[remote.remote(job_payload(job, ship_bytes=True, config_dirs=config_dirs))] = job
            ready, _ = _signal_safe(ray.wait, list(in_flight), num_returns=1)
            for ref in ready:
                job = in_flight.pop(ref)
                try:
                    outcome = _signal_safe(ray.get, ref)
                except RayError as exc:
                    outcome = ray_failed_outcome(exc)
                yield job, outcome, None
        finished = True
    finally:
        if not finished:  # Ctrl-C, a signal or the caller stopped: free the cluster's CPUs
            _cancel_ray(ray, list(in_flight))
        if started:
            ray.shutdown()


#: seconds the tasks of a stopped batch get to end by themselves (removing their temporary folders)
RAY_CANCEL_S = 3.0


def _cancel_ray(ray: Any, refs: list[Any]) -> None:
    """Cancel ``refs``: first as Ctrl-C would (each task's temporary folders are removed on its way
    out), then, after :data:`RAY_CANCEL_S`, by killing the workers of those still running."""
    from ray.exceptions import RayError

    refused = (RayError, ValueError, TypeError)  # a task already finished, or gone with its worker
    for ref in refs:
        with contextlib.suppress(*refused):
            ray.cancel(ref, force=False)
    with contextlib.suppress(*refused):
        ray.wait(refs, num_returns=len(refs), timeout=RAY_CANCEL_S)
    for ref in refs:
        with contextlib.suppress(*refused):
            ray.cancel(ref, force=True)


def _signal_safe(call: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """``call(*args, **kwargs)``, a Ray function that waits in C++: a signal handler's exception
    raised while it waits (SIGHUP, SIGTERM: :func:`grasplan.io.signals_raise`) comes back from Ray
    wrapped in a SystemError; it is raised as itself, so the batch stops as the signal asks."""
    try:
        return call(*args, **kwargs)
    except SystemError as exc:
        cause = exc.__cause__
        if isinstance(cause, BaseException) and not isinstance(cause, Exception):
            raise cause from None
        raise
