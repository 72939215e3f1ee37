"""Robot-program exports: KUKA KRL (.src/.dat), ABB RAPID (.mod) and MoveIt grasps (YAML).

The KRL and RAPID outputs are read back by the small strict parsers below (every code line must be
one of the statements the exporters emit; anything else fails), then checked: every declared target
is used by a motion and every motion target is declared, numbers are finite, joint values are
degrees within the robot's limits after the controller joint map and equal the planned path, and
the Cartesian targets composed with the tool/base frames agree with the plan's world TCP and with
Pinocchio's forward kinematics (rotations rebuilt here from KUKA A, B, C / quaternions by hand,
not by the exporters' SciPy calls).

Plans: UR5 and Panda on examples/parts/bracket.stl (mm) and on the paper parts TLess20 and
SileanePepper (skipped with the reason when absent), each computed once per module.
"""
from __future__ import annotations

import dataclasses
import json
import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import EXAMPLE_PARTS, paper_part

pin = pytest.importorskip("pinocchio")

import grasplan
from grasplan.errors import InputError
from grasplan.export import krl, moveit_grasp, rapid
from grasplan.export.program import motion_program
from grasplan.results.export_registry import FORMATS, ExportOptions
from grasplan.config.params import PlanParams

TOP = 2
PLANS = [("bracket.stl", "ur5"), ("bracket.stl", "panda"), ("TLess20.stl", "ur5"), ("TLess20.stl", "panda"),
         ("SileanePepper.stl", "ur5"), ("SileanePepper.stl", "panda")]
NUM = r"-?\d+(?:\.\d+)?"


def part_path(name: str):
    return EXAMPLE_PARTS / name if (EXAMPLE_PARTS / name).exists() else paper_part(name)


@pytest.fixture(scope="module", params=PLANS, ids=[f"{p.split('.')[0]}-{r}" for p, r in PLANS])
def plan(request):
    name, robot = request.param
    res = grasplan.plan(part_path(name), robot=robot, planning=PlanParams(top=TOP, seed=0))
    if not res.planned_ids():
        pytest.fail(f"{name} with {robot}: no planned grasp to export ({res.counts()})")
    return res


# -- independent helpers ------------------------------------------------------------------------

def rot_zyx_deg(a: float, b: float, c: float) -> np.ndarray:
    """KUKA A, B, C (deg) -> R = Rz(A) Ry(B) Rx(C), written out by hand."""
    a, b, c = np.radians([a, b, c])
    Rz = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    Ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    Rx = np.array([[1, 0, 0], [0, math.cos(c), -math.sin(c)], [0, math.sin(c), math.cos(c)]])
    return Rz @ Ry @ Rx


def quat_matrix(w: float, x: float, y: float, z: float) -> np.ndarray:
    """Rotation matrix of a unit quaternion (Hamilton, w first), written out by hand."""
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def transform(R: np.ndarray, p_m) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = p_m
    return T


def fk_flange(robot, q: np.ndarray) -> np.ndarray:
    """World pose of the robot's flange frame by Pinocchio directly."""
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, np.asarray(q, dtype=np.float64))
    return robot.T_world_base @ data.oMf[robot.model.getFrameId(robot.tool_frame)].homogeneous


def joint_map(robot):
    n = robot.nq
    sign = np.ones(n) if robot.joint_sign is None else np.asarray(robot.joint_sign, dtype=float)
    off = np.zeros(n) if robot.joint_offset_deg is None else np.asarray(robot.joint_offset_deg, dtype=float)
    return sign, off


def controller_limits_deg(robot):
    sign, off = joint_map(robot)
    a, b = sign * np.degrees(robot.lower) + off, sign * np.degrees(robot.upper) + off
    return np.minimum(a, b), np.maximum(a, b)


def to_rad(robot, deg: np.ndarray) -> np.ndarray:
    sign, off = joint_map(robot)
    return np.radians((np.asarray(deg) - off) / sign)


def single_line_ascii(text: str) -> None:
    """Only printable ASCII and '\\n': no CR, U+2028, NEL, VT, FF can split a line for any reader."""
    bad = sorted({c for c in text if not (c == "\n" or 32 <= ord(c) < 127)})
    assert not bad, f"non-printable or non-ASCII characters in a robot program: {bad!r}"
    assert text.splitlines() == text.split("\n")[:-1] and text.endswith("\n")


# -- KRL parser ---------------------------------------------------------------------------------

