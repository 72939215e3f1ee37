"""Every export format emits the whole pick(-and-place) sequence of a plan (issue 12, item 5).

Plans:
- a synthetic ``grasplan.plan/1`` document (UR5 of example-robot-data, Pinocchio FK and a small
  damped-least-squares IK written here): transit, approach, lift 0.10 m up, transfer, descent to a
  place 0.25 m away, release, retreat along the TCP -z; and the same without the place;
- a real pick-and-place plan of examples/parts/bracket.stl (mm) from ``grasplan.plan`` when the
  planner plans one (skipped with the reason otherwise).

Each output is parsed back (URScript by regular expressions, KRL/RAPID by the strict parsers of
test_export_programs, the joint trajectory and CSV as data) and checked against the plan: the
segments in order, exactly one close (and with a place one open) at the right waypoint, and the
joint values / TCP poses equal the path at the waypoints. An old pick-only plan exports as before.
"""
from __future__ import annotations

import copy
import csv
import io
import json
import re

import numpy as np
import pytest
import yaml
from test_export import (
    MOVEJ,
    MOVEL,
    PLANNED_IDS,
    T_FLANGE_TCP,
    RecordingScene,
    entry,
    fk_tool,
    floats,
    ik_tool,
    mini_ur5,
    pose_to_T,
    rot_angle,
    synthetic_plan,
    trans,
)
from test_export_programs import (
    controller_limits_deg,
    krl_pose,
    parse_krl,
    parse_rapid,
    rapid_pose,
    to_rad,
)

from grasplan.errors import InputError
from grasplan.export import render
from grasplan.export.trajectory import joint_trajectory
from grasplan.results.reader import load_result

pin = pytest.importorskip("pinocchio")

LIFT = 0.10          #: m, the contract's default retreat distance (world +z)
PLACE_SHIFT = (0.0, -0.25, 0.0)  #: m, the place = the part's pose shifted in the world
BACKOFF = 0.05       #: m, the plan's default back-off (retreat after release along the TCP -z)
#: the controller base of the UR arms: base_link rotated 180 deg about z (hard-coded here)
UR_BASE = np.diag([-1.0, -1.0, 1.0, 1.0])


# ------------------------------------------------------------------------------- synthetic plans
def _line(robot, T_from, T_to, q0, steps=5) -> list[np.ndarray]:
    """Joint samples (after q0) of a straight TCP line T_from -> T_to (same rotation), by IK."""
    out, q = [], q0
    for s in np.linspace(0, 1, steps + 1)[1:]:
        T = T_from.copy()
        T[:3, 3] = (1 - s) * T_from[:3, 3] + s * T_to[:3, 3]
        q = ik_tool(robot, T @ np.linalg.inv(T_FLANGE_TCP), q)
        out.append(q)
    return out


def add_sequence(robot, g: dict, T_world_part: np.ndarray, opening: float, *, place: bool = True) -> dict:
    """Grasp entry ``g`` (a planned pick) extended with lift (+ transfer, descend, retreat)."""
    g = copy.deepcopy(g)
    path = [np.asarray(q, dtype=float) for q in g["path"]]
    T_part_tcp = np.asarray(g["T_part_tcp"])
    T_grasp = fk_tool(robot, g["q_grasp"]) @ T_FLANGE_TCP   # robot at identity base: world = base_link
    lifted = trans(z=LIFT) @ T_grasp
    grasp_row = len(path) - 1
    path += _line(robot, T_grasp, lifted, path[-1])
    segs = [("transit", 0, g["pregrasp_index"]), ("approach", g["pregrasp_index"], grasp_row),
            ("lift", grasp_row, len(path) - 1)]
    events = [{"index": grasp_row, "action": "close", "width": g["width"]}]
    g["T_tcp_part"] = np.linalg.inv(T_part_tcp).tolist()
    if place:
        T_place_part = trans(*PLACE_SHIFT) @ T_world_part
        T_place = T_place_part @ T_part_tcp
        above = trans(z=LIFT) @ T_place
        q_above = ik_tool(robot, above @ np.linalg.inv(T_FLANGE_TCP), path[-1])
        s = len(path) - 1
        path += [0.5 * (path[-1] + q_above) + np.array([0.0, -0.15, 0.1, 0.0, 0.0, 0.0]), q_above]
        segs.append(("transfer", s, len(path) - 1))
        s = len(path) - 1
        path += _line(robot, above, T_place, path[-1])
        segs.append(("descend", s, len(path) - 1))
        events.append({"index": len(path) - 1, "action": "open", "width": opening})
        s = len(path) - 1
        path += _line(robot, T_place, T_place @ trans(z=-BACKOFF), path[-1], steps=3)
        segs.append(("retreat", s, len(path) - 1))
        g["T_world_part_place"] = T_place_part.tolist()
    g["path"] = [q.tolist() for q in path]
    g["segments"] = [{"label": a, "start": s, "end": e} for a, s, e in segs]
    g["gripper"] = events
    return g


