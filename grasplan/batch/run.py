"""``grasplan batch``: plan a whole catalogue of parts, resumable, on a local process pool or on Ray
(reference: docs/batch.md). :func:`run_batch` checks the inputs and the output folder, resolves
every robot, gripper and cell once (:func:`grasplan.batch.manifest.make_jobs`), locks the folder,
skips the parts whose ``done.json`` matches (same part sha256 and options hash, a finished status),
runs the rest on an engine, moves each part's files into ``OUTDIR/<stem>-<sha8>/`` complete from
``OUTDIR/.staging/`` (``done.json`` last) and writes ``summary.csv``, ``summary.json`` and
``index.html``. Exit code: :attr:`grasplan.batch.report.BatchSummary.exit_code`. Ctrl-C writes the
summary and raises KeyboardInterrupt; every other catchable ending signal stops the workers,
removes ``.staging`` and ends the process as the signal would (:func:`grasplan.io.signals_raise`).

Modules: :mod:`~grasplan.batch.options` (options, their hash), :mod:`~grasplan.batch.manifest`
(parts, manifests, jobs), :mod:`~grasplan.batch.outdir` (the output folder checked),
:mod:`~grasplan.batch.worker` (one part), :mod:`~grasplan.batch.engines` (local pool, Ray),
:mod:`~grasplan.batch.lifeline`, :mod:`~grasplan.batch.report`, :mod:`~grasplan.batch.layout`.
"""
from __future__ import annotations

import contextlib
import fcntl
import json
import os
import stat
import shutil
import time
import uuid
import zlib
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from ..errors import GrasplanError, InputError
from ..config.inputs import read_input_bytes
from ..io import show_path, signals_raise, write_atomic_bytes, write_json
from .engines import ENGINES
from .layout import (
    DONE_FILE,
    DONE_SCHEMA,
    FAILED_STATUSES,
    FINAL_STATUSES,
    LOCK_FILE,
    PLAN_FILE,
    STAGING_DIR,
    BatchStatus,
)
from .outdir import MAX_DONE_BYTES, check_out_dir, clear_staging, config_inputs
from .manifest import PartJob, discover_parts, make_jobs
from .options import BatchOptions
from .report import BatchSummary, pending_row, summary_row, write_summary


def run_batch(parts: Sequence[str | os.PathLike], out_dir: str | os.PathLike, *,
              options: BatchOptions = BatchOptions(), engine: str = "local", workers: int | None = None,
              ray_address: str | None = None, config_dirs: Sequence[str | os.PathLike] = (),
              progress: Callable[[dict[str, Any]], None] | None = None) -> BatchSummary:
    """Plan every part of ``parts`` (files, folders, manifests) into ``out_dir``; see the module doc.

    Parameters
    ----------
    options
        The batch's options; manifest rows override them per part.
    engine
        ``"local"`` (process pool of ``workers``, default one per core) or ``"ray"``.
    workers
        Local: pool size. Ray without address: CPUs of the local runtime (default: all).
    ray_address
        Join this Ray cluster instead of starting a local runtime (engine ``ray`` only).
    config_dirs
        Looked in first for robot/gripper/cell names (``--config-dir``); they must exist on every
        Ray node.
    progress
        Called after every part with ``{"done", "total", "failed", "planned", "skipped", "row",
        "elapsed_s"}``.

    Raises InputError (nothing written) for bad inputs; KeyboardInterrupt after writing the summary
    of what finished (the interrupted parts are left out of ``out_dir``).
    """
    with signals_raise():  # SIGHUP, SIGTERM, ...: the workers stopped and .staging removed on the way out
        return _run(parts, out_dir, options, engine, workers, ray_address, config_dirs, progress)


