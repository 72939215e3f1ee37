"""grasplan.results.json_columns: one field definition gives the Python values and the JSON text of every row.

The expected rows are built here by plain per-row Python (rounding, nulls, presence, names), then
compared with ``Record.values`` and, through ``json.dumps``, with the streamed text of
``join_rows(Record.pieces(...))``; the result files' own byte identity is tests/test_result_json.py.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from grasplan.results.json_columns import (
    Bools, Field, Items, Names, Numbers, Record, Spread, Strings, join_rows, number_texts
)

NAMES = ("point", "line", "surface")


class Obj:
    def __init__(self, d):
        self.d = d

    def to_json(self):
        return dict(self.d)


def table(M: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    T = rng.normal(size=(M, 2, 3))
    T[0, 0, 0] = -0.0
    T[1, 0, 0] = 1e-12            # rounds to 0.0 at 10 decimals
    T[2, 1, 2] = 0.012345678912345
    score = rng.random(M)
    score[rng.random(M) < 0.3] = np.nan
    gm = rng.random(M) * 3
    gm[rng.random(M) < 0.4] = np.nan
    return {
        "id": np.arange(M, dtype=np.int64) * 3,
        "T": T,
        "score": score,
        "rank": np.where(rng.random(M) < 0.5, -1, rng.integers(0, 50, M)).astype(np.int64),
        "status": np.array(rng.choice(["ok", "no_path", 'quote " \\ \u00e9'], M), dtype=object),
        "gm": gm,
        "kind": rng.integers(-1, 3, (M, 2)).astype(np.int8),
        "area": rng.random((M, 2)) * 1e-4,
        "succ": rng.integers(-1, 2, M).astype(np.int8),
        "slip": rng.random(M),
        "motions": {int(i): Obj({"path": [[float(i), 0.5]], "k": int(i)}) for i in range(0, M, 7)},
    }


def record(t: dict, motions: bool = True) -> Record:
    score = Numbers(t["score"], null=lambda r: np.isnan(t["score"][r]))
    jaw = lambda j: Record((Field("area_m2", Numbers(t["area"][:, j], decimals=12)),  # noqa: E731
                            Field("type", Names(t["kind"][:, j], NAMES))))
    fields = [
        Field("id", Numbers(t["id"])),
        Field("T", Numbers(t["T"], decimals=10)),
        Field("status", Strings(t["status"])),
        Field("score", score, present=lambda r: ~np.isnan(t["score"][r])),
        Field("quality", Record((Field("score", score), Field("gm", Numbers(t["gm"])),
                                 Field("contact", Items((jaw(0), jaw(1))))),
                                null=lambda r: ~np.isfinite(t["gm"][r]))),
        Field("sim", Record((Field("success", Bools(t["succ"])), Field("slip_m", Numbers(t["slip"])))),
              present=lambda r: t["succ"][r] >= 0),
        Field("rank", Numbers(t["rank"], null=lambda r: t["rank"][r] < 0)),
    ]
    if motions:
        spread = Spread(t["motions"])
        fields.append(Field(None, spread, present=spread.has))
    return Record(tuple(fields))


def expected(t: dict, rows, motions: bool = True) -> list:
    """The rows as dicts, written out per row without json_columns."""
    out = []
    for i in rows:
        sc = float(t["score"][i])
        e = {"id": int(t["id"][i]), "T": np.round(t["T"][i], 10).tolist(), "status": t["status"][i]}
        if not math.isnan(sc):
            e["score"] = sc
        e["quality"] = None if not math.isfinite(t["gm"][i]) else {
            "score": None if math.isnan(sc) else sc, "gm": float(t["gm"][i]),
            "contact": [{"area_m2": round(float(t["area"][i, j]), 12), "type": NAMES[int(t["kind"][i, j])]}
                        for j in range(2)]}
        if t["succ"][i] >= 0:
            e["sim"] = {"success": bool(t["succ"][i]), "slip_m": float(t["slip"][i])}
        e["rank"] = None if t["rank"][i] < 0 else int(t["rank"][i])
        if motions and int(i) in t["motions"]:
            e.update(t["motions"][int(i)].to_json())
        out.append(e)
    return out


@pytest.mark.parametrize("motions", [True, False])
def test_values_and_text_match_per_row_json(motions):
    t = table(300)
    rec = record(t, motions)
    for rows in (np.arange(300), np.array([5, 2, 2, 299, 0]), np.flatnonzero(t["succ"] >= 0), np.zeros(0, dtype=np.int64)):
        want = expected(t, rows.tolist(), motions)
        got = rec.values(rows)
        assert got == want
        # key order too (the text depends on it)
        assert [list(d) for d in got] == [list(d) for d in want]
        assert rec.encodable(rows)
        text = join_rows(rec.pieces(rows), len(rows)) if len(rows) else ""
        assert text == ", ".join(json.dumps(d, allow_nan=False) for d in want)


def test_signed_zero_and_rounding_are_written_as_json_writes_them():
    t = table(5)
    text = join_rows(record(t).pieces(np.arange(3)), 3)
    rows = json.loads("[" + text + "]")
    assert '"T": [[-0.0, ' in text and rows[1]["T"][0][0] == 0.0 and rows[2]["T"][1][2] == 0.0123456789
    assert number_texts(np.array([0.1, -0.0, 1e-300, 3])).tolist() == ["0.1", "-0.0", "1e-300", "3.0"]
    assert number_texts(np.array([[7, -2]], dtype=np.int64)).tolist() == [["7", "-2"]]


def test_non_finite_values_are_encodable_only_where_never_written():
    t = table(40)
    rec = record(t)
    written = np.flatnonzero(np.isfinite(t["score"]))
    t["gm"][~np.isfinite(t["gm"])] = np.inf      # not finite: a null quality, nothing non-finite written
    t["slip"][t["succ"] < 0] = np.inf            # only on rows without sim
    assert rec.encodable(np.arange(40))
    json.dumps(rec.values(np.arange(40)), allow_nan=False)
    t["score"][written[0]] = np.inf              # a written score
    assert not rec.encodable(np.arange(40))
    assert rec.encodable(np.delete(np.arange(40), written[0]))
    with pytest.raises(ValueError, match="JSON compliant"):
        json.dumps(rec.values(np.arange(40)), allow_nan=False)


def test_out_of_range_codes_and_unsortable_strings_are_not_encodable():
    t = table(20)
    has_q = np.flatnonzero(np.isfinite(t["gm"]))
    no_q = np.flatnonzero(~np.isfinite(t["gm"]))
    t["kind"][no_q[0], 0] = 9                    # on a null quality: never written, text still safe
    assert record(t).encodable(np.arange(20))
    assert join_rows(record(t).pieces(no_q[:1]), 1).count('"quality": null') == 1
    t["kind"][has_q[0], 1] = 9
    assert not record(t).encodable(np.arange(20))
    mixed = Strings(np.array(["a", None, "b"], dtype=object))
    assert not mixed.encodable(np.arange(3)) and mixed.encodable(np.array([0, 2]))
    assert not Strings(np.array([{1}, {2}], dtype=object)).encodable(np.arange(2))


def test_record_needs_a_first_key_on_every_row():
    n = Numbers(np.arange(3))
    with pytest.raises(ValueError, match="first field"):
        Record((Field("a", n, present=lambda r: r > 0), Field("b", n)))
    with pytest.raises(ValueError, match="first field"):
        Record((Field(None, Spread({})),))
    with pytest.raises(ValueError, match="present="):
        Record((Field("a", n), Field(None, Spread({}))))


@pytest.mark.parametrize("seed", range(5))
def test_a_block_is_written_as_json_writes_its_values(seed):
    """A block of listed columns (numbers of any row shape, rounded, null where a test says, names,
    plain values, nested blocks, zero rows): ``block_text`` is ``json.dumps(block_values(...))``
    byte for byte, and a column json refuses (NaN where it is written) raises json's error."""
    from grasplan.results.json_columns import Listed, block_text, block_values

    rng = np.random.default_rng(seed)
    M = int(rng.integers(0, 40))
    t = table(max(M, 3), seed)
    area = t["area"][:M]
    null = rng.random(M) < 0.3
    T = np.round(t["T"][:M], 10)
    block = {
        "frames": {"T": Listed(Numbers(t["T"][:M], decimals=10), M), "id": Listed(Numbers(t["id"][:M]), M),
                   "empty": Listed(Numbers(np.zeros((0, 3))), 0)},
        "names": ["a", 'b "c"'],
        "area": Listed(Numbers(area, decimals=12, null=lambda rows: null[rows]), M),
        "score": Listed(Numbers(t["score"][:M], null=lambda rows: np.isnan(t["score"][:M][rows])), M),
        "rank": Listed(Numbers(t["rank"][:M], null=lambda rows: t["rank"][:M][rows] < 0), M),
        "count": M, "none": None,
    }
    values = block_values(block)
    assert block_text(block) == json.dumps(values, allow_nan=False)
    assert values["frames"]["T"] == T.tolist() and values["names"] == ["a", 'b "c"']
    assert [v is None for v in values["area"]] == null.tolist()
    if M:
        bad = {"x": Listed(Numbers(np.where(null | (np.arange(M) == 0), np.nan, t["gm"][:M])), M)}
        with pytest.raises(ValueError):
            block_text(bad)