def sequence_plan(robot, *, place: bool = True) -> dict:
    """The synthetic plan of test_export with both planned grasps extended to a sequence."""
    from grasplan.gripper.load import load_gripper

    doc = synthetic_plan(robot)
    T_world_part = np.asarray(doc["part"]["T_world_part"])
    gripper = load_gripper("schunk_egp_c_40")
    doc["grasps"] = [add_sequence(robot, g, T_world_part, float(gripper.pregrasp_opening(g["width"])), place=place)
                     if g["status"] == "planned" else g for g in doc["grasps"]]
    return doc


@pytest.fixture(scope="module")
def ur5():
    return mini_ur5()


@pytest.fixture(scope="module")
def old_doc(ur5):
    return synthetic_plan(ur5)


@pytest.fixture(scope="module", params=[True, False], ids=["place", "lift-only"])
def seq_doc(ur5, request):
    return sequence_plan(ur5, place=request.param)


def test_synthetic_sequence_loads(seq_doc):
    """The synthetic document passes the plan loader (segments, events, FK) with its sequence."""
    res = load_result(seq_doc)
    for gid in PLANNED_IDS:
        m = res.motions[gid]
        e = entry(seq_doc, gid)
        assert [s[0] for s in m.segment_list()] == [s["label"] for s in e["segments"]]
        assert [(ev.action, ev.index) for ev in m.gripper] == [(ev["action"], ev["index"]) for ev in e["gripper"]]


# ------------------------------------------------------------------------------- helpers
def segments_of(g: dict) -> list[tuple[str, int, int]]:
    return [(s["label"], s["start"], s["end"]) for s in g["segments"]]


def events_of(g: dict) -> list[tuple[str, int, float]]:
    return [(e["action"], e["index"], e["width"]) for e in g["gripper"]]


def expected_moves(g: dict) -> list[tuple]:
    """What a program must do, derived here from the plan: per segment ("segment", label), then
    ("joint", row) for every row of transit (from row 0) / transfer (after its start) or
    ("linear", row) to a straight segment's end, then ("gripper", action, width) at its events."""
    out = []
    ev = events_of(g)
    for lab, s, e in segments_of(g):
        out.append(("segment", lab))
        if lab in ("transit", "transfer"):
            out += [("joint", r) for r in range(0 if s == 0 else s + 1, e + 1)]
        else:
            out.append(("linear", e))
        out += [("gripper", a, w) for a, i, w in ev if i == e]
    return out


def tcp_world(robot, q) -> np.ndarray:
    return fk_tool(robot, q) @ T_FLANGE_TCP  # the synthetic robot stands at the world origin


URS_LINE = re.compile(r"^\s*(?:# segment (\w+)|(movej)\(\[([^\]]*)\]|(movel)\(p\[([^\]]*)\]|"
                      r"grasplan_(open|close)_gripper\(([0-9.]+)\))", re.M)


def parse_urscript(text: str) -> list[tuple]:
    """The program's segment comments, moves and gripper calls in order (inside def grasplan_pick)."""
    body = text[text.index("  # ---------------------------------------------------------------------------------------"
                           "-\n"):]
    out = []
    for m in URS_LINE.finditer(body):
        if m.group(1):
            out.append(("segment", m.group(1)))
        elif m.group(2):
            out.append(("joint", floats(m.group(3))))
        elif m.group(4):
            out.append(("linear", floats(m.group(5))))
        else:
            out.append(("gripper", m.group(6), float(m.group(7))))
    return out


