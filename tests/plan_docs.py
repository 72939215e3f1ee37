"""An independent reading of a plan document's two forms (``keep`` collision_free or all) for
tests: the grasps as full dicts, written here from the schema's description rather than with
grasplan's reader, so each checks the other."""
from __future__ import annotations

import numpy as np

REJECTED = ("collision_part", "collision_table", "collision_obstacle")


def rx(roll: float) -> np.ndarray:
    c, s = np.cos(roll), np.sin(roll)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def kept_grasps(doc: dict) -> list[dict]:
    """Every grasp the document lists, as full dicts ordered by id: ``grasps`` plus the rows of a
    compact plan's ``untried`` columns (T_part_tcp = frames.T_part_tcp_roll0[frame] @ Rx(roll))."""
    out = list(doc["grasps"])
    u = doc.get("untried")
    if u is not None:
        fr = u["frames"]
        q = u.get("quality")
        for k, gid in enumerate(u["id"]):
            f = u["frame"][k]
            g = {"id": gid, "candidate": fr["candidate"][f], "region": fr["region"][f],
                 "contacts": fr["contacts"][f], "normals": fr["normals"][f], "width": fr["width"][f],
                 "T_part_tcp": (np.array(fr["T_part_tcp_roll0"][f]) @ rx(u["roll"][k])).tolist(),
                 "roll": u["roll"][k], "status": u["statuses"][u["status"][k]], "score": u["score"][k],
                 "rank": u["rank"][k], "reason": u["reasons"][u["reason"][k]]}
            if q is not None:
                g["quality"] = None if q["gravity_margin"][k] is None else {
                    "score": u["score"][k], "gravity_margin": q["gravity_margin"][k], "epsilon": q["epsilon"][k],
                    "contact": [{"area_m2": a, "type": q["types"][t]} for a, t in zip(q["area_m2"][k], q["type"][k])]}
                if g["quality"] is not None and "hold_force_N" in q:
                    g["quality"]["hold_force_N"] = q["hold_force_N"][k]
            out.append(g)
    return sorted(out, key=lambda g: g["id"])


def status_counts(doc: dict, statuses) -> dict[str, int]:
    """Grasps per status: the listed ones plus a compact plan's rejected counts."""
    rows = kept_grasps(doc)
    counts = {s: sum(g["status"] == s for g in rows) for s in statuses}
    rej = doc.get("rejected")
    if rej is not None:
        for s in REJECTED:
            counts[s] = counts.get(s, 0) + sum(rej[s])
    return counts