KRL_SRC = [
    ("access", r"&ACCESS RVP"), ("rel", r"&REL 1"), ("def", r"DEF (\w+)\( \)"), ("end", r"END"),
    ("decl_int", r"DECL INT I"), ("bas", r"BAS\(#INITMOV,0\)"), ("frame", r"\$(TOOL|BASE)=(\w+)"),
    ("for", r"FOR I=1 TO 6"), ("endfor", r"ENDFOR"), ("vel", rf"\$(?:VEL|ACC)_AXIS\[I\]=({NUM})"),
    ("velx", rf"\$(?:VEL|ACC)_EXTAX\[1\]=({NUM})"), ("cp", rf"\$(?:VEL|ACC)\.CP=({NUM})"),
    ("gripper", rf"GRASPLAN_GRIPPER\(({NUM})\)"), ("move", r"(PTP|LIN) (\w+)"),
    ("def_gripper", r"DEF GRASPLAN_GRIPPER\(OPENING_MM:IN\)"), ("decl_real", r"DECL REAL OPENING_MM"),
    ("wait", rf"WAIT SEC ({NUM})"),
]
KRL_DAT = [("access", r"&ACCESS RVP"), ("rel", r"&REL 1"), ("defdat", r"DEFDAT (\w+)"), ("enddat", r"ENDDAT"),
           ("decl", r"DECL (E6AXIS|E6POS|FRAME) (\w+)=\{([^{}]*)\}")]


def krl_code(text: str) -> list[str]:
    """Code lines: comments (';' to the end of the line) and blank lines removed."""
    return [s for s in (line.split(";", 1)[0].strip() for line in text.split("\n")) if s]


def match_line(line: str, grammar) -> tuple[str, tuple]:
    for kind, pat in grammar:
        m = re.fullmatch(pat, line)
        if m:
            return kind, m.groups()
    raise AssertionError(f"line not made by the exporter's templates: {line!r}")


def krl_aggregate(body: str) -> dict[str, float]:
    out = {}
    for item in body.split(","):
        m = re.fullmatch(rf"([A-Z]\d?) ({NUM})", item.strip())
        assert m, f"malformed aggregate component {item!r}"
        v = float(m.group(2))
        assert math.isfinite(v)
        out[m.group(1)] = v
    return out


def parse_krl(src: str, dat: str) -> dict:
    single_line_ascii(src)
    single_line_ascii(dat)
    decl, moves, frames, names, grip = {}, [], {}, [], []
    for line in krl_code(dat):
        kind, g = match_line(line, KRL_DAT)
        if kind == "defdat":
            names.append(g[0])
        elif kind == "decl":
            assert g[1] not in decl, f"{g[1]} declared twice"
            decl[g[1]] = (g[0], krl_aggregate(g[2]))
    for line in krl_code(src):
        kind, g = match_line(line, KRL_SRC)
        if kind == "def":
            names.append(g[0])
        elif kind == "move":
            moves.append(g)
        elif kind == "frame":
            frames[g[0]] = g[1]
        elif kind == "gripper":
            grip.append(float(g[0]))
        for v in g:
            if v is not None and re.fullmatch(NUM, v):
                assert math.isfinite(float(v))
    return {"decl": decl, "moves": moves, "frames": frames, "names": names, "gripper": grip}


def krl_pose(agg: dict) -> np.ndarray:
    return transform(rot_zyx_deg(agg["A"], agg["B"], agg["C"]), np.array([agg["X"], agg["Y"], agg["Z"]]) / 1000.0)


# -- RAPID parser -------------------------------------------------------------------------------

RAPID = [
    ("module", r"MODULE (\w+)"), ("endmodule", r"ENDMODULE"),
    ("tool", r"PERS tooldata (\w+):=(\[.*\]);"), ("wobj", r"PERS wobjdata (\w+):=(\[.*\]);"),
    ("const", r"LOCAL CONST (jointtarget|robtarget) (\w+):=(\[.*\]);"),
    ("proc", r"PROC (\w+)\(\)"), ("endproc", r"ENDPROC"),
    ("gripper_proc", r"LOCAL PROC grasplan_gripper_(open|close)\(num \w+\)"),
    ("gripper", rf"grasplan_gripper_(open|close) ({NUM});"),
    ("absj", r"MoveAbsJ (\w+)\\NoEOffs,v\d+,fine,(\w+)\\WObj:=(\w+);"),
    ("movel", r"MoveL (\w+),v\d+,fine,(\w+)\\WObj:=(\w+);"),
    ("conf", r"ConfL\\(On|Off);"), ("wait", rf"WaitTime ({NUM});"),
]