def check_program_order(got: list[tuple], want: list[tuple], path: np.ndarray, robot, T_base_world, pose_of,
                        joint_of, width_scale=1.0) -> None:
    """``got``: parsed (kind, payload) in program order; compares kinds/labels/rows with ``want``,
    joint values with the path rows and linear targets with FK of the rows (1e-6 m / rad)."""
    assert [w[0] for w in got] == [w[0] for w in want], f"{[w[0] for w in got]} != {[w[0] for w in want]}"
    for gt, wt in zip(got, want):
        if wt[0] == "segment":
            assert gt[1] == wt[1]
        elif wt[0] == "joint":
            np.testing.assert_allclose(joint_of(gt[1]), path[wt[1]], atol=1e-6)
        elif wt[0] == "linear":
            T = pose_of(gt[1])
            T_want = T_base_world @ tcp_world(robot, path[wt[1]])
            assert np.linalg.norm(T[:3, 3] - T_want[:3, 3]) < 1e-6 and rot_angle(T[:3, :3], T_want[:3, :3]) < 1e-6
        else:
            assert gt[1] == wt[1] and gt[2] == pytest.approx(wt[2] * width_scale, abs=1e-6)


# ------------------------------------------------------------------------------- URScript
def test_urscript_emits_the_sequence(seq_doc, ur5):
    check_urscript(seq_doc, ur5, PLANNED_IDS)


def check_urscript(seq_doc, ur5, gids):
    for gid in gids:
        g = entry(seq_doc, gid)
        text = render(seq_doc, "urscript", grasp_id=gid)[".script"]
        got = parse_urscript(text)
        assert got[0] == ("gripper", "open", pytest.approx(float(load_result(seq_doc).gripper.pregrasp_opening(g["width"]))))
        want = expected_moves(g)
        check_program_order(got[1:], want, np.asarray(g["path"]), ur5, np.linalg.inv(UR_BASE),
                            pose_of=pose_to_T, joint_of=lambda v: v)
        grip = [x for x in got[1:] if x[0] == "gripper"]
        assert [x[1] for x in grip] == (["close", "open"] if "descend" in text else ["close"])
        assert len(MOVEL.findall(text)) == sum(1 for w in want if w[0] == "linear")
        assert len(MOVEJ.findall(text)) == sum(1 for w in want if w[0] == "joint")
        assert ("pick-and-place program" in text) == any(s["label"] == "descend" for s in g["segments"])


# ------------------------------------------------------------------------------- KRL, RAPID
KRL_SEGMENT = re.compile(r"^; segment (\w+) ", re.M)
KRL_LINE = re.compile(r"^(?:; segment (\w+) |(PTP|LIN) (\w+)|GRASPLAN_GRIPPER\(([0-9.]+)\))", re.M)


def test_krl_emits_the_sequence(seq_doc, ur5):
    check_krl(seq_doc, ur5, PLANNED_IDS)


def check_krl(seq_doc, ur5, gids):
    res = load_result(seq_doc)
    robot = res.robot
    lo, hi = controller_limits_deg(robot)
    for gid in gids:
        g = entry(seq_doc, gid)
        files = render(seq_doc, "krl", grasp_id=gid)
        P = parse_krl(files[".src"], files[".dat"])  # the strict grammar: every code line a known statement
        decl = P["decl"]
        used = {t for _, t in P["moves"]} | set(P["frames"].values())
        assert set(decl) == used
        T_base = krl_pose(decl[P["frames"]["BASE"]][1])
        np.testing.assert_allclose(krl_pose(decl[P["frames"]["TOOL"]][1]), T_FLANGE_TCP, atol=1e-6)
        body = files[".src"].split("GRASPLAN_GRIPPER(", 1)[1]  # after the initial open
        got = []
        for m in KRL_LINE.finditer(body.split("\nEND\n", 1)[0]):
            if m.group(1):
                got.append(("segment", m.group(1)))
            elif m.group(2) == "PTP":
                got.append(("joint", decl[m.group(3)]))
            elif m.group(2) == "LIN":
                got.append(("linear", decl[m.group(3)]))
            else:
                got.append(("gripper", None, float(m.group(4))))
        want = [w if w[0] != "gripper" else ("gripper", None, w[2]) for w in expected_moves(g)]

        def joint_of(d):
            assert d[0] == "E6AXIS"
            deg = np.array([d[1][f"A{i}"] for i in range(1, 7)])
            assert np.all(deg >= lo - 1e-6) and np.all(deg <= hi + 1e-6)
            return to_rad(robot, deg)

        def pose_of(d):
            assert d[0] == "E6POS"
            return krl_pose(d[1])

        check_program_order(got, want, np.asarray(g["path"]), ur5, np.linalg.inv(T_base) @ np.eye(4),
                            pose_of=pose_of, joint_of=joint_of, width_scale=1000.0)
        # the first gripper call opens to the pre-grasp opening, then exactly one close (+ one open)
        assert P["gripper"][0] == pytest.approx(1000 * float(res.gripper.pregrasp_opening(g["width"])), abs=1e-3)
        assert P["gripper"][1:] == pytest.approx([1000 * w for _, _, w in events_of(g)], abs=1e-3)


