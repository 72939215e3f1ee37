"""One part of a batch, in a worker: :func:`run_part` plans it as ``grasplan plan`` would (the same
files: ``plan.json``, or with ``--pose-index all`` one ``plan.pose<k>.json`` per resting pose and
``plan.json`` = the chosen pose; the exports, ``view.html``, ``log.txt``) and returns its summary
row. Both engines (:mod:`grasplan.batch.engines`) call it, so results are identical across them."""
from __future__ import annotations

import contextlib
import dataclasses
import tempfile
import time
import traceback
import warnings
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import GrasplanError
from ..io import write_atomic_text
from ..config.params import ALL_POSES
from ..status import Status
from .layout import LOG_FILE, MAX_CRASHES, PLAN_FILE, VIEW_FILE, BatchStatus
from .options import BatchOptions, export_file, export_formats

if TYPE_CHECKING:
    from ..part.mesh import Part
    from ..results.plan_result import PlanResult
    from ..setup.resolved import Setup
    from .manifest import PartJob


def job_payload(job: PartJob, *, ship_bytes: bool, config_dirs: Sequence[str]) -> dict[str, Any]:
    """Plain data for a worker (picklable, no shared filesystem needed when ``ship_bytes``).
    ``refs``: the robot, gripper and cell the worker loads: the files the batch resolved them to
    (:meth:`~grasplan.setup.resolved.Setup.resolved_refs`) when the worker shares this file system,
    else the names and paths as given, looked up on the worker's machine (``config_dirs`` first)."""
    o = job.options
    refs = {"robot": o.robot, "gripper": o.gripper, "cell": o.cell}
    if job.setup is not None and not ship_bytes:
        refs.update(job.setup.resolved_refs())
    return {"path": job.path, "sha256": job.sha256, "options": job.options.to_json(),
            "options_hash": job.options_hash, "config_dirs": list(config_dirs), "refs": refs,
            "data": Path(job.path).read_bytes() if ship_bytes else None}


def _row(status: BatchStatus, exit_code: int, error: str = "") -> dict[str, Any]:
    """A worker's summary row before the plan's counts are known."""
    return {"status": status.value, "exit_code": exit_code, "planned": 0, "grasps": 0, "best_score": None,
            "timing_s": {}, "error": error}


def died_outcome(n: int) -> dict[str, Any]:
    """The outcome of a part whose worker died ``n`` times (killed, out of memory)."""
    return {"row": _row(BatchStatus.ERROR, 1, f"the worker process died {n} times while planning this part "
                                              "(killed, or out of memory); rerun the batch to retry it")}


def ray_failed_outcome(exc: BaseException) -> dict[str, Any]:
    """The outcome of a Ray task that failed (after its retries)."""
    out = died_outcome(MAX_CRASHES)
    out["row"]["error"] = f"Ray task failed ({type(exc).__name__}); rerun the batch to retry it"
    return out


def run_part(payload: dict[str, Any], out_dir: str | None = None) -> dict[str, Any]:
    """Plan one part; never raises for a bad part (the outcome records it).

    ``payload``: from :func:`job_payload` (``data`` holds the mesh bytes when the worker has no
    access to ``path``). With ``out_dir`` the files are written there (plan.json, exports,
    view.html, log.txt); without, they are written to a private temporary folder and returned as
    ``{"files": {name: zlib-compressed bytes}}`` (the Ray engine). The returned ``row`` is the
    summary row (see :data:`grasplan.batch.report.SUMMARY_COLUMNS`)."""
    if out_dir is not None:
        return _run_part_in(payload, Path(out_dir))
    with tempfile.TemporaryDirectory(prefix="grasplan-batch-") as tmp:
        outcome = _run_part_in(payload, Path(tmp) / "out")
        files = {}
        for p in sorted((Path(tmp) / "out").iterdir()):
            files[p.name] = zlib.compress(p.read_bytes(), 3)
        outcome["files"] = files
        return outcome


def _run_part_in(payload: dict[str, Any], out: Path) -> dict[str, Any]:
    from ..config.lookup import use_config_dirs

    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    log: list[str] = [f"part: {payload['path']}", f"sha256: {payload['sha256']}",
                      f"options_hash: {payload['options_hash']}"]
    row = _row(BatchStatus.ERROR, 1)
    local = Path(payload["path"])
    try:
        with contextlib.ExitStack() as stack:
            if payload["config_dirs"]:
                stack.enter_context(use_config_dirs(*payload["config_dirs"]))
            if payload["data"] is not None:
                tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="grasplan-part-")))
                local = tmp / Path(payload["path"]).name
                local.write_bytes(payload["data"])
            _plan_one(payload, local, out, row, log)
    except GrasplanError as exc:
        msg = str(exc).replace(str(local), payload["path"])  # name the part, not the worker's copy
        status = BatchStatus.BAD if exc.exit_code == 3 else BatchStatus.NOTHING
        row.update(status=status.value, exit_code=exc.exit_code, error=msg)
        log.append(f"error (exit {exc.exit_code}): {msg}")
    except Exception as exc:  # noqa: BLE001 - isolate the part: the batch goes on, the log keeps the traceback
        row.update(status=BatchStatus.ERROR.value, exit_code=1, error=f"internal error: {type(exc).__name__}: {exc}")
        log.append("internal error (a bug; please report it with this log):")
        log.append(traceback.format_exc())
    row["timing_s"]["total"] = time.perf_counter() - t0
    log.append(f"status: {row['status']} (exit code {row['exit_code']}), {row['timing_s']['total']:.2f} s")
    write_atomic_text(out / LOG_FILE, "\n".join(log) + "\n")
    return {"row": row}