def _run(parts: Sequence[str | os.PathLike], out_dir: str | os.PathLike, options: BatchOptions, engine: str,
         workers: int | None, ray_address: str | None, config_dirs: Sequence[str | os.PathLike],
         progress: Callable[[dict[str, Any]], None] | None) -> BatchSummary:
    """:func:`run_batch` once the signals are set: check, lock, run."""
    if engine not in ENGINES:
        raise InputError(f"--engine {engine!r}: use one of {', '.join(ENGINES)}")
    if ray_address and engine != "ray":
        raise InputError("--ray-address needs --engine ray")
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be >= 1, got {workers}")
    cdirs = [str(Path(d).expanduser().resolve()) for d in config_dirs]
    from ..config.lookup import use_config_dirs

    check_out_dir(out_dir, inputs=parts, create=False)  # before a manifest is read: -o out with out/summary.csv
    with use_config_dirs(*cdirs):
        entries = discover_parts(parts)
        jobs = make_jobs(entries, options)
        out = check_out_dir(out_dir, jobs, inputs=[*parts, *(e.path for e in entries), *config_inputs(jobs)])
    with _lock(out):
        staging = out / STAGING_DIR
        try:
            return _run_locked(out, staging, jobs, options, engine, workers, ray_address, cdirs, progress)
        finally:
            shutil.rmtree(staging, ignore_errors=True)  # also on a signal or an engine failure


def _run_locked(out: Path, staging: Path, jobs: list[PartJob], options: BatchOptions, engine: str,
                workers: int | None, ray_address: str | None, cdirs: list[str],
                progress: Callable[[dict[str, Any]], None] | None) -> BatchSummary:
    """The batch once ``out`` is locked: stage, run, finalise, summarise (see :func:`run_batch`)."""
    clear_staging(staging)  # left by an interrupted batch: never a finished result
    staging.mkdir()
    rows: dict[int, dict[str, Any]] = {}
    todo: list[PartJob] = []
    out_text = os.fspath(out)
    with os.scandir(out) as listing:  # one listing, not one lookup per part
        present = {e.name for e in listing}
    for i, job in enumerate(jobs):
        if job.duplicate_of is not None:
            continue
        row = _read_done(os.path.join(out_text, job.dir_name), job) if job.dir_name in present else None
        if row is not None:
            rows[i] = {**row, "part": job.path, "resumed": True}
        else:
            todo.append(job)
    # largest files first: the long parts do not end up alone at the tail (rows keep input order)
    todo.sort(key=lambda j: -(j.size if j.size is not None else _file_size(j.path)))
    position = {id(j): i for i, j in enumerate(jobs)}
    t0 = time.perf_counter()
    state = {"done": len(rows), "failed": sum(r["status"] in FAILED_STATUSES for r in rows.values()),
             "planned": sum(r["status"] == BatchStatus.PLANNED for r in rows.values()), "skipped": len(rows)}
    n_unique = sum(j.duplicate_of is None for j in jobs)
    interrupted = False
    if todo:
        it = ENGINES[engine](todo, workers=workers, address=ray_address, staging=staging, config_dirs=cdirs)
        try:
            for job, outcome, files_dir in it:
                row = _finalise(out, staging, job, outcome, files_dir)
                rows[position[id(job)]] = row
                state["done"] += 1
                state["failed"] += row["status"] in FAILED_STATUSES
                state["planned"] += row["status"] == BatchStatus.PLANNED
                if progress is not None:
                    progress({**state, "total": n_unique, "row": row, "elapsed_s": time.perf_counter() - t0})
        except KeyboardInterrupt:
            interrupted = True
        finally:
            it.close()
    # duplicates share the first occurrence's result
    first_row = {}
    for i, job in enumerate(jobs):
        if job.duplicate_of is None and i in rows:
            first_row[(job.sha256, job.options_hash)] = rows[i]
    for i, job in enumerate(jobs):
        if job.duplicate_of is not None and (job.sha256, job.options_hash) in first_row:
            src = first_row[(job.sha256, job.options_hash)]
            rows[i] = {**src, "part": job.path,
                       "error": (src["error"] + "; " if src["error"] else "") + f"same file and options as "
                                                                                 f"{job.duplicate_of}"}
    final_rows = [rows.get(i) or pending_row(job) for i, job in enumerate(jobs)]
    summary = BatchSummary(out_dir=out, rows=final_rows, interrupted=interrupted)
    write_summary(summary, options=options, engine=engine)
    if interrupted:
        raise KeyboardInterrupt
    return summary