RAPID_LINE = re.compile(r"^\s*(?:! segment (\w+) |MoveAbsJ (\w+)\\|MoveL (\w+),|grasplan_gripper_(open|close) ([0-9.]+);)",
                        re.M)


def test_rapid_emits_the_sequence(seq_doc, ur5):
    check_rapid(seq_doc, ur5, PLANNED_IDS)


def check_rapid(seq_doc, ur5, gids):
    res = load_result(seq_doc)
    robot = res.robot
    for gid in gids:
        g = entry(seq_doc, gid)
        text = render(seq_doc, "rapid", grasp_id=gid)[".mod"]
        P = parse_rapid(text)
        consts = P["consts"]
        assert set(consts) == {t for _, t, _, _ in P["moves"]}
        (wobj,) = P["wobjs"].values()
        T_base = rapid_pose(wobj[3]) @ rapid_pose(wobj[4])
        proc = text.split(f"PROC {P['names'][0]}_main()", 1)[1].split("ENDPROC", 1)[0]
        got = []
        for m in RAPID_LINE.finditer(proc):
            if m.group(1):
                got.append(("segment", m.group(1)))
            elif m.group(2):
                got.append(("joint", consts[m.group(2)]))
            elif m.group(3):
                got.append(("linear", consts[m.group(3)]))
            else:
                got.append(("gripper", m.group(4), float(m.group(5))))
        assert got[0] == ("gripper", "open", pytest.approx(1000 * float(res.gripper.pregrasp_opening(g["width"])), abs=1e-3))

        def joint_of(c):
            assert c[0] == "jointtarget"
            return to_rad(robot, np.array(c[1][0]))

        def pose_of(c):
            assert c[0] == "robtarget"
            q_deg = None  # confdata is checked below
            del q_deg
            return rapid_pose(c[1][:2])

        check_program_order(got[1:], expected_moves(g), np.asarray(g["path"]), ur5, np.linalg.inv(T_base),
                            pose_of=pose_of, joint_of=joint_of, width_scale=1000.0)
        # confdata of each linear target: quarter turns of axes 1, 4, 6 at the segment's end row
        path = np.asarray(g["path"])
        lin = [w[1] for w in expected_moves(g) if w[0] == "linear"]
        targets = [x[1] for x in got if x[0] == "linear"]
        for row, c in zip(lin, targets):
            d = np.degrees(path[row])
            assert c[1][2][:3] == [int(np.floor(d[i] / 90)) for i in (0, 3, 5)]


# ------------------------------------------------------------------------------- joint trajectory
class SequenceScene(RecordingScene):
    """Records which scene variant checks what: 'static', 'attached' (with T_tcp_part), 'placed'."""

    def __init__(self, kind="static", log=None, arg=None, bad_q=None, radius=0.05):
        super().__init__(bad_q=bad_q, radius=radius)
        self.kind, self.arg = kind, arg
        self.log = [] if log is None else log

    def path_free(self, qs, opening, *, step=0.01):
        self.log.append((self.kind, np.asarray(qs).copy(), opening, self.arg))
        return super().path_free(qs, opening, step=step)

    def attached(self, T_tcp_part):
        return SequenceScene("attached", self.log, np.asarray(T_tcp_part), self.bad_q, self.radius)

    def with_part_at(self, T_world_part):
        return SequenceScene("placed", self.log, np.asarray(T_world_part), self.bad_q, self.radius)


def t_of(p) -> float:
    return p["time_from_start"]["sec"] + 1e-9 * p["time_from_start"]["nanosec"]


def test_joint_trajectory_emits_the_sequence(seq_doc):
    check_joint_trajectory(seq_doc, PLANNED_IDS, SequenceScene)


