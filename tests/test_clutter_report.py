"""The clutter report's totals (grasplan/clutter/report.py) from per-round documents: the 95 %
intervals cover a known rate as often as they claim, pushes stay out of GSR and the failures,
the parts left are counted by status and wall distance; and the perception's pose errors
(grasplan/clutter/perception.py) are drawn once per part and round, of exactly the size asked."""
from __future__ import annotations

import math

import numpy as np
import pytest

from grasplan.clutter.perception import apply_error, draw_errors, perturb
from grasplan.clutter.report import WALL_BINS, interval, total_json
from grasplan.geometry.transforms import pose_error


def _round(attempts, parts, removed, *, picks=(), left=(), ended="empty"):
    return {"round": 0, "seed": 0, "attempts": attempts, "successes": removed, "parts": parts, "removed": removed,
            "ended": ended, "picks": list(picks), "left": list(left), "fell_out": [], "outside": [], "seconds": 1.0,
            "cpu_s": 1.0, "freed": []}


def test_the_interval_covers_a_known_rate_about_95_times_in_100():
    """Rounds of 5 parts, each removed with probability 0.8 (DR's model): over 200 synthetic runs
    of 100 rounds, the bootstrap interval holds 0.8 in 90-99 % of them (95 % nominal)."""
    rng = np.random.default_rng(7)
    hits = 0
    for _ in range(200):
        removed = rng.binomial(5, 0.8, size=100)
        lo, hi = interval(removed, np.full(100, 5))
        hits += lo <= 0.8 <= hi
    assert 180 <= hits <= 198, hits


def test_the_interval_is_wilsons_when_rounds_agree_and_wider_when_they_cluster():
    # 15 of 15: Wilson's 95 % interval for 15 trials, [0.796, 1] (not a point at 100 %)
    lo, hi = interval(np.array([5, 5, 5]), np.array([5, 5, 5]))
    assert hi == 1.0 and lo == pytest.approx(0.7961, abs=1e-3)
    assert interval(np.array([4]), np.array([5])) is None
    assert interval(np.array([0, 0]), np.array([0, 0])) is None
    # all-or-nothing rounds: the same pooled 0.75 as 15 of 20 spread evenly, but a wider interval
    spread = interval(np.array([4, 4, 4, 3]), np.array([5, 5, 5, 5]))
    lumped = interval(np.array([5, 0, 5, 5]), np.array([5, 5, 5, 5]))
    assert spread[0] < 0.75 < spread[1] and lumped[0] < 0.75 < lumped[1]
    assert lumped[1] - lumped[0] > spread[1] - spread[0] + 0.1


def test_totals_keep_pushes_out_of_gsr_and_count_the_parts_left():
    push = {"kind": "push", "instance": "a", "plan_ms": 3.0, "cold": False, "outcome": "moved"}
    pick_ok = {"kind": "pick", "instance": "a", "plan_ms": 5.0, "cold": False, "outcome": "success"}
    pick_bad = {"kind": "pick", "instance": "b", "plan_ms": 7.0, "cold": False, "outcome": "turned"}
    left = [{"instance": "b", "part": "P", "status": "bin", "reason": "", "wall_m": 0.001, "occlusion": None},
            {"instance": "c", "part": "Q", "status": "no_grasp", "reason": "", "wall_m": 0.05, "occlusion": None}]
    r1 = _round(2, 3, 1, picks=[push, pick_ok, pick_bad], left=left, ended="two_failures")
    r1["freed"] = ["a"]
    r2 = _round(1, 3, 1, picks=[pick_ok])
    t = total_json([r1, r2])
    assert (t["attempts"], t["successes"], t["parts"], t["removed"]) == (3, 2, 6, 2)
    assert t["gsr"] == pytest.approx(2 / 3) and t["dr"] == pytest.approx(2 / 6)
    assert t["failures"]["turned"] == 1 and "moved" not in t["failures"]
    assert t["outcomes"]["success"] == 2 and t["outcomes"]["turned"] == 1
    assert t["pushes"] == {"n": 1, "outcomes": {"moved": 1}, "freed": 1}
    assert t["left"]["n"] == 2 and t["left"]["by_status"] == {"bin": 1, "no_grasp": 1}
    assert t["left"]["by_wall"][f"< {WALL_BINS[0] * 1e3:g} mm"] == 1
    assert t["left"]["by_wall"][f">= {WALL_BINS[-1] * 1e3:g} mm"] == 1
    assert t["ended"] == {"empty": 1, "two_failures": 1, "nothing_feasible": 0}
    assert t["plan_ms"]["n"] == 4


def test_pose_errors_are_drawn_once_per_part_and_have_the_size_asked():
    ids = ["a_0", "a_1", "b_0"]
    e1 = draw_errors(ids, (0.002, 2.0), np.random.default_rng([3, 1]))
    e2 = draw_errors(ids, (0.002, 2.0), np.random.default_rng([3, 1]))
    assert list(e1) == ids
    for k in ids:
        np.testing.assert_array_equal(e1[k][0], e2[k][0])
        assert np.linalg.norm(e1[k][0]) == pytest.approx(0.002)
    assert not np.allclose(e1["a_0"][0], e1["a_1"][0])
    com = np.array([0.01, -0.02, 0.005])
    T = np.eye(4)
    T[:3, 3] = [0.4, 0.1, 0.05]
    seen = apply_error(T, com, *e1["b_0"])
    assert np.linalg.norm((seen[:3, :3] @ com + seen[:3, 3]) - (T[:3, :3] @ com + T[:3, 3])) == pytest.approx(0.002)
    assert math.degrees(pose_error(T, seen)[1]) == pytest.approx(2.0)
    # perturb is one draw applied: the same generator state gives the same pose
    np.testing.assert_array_equal(perturb(T, com, 0.002, 2.0, np.random.default_rng(9)),
                                  apply_error(T, com, *draw_errors(["x"], (0.002, 2.0),
                                                                   np.random.default_rng(9))["x"]))
