"""What a batch writes and how it names a part's outcome: the part statuses, the file names in
``OUTDIR`` and in each part's folder, and the schemas of the batch's JSON files."""
from __future__ import annotations

import enum

SUMMARY_SCHEMA = "grasplan.batch-summary/1"
DONE_SCHEMA = "grasplan.batch-done/1"
OPTIONS_SCHEMA = "grasplan.batch-options/1"


class BatchStatus(str, enum.Enum):
    """A part's outcome in a batch (``summary.csv``'s ``status``): ``planned`` (some grasp
    planned), ``nothing_planned`` (the pipeline ran, exit 4), ``bad_input`` (exit 3): final, a rerun
    skips them; ``error`` (an internal error or a worker that died): retried; ``pending``: not run
    (the batch was interrupted). Rows hold the ``.value`` strings."""

    PLANNED = "planned"
    NOTHING = "nothing_planned"
    BAD = "bad_input"
    ERROR = "error"
    PENDING = "pending"


#: statuses a rerun skips (``error`` and ``pending`` are run again)
FINAL_STATUSES: tuple[str, ...] = (BatchStatus.PLANNED.value, BatchStatus.NOTHING.value, BatchStatus.BAD.value)
#: statuses that count as failed parts in the progress report
FAILED_STATUSES: tuple[str, ...] = (BatchStatus.BAD.value, BatchStatus.ERROR.value)
#: file names inside a part's folder
PLAN_FILE, VIEW_FILE, LOG_FILE, DONE_FILE = "plan.json", "view.html", "log.txt", "done.json"
#: in OUTDIR: where parts are produced before their one rename, and the lock of a running batch
STAGING_DIR, LOCK_FILE = ".staging", ".grasplan-batch.lock"
#: a part that was in flight when a worker process died this many times is recorded as ``error``
MAX_CRASHES = 2