def rapid_code(text: str) -> list[str]:
    """Code lines: '!' comments (outside strings) and blank lines removed."""
    out = []
    for line in text.split("\n"):
        in_str, cut = False, len(line)
        for i, c in enumerate(line):
            if c == '"':
                in_str = not in_str
            elif c == "!" and not in_str:
                cut = i
                break
        s = line[:cut].strip()
        if s:
            out.append(s)
    return out


def rapid_value(text: str):
    try:  # RAPID aggregates are JSON arrays once TRUE/FALSE are lower case (9E9 is a JSON number)
        v = json.loads(text.replace("TRUE", "true").replace("FALSE", "false"))
    except ValueError as exc:
        raise AssertionError(f"malformed RAPID value {text[:80]!r}: {exc}") from None

    def walk(x):
        if isinstance(x, list):
            for y in x:
                walk(y)
        elif isinstance(x, float | int) and not isinstance(x, bool):
            assert math.isfinite(x)
    walk(v)
    return v


def parse_rapid(text: str) -> dict:
    single_line_ascii(text)
    tools, wobjs, consts, moves, names = {}, {}, {}, [], []
    for line in rapid_code(text):
        kind, g = match_line(line, RAPID)
        if kind == "module":
            names.append(g[0])
        elif kind == "tool":
            tools[g[0]] = rapid_value(g[1])
        elif kind == "wobj":
            wobjs[g[0]] = rapid_value(g[1])
        elif kind == "const":
            assert g[1] not in consts, f"{g[1]} declared twice"
            consts[g[1]] = (g[0], rapid_value(g[2]))
        elif kind in ("absj", "movel"):
            moves.append((kind, *g))
    return {"tools": tools, "wobjs": wobjs, "consts": consts, "moves": moves, "names": names}


def rapid_pose(pose) -> np.ndarray:
    (p, q) = pose
    assert abs(np.linalg.norm(q) - 1.0) < 1e-6, f"quaternion {q} is not unit"
    return transform(quat_matrix(*q), np.asarray(p) / 1000.0)


# -- KRL ----------------------------------------------------------------------------------------

def sequence_moves(m) -> list[tuple[str, int]]:
    """(kind, path row) of the moves a pick(-and-place) program must make, from the motion's
    segments: joint moves through transit (from row 0) / transfer (after its start), one linear
    move to the end of every other segment."""
    out = []
    for lab, s, e in m.segment_list():
        if lab in ("transit", "transfer"):
            out += [("joint", r) for r in range(0 if s == 0 else s + 1, e + 1)]
        else:
            out.append(("linear", e))
    return out


def check_sequence_targets(plan, m, kinds_targets, T_base, T_tool, joint_deg, pose_of, ext_of) -> None:
    """Joint targets equal the path rows; linear targets composed with base and tool equal FK of
    the path rows (Pinocchio directly); joint 7 (E1 / eax_a) at each linear target is the row's."""
    robot = plan.robot
    want = sequence_moves(m)
    assert [kd for kd, _ in kinds_targets] == [kd for kd, _ in want]
    lo, hi = controller_limits_deg(robot)
    for (kd, tgt), (_, row) in zip(kinds_targets, want):
        q = m.path[row]
        if kd == "joint":
            deg = joint_deg(tgt)
            assert np.all(deg >= lo - 1e-6) and np.all(deg <= hi + 1e-6)
            np.testing.assert_allclose(to_rad(robot, deg), q, atol=1e-7)
        else:
            T = T_base @ pose_of(tgt)
            T_fk = fk_flange(robot, q) @ T_tool
            np.testing.assert_allclose(T[:3, 3], T_fk[:3, 3], atol=1e-6)
            assert np.linalg.norm(T[:3, :3] - T_fk[:3, :3]) < 1e-6
            if robot.nq == 7:
                assert ext_of(tgt) == pytest.approx(np.degrees(q[6]), abs=1e-5)


