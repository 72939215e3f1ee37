"""A batch's report: the summary rows (one per part, :func:`summary_row`), ``summary.csv``,
``summary.json`` and the offline ``index.html`` (:func:`write_summary`), and the progress line of
a finished part (:func:`format_row`)."""
from __future__ import annotations

import csv
import html
import io
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import quote

from ..config.params import ALL_POSES
from ..io import to_json_text, write_atomic_chunks, write_atomic_text
from .layout import FINAL_STATUSES, LOG_FILE, SUMMARY_SCHEMA, VIEW_FILE, BatchStatus
from .manifest import PartJob
from .options import BatchOptions

#: fixed summary columns; one ``s_<stage>`` column per stage timing follows, then ``error``
SUMMARY_COLUMNS = ("part", "dir", "status", "exit_code", "planned", "grasps", "best_score", "seconds", "resumed",
                   "sha256", "options_hash")


@dataclass
class BatchSummary:
    """Rows (one per part, in input order), the output folder, and the exit code."""

    out_dir: Path
    rows: list[dict[str, Any]]
    interrupted: bool = False

    @property
    def counts(self) -> dict[str, int]:
        out = {s: 0 for s in (*FINAL_STATUSES, BatchStatus.ERROR.value, BatchStatus.PENDING.value)}
        for r in self.rows:
            out[r["status"]] = out.get(r["status"], 0) + 1
        out["resumed"] = sum(1 for r in self.rows if r.get("resumed"))
        return out

    @property
    def exit_code(self) -> int:
        """0 when some part has a planned grasp, else 4."""
        return 0 if any(r["status"] == BatchStatus.PLANNED for r in self.rows) else 4


def summary_row(job: PartJob, r: dict[str, Any]) -> dict[str, Any]:
    """The summary row of ``job`` from its worker's row ``r`` (:func:`grasplan.batch.worker.run_part`)."""
    error = r["error"]
    if r["status"] == BatchStatus.NOTHING.value:
        error += other_poses_hint(job)
    return {"part": job.path, "dir": job.dir_name, "status": r["status"], "exit_code": r["exit_code"],
            "planned": r["planned"], "grasps": r["grasps"], "best_score": r["best_score"],
            "seconds": r["timing_s"].get("total"), "timing_s": r["timing_s"], "error": error,
            "resumed": False, "sha256": job.sha256, "options_hash": job.options_hash}


def other_poses_hint(job: PartJob) -> str:
    """What to try when a part planned in one resting pose has no planned grasp (as ``grasplan plan``
    says it): another pose, or every pose; ``""`` when the part's pose or a place was given or every
    pose was planned already."""
    o = job.options
    if o.T_world_part is not None or o.planning.place_matrix() is not None or o.grasps.pose_index == ALL_POSES:
        return ""
    used = o.grasps.single_pose_index()
    if used is None and job.setup is not None and job.setup.cell is not None:
        used = job.setup.cell.pose_index
    other = 1 if not used else 0
    return (f"; other resting poses may have grasps: try --pose-index {other} or --pose-index all "
            "(every pose of probability >= 2 %)")


def pending_row(job: PartJob) -> dict[str, Any]:
    """The row of a part the interrupted batch did not run."""
    return summary_row(job, {"status": BatchStatus.PENDING.value, "exit_code": None, "planned": 0, "grasps": 0,
                             "best_score": None, "timing_s": {},
                             "error": "not run (the batch was interrupted); rerun to finish"})


def _stage_names(rows: Sequence[dict[str, Any]]) -> list[str]:
    names: list[str] = []
    for r in rows:
        for k in r.get("timing_s", {}):
            if k != "total" and k not in names:
                names.append(k)
    return names


def write_summary(summary: BatchSummary, *, options: BatchOptions, engine: str) -> None:
    """``summary.csv``, ``summary.json`` and ``index.html`` in ``summary.out_dir`` (atomic writes)."""
    rows = summary.rows
    stages = _stage_names(rows)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([*SUMMARY_COLUMNS, *(f"s_{s}" for s in stages), "error"])
    for r in rows:
        vals = []
        for c in SUMMARY_COLUMNS:
            v = r.get(c)
            vals.append("" if v is None else (f"{v:.6g}" if isinstance(v, float) else str(v).lower()
                                               if isinstance(v, bool) else v))
        t = r.get("timing_s", {})
        vals += [f"{t[s]:.4f}" if s in t else "" for s in stages]
        vals.append(r.get("error", ""))
        w.writerow(vals)
    write_atomic_text(summary.out_dir / "summary.csv", buf.getvalue())
    head = {"schema": SUMMARY_SCHEMA, "engine": engine, "options": options.to_json(),
            "interrupted": summary.interrupted, "exit_code": summary.exit_code, "counts": summary.counts}
    write_atomic_chunks(summary.out_dir / "summary.json", _json_parts(head, rows))
    write_atomic_text(summary.out_dir / "index.html", index_html(summary))