def _read_done(folder: str, job: PartJob) -> dict[str, Any] | None:
    """The finished row in ``folder/done.json`` when it matches ``job`` (sha256 and options hash)
    and every file it lists is still there with its recorded size; None (plan the part again)
    otherwise, whatever ``done.json`` holds: a damaged record affects only its part."""
    if not os.path.isdir(folder):  # not planned yet
        return None
    try:
        raw = read_input_bytes(os.path.join(folder, DONE_FILE), what="done.json", max_bytes=MAX_DONE_BYTES)
        done = json.loads(raw)
    except (GrasplanError, ValueError, RecursionError, MemoryError):
        return None
    if not (isinstance(done, dict) and done.get("schema") == DONE_SCHEMA and done.get("sha256") == job.sha256
            and done.get("options_hash") == job.options_hash and done.get("status") in FINAL_STATUSES
            and isinstance(done.get("row"), dict)):
        return None
    files = done.get("files")
    if not isinstance(files, dict):  # a record of an older batch: plan.json must be there at least
        files = {} if done["status"] == BatchStatus.BAD.value else {PLAN_FILE: None}
    for name, size in files.items():
        if not isinstance(name, str) or "/" in name or name.startswith("."):
            return None
        try:
            st = os.stat(os.path.join(folder, name))
        except OSError:
            return None
        if not stat.S_ISREG(st.st_mode) or (isinstance(size, int) and st.st_size != size):
            return None
    return done["row"]


def _finalise(out_dir: Path, staging: Path, job: PartJob, outcome: dict[str, Any], files_dir: Path | None
              ) -> dict[str, Any]:
    """Move a part's files into ``out_dir/<dir_name>`` complete (done.json last, then one rename)."""
    row = summary_row(job, outcome["row"])
    work = files_dir if files_dir is not None else staging / f"{job.dir_name}.{uuid.uuid4().hex[:8]}"
    if files_dir is None:
        for name, blob in outcome.get("files", {}).items():
            if "/" in name or name.startswith("."):
                raise RuntimeError(f"unexpected result file name {name!r}")
            write_atomic_bytes(work / name, zlib.decompress(blob))
    files = {p.name: p.stat().st_size for p in sorted(work.iterdir()) if p.is_file() and p.name != DONE_FILE
             and not p.name.startswith(".")}  # a rerun checks they are all still there
    write_json(work / DONE_FILE, {"schema": DONE_SCHEMA, "sha256": job.sha256, "options_hash": job.options_hash,
                                  "status": row["status"], "options": job.options.to_json(), "row": row,
                                  "files": files}, indent=1)
    final = out_dir / job.dir_name
    if final.exists():
        trash = staging / f"{job.dir_name}.old.{uuid.uuid4().hex[:8]}"
        os.replace(final, trash)
        os.replace(work, final)
        shutil.rmtree(trash, ignore_errors=True)
    else:
        os.replace(work, final)
    return row


def _file_size(path: str) -> int:
    try:
        return os.stat(path).st_size
    except OSError:
        return 0


@contextlib.contextmanager
def _lock(out_dir: Path) -> Iterator[None]:
    try:
        f = open(out_dir / LOCK_FILE, "w")
    except OSError as exc:
        raise InputError(f"-o {show_path(out_dir)}: cannot create the lock file {LOCK_FILE} "
                         f"({exc.strerror or 'operating-system error'}); remove what has that name or "
                         "choose another -o") from None
    with f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(f"{out_dir}: another grasplan batch is writing to this folder; wait for it or "
                             "choose another -o") from None
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)