def check_krl(plan, files: dict, grasp_id: int) -> None:
    robot = plan.robot
    n = robot.nq
    g = plan.grasp(grasp_id)
    m = g.motion
    k = m.pregrasp_index
    P = parse_krl(files[".src"], files[".dat"])
    if len(m.segment_list()) > 2:  # a pick(-and-place) sequence
        decl = P["decl"]
        assert set(decl) == {t for _, t in P["moves"]} | set(P["frames"].values())
        keys = [f"A{i}" for i in range(1, 7)] + (["E1"] if n == 7 else [])
        check_sequence_targets(
            plan, m, [({"PTP": "joint", "LIN": "linear"}[kd], decl[t]) for kd, t in P["moves"]],
            krl_pose(decl[P["frames"]["BASE"]][1]), krl_pose(decl[P["frames"]["TOOL"]][1]),
            joint_deg=lambda d: np.array([d[1][c] for c in keys]), pose_of=lambda d: krl_pose(d[1]),
            ext_of=lambda d: d[1]["E1"])
        assert P["gripper"] == pytest.approx([1000 * float(plan.gripper.pregrasp_opening(g.width))]
                                             + [1000 * e.width for e in m.gripper], abs=1e-3)
        return
    assert P["names"] == ["grasplan_pick", "grasplan_pick"]  # DEFDAT and DEF: KUKA needs them equal
    decl, moves = P["decl"], P["moves"]
    used = {t for _, t in moves} | set(P["frames"].values())
    assert set(decl) == used, f"declared but unused: {set(decl) - used}; used but undeclared: {used - set(decl)}"
    for kind, t in moves:
        assert decl[t][0] == {"PTP": "E6AXIS", "LIN": "E6POS"}[kind]
    assert moves[0][0] == "PTP", "the first motion must be a PTP to a full joint target (BCO run)"
    assert [kd for kd, _ in moves] == ["PTP"] * (k + 1) + ["LIN", "LIN"]
    # joint targets: degrees, within the mapped limits, equal to the planned path
    lo, hi = controller_limits_deg(robot)
    keys = [f"A{i}" for i in range(1, 7)] + (["E1"] if n == 7 else [])
    deg = np.array([[decl[t][1][c] for c in keys] for kd, t in moves if kd == "PTP"])
    for kd, t in moves:
        if kd == "PTP":
            assert sorted(decl[t][1]) == sorted(keys), f"{t}: components {sorted(decl[t][1])}"
    assert np.all(deg >= lo - 1e-6) and np.all(deg <= hi + 1e-6)
    np.testing.assert_allclose(to_rad(robot, deg), m.path[: k + 1], atol=1e-7)
    # Cartesian: $BASE @ XGRASP = the plan's world TCP; FK(pregrasp) @ $TOOL = $BASE @ XGRASP backed off
    T_base = krl_pose(decl[P["frames"]["BASE"]][1])
    T_tool = krl_pose(decl[P["frames"]["TOOL"]][1])
    lin = [t for kd, t in moves if kd == "LIN"]
    T_grasp = T_base @ krl_pose(decl[lin[0]][1])
    np.testing.assert_allclose(T_grasp, g.T_world_tcp, atol=1e-6)
    np.testing.assert_allclose(T_tool, plan.gripper.T_flange_tcp, atol=1e-6)
    T_pre_fk = fk_flange(robot, to_rad(robot, deg[-1])) @ T_tool
    back = transform(np.eye(3), [0, 0, -plan.params.planning.backoff])
    np.testing.assert_allclose(T_pre_fk[:3, 3], (T_grasp @ back)[:3, 3], atol=2e-3)
    T_retreat = T_base @ krl_pose(decl[lin[1]][1])
    np.testing.assert_allclose(T_retreat[:3, 3], T_pre_fk[:3, 3], atol=1e-6)  # retreat to the pre-grasp pose
    if n == 7:  # joint 7 as E1: at the grasp, and at the pre-grasp for the retreat that ends there
        assert decl[lin[0]][1]["E1"] == pytest.approx(np.degrees(m.q_grasp[6]), abs=1e-5)
        assert decl[lin[1]][1]["E1"] == pytest.approx(np.degrees(m.q_pregrasp[6]), abs=1e-5)
    else:
        assert all(not c.startswith("E") for t in lin for c in decl[t][1]), "6 joints: external axes untouched"
    # gripper: open to the pre-grasp opening, close to the width (mm)
    assert P["gripper"] == pytest.approx([1000 * float(plan.gripper.pregrasp_opening(g.width)), 1000 * g.width],
                                         abs=1e-3)