def _json_parts(head: dict[str, Any], rows: Sequence[dict[str, Any]]) -> Iterator[str]:
    """The JSON text of ``{**head, "parts": rows}``: ``head`` indented, one part per line (each
    encoded on its own: the time is linear in the rows, the memory one row at a time)."""
    text = to_json_text(head, indent=1)
    yield text[:-2] + ',\n "parts": ['  # text ends with "\n}"
    for i, r in enumerate(rows):
        yield ("\n  " if i == 0 else ",\n  ") + to_json_text(r)
    yield "\n ]\n}\n" if rows else "]\n}\n"


#: index.html sorts by status in this order (planned parts first)
_STATUS_ORDER = {s.value: i for i, s in enumerate(BatchStatus)}


def index_html(summary: BatchSummary) -> str:
    """An offline page (no network request): one table row per part linking its view.html;
    columns sort on click (status by default, planned parts first)."""
    e = html.escape
    trs = []
    out_text = os.fspath(summary.out_dir)
    for r in summary.rows:
        folder = os.path.join(out_text, r["dir"])
        has_view = r["status"] != BatchStatus.PENDING and os.path.isfile(os.path.join(folder, VIEW_FILE))
        name = e(r["part"])
        link = f'<a href="{e(quote(r["dir"]))}/{VIEW_FILE}">{name}</a>' if has_view else name
        log = (f' <a class="log" href="{e(quote(r["dir"]))}/{LOG_FILE}">log</a>'
               if os.path.isfile(os.path.join(folder, LOG_FILE)) else "")
        score = "" if r["best_score"] is None else f"{r['best_score']:.3f}"
        secs = "" if r.get("seconds") is None else f"{r['seconds']:.2f}"
        trs.append(
            f'<tr class="{e(r["status"])}"><td>{link}{log}</td>'
            f'<td data-v="{_STATUS_ORDER.get(r["status"], 9)}">{e(r["status"])}</td>'
            f'<td data-v="{r["planned"]}">{r["planned"]}</td><td data-v="{r["grasps"]}">{r["grasps"]}</td>'
            f'<td data-v="{score or -1}">{score}</td><td data-v="{secs or -1}">{secs}</td>'
            f'<td>{e(r.get("error") or "")}</td></tr>')
    c = summary.counts
    head = ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in c.items() if v)
    return _INDEX_TEMPLATE.format(title=e(f"grasplan batch: {len(summary.rows)} parts"), counts=e(head),
                                  rows="\n".join(trs))


_INDEX_TEMPLATE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>
body {{ font: 14px system-ui, sans-serif; margin: 1.5em; }}
table {{ border-collapse: collapse; }}
th, td {{ padding: .25em .7em; border-bottom: 1px solid #ddd; text-align: left; }}
th {{ cursor: pointer; user-select: none; background: #f4f4f4; }} th:after {{ content: " \\2195"; color: #aaa; }}
tr.planned td:nth-child(2) {{ color: #1a7f37; }} tr.nothing_planned td:nth-child(2) {{ color: #9a6700; }}
tr.bad_input td:nth-child(2), tr.error td:nth-child(2) {{ color: #cf222e; }}
a.log {{ font-size: 85%; color: #666; }}
</style></head><body>
<h1>{title}</h1><p>{counts}</p>
<table id="parts"><thead><tr><th>part</th><th>status</th><th>planned</th><th>grasps</th><th>best score</th>
<th>seconds</th><th>error</th></tr></thead>
<tbody>
{rows}
</tbody></table>
<script>
(function () {{
  var table = document.getElementById("parts"), body = table.tBodies[0], dir = {{}};
  function key(tr, i) {{
    var td = tr.cells[i], v = td.getAttribute("data-v");
    return v === null ? td.textContent.toLowerCase() : parseFloat(v);
  }}
  function sort(i, asc) {{
    var rows = Array.prototype.slice.call(body.rows);
    rows.sort(function (a, b) {{
      var x = key(a, i), y = key(b, i);
      return (x < y ? -1 : x > y ? 1 : 0) * (asc ? 1 : -1);
    }});
    rows.forEach(function (r) {{ body.appendChild(r); }});
  }}
  Array.prototype.forEach.call(table.tHead.rows[0].cells, function (th, i) {{
    th.addEventListener("click", function () {{ dir[i] = !dir[i]; sort(i, dir[i]); }});
  }});
  sort(1, true);
}})();
</script>
</body></html>
"""


def format_row(row: dict[str, Any]) -> str:
    """One plain progress line for a finished part."""
    score = "" if row["best_score"] is None else f", best score {row['best_score']:.3f}"
    secs = "" if row.get("seconds") is None else f" in {row['seconds']:.1f} s"
    err = f": {row['error']}" if row["status"] != BatchStatus.PLANNED and row.get("error") else ""
    return f"{row['part']}: {row['status']}, {row['planned']} planned{score}{secs}{err}"