def check_joint_trajectory(seq_doc, gids, make_scene):
    from grasplan.export.trajectory import GRIPPER_DWELL_S
    from grasplan.schemas.documents import validate

    res = load_result(seq_doc)
    for gid in gids:
        g = entry(seq_doc, gid)
        scene = make_scene()
        doc = joint_trajectory(res, grasp_id=gid, scene=scene)
        assert validate(doc) == "grasplan.joint_trajectory/1"
        pts = doc["points"]
        q = np.array([p["positions"] for p in pts])
        t = np.array([t_of(p) for p in pts])
        assert np.all(np.diff(t) > 0)
        path = np.asarray(g["path"])
        segs = segments_of(g)
        assert [(s["label"], s["path_start"], s["path_end"]) for s in doc["segments"]] == segs
        for s in doc["segments"]:  # the points at the segment ends are the path rows
            np.testing.assert_allclose(q[s["end"]], path[s["path_end"]], atol=1e-9)
            np.testing.assert_allclose(q[s["start"]], path[s["path_start"]], atol=1e-9)
        assert doc["segments"][0]["start"] == 0 and doc["segments"][-1]["end"] == len(pts) - 1
        assert [(e["action"], e["path_index"], e["width"]) for e in doc["gripper"]] == events_of(g)
        for e in doc["gripper"]:  # the robot stands still at the event for the dwell
            i = e["point"]
            np.testing.assert_allclose(q[i], path[e["path_index"]], atol=1e-9)
            np.testing.assert_allclose(q[i + 1], q[i], atol=0)
            assert t[i + 1] - t[i] == pytest.approx(GRIPPER_DWELL_S, abs=1e-6)
            assert np.all(np.array(pts[i]["velocities"]) == 0) and np.all(np.array(pts[i + 1]["velocities"]) == 0)
        # every segment was collision-checked with its own scene: static part before the close,
        # attached between close and open (with the plan's T_tcp_part), at the place after the open
        kinds = [c[0] for c in scene.log]
        want = ["static" if lab in ("transit", "approach") else "placed" if lab == "retreat" else "attached"
                for lab, _, _ in segs]
        assert kinds == want
        for (kind, qs, opening, arg), s in zip(scene.log, doc["segments"]):
            np.testing.assert_allclose(qs, q[s["start"]:s["end"] + 1])
            if kind == "attached":
                np.testing.assert_allclose(arg, g["T_tcp_part"], atol=1e-12)
                assert opening == pytest.approx(g["width"])
            if kind == "placed":
                np.testing.assert_allclose(arg, g["T_world_part_place"], atol=1e-12)


def test_joint_trajectory_collision_in_an_attached_segment_fails(seq_doc):
    from grasplan.errors import PlanningError

    g = entry(seq_doc, PLANNED_IDS[0])
    res = load_result(seq_doc)
    lift = next(s for s in g["segments"] if s["label"] == "lift")
    bad = np.asarray(g["path"])[lift["end"]]  # the lifted pose (the approach stays 5 cm lower)
    scene = SequenceScene(bad_q=bad, radius=0.01)
    with pytest.raises(PlanningError, match="collides in the lift segment"):
        joint_trajectory(res, grasp_id=PLANNED_IDS[0], scene=scene)
    assert [c[0] for c in scene.log] == ["static", "static", "attached"]  # stopped at the lift


# ------------------------------------------------------------------------------- path CSV, MoveIt
def test_path_csv_emits_the_sequence(seq_doc, ur5):
    check_path_csv(seq_doc, ur5, PLANNED_IDS)


def check_path_csv(seq_doc, ur5, gids):
    for gid in gids:
        g = entry(seq_doc, gid)
        text = render(seq_doc, "path-csv", grasp_id=gid)[".csv"]
        rows = list(csv.DictReader(io.StringIO(text)))
        path = np.asarray(g["path"])
        assert [int(r["row"]) for r in rows] == list(range(len(path)))
        joints = [c for c in rows[0] if c.startswith("q_")]
        np.testing.assert_allclose([[float(r[c]) for c in joints] for r in rows], path, atol=1e-10)
        want_seg = [segments_of(g)[0][0]] + [next(lab for lab, s, e in segments_of(g) if s < r <= e)
                                             for r in range(1, len(path))]
        assert [r["segment"] for r in rows] == want_seg
        # labels appear in the plan's order, each once as a run
        runs = [lab for i, lab in enumerate(want_seg) if i == 0 or lab != want_seg[i - 1]]
        assert runs == [s[0] for s in segments_of(g)]
        grip = [(r["gripper"], int(r["row"]), float(r["gripper_width"])) for r in rows if r["gripper"]]
        assert grip == [(a, i, pytest.approx(w)) for a, i, w in events_of(g)]
        assert sum(r["gripper"] == "close" for r in rows) == 1
        c0 = events_of(g)[0][1]
        c1 = events_of(g)[1][1] if len(events_of(g)) > 1 else len(path) - 1
        assert [int(r["attached"]) for r in rows] == [int(c0 < i <= c1) for i in range(len(path))]
        for r, q in zip(rows, path):
            T = tcp_world(ur5, q)
            np.testing.assert_allclose([float(r[f"tcp_{c}"]) for c in "xyz"], T[:3, 3], atol=1e-9)


