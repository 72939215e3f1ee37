"""Compact plans: what a ``grasplan.plan/1`` file keeps of the poses the robot stage never tried.

``keep="collision_free"`` (the default, :data:`DEFAULT_KEEP`) writes

* ``grasps``: every grasp the robot stage tried (planned, unreachable, ik_collision, no_path,
  place_*) and every simulated grasp, as full objects (unchanged form);
* ``untried``: the other collision-free grasps (not_tried, not_checked) in column form
  (:func:`untried_block`): one row per grasp (id, frame, roll, status, reason, score, rank,
  quality) and one ``frames`` row per distinct contact pair (candidate, region, contacts,
  normals, width and the TCP pose at roll 0: ``T_part_tcp = T_part_tcp_roll0 @ Rx(roll)``);
* ``rejected``: the poses that collide, as counts per candidate and reason (:class:`RejectedCounts`).

``keep="all"`` writes every pose as a full object in ``grasps`` (the 0.2 form). The reader
(:mod:`grasplan.results.reader`) reads both and rebuilds one :class:`GraspTable` of the kept grasps.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from ..status import Status
from .grasp_table import GraspTable
from .json_columns import Listed, Numbers
from .quality_json import CONTACT_TYPES, HOLD_FORCE_DECIMALS, hold_force

KEEP_COLLISION_FREE = "collision_free"
KEEP_ALL = "all"
#: what a plan file keeps (``--keep``): the collision-free grasps (rejected poses as counts) or every pose
KEEP_CHOICES = (KEEP_COLLISION_FREE, KEEP_ALL)
DEFAULT_KEEP = KEEP_COLLISION_FREE
#: statuses of poses the gripper cannot take: counted per candidate in ``rejected``
REJECTED = (Status.COLLISION_PART.value, Status.COLLISION_TABLE.value, Status.COLLISION_OBSTACLE.value)
#: statuses of collision-free grasps the robot stage did not try: columns in ``untried``
UNTRIED = (Status.NOT_TRIED.value, Status.NOT_CHECKED.value)
#: decimals of lengths and rotations (as the full form's), of contact areas (m^2)
DECIMALS, AREA_DECIMALS = 10, 12


def check_keep(keep: str) -> str:
    """``keep`` if it is one of :data:`KEEP_CHOICES`, else InputError listing them."""
    if keep not in KEEP_CHOICES:
        raise InputError(f"keep: unknown value {str(keep)[:40]!r}; expected one of {', '.join(KEEP_CHOICES)}")
    return keep


@dataclass(frozen=True)
class RejectedCounts:
    """Rejected poses per candidate: ``candidate`` (K,) int64, increasing; ``counts`` (K, 3) int64,
    one column per status of :data:`REJECTED`."""

    candidate: np.ndarray
    counts: np.ndarray

    def totals(self) -> dict[str, int]:
        """Poses per rejected status."""
        return {s: int(self.counts[:, j].sum()) for j, s in enumerate(REJECTED)}

    def merged(self, other: RejectedCounts) -> RejectedCounts:
        """The sum of two counts (a loaded compact result's counts and its table's rejected rows)."""
        cand = np.concatenate([self.candidate, other.candidate])
        u, inv = np.unique(cand, return_inverse=True)
        out = np.zeros((len(u), len(REJECTED)), dtype=np.int64)
        np.add.at(out, inv.reshape(-1), np.concatenate([self.counts, other.counts]))
        return RejectedCounts(u, out)

    def to_json(self) -> dict[str, Any]:
        return {"candidate": self.candidate.tolist(), **{s: self.counts[:, j].tolist() for j, s in enumerate(REJECTED)}}

    @staticmethod
    def of_rows(table: GraspTable, rows: np.ndarray) -> RejectedCounts:
        """The rejected poses among ``rows`` of ``table``, counted per candidate and status."""
        st = table.status[rows].astype(str)
        cand = table.candidate[rows]
        u, inv = np.unique(cand, return_inverse=True)
        out = np.zeros((len(u), len(REJECTED)), dtype=np.int64)
        for j, s in enumerate(REJECTED):
            np.add.at(out[:, j], inv.reshape(-1)[st == s], 1)
        return RejectedCounts(u.astype(np.int64), out)

    @staticmethod
    def from_json(doc: Any, where: str) -> RejectedCounts:
        """The ``rejected`` block of a file; InputError naming what is malformed."""
        want = "{candidate: [int], " + ", ".join(f"{s}: [int]" for s in REJECTED) + "} of equal lengths, counts >= 0"
        try:
            cand = _ints(doc["candidate"])
            counts = np.stack([_ints(doc[s]) for s in REJECTED], axis=1) if len(cand) \
                else np.zeros((0, len(REJECTED)), dtype=np.int64)
            ok = (isinstance(doc, dict) and set(doc) == {"candidate", *REJECTED} and counts.shape[0] == len(cand)
                  and bool(np.all(counts >= 0)) and bool(np.all(cand >= 0)) and bool(np.all(np.diff(cand) > 0)))
        except (KeyError, TypeError, ValueError, OverflowError):
            ok = False
        if not ok:
            raise InputError(f"{where}: $.rejected malformed; expected {want}, candidates increasing")
        return RejectedCounts(cand, counts)


def _ints(v: Any) -> np.ndarray:
    if not isinstance(v, list) or any(isinstance(x, bool) or not isinstance(x, int) for x in v):
        raise TypeError("not a list of integers")
    return np.array(v, dtype=np.int64).reshape(len(v))


@dataclass(frozen=True)
class Split:
    """Where the rows of a table go in a file: ``grasps`` (full objects), ``untried`` (columns),
    ``rejected`` (counts)."""

    grasps: np.ndarray
    untried: np.ndarray
    rejected: np.ndarray


def split_rows(table: GraspTable, rows: np.ndarray, keep: str) -> Split:
    """``rows`` of ``table`` split by :func:`check_keep`-ed ``keep``: all in ``grasps`` for
    :data:`KEEP_ALL`; else rejected poses counted, untried unsimulated grasps in columns."""
    none = np.zeros(0, dtype=np.int64)
    if check_keep(keep) == KEEP_ALL:
        return Split(rows, none, none)
    st = table.status[rows].astype(str)
    rej = np.isin(st, REJECTED)
    untried = np.isin(st, UNTRIED)
    if table.sim_success is not None:
        untried &= table.sim_success[rows] < 0
    return Split(rows[~rej & ~untried], rows[untried], rows[rej])


def _rx(roll: np.ndarray) -> np.ndarray:
    """(n, 4, 4) rotations about x by ``roll`` (rad)."""
    c, s = np.cos(roll), np.sin(roll)
    R = np.zeros((len(roll), 4, 4))
    R[:, 0, 0] = R[:, 3, 3] = 1.0
    R[:, 1, 1], R[:, 1, 2], R[:, 2, 1], R[:, 2, 2] = c, -s, s, c
    return R


def _codes(values: np.ndarray) -> tuple[list[str], np.ndarray]:
    """``(names, code per value)``: the distinct ``str(value)`` sorted, and each value's index among
    them (``np.unique(..., return_inverse=True)`` without sorting every string)."""
    texts = [str(v) for v in values.tolist()]
    names = sorted(set(texts))
    index = {n: i for i, n in enumerate(names)}
    return names, np.fromiter((index[t] for t in texts), dtype=np.int64, count=len(texts))


def _listed(a: np.ndarray, decimals: int | None = None, null: np.ndarray | None = None) -> Listed:
    """The rows of ``a`` as a list (rounded to ``decimals``; ``null``: the rows written null)."""
    mask = None if null is None else (lambda rows, m=np.asarray(null, dtype=bool): m[rows])
    return Listed(Numbers(np.asarray(a), decimals=decimals, null=mask), len(a))


def untried_block(table: GraspTable, rows: np.ndarray, grip_force: float) -> dict[str, Any]:
    """The ``untried`` block: ``rows`` of ``table`` in column form (module docstring), its lists
    as :class:`~grasplan.results.json_columns.Listed` columns
    (:func:`~grasplan.results.json_columns.block_values`: as lists;
    :func:`~grasplan.results.json_columns.block_text`: its JSON text); ``grip_force`` (N) gives
    each grasp's ``hold_force_N``."""
    r = np.asarray(rows, dtype=np.int64)
    T0 = table.T_part_tcp[r] @ _rx(-table.roll[r]) if len(r) else np.zeros((0, 4, 4))
    key = np.concatenate([table.candidate[r, None].astype(np.float64), table.region[r, None].astype(np.float64),
                          np.round(table.contacts[r].reshape(-1, 6), DECIMALS),
                          np.round(table.normals[r].reshape(-1, 6), DECIMALS),
                          np.round(table.width[r, None], DECIMALS),
                          np.round(T0[:, :3].reshape(-1, 12), DECIMALS) + 0.0], 1)  # + 0.0: no -0.0 from the product
    frames, first, frame = np.unique(key, axis=0, return_index=True, return_inverse=True) if len(r) \
        else (key, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
    f = r[first]
    T0f = np.round(T0[first], DECIMALS) + 0.0
    T0f[:, 3] = (0.0, 0.0, 0.0, 1.0)
    status_names, status = _codes(table.status[r])
    reason_names, reason = _codes(table.reason[r])
    out: dict[str, Any] = {
        "frames": {"candidate": _listed(table.candidate[f]), "region": _listed(table.region[f]),
                   "contacts": _listed(table.contacts[f], DECIMALS), "normals": _listed(table.normals[f], DECIMALS),
                   "width": _listed(table.width[f], DECIMALS), "T_part_tcp_roll0": _listed(T0f)},
        "id": _listed(table.ids[r]), "frame": _listed(frame.reshape(-1)),
        "roll": _listed(table.roll[r], DECIMALS),
        "statuses": status_names, "status": _listed(status), "reasons": reason_names, "reason": _listed(reason),
        "score": _listed(table.score[r], null=np.isnan(table.score[r])),
        "rank": _listed(table.rank[r], null=table.rank[r] < 0),
    }
    gm, eps, area, kind = table.gravity_margin, table.epsilon, table.contact_area, table.contact_type
    if gm is not None and eps is not None and area is not None and kind is not None:
        none = ~np.isfinite(gm[r])
        hold = hold_force(gm[r], grip_force)
        out["quality"] = {"gravity_margin": _listed(gm[r], null=none),
                          "hold_force_N": _listed(hold, HOLD_FORCE_DECIMALS, null=np.isnan(hold)),
                          "epsilon": _listed(eps[r], null=none),
                          "area_m2": _listed(area[r], AREA_DECIMALS, null=none),
                          "type": _listed(kind[r].astype(np.int64), null=none), "types": list(CONTACT_TYPES)}
    return out


def _column(doc: dict[str, Any], key: str, shape: tuple[int, ...], where: str, *, dtype: Any = np.float64,
            null: bool = False, n: int | None = None) -> np.ndarray:
    """``doc[key]``: a list of ``n`` numbers of ``shape`` each (``null``: a row may be null: NaN),
    finite; InputError naming ``$.untried.key`` and what would pass."""
    v = doc.get(key)
    ok = isinstance(v, list) and (n is None or len(v) == n)
    a = np.zeros(0)
    if ok:
        assert isinstance(v, list)
        try:
            rows = [np.full(shape, np.nan) if (null and x is None) else x for x in v]
            if any(isinstance(x, bool) for x in np.asarray(rows, dtype=object).ravel()):
                raise TypeError("booleans are not numbers")
            a = np.array(rows, dtype=np.float64).reshape(len(v), *shape) if v else np.zeros((0, *shape))
            nulls = np.array([x is None for x in v], dtype=bool)
            ok = bool(np.all(np.isfinite(a[~nulls]))) and (dtype is np.float64 or bool(np.all(a[~nulls] == np.round(a[~nulls]))))
        except (TypeError, ValueError, OverflowError):
            ok = False
    if not ok:
        count = f"{n} " if n is not None else ""
        raise InputError(f"{where}: $.untried.{key} malformed; expected a list of {count}finite "
                         f"{'integers' if dtype is not np.float64 else 'numbers'}{' of shape ' + str(shape) if shape else ''}"
                         f"{' (or null)' if null else ''}")
    return a


def _names(doc: dict[str, Any], key: str, allowed: tuple[str, ...] | None, where: str) -> list[str]:
    v = doc.get(key)
    if not isinstance(v, list) or not all(isinstance(x, str) for x in v) or (allowed and not set(v) <= set(allowed)):
        raise InputError(f"{where}: $.untried.{key} malformed; expected a list of "
                         + (f"names among {', '.join(allowed)}" if allowed else "strings"))
    return list(v)


def _index(doc: dict[str, Any], key: str, size: int, n: int, where: str) -> np.ndarray:
    a = _column(doc, key, (), where, dtype=np.int64, n=n).astype(np.int64)
    if len(a) and (a.min() < 0 or a.max() >= size):
        raise InputError(f"{where}: $.untried.{key} indexes beyond its {size} entries")
    return a


UNTRIED_KEYS = {"frames", "id", "frame", "roll", "statuses", "status", "reasons", "reason", "score", "rank", "quality"}
FRAME_KEYS = {"candidate", "region", "contacts", "normals", "width", "T_part_tcp_roll0"}


def untried_from_json(doc: Any, where: str) -> GraspTable:
    """The grasps of an ``untried`` block (:func:`untried_block`), checked in full: every column of
    the same length, finite numbers, frame / status / reason indices in range, statuses among
    :data:`UNTRIED`, rigid roll-0 poses. InputError naming the column and what would pass."""
    from ..geometry.transforms import check_transform

    if not isinstance(doc, dict) or not isinstance(doc.get("frames"), dict) or set(doc) - UNTRIED_KEYS \
            or set(doc["frames"]) != FRAME_KEYS:
        raise InputError(f"{where}: $.untried malformed; expected an object with keys {', '.join(sorted(UNTRIED_KEYS))} "
                         f"and frames {{{', '.join(sorted(FRAME_KEYS))}}}")
    fr = doc["frames"]
    nf = len(fr["candidate"]) if isinstance(fr["candidate"], list) else -1
    cand = _column(fr, "candidate", (), where + " frames", dtype=np.int64, n=nf).astype(np.int64)
    region = _column(fr, "region", (), where + " frames", dtype=np.int64, n=nf).astype(np.int64)
    contacts = _column(fr, "contacts", (2, 3), where + " frames", n=nf)
    normals = _column(fr, "normals", (2, 3), where + " frames", n=nf)
    width = _column(fr, "width", (), where + " frames", n=nf)
    T0 = _column(fr, "T_part_tcp_roll0", (4, 4), where + " frames", n=nf)
    if nf:
        check_transform(T0, f"{where}: $.untried.frames.T_part_tcp_roll0", batch=True)
    ids = _column(doc, "id", (), where, dtype=np.int64)
    n = len(ids)
    frame = _index(doc, "frame", nf, n, where)
    roll = _column(doc, "roll", (), where, n=n)
    statuses = _names(doc, "statuses", UNTRIED, where)
    reasons = _names(doc, "reasons", None, where)
    status = np.array(statuses, dtype=object)[_index(doc, "status", len(statuses), n, where)] if n \
        else np.zeros(0, dtype=object)
    reason = np.array(reasons, dtype=object)[_index(doc, "reason", len(reasons), n, where)] if n \
        else np.zeros(0, dtype=object)
    rank = _column(doc, "rank", (), where, null=True, n=n)
    quality = _quality(doc.get("quality"), n, where) if "quality" in doc else {}
    return GraspTable(candidate=cand[frame], region=region[frame], contacts=contacts[frame], normals=normals[frame],
                      width=width[frame], T_part_tcp=T0[frame] @ _rx(roll), roll=roll, status=status,
                      score=_column(doc, "score", (), where, null=True, n=n),
                      rank=np.where(np.isnan(rank), -1, rank).astype(np.int64), reason=reason,
                      id_values=ids.astype(np.int64), **quality)


def _quality(q: Any, n: int, where: str) -> dict[str, np.ndarray]:
    keys = {"gravity_margin", "epsilon", "area_m2", "type", "types"}
    if not isinstance(q, dict) or not keys <= set(q) <= keys | {"hold_force_N"} or q.get("types") != list(CONTACT_TYPES):
        raise InputError(f"{where}: $.untried.quality malformed; expected {{{', '.join(sorted(keys))}}} with "
                         f"types {list(CONTACT_TYPES)}")
    w = where + " quality"
    gm = _column(q, "gravity_margin", (), w, null=True, n=n)
    eps = _column(q, "epsilon", (), w, null=True, n=n)
    area = _column(q, "area_m2", (2,), w, null=True, n=n)
    kind = _column(q, "type", (2,), w, null=True, n=n)
    none = np.isnan(gm)
    if np.any(np.isnan(eps) != none) or np.any(np.isnan(area[:, 0]) != none) or np.any(np.isnan(kind[:, 0]) != none):
        raise InputError(f"{where}: $.untried.quality: a grasp has some quality columns null and others not")
    hold = _column(q, "hold_force_N", (), w, null=True, n=n) if "hold_force_N" in q else np.zeros(n)
    bad = (gm[~none] < 0).any() or (eps[~none] < 0).any() or (area[~none] < 0).any() or (hold[~np.isnan(hold)] < 0).any() \
        or (kind[~none] < 0).any() or (kind[~none] >= len(CONTACT_TYPES)).any() or (kind[~none] != np.round(kind[~none])).any()
    if bad:
        raise InputError(f"{where}: $.untried.quality: gravity_margin, hold_force_N, epsilon and area_m2 must be >= 0 "
                         f"and type an index into types")
    return {"gravity_margin": gm, "epsilon": eps, "contact_area": area,
            "contact_type": np.where(np.isnan(kind), -1, kind).astype(np.int8)}
