"""The streamed result writer (PlanResult.write -> grasplan.results.writer.stream_document) writes exactly
the bytes of the reference path: the document dict (PlanResult.to_json) encoded by json.dumps
(grasplan.io.write_json). Checked on a grasps result (also --only-ok), a plan, a plan with a place
and a plan with quality + simulation; edge cases (NaN / None, -0.0, empty tables, values json
refuses) are checked on edited copies of those results."""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from grasplan.io import to_json_text
from grasplan.config.params import PlanParams
from grasplan.results.reader import load_result
from grasplan.results.writer import stream_document as _stream_document

BRACKET = Path(__file__).resolve().parents[1] / "examples" / "parts" / "bracket.stl"


def reference_bytes(res, **kw) -> bytes:
    return to_json_text(res.to_json(**kw)).encode("utf-8")


def fast_bytes(res, tmp_path, name="out.json", **kw) -> bytes:
    assert _stream_document(res, **kw) is not None, "the streamed path must be the one under test"
    out = tmp_path / name
    res.write(out, **kw)
    return out.read_bytes()


@pytest.fixture(scope="module")
def part():
    from grasplan.part.mesh import load_part

    return load_part(BRACKET, units="mm")


@pytest.fixture(scope="module")
def grasps_result(part):
    from grasplan.grasps.pipeline import compute_grasps

    return compute_grasps(part).to_result()


@pytest.fixture(scope="module")
def plan_result(part):
    from grasplan import plan

    return plan(part, "ur5", planning=PlanParams(top=3, grasp_db="off"))  # every pose in the table


def test_grasps_file_bytes_identical(grasps_result, tmp_path):
    res = grasps_result
    st = res.grasps.status.astype(str)
    assert (st == "ok").any() and (st != "ok").any()  # both score present and absent
    assert res.grasps.gravity_margin is not None  # quality objects and nulls
    assert fast_bytes(res, tmp_path) == reference_bytes(res)
    assert fast_bytes(res, tmp_path, only_ok=True) == reference_bytes(res, only_ok=True)


@pytest.mark.parametrize("keep", ["collision_free", "all"])
def test_plan_bytes_identical_and_round_trip(plan_result, tmp_path, keep):
    res = plan_result
    assert res.motions
    got = fast_bytes(res, tmp_path, keep=keep)
    assert got == reference_bytes(res, keep=keep)
    # a loaded plan writes the same bytes again, through both paths (a compact one keeps its form)
    back = load_result(tmp_path / "out.json")
    assert fast_bytes(back, tmp_path, "again.json", keep=keep) == got == reference_bytes(back, keep=keep)
    if keep == "collision_free":
        assert fast_bytes(back, tmp_path, "again_all.json", keep="all") == got  # its rejected poses are counts


def test_plan_with_place_bytes_identical(part, plan_result, tmp_path):
    from grasplan import plan

    T = np.array(plan_result.T_world_part, dtype=np.float64)
    T[1, 3] += 0.3
    res = plan(part, "ur5", planning=PlanParams(top=2), place=T)
    m = next(iter(res.motions.values()), None)
    if m is None or m.T_world_part_place is None:
        pytest.skip("no grasp of the bracket could be placed 0.3 m along y with the default cell")
    assert fast_bytes(res, tmp_path) == reference_bytes(res)


def test_plan_with_quality_and_sim_bytes_identical(part, tmp_path):
    pytest.importorskip("mujoco")
    from grasplan import plan

    res = plan(part, "ur5", planning=PlanParams(top=2, simulate=1))
    assert res.grasps.sim_success is not None and (res.grasps.sim_success >= 0).any()
    assert res.grasps.gravity_margin is not None
    assert fast_bytes(res, tmp_path) == reference_bytes(res)
    assert '"sim": {"success": ' in (tmp_path / "out.json").read_text()


def test_edge_values(plan_result, tmp_path):
    t = plan_result.grasps
    score = t.score.copy()
    score[: len(score) // 2] = np.nan
    T = t.T_part_tcp.copy()
    T[:, 3, :3] = -0.0  # written "-0.0", not "0.0"
    width = t.width.copy()
    width[0] = 1e-12  # rounds to 0.0
    width[1] = 0.012345678912345  # rounded to 1e-10
    reason = t.reason.copy()
    reason[0] = 'quote " backslash \\ non-ascii \u00e9 \n'
    res = replace(plan_result, grasps=replace(t, score=score, T_part_tcp=T, width=width, reason=reason))
    got = fast_bytes(res, tmp_path, keep="all")
    assert got == reference_bytes(res, keep="all")
    doc = json.loads(got)
    assert doc["grasps"][0]["T_part_tcp"][3][0] == 0.0 and '"T_part_tcp": [[' in got.decode()
    assert doc["grasps"][0]["score"] is None and doc["grasps"][0]["reason"] == reason[0]


def test_extra_keys_follow_grasps(plan_result, tmp_path):
    out = tmp_path / "x.json"
    plan_result.write(out, extra={"poses": {"chosen": 0}})
    doc = plan_result.to_json()
    doc["poses"] = {"chosen": 0}
    assert out.read_bytes() == to_json_text(doc).encode()


def test_empty_table(grasps_result, tmp_path):
    t = grasps_result.grasps
    none = np.zeros(0, dtype=np.int64)
    sub = {f: (getattr(t, f)[none] if getattr(t, f) is not None else None)
           for f in t.__dataclass_fields__ if f != "id_values"}
    res = replace(grasps_result, grasps=replace(t, **sub))
    got = fast_bytes(res, tmp_path)
    assert got == reference_bytes(res) and got.endswith(b'"grasps": []}')


def test_values_json_refuses_take_the_reference_path(plan_result, tmp_path):
    t = plan_result.grasps
    width = t.width.copy()
    width[-1] = np.nan
    res = replace(plan_result, grasps=replace(t, width=width))
    assert _stream_document(res, keep="all") is None
    with pytest.raises(ValueError, match="JSON compliant"):
        reference_bytes(res, keep="all")
    out = tmp_path / "bad.json"
    out.write_text("previous")
    with pytest.raises(ValueError, match="JSON compliant"):
        res.write(out, keep="all")
    assert out.read_text() == "previous" and list(tmp_path.iterdir()) == [out]


def test_streamed_in_chunks(plan_result, tmp_path, monkeypatch):
    import grasplan.results.writer as gr

    monkeypatch.setattr(gr, "WRITE_CHUNK", 7)
    chunks = list(_stream_document(plan_result, keep="all"))
    assert len(chunks) >= 2 + len(plan_result.grasps) // 7
    assert "".join(chunks).encode() == reference_bytes(plan_result, keep="all")


def test_indent_uses_the_dict(plan_result, tmp_path):
    out = tmp_path / "i.json"
    plan_result.write(out, indent=1)
    assert out.read_text() == to_json_text(plan_result.to_json(), indent=1)