def test_moveit_retreats_come_from_the_plan(seq_doc):
    res = load_result(seq_doc)
    docs = yaml.safe_load(render(seq_doc, "moveit-grasp")[".yaml"])
    for d in docs:
        g = entry(seq_doc, int(d["id"].split("_")[1]))
        vec = lambda t: np.array([t["direction"]["vector"][c] for c in "xyz"])
        rt = d["post_grasp_retreat"]
        np.testing.assert_allclose(vec(rt), getattr(res.cell, "retreat_direction", (0, 0, 1)), atol=1e-9)
        assert rt["desired_distance"] == pytest.approx(LIFT, abs=1e-9)
        # the lift measured on the path by FK (independent of the exporter)
        path = np.asarray(g["path"])
        lift = next(s for s in g["segments"] if s["label"] == "lift")
        ur5 = mini_ur5()
        dp = tcp_world(ur5, path[lift["end"]])[:3, 3] - tcp_world(ur5, path[lift["start"]])[:3, 3]
        np.testing.assert_allclose(dp, vec(rt) * rt["desired_distance"], atol=1e-6)
        pr = d["post_place_retreat"]
        if "T_world_part_place" in g:
            T_place_tcp = np.asarray(g["T_world_part_place"]) @ np.asarray(g["T_part_tcp"])
            np.testing.assert_allclose(vec(pr), -T_place_tcp[:3, 2], atol=1e-9)
            assert pr["desired_distance"] == pytest.approx(BACKOFF)
        else:
            T = np.asarray(g["T_part_tcp"])
            np.testing.assert_allclose(vec(pr), -(np.asarray(seq_doc["part"]["T_world_part"]) @ T)[:3, 2], atol=1e-9)


# ------------------------------------------------------------------------------- refusals, back-compat
def test_crooked_linear_segment_is_refused(ur5):
    """A lift whose middle sample leaves the straight line: the controller's linear move would not
    follow the verified path; every program format refuses it."""
    doc = sequence_plan(ur5, place=False)
    g = entry(doc, PLANNED_IDS[0])
    lift = next(s for s in g["segments"] if s["label"] == "lift")
    mid = (lift["start"] + lift["end"]) // 2
    g["path"][mid] = (np.asarray(g["path"][mid]) + np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.05])).tolist()
    g["path"][mid][1] += 0.02
    for fmt in ("urscript", "krl", "rapid"):
        with pytest.raises(InputError, match="lift segment .* not one straight TCP move"):
            render(doc, fmt, grasp_id=PLANNED_IDS[0])


def _pick_only_roundtrip(doc: dict) -> dict:
    """The plan written back by grasplan (segments written explicitly: transit, approach)."""
    return json.loads(json.dumps(load_result(doc).to_json()))