def test_krl_on_plans(plan):
    best = plan.planned_ids()[0]
    check_krl(plan, krl.render(plan, ExportOptions(source="plan.json")), best)
    last = plan.planned_ids()[-1]
    check_krl(plan, krl.render(plan, ExportOptions(grasp_id=last)), last)


# -- RAPID --------------------------------------------------------------------------------------

def check_rapid(plan, text: str, grasp_id: int) -> None:
    robot = plan.robot
    n = robot.nq
    g = plan.grasp(grasp_id)
    m = g.motion
    k = m.pregrasp_index
    P = parse_rapid(text)
    assert P["names"] == ["grasplan_pick"]
    if len(m.segment_list()) > 2:  # a pick(-and-place) sequence
        consts = P["consts"]
        assert set(consts) == {t for _, t, _, _ in P["moves"]}
        (tool,) = P["tools"].values()
        (wobj,) = P["wobjs"].values()
        check_sequence_targets(
            plan, m, [({"absj": "joint", "movel": "linear"}[kd], consts[t][1]) for kd, t, _, _ in P["moves"]],
            rapid_pose(wobj[3]) @ rapid_pose(wobj[4]), rapid_pose(tool[1]),
            joint_deg=lambda c: np.array(c[0] + c[1][: n - 6]), pose_of=lambda c: rapid_pose(c[:2]),
            ext_of=lambda c: c[3][0])
        return
    consts, moves = P["consts"], P["moves"]
    used = {t for _, t, _, _ in moves}
    assert set(consts) == used, f"declared but unused: {set(consts) - used}; used but undeclared: {used - set(consts)}"
    assert {tl for _, _, tl, _ in moves} == set(P["tools"]) and {w for _, _, _, w in moves} == set(P["wobjs"])
    assert [kd for kd, *_ in moves] == ["absj"] * (k + 1) + ["movel", "movel"]
    for kd, t, _, _ in moves:
        assert consts[t][0] == {"absj": "jointtarget", "movel": "robtarget"}[kd]
    lo, hi = controller_limits_deg(robot)
    deg = []
    for kd, t, _, _ in moves:
        if kd == "absj":
            rax, ext = consts[t][1]
            assert len(rax) == 6 and len(ext) == 6
            assert ext[n - 6:] == [9e9] * (12 - n), "unused external axes must be 9E9"
            deg.append(rax + ext[: n - 6])
    deg = np.array(deg)
    assert np.all(deg >= lo - 1e-6) and np.all(deg <= hi + 1e-6)
    np.testing.assert_allclose(to_rad(robot, deg), m.path[: k + 1], atol=1e-7)
    (tool,) = P["tools"].values()
    (wobj,) = P["wobjs"].values()
    assert tool[0] is True and tool[2][0] > 0, "robhold TRUE and a positive load mass"
    assert abs(np.linalg.norm(tool[2][2]) - 1.0) < 1e-9, "load axes quaternion must be unit"
    T_tool = rapid_pose(tool[1])
    assert wobj[:3] == [False, True, ""]
    T_base = rapid_pose(wobj[3]) @ rapid_pose(wobj[4])
    targets = [consts[t][1] for kd, t, _, _ in moves if kd == "movel"]
    for rt in targets:
        assert len(rt[2]) == 4 and all(isinstance(c, int) for c in rt[2])
        assert rt[3][n - 6:] == [9e9] * (12 - n)
    if n == 7:
        assert targets[0][3][0] == pytest.approx(np.degrees(m.q_grasp[6]), abs=1e-5)
        assert targets[1][3][0] == pytest.approx(np.degrees(m.q_pregrasp[6]), abs=1e-5)
    T_grasp = T_base @ rapid_pose(targets[0][:2])
    np.testing.assert_allclose(T_grasp, g.T_world_tcp, atol=1e-6)
    np.testing.assert_allclose(T_tool, plan.gripper.T_flange_tcp, atol=1e-6)
    T_pre_fk = fk_flange(robot, to_rad(robot, deg[-1])) @ T_tool
    np.testing.assert_allclose((T_base @ rapid_pose(targets[1][:2]))[:3, 3], T_pre_fk[:3, 3], atol=1e-6)
    # confdata: quarter revolutions of axes 1, 4, 6 at the grasp
    q_deg = np.degrees(m.q_grasp)
    assert targets[0][2][:3] == [math.floor(q_deg[i] / 90) for i in (0, 3, 5)]