def _plan_one(payload: dict[str, Any], local: Path, out: Path, row: dict[str, Any], log: list[str]) -> None:
    from ..part.mesh import load_part
    from ..setup.resolved import build_setup

    o = BatchOptions.from_json(payload["options"])
    refs = payload.get("refs") or {"robot": o.robot, "gripper": o.gripper, "cell": o.cell}
    t = time.perf_counter()
    part = load_part(local, units=o.units)
    load_s = time.perf_counter() - t
    if str(local) != payload["path"]:
        # the worker's copy: record the path the part was named by, as `grasplan plan` would
        part = dataclasses.replace(part, path=payload["path"],
                                   warnings=tuple(w.replace(str(local), payload["path"]) for w in part.warnings))
    log.append(f"{part.triangles} triangles ({part.units_note})")
    log += [f"warning: {w}" for w in part.warnings]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        setup = build_setup(robot=refs["robot"], gripper=refs["gripper"], cell=refs["cell"])
        result = _plan_files(o, setup, part, load_s, out, log)
    log += [f"warning: {w.message}" for w in caught]
    counts = result.counts()
    planned = int(counts[Status.PLANNED.value])
    scores = [e["score"] for e in result.planned() if e.get("score") is not None]
    timing = {"load": load_s, **{k: float(v) for k, v in result.timing_s.items()}}  # the same load_s
    row.update(planned=planned, grasps=int(counts["grasps"]), best_score=max(scores) if scores else None,
               timing_s=timing)
    log.append("counts: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    notes = []
    if o.exports:
        t = time.perf_counter()
        registry = export_formats()
        for name in o.exports:
            fmt = registry[name]
            if planned == 0 and fmt.per_grasp:
                notes.append(f"export {name}: skipped, nothing planned")
                continue
            try:
                result.export(name, out / export_file(fmt), source=PLAN_FILE)
                log.append(f"export {name}: {export_file(fmt)}")
            except GrasplanError as exc:  # e.g. urscript for a non-UR robot: the part's plan still stands
                notes.append(f"export {name} failed: {exc}")
        timing["exports"] = time.perf_counter() - t
    if o.view:
        from ..viewer.page import write_viewer

        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            write_viewer(result, out / VIEW_FILE)
        timing["view"] = time.perf_counter() - t
    log += notes
    log.append("seconds: " + ", ".join(f"{k} {v:.3f}" for k, v in timing.items()))
    if planned:
        row.update(status=BatchStatus.PLANNED.value, exit_code=0, error="; ".join(notes))
    else:
        row.update(status=BatchStatus.NOTHING.value, exit_code=4,
                   error="; ".join([f"no grasp could be planned for {o.robot} (plan.json lists every grasp's "
                                    "status and reason)", *notes]))


def _plan_files(o: BatchOptions, setup: Setup, part: Part, load_s: float, out: Path, log: list[str]) -> PlanResult:
    """Plan ``part`` with ``o`` and the ``setup``'s robot, gripper and cell, and write ``plan.json``
    (with ``pose_index="all"``: one ``plan.pose<k>.json`` per resting pose and ``plan.json`` = the
    chosen one, as ``grasplan plan`` writes them); the result ``plan.json`` holds."""
    import numpy as np

    from ..motion.planning import MIN_POSE_PROBABILITY, plan, plan_poses, planning_for_keep

    T = None if o.T_world_part is None else np.asarray(o.T_world_part, dtype=np.float64)
    kw: dict[str, Any] = dict(robot=setup.robot, gripper=setup.gripper, cell=setup.cell, candidates=o.candidates,
                              grasps=o.grasps, planning=planning_for_keep(o.planning, o.keep), T_world_part=T,
                              place=o.planning.place_matrix())
    if o.grasps.pose_index != ALL_POSES:
        result = plan(part, load_s=load_s, **kw)
        result.write(out / PLAN_FILE, keep=o.keep)
        return result
    from ..results.pose_plans import write_pose_plans

    done = write_pose_plans(plan_poses(part, load_s=load_s, **kw), out / PLAN_FILE,
                            min_probability=MIN_POSE_PROBABILITY, keep=o.keep)
    log += [f"pose {p['pose_index']} ({p['probability'] * 100:.1f} %): "
            + (f"{p['planned']} planned, {p['collision_free']} collision-free, {p['file']}" if p["file"]
               else p["error"]) for p in done.poses]
    if done.result is None:
        raise done.error(part.path)
    log.append(f"chosen: pose {done.chosen}, {done.planned} planned (plan.json)")
    return done.result
