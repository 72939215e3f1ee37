"""``grasplan batch``: plans of a whole catalogue of parts, locally or on Ray (:func:`run_batch` in :mod:`.run`)."""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "ENGINES": ".engines",
    "DONE_FILE": ".layout",
    "DONE_SCHEMA": ".layout",
    "FAILED_STATUSES": ".layout",
    "FINAL_STATUSES": ".layout",
    "LOCK_FILE": ".layout",
    "PLAN_FILE": ".layout",
    "STAGING_DIR": ".layout",
    "BatchStatus": ".layout",
    "MAX_DONE_BYTES": ".outdir",
    "check_out_dir": ".outdir",
    "clear_staging": ".outdir",
    "config_inputs": ".outdir",
    "PartJob": ".manifest",
    "discover_parts": ".manifest",
    "make_jobs": ".manifest",
    "BatchOptions": ".options",
    "BatchSummary": ".report",
    "pending_row": ".report",
    "summary_row": ".report",
    "write_summary": ".report",
    "run_batch": ".run",
})
