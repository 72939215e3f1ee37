"""Pick statuses and reason codes (:mod:`grasplan.pick.codes`): the status words are the picks
schema's, a status prints and serialises as its word, code branches on the reason code (never on
the words), and every report an instance can end with carries its code."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from grasplan.io import to_json_text
from grasplan.motion.codes import Reason
from grasplan.pick.codes import GRASP_STATUS, INSTANCE_STATUSES, LIFT_MAY_HELP, PickStatus
from grasplan.motion.grasp_motion import Outcome
from grasplan.pick.reasons import (collides_report, lift_blocked_report, no_grasp_report, not_tried_report,
                                   picked_report, unplanned_report)
from grasplan.pick.result import InstanceReport
from grasplan.piles.scene_file import Instance

SCHEMA = Path(__file__).resolve().parents[1] / "grasplan" / "schemas" / "picks.schema.json"


def _schema_statuses() -> list[str]:
    doc = json.loads(SCHEMA.read_text())
    found: list[list[str]] = []

    def walk(node: object) -> None:
        if isinstance(node, dict):
            st = node.get("properties", {}).get("status") if isinstance(node.get("properties"), dict) else None
            if isinstance(st, dict) and "enum" in st and "blocked_by" in node["properties"]:
                found.append(st["enum"])
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(doc)
    assert len(found) == 1, found
    return found[0]


def test_the_status_words_are_the_schemas_in_its_order():
    assert list(INSTANCE_STATUSES) == _schema_statuses()
    assert [s.value for s in PickStatus] == list(INSTANCE_STATUSES)


def test_a_status_prints_and_serialises_as_its_word():
    s = PickStatus.LIFT_COLLISION
    assert f"{s}" == str(s) == "lift_collision" and f"{s:>16}" == "  lift_collision"
    assert s == "lift_collision" and {"lift_collision": 1}[s] == 1 and hash(s) == hash("lift_collision")
    assert json.dumps({s: s}) == '{"lift_collision": "lift_collision"}'
    assert to_json_text([Reason.NO_IK]) == '["no_ik"]'


def test_a_report_takes_a_status_word_and_refuses_an_unknown_one():
    rep = InstanceReport("a", "box", "blocked", "why", ("b",))
    assert rep.status is PickStatus.BLOCKED
    assert rep.to_json() == {"id": "a", "part": "box", "status": "blocked", "reason": "why", "blocked_by": ["b"]}
    assert type(rep.to_json()["status"]) is str
    with pytest.raises(ValueError):
        InstanceReport("a", "box", "stuck", "why")
    # the code is beside the words: a report read back (no code) equals the planned one
    assert InstanceReport("a", "box", PickStatus.BLOCKED, "why", ("b",), code=Reason.LIFT_BLOCKED) == rep


def test_lift_may_help_follows_the_code_not_the_words():
    misleading = Outcome(Reason.LINE_NOT_FOLLOWED, "no IK solution follows the lift (words only)")
    assert misleading.code in LIFT_MAY_HELP and GRASP_STATUS[misleading.code] is PickStatus.UNREACHABLE
    no_ik = Outcome(Reason.NO_IK, "4 IK solutions: ... (words only)")
    assert no_ik.code not in LIFT_MAY_HELP and GRASP_STATUS[no_ik.code] is PickStatus.UNREACHABLE
    assert LIFT_MAY_HELP < set(GRASP_STATUS)
    assert GRASP_STATUS[Reason.PLANNED] is PickStatus.PICKED
    assert GRASP_STATUS[Reason.LIFT_GRIPPER] is GRASP_STATUS[Reason.LIFT_COLLISION]


def test_every_report_carries_its_code():
    inst = Instance("a", "box", np.eye(4))
    hits = {"instance:b": 3, "bin": 1}
    cases = [
        (no_grasp_report(inst, 10, 75.0, "egp"), PickStatus.NO_GRASP, Reason.NO_GRASP_FROM_ABOVE),
        (no_grasp_report(inst, 0, 75.0, "egp"), PickStatus.NO_GRASP, Reason.EMPTY_DATABASE),
        (lift_blocked_report(inst, "instance:b", 0.01, 0.1, None, 0.0, (0.001, 0.002), 2, 30.0, False),
         PickStatus.BLOCKED, Reason.LIFT_BLOCKED),
        (lift_blocked_report(inst, "cloud", 0.01, 0.1, None, 0.0, (0.001, 0.002), 0, 0.0, False),
         PickStatus.CLOUD, Reason.LIFT_BLOCKED),
        (picked_report(inst, 2, 9, Outcome(Reason.PLANNED, "planned"), (), 0.0, None, hits),
         PickStatus.PICKED, Reason.PLANNED),
        (unplanned_report(inst, 3, Outcome(Reason.NO_TRANSIT, "no transit"), {}), PickStatus.NO_PATH,
         Reason.NO_TRANSIT),
        (unplanned_report(inst, 3, Outcome(Reason.LIFT_COLLISION, "lift", blockers=("instance:b",)), hits),
         PickStatus.BLOCKED, Reason.LIFT_COLLISION),
        (collides_report(inst, 9, hits), PickStatus.BLOCKED, Reason.GRASPS_COLLIDE),
        (collides_report(inst, 9, {"cloud": 2, "bin": 5}), PickStatus.CLOUD, Reason.GRASPS_COLLIDE),
        (collides_report(inst, 9, {"bin": 5}), PickStatus.BIN, Reason.GRASPS_COLLIDE),
        (not_tried_report(inst, True), PickStatus.NOT_TRIED, Reason.BUDGET_SPENT),
        (not_tried_report(inst, False), PickStatus.NOT_TRIED, Reason.MAX_PICKS),
    ]
    for rep, status, code in cases:
        assert (rep.status, rep.code) == (status, code), rep
    assert cases[2][0].blocked_by == ("b",) and cases[4][0].blocked_by == ("b",)
    assert "every one of the 2 tilted lifts" in cases[2][0].reason and "tilted" not in cases[3][0].reason
    assert cases[-1][0].reason == "not tried: max_picks reached"
