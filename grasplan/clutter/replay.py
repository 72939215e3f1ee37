"""``grasplan clutter --view OUT.html``: one self-contained HTML page replaying every round.

The page has the viewer's look and rules (:mod:`grasplan.viewer`: three.js inlined, arrays as
base64 of deflated little-endian bytes, a Content-Security-Policy that forbids every request). It
lists the rounds and their picks (outcome colours, reasons, planning times); selecting a pick shows
the pile as it was before it (true poses), the target's pose as planned (a wireframe: the pose
noise), the planned pre-grasp, grasp and lifted TCP frames, and plays the simulation back: the
gripper and every part as recorded every :data:`grasplan.clutter.execute.TRACK_DT`.

Computed here, not in the browser: each part's display mesh (decimated to
:data:`MAX_PART_TRIANGLES`), poses as (x, y, z, qx, qy, qz, qw), the gripper's shapes (as the
viewer encodes them) and the cell's obstacles.
"""
from __future__ import annotations

import html
import json
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..cell.model import Cell
from ..gripper.model import Gripper
from ..io import write_atomic_text
from ..part.mesh import Part
from ..geometry.transforms import pose7
from ..viewer.page import cell_data, decimate_mesh, encode_array, mesh_block, read_asset, script_safe, shape_json
from .execute import OUTCOMES, SUCCESS
from .rounds import NO_PLAN, Attempt, RoundResult

#: a part above this many triangles is decimated for the page
MAX_PART_TRIANGLES = 20_000
#: outcome colours (the viewer's palette: green held, orange/red failures)
OUTCOME_COLORS = {SUCCESS: "#00c853", "slipped": "#fb8c00", "pushed_away": "#ab47bc", "collided": "#e53935",
                  "missed": "#1e88e5", "turned": "#fdd835", "dropped": "#8d6e63", NO_PLAN: "#9e9e9e",
                  "moved": "#26a69a", "no_effect": "#bdbdbd"}
assert set(OUTCOME_COLORS) >= {*OUTCOMES, NO_PLAN}
_HERE = Path(__file__).resolve().parent


def _p7(T: ArrayLike) -> list[float]:
    return pose7(np.asarray(T, dtype=np.float64), order="xyzw").tolist()


def _p7s(Ts: np.ndarray) -> np.ndarray:
    """(n, 4, 4) -> (n, 7) x, y, z, qx, qy, qz, qw."""
    Ts = np.asarray(Ts, dtype=np.float64).reshape(-1, 4, 4)
    return np.array([pose7(T, order="xyzw") for T in Ts]).reshape(-1, 7)


def _attempt_data(a: Attempt, replay: Mapping[str, Any] | None, names: list[str]) -> dict[str, Any]:
    d: dict[str, Any] = {"kind": a.kind, "instance": a.instance, "part": a.part, "outcome": a.outcome,
                         "reason": a.reason, "plan_ms": round(a.plan_ms, 2)}
    ex = a.execution if a.execution is not None else a.push_execution
    if ex is None or replay is None:
        return d
    track = replay["track"]
    ids = [names.index(n) for n in ex.track_parts]
    before = replay["before"]
    # a push is shown as a pick's frames: above the start, the start, the end
    frames = a.pick if a.execution is not None else {
        "T_world_pregrasp": a.push["T_world_above"], "T_world_tcp": a.push["T_world_start"],
        "T_world_lifted": a.push["T_world_end"], "opening": a.push["opening"]}
    d.update(pick={"pre": _p7(frames["T_world_pregrasp"]), "tcp": _p7(frames["T_world_tcp"]),
                   "lifted": _p7(frames["T_world_lifted"]), "opening": frames["opening"],
                   "raises": list(frames.get("lift_carries", ()))},
             seen=_p7(replay["seen"]), ids=ids, before=_p7s(np.stack([before[names[i]] for i in ids])).reshape(-1).tolist(),
             samples=len(track), pose_error_mm=round(a.pose_error_mm, 3), pose_error_deg=round(a.pose_error_deg, 3))
    if track:
        d["t"] = encode_array([s[0] for s in track], "<f4")
        d["hand"] = encode_array(_p7s(np.stack([s[1] for s in track])), "<f4")
        d["opening"] = encode_array([s[2] for s in track], "<f4")
        d["parts"] = encode_array(_p7s(np.concatenate([s[3] for s in track])), "<f4")
    return d