def test_old_plans_export_as_before(old_doc):
    """A plan without segments (old file) exports the pick program of before: joint moves to the
    pre-grasp, one linear approach, close, one linear retreat to the pre-grasp pose, no segment
    lines; the same when grasplan writes the plan back (segments then explicit)."""
    again = _pick_only_roundtrip(old_doc)
    for fmt in ("urscript", "krl", "rapid", "moveit-grasp", "csv", "path-csv"):
        for gid in (None, 0):
            a = render(old_doc, fmt, grasp_id=gid)
            if fmt in ("urscript", "krl", "rapid"):  # 6 digits: the file's 1e-10 rounding does not show
                assert a == render(again, fmt, grasp_id=gid), fmt
            text = "".join(a.values())
            assert "segment" not in text.lower() or fmt == "path-csv"
            assert "pick-and-place" not in text
    text = render(old_doc, "urscript", grasp_id=0)[".script"]
    g = entry(old_doc, 0)
    assert len(MOVEJ.findall(text)) == g["pregrasp_index"] + 1 and len(MOVEL.findall(text)) == 2
    assert text.count("grasplan_close_gripper(0") == 1 and text.count("grasplan_open_gripper(0") == 1
    src = render(old_doc, "krl", grasp_id=0)[".src"]
    assert re.findall(r"^(PTP|LIN) (\w+)", src, re.M)[-2:] == [("LIN", "XGRASP"), ("LIN", "XRETREAT")]
    traj = joint_trajectory(load_result(old_doc), grasp_id=0, scene=RecordingScene())
    assert "segments" not in traj and "gripper" not in traj
    np.testing.assert_allclose(traj["points"][-1]["positions"], g["q_grasp"], atol=1e-9)
    rows = list(csv.DictReader(io.StringIO(render(old_doc, "path-csv", grasp_id=0)[".csv"])))
    assert [r["gripper"] for r in rows] == [""] * (len(rows) - 1) + ["close"]
    assert {r["segment"] for r in rows} == {"transit", "approach"}


# ------------------------------------------------------------------------------- a real plan
class RealRecorder:
    """The plan's own CollisionScene (real checks), recording which variant checks what."""

    def __init__(self, scene, kind="static", log=None, arg=None):
        self.scene, self.kind, self.arg = scene, kind, arg
        self.log = [] if log is None else log

    def path_free(self, qs, opening, *, step=0.01):
        self.log.append((self.kind, np.asarray(qs).copy(), opening, self.arg))
        return self.scene.path_free(qs, opening, step=step)

    def attached(self, T):
        return RealRecorder(self.scene.attached(T), "attached", self.log, np.asarray(T))

    def with_part_at(self, T):
        return RealRecorder(self.scene.with_part_at(T), "placed", self.log, np.asarray(T))


@pytest.fixture(scope="module")
def real_plan(tmp_path_factory):
    """A pick-and-place plan of the bracket (mm) by grasplan.plan: the place 0.25 m from the
    pick pose along -y (same orientation)."""
    from test_viewer import BRACKET

    import grasplan
    from grasplan.cell.model import load_cell
    from grasplan.cell.resting import stable_pose
    from grasplan.part.mesh import load_part
    from grasplan.config.params import PlanParams

    part = load_part(BRACKET, units="mm")
    T0 = stable_pose(part.mesh, load_cell("table"))
    try:
        res = grasplan.plan(part, robot="ur5", place=trans(*PLACE_SHIFT) @ T0, planning=PlanParams(top=2, seed=0))
    except TypeError as exc:  # the planner without pick-and-place
        pytest.skip(f"grasplan.plan has no pick-and-place yet: {exc}")
    ids = [i for i in res.planned_ids() if "descend" in [s[0] for s in res.motions[i].segment_list()]]
    if not ids:
        pytest.skip(f"the planner planned no pick-and-place of the bracket: {res.counts()}")
    folder = tmp_path_factory.mktemp("real")
    path = folder / "plan.json"
    res.write(path)
    doc = json.loads(path.read_text())
    return doc, ids[:2], path


@pytest.mark.slow
def test_real_pick_and_place_plan_exports(real_plan):
    """Every format on a real pick-and-place plan of the bracket (the robot stands at the world
    origin, so the FK checks of the helpers apply): segments in order, one close and one open at
    their rows, joint values and TCP poses equal to the path; the timed trajectory re-checked with
    the real scenes (static part, attached part, part at the place)."""
    from grasplan.export.trajectory import build_scene

    doc, ids, path = real_plan
    res = load_result(path)
    np.testing.assert_allclose(res.robot.T_world_base, np.eye(4), atol=1e-12)
    ur5 = mini_ur5()
    for gid in ids:
        g = entry(doc, gid)
        assert [s[0] for s in segments_of(g)] == ["transit", "approach", "lift", "transfer", "descend", "retreat"]
        assert [e[0] for e in events_of(g)] == ["close", "open"]
    check_urscript(doc, ur5, ids)
    check_krl(doc, ur5, ids)
    check_rapid(doc, ur5, ids)
    check_path_csv(doc, ur5, ids)
    check_joint_trajectory(doc, ids[:1], lambda: RealRecorder(build_scene(res)))