def test_rapid_on_plans(plan):
    best = plan.planned_ids()[0]
    check_rapid(plan, rapid.render(plan, ExportOptions(source="plan.json"))[".mod"], best)
    last = plan.planned_ids()[-1]
    check_rapid(plan, rapid.render(plan, ExportOptions(grasp_id=last))[".mod"], last)


# -- MoveIt -------------------------------------------------------------------------------------

def test_moveit_grasps_on_plans(plan):
    docs = yaml.safe_load(moveit_grasp.render(plan, ExportOptions())[".yaml"])
    ids = plan.planned_ids()
    assert [d["id"] for d in docs] == [f"grasp_{i}" for i in ids]
    for d, i in zip(docs, ids):
        g = plan.grasp(i)
        pose = d["grasp_pose"]
        assert pose["header"]["frame_id"] == "world"
        o, p = pose["pose"]["orientation"], pose["pose"]["position"]
        q = np.array([o["w"], o["x"], o["y"], o["z"]])
        assert abs(np.linalg.norm(q) - 1) < 1e-9
        T = transform(quat_matrix(*q), [p["x"], p["y"], p["z"]])
        np.testing.assert_allclose(T, g.T_world_tcp, atol=1e-9)
        assert d["grasp_quality"] == pytest.approx(g.score)
        ap = d["pre_grasp_approach"]
        np.testing.assert_allclose([ap["direction"]["vector"][c] for c in "xyz"], g.T_world_tcp[:3, 2], atol=1e-12)
        assert ap["desired_distance"] == pytest.approx(plan.params.planning.backoff)
        rt = d["post_grasp_retreat"]
        if len(g.motion.segment_list()) > 2:  # the planned lift: the cell's retreat (world)
            np.testing.assert_allclose([rt["direction"]["vector"][c] for c in "xyz"], plan.cell.retreat_direction,
                                       atol=1e-12)
            assert rt["desired_distance"] == pytest.approx(plan.cell.retreat_distance)
            s, e = g.motion.segment("lift")
            dp = (fk_flange(plan.robot, g.motion.path[e]) - fk_flange(plan.robot, g.motion.path[s]))[:3, 3]
            np.testing.assert_allclose(dp, np.asarray(plan.cell.retreat_direction) * plan.cell.retreat_distance,
                                       atol=1e-3)
        else:
            np.testing.assert_allclose([rt["direction"]["vector"][c] for c in "xyz"], -g.T_world_tcp[:3, 2], atol=1e-12)
            assert rt["desired_distance"] == pytest.approx(plan.retreat_distance)
        opening = float(plan.gripper.pregrasp_opening(g.width))
        for key, o_m in (("pre_grasp_posture", opening), ("grasp_posture", g.width)):
            post = d[key]
            assert len(post["joint_names"]) == 2 and len(set(post["joint_names"])) == 2
            (pt,) = post["points"]
            assert sum(pt["positions"]) == pytest.approx(o_m) and pt["positions"][0] == pt["positions"][1]
        assert d["max_contact_force"] > 0
    one = yaml.safe_load(moveit_grasp.render(plan, ExportOptions(grasp_id=ids[-1]))[".yaml"])
    assert [d["id"] for d in one] == [f"grasp_{ids[-1]}"]


# -- registry, joint map, refusals --------------------------------------------------------------

def test_registry_lists_the_three_formats():
    for name, ext, per_grasp in (("krl", ".src", True), ("rapid", ".mod", True), ("moveit-grasp", ".yaml", False)):
        f = FORMATS[name]
        assert f.extension == ext and f.per_grasp is per_grasp
        assert f.description and "\n" not in f.description


@pytest.fixture(scope="module")
def bracket_ur5():
    return grasplan.plan(EXAMPLE_PARTS / "bracket.stl", robot="ur5", planning=PlanParams(top=1, seed=0))


def test_joint_map_applies(bracket_ur5):
    mp = motion_program(bracket_ur5)
    sign = np.array([-1.0, 1, 1, 1, 1, -1])
    off = np.array([90.0, 0, 0, 0, 0, 180])
    mp2 = dataclasses.replace(mp, joint_sign=sign, joint_offset_deg=off)
    P = parse_krl(*krl.krl_program(mp2).values())
    first = next(P["decl"][t][1] for kd, t in P["moves"] if kd == "PTP")
    want = sign * np.degrees(mp.q_home) + off
    np.testing.assert_allclose([first[f"A{i}"] for i in range(1, 7)], want, atol=1e-6)
    R = parse_rapid(rapid.rapid_module(mp2)[".mod"])
    jt = next(R["consts"][t][1][0] for kd, t, _, _ in R["moves"] if kd == "absj")
    np.testing.assert_allclose(jt, want, atol=1e-6)