def build_data(rounds: Sequence[RoundResult], parts: Mapping[str, Part], gripper: Gripper, cell: Cell, *,
               total: Mapping[str, Any], title: str = "grasplan clutter") -> dict[str, Any]:
    """The page's JSON (module docstring)."""
    meshes = {}
    for name, p in parts.items():
        V, F = decimate_mesh(np.asarray(p.vertices), np.asarray(p.faces), MAX_PART_TRIANGLES)
        meshes[name] = {**mesh_block(V, F), "path": p.path, "sha256": p.sha256, "scale_to_m": float(p.scale_to_m)}
    gm: list[dict] = []
    cache: dict = {}
    f_a, f_b = gripper.fingers(0.0), gripper.fingers(float(gripper.max_opening))
    grip = {"body": [shape_json(s, cache, gm) for s in gripper.body],
            "fingers": [shape_json(s, cache, gm) for s in f_a],
            "finger_shift": [(np.asarray(b.corners()).mean(0) - np.asarray(a.corners()).mean(0)).tolist()
                             for a, b in zip(f_a, f_b)],
            "max_opening": float(gripper.max_opening), "meshes": gm, "name": gripper.name}
    notes: list[str] = []
    out_rounds = []
    for rr in rounds:
        names = [i.id for i in rr.scene.instances]
        executed = iter(rr.replay)
        attempts = [_attempt_data(a, next(executed, None) if a.execution is not None or a.push_execution is not None
                                  else None, names) for a in rr.attempts]
        ex = rr.executed
        out_rounds.append({"r": rr.r, "seed": rr.seed, "ended": rr.ended, "parts": rr.parts, "attempts": attempts,
                           "successes": rr.successes, "tried": len(ex), "ids": names,
                           "part_of": [i.part for i in rr.scene.instances],
                           "pile": _p7s(np.stack([i.T_world_part for i in rr.scene.instances])).reshape(-1).tolist()})
    return {"schema": "grasplan.clutter-view/1", "title": title, "total": dict(total), "parts": meshes,
            "gripper": grip, "cell": {"name": cell.name, "table_z": float(cell.table_z), **cell_data(cell, notes)},
            "outcomes": OUTCOME_COLORS, "rounds": out_rounds, "notes": notes}


def _asset(name: str) -> str:
    return (_HERE / name).read_text(encoding="utf-8")


def build_html(data: Mapping[str, Any]) -> str:
    """The replay page for :func:`build_data`'s JSON, as one HTML string."""
    payload = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("<", "\\u003c")
    template = _asset("replay.html")
    values = {"TITLE": html.escape(str(data["title"])), "CSS": read_asset("viewer.css") + _asset("replay.css"),
              "THREE_LICENSE": html.escape(read_asset("THREE_LICENSE")), "DATA": payload,
              "THREE": script_safe(read_asset("three.iife.min.js")), "APP": script_safe(_asset("replay.js"))}
    missing = [k for k in values if "{{" + k + "}}" not in template]
    if missing:
        raise RuntimeError(f"replay template lacks {missing}")
    return re.sub(r"\{\{([A-Z_]+)\}\}", lambda m: values[m.group(1)], template)


def write_replay(path: str | Path, rounds: Sequence[RoundResult], parts: Mapping[str, Part], gripper: Gripper, cell: Cell,
                 *, total: Mapping[str, Any], title: str = "grasplan clutter") -> Path:
    """Write the replay page atomically; returns the path."""
    return write_atomic_text(path, build_html(build_data(rounds, parts, gripper, cell, total=total, title=title)))