@pytest.mark.parametrize("render", [krl.krl_program, rapid.rapid_module], ids=["krl", "rapid"])
def test_refuses_nonfinite_and_out_of_limits(bracket_ur5, render):
    mp = motion_program(bracket_ur5)
    path = mp.path.copy()
    path[-1, 2] = np.nan
    with pytest.raises(InputError, match="not finite"):
        render(dataclasses.replace(mp, path=path))
    path = mp.path.copy()
    path[0, 1] = mp.upper[1] + 0.01
    with pytest.raises(InputError, match="outside the robot's limits"):
        render(dataclasses.replace(mp, path=path))
    # an offset moves the limits with the values: still accepted
    render(dataclasses.replace(mp, joint_offset_deg=np.full(6, 30.0)))
    T = mp.T_world_base.copy()
    T[0, 3] = np.inf
    with pytest.raises(InputError, match="T_world_base"):
        render(dataclasses.replace(mp, T_world_base=T))
    with pytest.raises(InputError, match="width"):
        render(dataclasses.replace(mp, width=float("nan")))
    with pytest.raises(InputError, match="6 joints"):
        render(dataclasses.replace(mp, joint_names=mp.joint_names[:5]))


# -- hostile names ------------------------------------------------------------------------------

HOSTILE_PART = 'evil\n  popup("x")\n#.stl'
HOSTILE_NAME = 'grip\r  popup("x")\u2028#\n;MoveL x;\x85 !'


@pytest.fixture(scope="module")
def hostile_plan(tmp_path_factory):
    d = tmp_path_factory.mktemp("hostile")
    src = d / HOSTILE_PART
    shutil.copyfile(EXAMPLE_PARTS / "bracket.stl", src)
    gy = d / "gripper.yaml"
    from grasplan.gripper.load import load_gripper

    base = load_gripper("schunk_egp_c_40")
    if not str(base.source).endswith(".yaml"):
        pytest.fail(f"cannot find the gripper YAML of schunk_egp_c_40 to copy (source {base.source!r})")
    doc = yaml.safe_load(Path(base.source).read_text(encoding="utf-8"))
    doc["name"] = HOSTILE_NAME
    gy.write_text(yaml.safe_dump(doc, allow_unicode=True), encoding="utf-8")
    res = grasplan.plan(src, robot="ur5", gripper=str(gy), planning=PlanParams(top=1, seed=0))
    assert "popup" in res.part.path and "popup" in res.gripper.name, "the hostile names must reach the exporter"
    robot = dataclasses.replace(res.robot, name=HOSTILE_NAME)
    return dataclasses.replace(res, robot=robot)


def test_hostile_names_stay_in_comments(hostile_plan):
    opts = ExportOptions(source=HOSTILE_PART)
    mp = motion_program(hostile_plan, source=HOSTILE_PART)
    benign = dataclasses.replace(mp, robot_name="r", gripper_name="g", part_label="p.stl", source="s")
    k_src, k_dat = krl.render(hostile_plan, opts).values()
    parse_krl(k_src, k_dat)  # strict grammar: no line outside the templates
    b_src, b_dat = krl.krl_program(benign).values()
    assert krl_code(k_src) == krl_code(b_src) and krl_code(k_dat) == krl_code(b_dat)
    assert len(k_src.split("\n")) == len(b_src.split("\n")) and len(k_dat.split("\n")) == len(b_dat.split("\n"))
    r = rapid.render(hostile_plan, opts)[".mod"]
    parse_rapid(r)
    rb = rapid.rapid_module(benign)[".mod"]
    assert rapid_code(r) == rapid_code(rb) and len(r.split("\n")) == len(rb.split("\n"))
    y = moveit_grasp.render(hostile_plan, opts)[".yaml"]
    single_line_ascii(y)
    docs = yaml.safe_load(y)
    for text in (k_src, k_dat, r, y):
        assert 'popup("x")' not in text  # the quotes are reduced; the rest may stay, inside a comment
        assert any("popup(_x_)" in line for line in text.split("\n")), "the label is still shown (reduced)"
    names = docs[0]["grasp_posture"]["joint_names"] + docs[0]["allowed_touch_objects"]
    assert all(re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", s) for s in names), names
