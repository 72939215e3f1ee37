"""Exports of a plan: URScript, timed joint trajectory, CSV, and the `grasplan export` CLI.

Two sources of plans:
- a synthetic ``grasplan.plan/1`` document built here with the real UR5 model of example-robot-data
  (Pinocchio FK + a small damped-least-squares IK for the pre-grasp and approach), so the exporters
  are tested on their own;
- the real pipeline on the paper's TLess20 (``grasplan.motion.planning.plan``), once per module, skipped when
  the part or the upstream stages are absent.
"""
from __future__ import annotations

import csv
import io
import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from grasplan.errors import InputError, PlanningError
from grasplan.export import FORMATS, render, write
from grasplan.export.trajectory import (
    densify,
    joint_trajectory,
    point_to_polyline_distance,
)
from grasplan.results.plan_result import PlanResult
from grasplan.results.reader import load_result

pin = pytest.importorskip("pinocchio")

UR_JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
             "wrist_3_joint"]
Q_HOME = np.array([0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0])
T_FLANGE_TCP = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.127], [0, 0, 0, 1.0]])
#: ids of the synthetic plan: two planned grasps (PLANNED_IDS, best first), one not_tried, one collision_part
PLANNED_IDS = [1, 0]
NOT_TRIED, COLLIDING = 2, 3


def ur5_urdf() -> Path:
    import pinocchio

    site = Path(pinocchio.__file__).resolve()
    for parent in site.parents:
        cand = parent / "cmeel.prefix" / "share" / "example-robot-data" / "robots" / "ur_description" / "urdf" / "ur5_robot.urdf"
        if cand.exists():
            return cand
    pytest.skip("example-robot-data's ur5_robot.urdf not found")


@dataclass
class MiniRobot:
    """What the checks need of a robot, built here from the URDF (independent of robot.py)."""
    name: str
    model: object
    joint_names: tuple
    velocity_limit: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    tool_frame: str = "tool0"


def mini_ur5() -> MiniRobot:
    model = pin.buildModelFromUrdf(str(ur5_urdf()))
    names = tuple(model.names[1:])
    assert list(names) == UR_JOINTS
    return MiniRobot("ur5", model, names, model.velocityLimit.copy(), model.lowerPositionLimit.copy(),
                     model.upperPositionLimit.copy())


@pytest.fixture(scope="module")
def ur5() -> MiniRobot:
    return mini_ur5()


def fk_tool(robot, q) -> np.ndarray:
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, np.asarray(q, dtype=float))
    return data.oMf[robot.model.getFrameId("tool0")].homogeneous.copy()


def ik_tool(robot, T_target, q0, iters=200) -> np.ndarray:
    model = robot.model
    data = model.createData()
    fid = model.getFrameId("tool0")
    q = np.array(q0, dtype=float)
    target = pin.SE3(T_target[:3, :3], T_target[:3, 3])
    for _ in range(iters):
        pin.framesForwardKinematics(model, data, q)
        err = pin.log6(data.oMf[fid].actInv(target)).vector
        if np.linalg.norm(err) < 1e-10:
            break
        J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL)
        q = q + J.T @ np.linalg.solve(J @ J.T + 1e-10 * np.eye(6), err)
    assert np.allclose(fk_tool(robot, q), T_target, atol=1e-8)
    return q


def trans(x=0.0, y=0.0, z=0.0):
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def rot_z(angle):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("z", angle).as_matrix()
    return T


def planned_entry(robot, gid, q_grasp, T_world_part, *, width=0.02, score=1.0, rank=0, mid=None,
                  T_world_base=None):
    """A planned grasp whose q_grasp reaches its T_part_tcp (FK), pregrasp 5 cm back along -z;
    ``T_world_base`` (4, 4): the robot's placement (default identity)."""
    T_world_base = np.eye(4) if T_world_base is None else np.asarray(T_world_base, dtype=float)
    T_base_tcp = fk_tool(robot, q_grasp) @ T_FLANGE_TCP
    T_pre = T_base_tcp @ trans(z=-0.05)
    q_pre = ik_tool(robot, T_pre @ np.linalg.inv(T_FLANGE_TCP), q_grasp)
    approach = [q_pre]
    for s in np.linspace(0, 1, 6)[1:]:
        T = T_base_tcp @ trans(z=-0.05 * (1 - s))
        approach.append(ik_tool(robot, T @ np.linalg.inv(T_FLANGE_TCP), approach[-1]))
    approach[-1] = np.asarray(q_grasp, dtype=float)
    mid = [0.5 * (Q_HOME + q_pre) + np.array([0.3, -0.2, 0.1, 0.0, 0.2, -0.3])] if mid is None else mid
    path = [Q_HOME] + list(mid) + approach
    T_part_tcp = np.linalg.inv(T_world_part) @ T_world_base @ T_base_tcp
    c = T_part_tcp[:3, 3]
    x = T_part_tcp[:3, 0]
    return {
        "id": gid, "candidate": gid // 2, "region": -1,
        "contacts": [(c - x * width / 2).tolist(), (c + x * width / 2).tolist()],
        "normals": [(-x).tolist(), x.tolist()],
        "width": width, "T_part_tcp": T_part_tcp.tolist(), "roll": 0.0, "status": "planned",
        "score": score, "rank": rank, "reason": "planned (synthetic)", "q_grasp": list(map(float, q_grasp)),
        "q_pregrasp": q_pre.tolist(), "path": [list(map(float, q)) for q in path], "pregrasp_index": 1 + len(mid),
    }


def robot_block(name="ur5", T_world_base=None) -> dict:
    """The self-contained ``robot`` block of a plan (grasplan's own robot description, embedded);
    ``T_world_base`` places the robot elsewhere by editing the embedded YAML."""
    from grasplan.robot.description import load_robot

    block = load_robot(name).to_json(source=True)
    if T_world_base is not None:
        text = block["source"]["yaml"]
        assert text.count("T_world_base: identity") == 1
        block["source"]["yaml"] = text.replace("T_world_base: identity",
                                               f"T_world_base: {json.dumps(np.asarray(T_world_base).tolist())}")
        block["T_world_base"] = np.asarray(T_world_base).tolist()
    return block


def synthetic_plan(robot, *, T_world_base=None, part=None) -> dict:
    """A ``grasplan.plan/1`` document: grasps 0 and 1 planned (1 is the best), 2 not_tried,
    3 collision_part. Poses by Pinocchio here (``robot``: a MiniRobot); the gripper, cell and robot
    blocks are grasplan's embedded definitions. ``part``: a mesh file to record (default: a
    non-existent path, fine for exports that need no collision check)."""
    from grasplan.cell.model import load_cell
    from grasplan.gripper.load import load_gripper
    from grasplan.io import sha256_file

    T_world_base = np.eye(4) if T_world_base is None else np.asarray(T_world_base, dtype=float)
    T_world_part = T_world_base @ trans(0.45, 0.0, 0.0) @ rot_z(0.4)
    g0 = planned_entry(robot, 0, [0.3, -1.3, 1.8, -2.07, -1.57, 0.5], T_world_part, score=0.7, rank=1,
                       T_world_base=T_world_base)
    g1 = planned_entry(robot, 1, [-0.2, -1.1, 1.5, -1.97, -1.57, -0.1], T_world_part, score=0.9, rank=0,
                       width=0.03, T_world_base=T_world_base)
    ok_not_tried = dict(g0, id=NOT_TRIED, status="not_tried", score=0.1, rank=None, reason="not tried")
    for k in ("q_grasp", "q_pregrasp", "path", "pregrasp_index"):
        ok_not_tried.pop(k)
    coll = dict(ok_not_tried, id=COLLIDING, status="collision_part", score=None, reason="grasp stage")
    gripper = load_gripper("schunk_egp_c_40").to_json(definition=True)
    np.testing.assert_allclose(gripper["T_flange_tcp"], T_FLANGE_TCP, atol=1e-12)  # the poses above assume it
    cell = dict(load_cell("table").to_json(), part_pose="given")
    rec = {"path": "/nonexistent/part.stl", "sha256": "0" * 64, "scale_to_m": 0.001, "triangles": 12}
    if part is not None:
        rec = {"path": str(part), "sha256": sha256_file(part), "scale_to_m": 0.001, "triangles": 12}
        # loading a plan checks that its contacts lie on the part it names: put them on two corners
        from grasplan.part.mesh import load_part

        corners = np.asarray(load_part(part, units="mm").mesh.vertices)[:2].tolist()
        for g in (g0, g1, ok_not_tried, coll):
            g["contacts"] = corners
    return {
        "schema": "grasplan.plan/1",
        "part": {**rec, "T_world_part": T_world_part.tolist()},
        "gripper": gripper,
        "cell": cell,
        "params": {},
        "robot": robot_block("ur5", T_world_base if not np.allclose(T_world_base, np.eye(4)) else None),
        "counts": {}, "timing_s": {"plan": 1.0},
        "grasps": [g0, g1, ok_not_tried, coll],
    }


def entry(doc, gid) -> dict:
    return next(g for g in doc["grasps"] if g["id"] == gid)


class RecordingScene:
    """Stand-in for CollisionScene: records what is checked; 'collides' inside a joint-space ball."""

    def __init__(self, bad_q=None, radius=0.05):
        self.calls = []
        self.bad_q = bad_q
        self.radius = radius

    def path_free(self, qs, opening, *, step=0.01):
        qs = np.asarray(qs)
        self.calls.append((qs.copy(), opening, step))
        if self.bad_q is None:
            return True
        dense = densify(qs, step)
        return bool(np.all(np.linalg.norm(dense - self.bad_q, axis=1) > self.radius))


@pytest.fixture(scope="module")
def plan_doc(ur5):
    return synthetic_plan(ur5)


# ------------------------------------------------------------------------------------------- parsing
MOVEJ = re.compile(r"^\s*movej\(\[([^\]]*)\],\s*a=([0-9.e+-]+),\s*v=([0-9.e+-]+)\)", re.M)
MOVEL = re.compile(r"^\s*movel\(p\[([^\]]*)\],\s*a=([0-9.e+-]+),\s*v=([0-9.e+-]+)\)", re.M)
SET_TCP = re.compile(r"^\s*set_tcp\(p\[([^\]]*)\]\)", re.M)


def floats(s):
    return np.array([float(x) for x in s.split(",")])


def pose_to_T(p):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(p[3:]).as_matrix()
    T[:3, 3] = p[:3]
    return T


def rot_angle(Ra, Rb):
    return float(np.linalg.norm(Rotation.from_matrix(Ra.T @ Rb).as_rotvec()))


def check_urscript(text, plan, g, robot):
    """Independent check of a URScript program against the plan (pose math redone here)."""
    movej = [floats(m.group(1)) for m in MOVEJ.finditer(text)]
    movel = [floats(m.group(1)) for m in MOVEL.finditer(text)]
    tcp = [floats(m.group(1)) for m in SET_TCP.finditer(text)]
    path = np.array(g["path"])
    k = g["pregrasp_index"]
    assert len(movej) == k + 1
    np.testing.assert_allclose(np.array(movej), path[: k + 1], atol=1e-6)
    np.testing.assert_allclose(movej[0], plan["robot"]["q_home"], atol=1e-6)
    np.testing.assert_allclose(movej[-1], g["q_pregrasp"], atol=1e-6)
    assert len(tcp) == 1 and np.allclose(pose_to_T(tcp[0]), np.array(plan["gripper"]["T_flange_tcp"]), atol=1e-6)
    assert len(movel) == 2
    # the controller's base frame: base_link rotated 180 deg about z (the UR convention, hard-coded here)
    T_world_urbase = np.array(plan["robot"]["T_world_base"]) @ np.diag([-1.0, -1.0, 1.0, 1.0])
    T_expected = np.linalg.inv(T_world_urbase) @ np.array(plan["part"]["T_world_part"]) @ np.array(g["T_part_tcp"])
    T_movel = pose_to_T(movel[0])
    assert np.linalg.norm(T_movel[:3, 3] - T_expected[:3, 3]) < 1e-3
    assert rot_angle(T_movel[:3, :3], T_expected[:3, :3]) < 0.01
    # and via FK of q_grasp, through the 'base' frame of the model
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, np.array(g["q_grasp"]))
    T_base_tool = data.oMf[robot.model.getFrameId("base")].actInv(data.oMf[robot.model.getFrameId("tool0")]).homogeneous
    T_fk = T_base_tool @ np.array(plan["gripper"]["T_flange_tcp"])
    assert np.linalg.norm(T_movel[:3, 3] - T_fk[:3, 3]) < 1e-3 and rot_angle(T_movel[:3, :3], T_fk[:3, :3]) < 0.01
    T_retreat = pose_to_T(movel[1])
    if any(s_["label"] == "lift" for s_ in g.get("segments", [])):
        # a pick sequence: the part is lifted along the cell's retreat direction (world) by its distance
        lift = np.eye(4)
        lift[:3, 3] = np.array(plan["cell"]["retreat"]["direction"]) * plan["cell"]["retreat"]["distance"]
        T_lift = np.linalg.inv(T_world_urbase) @ lift @ np.array(plan["part"]["T_world_part"]) @ np.array(g["T_part_tcp"])
        np.testing.assert_allclose(T_retreat[:3, 3], T_lift[:3, 3], atol=1e-3)
        assert rot_angle(T_retreat[:3, :3], T_lift[:3, :3]) < 0.01
    else:
        # retreat = the pre-grasp pose: 5 cm back along the TCP's -z
        np.testing.assert_allclose(T_retreat[:3, 3], (T_expected @ trans(z=-0.05))[:3, 3], atol=1e-3)
    # order: set_tcp, open, movej..., movel grasp, close, movel retreat
    i_close = text.index("  grasplan_close_gripper(")
    i_movel = [m.start() for m in MOVEL.finditer(text)]
    assert text.index("def grasplan_close_gripper") < text.index("set_tcp(") < i_movel[0] < i_close < i_movel[1]
    return T_movel


def check_trajectory(traj, plan, g, robot, amax):
    """Independent checks of a joint-trajectory document."""
    assert traj["joint_names"] == plan["robot"]["joint_names"] and traj["grasp_id"] == g["id"]
    pts = traj["points"]
    t = np.array([p["time_from_start"]["sec"] + 1e-9 * p["time_from_start"]["nanosec"] for p in pts])
    q = np.array([p["positions"] for p in pts])
    qd = np.array([p["velocities"] for p in pts])
    qdd = np.array([p["accelerations"] for p in pts])
    assert np.all(np.diff(t) > 0), "times strictly increasing"
    np.testing.assert_allclose(q[0], plan["robot"]["q_home"], atol=1e-9)
    np.testing.assert_allclose(q[-1], np.array(g["path"])[-1], atol=1e-9)  # the motion's last waypoint
    assert np.all(qd[0] == 0) and np.all(qd[-1] == 0)
    assert np.max(np.abs(np.diff(q, axis=0))) <= 0.01 + 1e-12
    vlim = np.asarray(robot.velocity_limit)
    assert np.all(np.abs(qd) <= vlim + 1e-9)
    fd = np.abs(np.diff(q, axis=0)) / np.diff(t)[:, None]
    assert np.all(fd <= vlim * (1 + 1e-6)), f"finite-difference velocity {np.max(fd / vlim):.3f} x limit"
    # accelerations: TOPP-RA enforces them at its grid points; between them small excursions are allowed
    assert np.max(np.abs(qdd) / amax) < 1.5
    # the timed motion stays on the planned path (brute force against a 1 mrad densification)
    poly = densify(np.array(g["path"]), 0.001)
    dmin = np.array([np.min(np.linalg.norm(poly - qi, axis=1)) for qi in q[:: max(1, len(q) // 400)]])
    assert np.max(dmin) < 0.01
    return t, q, qd


# ------------------------------------------------------------------------------------------- tests
def test_doc_loads_as_a_typed_plan(plan_doc):
    """The synthetic document passes the full loader (schema, FK of planned grasps vs their TCP)."""
    res = load_result(plan_doc)
    assert isinstance(res, PlanResult) and res.schema == "grasplan.plan/1" and res.robot.name == "ur5"
    np.testing.assert_allclose(res.robot.q_home, Q_HOME, atol=1e-12)
    assert sorted(res.motions) == sorted(PLANNED_IDS)
    assert res.counts()["planned"] == 2 and res.counts()["not_tried"] == 1 and res.counts()["collision_part"] == 1
    # the result writes back the document it was read from (the grasps, bit for bit after rounding)
    again = res.to_json()
    for a, b in zip(again["grasps"], plan_doc["grasps"]):
        assert a["id"] == b["id"] and a["status"] == b["status"] and a["rank"] == b["rank"]
        np.testing.assert_allclose(a["T_part_tcp"], b["T_part_tcp"], atol=1e-9)
        if b["status"] == "planned":
            np.testing.assert_allclose(a["path"], b["path"], atol=1e-12)


def test_best_grasp_selection(plan_doc):
    res = load_result(plan_doc)
    assert res.planned_ids() == PLANNED_IDS
    assert res.select().id == PLANNED_IDS[0]
    assert res.select(0).id == 0
    assert [g["id"] for g in res.planned()] == PLANNED_IDS
    with pytest.raises(InputError, match=r"unknown grasp id 42; planned grasps: 1, 0"):
        res.select(42)
    with pytest.raises(InputError, match=rf"grasp {COLLIDING} is not planned \(status: collision_part\)"):
        res.select(COLLIDING)


def test_registry_lists_the_shipped_formats():
    from grasplan.export import load_builtin_formats

    load_builtin_formats()
    assert {"urscript", "joint-trajectory", "csv", "krl", "rapid", "moveit-grasp"} <= set(FORMATS)
    for name, f in FORMATS.items():
        assert f.name == name and f.extension.startswith(".") and f.description
    with pytest.raises(InputError, match=r"unknown export format 'nope'; available: .*urscript"):
        render({}, "nope")


def test_urscript_synthetic(plan_doc, ur5):
    for gid in (None, 0):
        files = render(plan_doc, "urscript", grasp_id=gid)
        assert list(files) == [".script"]
        text = files[".script"]
        g = entry(plan_doc, PLANNED_IDS[0] if gid is None else gid)
        check_urscript(text, plan_doc, g, ur5)
        assert "def grasplan_close_gripper(width):" in text and "def grasplan_open_gripper(opening):" in text
        # balanced def/end blocks
        assert len(re.findall(r"^\s*def ", text, re.M)) == len(re.findall(r"^\s*end\s*$", text, re.M)) == 3


def test_urscript_base_frame_follows_robot_placement(plan_doc, ur5):
    """Moving the robot base in the world moves the program's poses by exactly the inverse."""
    T_move = trans(0.1, -0.2, 0.05) @ rot_z(0.7)
    plan = synthetic_plan(ur5, T_world_base=T_move)
    assert np.allclose(load_result(plan).robot.T_world_base, T_move)
    a = render(plan_doc, "urscript")[".script"]
    b = render(plan, "urscript")[".script"]
    pa = [floats(m.group(1)) for m in MOVEL.finditer(a)]
    pb = [floats(m.group(1)) for m in MOVEL.finditer(b)]
    assert len(pa) == len(pb) == 2
    for x, y in zip(pa, pb):
        assert np.linalg.norm(pose_to_T(x)[:3, 3] - pose_to_T(y)[:3, 3]) < 1e-6
        assert rot_angle(pose_to_T(x)[:3, :3], pose_to_T(y)[:3, :3]) < 1e-6
    check_urscript(b, plan, entry(plan, PLANNED_IDS[0]), ur5)


def test_urscript_refuses_inconsistent_and_non_ur(plan_doc, tmp_path):
    bad = json.loads(json.dumps(plan_doc))
    bad["gripper"]["T_flange_tcp"] = trans(z=0.2).tolist()   # another gripper than the plan's
    with pytest.raises(InputError, match="another robot or gripper"):
        render(bad, "urscript")
    out = tmp_path / "p.script"
    with pytest.raises(InputError, match="another robot or gripper"):
        write(bad, "urscript", out)
    assert not out.exists()
    # a plan for a Panda (7 joints, not a UR arm): URScript refuses it and names the other formats
    from grasplan.robot.description import load_robot

    panda = load_robot("panda")
    q_home = np.asarray(panda.q_home)
    step = 0.05 * np.sign(np.asarray(panda.upper) - q_home)   # towards the inside of the limits
    q_pre, q_grasp = q_home + step, q_home + 2 * step
    doc = json.loads(json.dumps(plan_doc))
    T_world_part = np.array(doc["part"]["T_world_part"])
    T_world_tcp = panda.fk(q_grasp) @ T_FLANGE_TCP
    g = dict(entry(doc, 0), T_part_tcp=(np.linalg.inv(T_world_part) @ T_world_tcp).tolist(), q_grasp=q_grasp.tolist(),
             q_pregrasp=q_pre.tolist(), path=[q_home.tolist(), q_pre.tolist(), q_grasp.tolist()], pregrasp_index=1)
    doc["grasps"] = [g]
    doc["robot"] = robot_block("panda")
    assert load_result(doc).robot.nq == 7
    with pytest.raises(InputError, match="only on Universal Robots.*joint-trajectory") as err:
        render(doc, "urscript")
    # the formats it suggests run on a Panda: robot-neutral ones, not KUKA's or ABB's languages
    from grasplan.export.urscript import NON_UR_FORMATS
    from grasplan.results.export_registry import FORMATS

    assert all(f in str(err.value) and f in FORMATS for f in NON_UR_FORMATS)
    assert "krl" not in str(err.value).lower() and "rapid" not in str(err.value).lower()


def test_rotvec_near_pi():
    from grasplan.export.urscript import pose_vector

    rng = np.random.default_rng(0)
    for _ in range(200):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = np.pi - rng.uniform(0, 1e-6) if rng.uniform() < 0.5 else rng.uniform(0, np.pi)
        T = np.eye(4)
        T[:3, :3] = Rotation.from_rotvec(axis * angle).as_matrix()
        p = pose_vector(T)
        assert np.linalg.norm(p[3:]) <= np.pi + 1e-9
        assert rot_angle(pose_to_T(p)[:3, :3], T[:3, :3]) < 1e-9


@pytest.mark.parametrize("gid", PLANNED_IDS)
def test_joint_trajectory_synthetic(plan_doc, ur5, gid):
    scene = RecordingScene()
    traj = joint_trajectory(load_result(plan_doc), grasp_id=gid, scene=scene, max_accel=2.0)
    g = entry(plan_doc, gid)
    t, q, qd = check_trajectory(traj, plan_doc, g, ur5, 2.0)
    # the scene was asked about exactly the output positions, at 0.01 rad, with the pre-grasp opening
    assert len(scene.calls) == 1
    np.testing.assert_allclose(scene.calls[0][0], q, atol=1e-12)
    assert scene.calls[0][2] == 0.01 and scene.calls[0][1] == pytest.approx(min(0.05, g["width"] + 0.01))
    # at rest: the first and last accelerations are finite, velocities ramp from 0
    assert np.linalg.norm(qd[1]) < 0.2 * np.max(np.linalg.norm(qd, axis=1))
    assert traj["grasplan"]["max_deviation_rad"] < 0.005
    # the reported deviation is the distance of the samples to the planned polyline
    assert traj["grasplan"]["max_deviation_rad"] == pytest.approx(
        float(np.max(point_to_polyline_distance(q, np.array(g["path"])))), abs=1e-12)


def test_joint_trajectory_slower_with_lower_limits(plan_doc, ur5):
    res = load_result(plan_doc)
    fast = joint_trajectory(res, scene=RecordingScene(), max_accel=3.0)
    slow = joint_trajectory(res, scene=RecordingScene(), max_accel=0.5, velocity_scale=0.3)
    assert slow["grasplan"]["duration_s"] > 1.5 * fast["grasplan"]["duration_s"]
    g = entry(plan_doc, PLANNED_IDS[0])
    check_trajectory(slow, plan_doc, g, MiniRobot("ur5", ur5.model, ur5.joint_names, 0.3 * ur5.velocity_limit,
                                                 ur5.lower, ur5.upper), 0.5)


def test_joint_trajectory_collision_fails_loudly(plan_doc, tmp_path, monkeypatch):
    """write() with a scene that reports a collision near the path's corner: PlanningError, no file."""
    from grasplan.export import trajectory

    g = entry(plan_doc, PLANNED_IDS[0])
    bad_q = np.array(g["path"])[1]           # a 'collision' around the path's corner
    scene = RecordingScene(bad_q=bad_q, radius=0.05)
    monkeypatch.setattr(trajectory, "build_scene", lambda plan: scene)
    out = tmp_path / "traj.json"
    with pytest.raises(PlanningError, match="collides"):
        write(plan_doc, "joint-trajectory", out)
    assert len(scene.calls) == 1 and not out.exists()
    assert list(tmp_path.iterdir()) == []   # no temporary file left either


def test_csv_rows(plan_doc):
    text = render(plan_doc, "csv")[".csv"]
    rows = list(csv.DictReader(io.StringIO(text)))
    assert len(rows) == len(plan_doc["grasps"])
    header = text.splitlines()[0].split(",")
    assert header[:4] == ["id", "status", "width", "score"]
    j0 = header.index("q_" + UR_JOINTS[0])  # joints, then the part's scale (issue 11's quality columns may follow)
    assert header[j0:j0 + 7] == [f"q_{j}" for j in UR_JOINTS] + ["part_scale_to_m"] and "-0," not in text
    T_world_part = np.array(plan_doc["part"]["T_world_part"])
    for row, g in zip(rows, plan_doc["grasps"]):
        assert int(row["id"]) == g["id"] and row["status"] == g["status"]
        assert float(row["part_scale_to_m"]) == plan_doc["part"]["scale_to_m"]
        assert float(row["width"]) == pytest.approx(g["width"], abs=1e-9)
        for frame, T in (("part", np.array(g["T_part_tcp"])), ("world", T_world_part @ np.array(g["T_part_tcp"]))):
            xyz = np.array([float(row[f"{frame}_{c}"]) for c in "xyz"])
            wxyz = np.array([float(row[f"{frame}_q{c}"]) for c in "wxyz"])
            np.testing.assert_allclose(xyz, T[:3, 3], atol=1e-8)
            assert abs(np.linalg.norm(wxyz) - 1) < 1e-6 and wxyz[0] >= 0
            R = Rotation.from_quat([*wxyz[1:], wxyz[0]]).as_matrix()
            assert rot_angle(R, T[:3, :3]) < 1e-7
        q = [row[f"q_{j}"] for j in UR_JOINTS]
        if g["status"] == "planned":
            np.testing.assert_allclose([float(x) for x in q], g["q_grasp"], atol=1e-8)
        else:
            assert q == [""] * 6
        if g["score"] is None:
            assert row["score"] == ""
        else:
            assert float(row["score"]) == pytest.approx(g["score"], abs=1e-9)
    one = list(csv.DictReader(io.StringIO(render(plan_doc, "csv", grasp_id=1)[".csv"])))
    assert len(one) == 1 and one[0]["status"] == "planned" and int(one[0]["id"]) == 1
    with pytest.raises(InputError, match=rf"grasp {COLLIDING} is not planned \(status: collision_part\)"):
        render(plan_doc, "csv", grasp_id=COLLIDING)


def test_grasps_result_is_not_exported(plan_doc):
    """A grasps result (no robot, no motion) is refused with the command that makes a plan."""
    doc = grasps_doc(plan_doc)
    res = load_result(doc)
    assert res.robot is None
    for fmt in ("csv", "urscript"):
        with pytest.raises(InputError, match=r"grasplan plan PART --robot NAME"):
            render(res, fmt)


def grasps_doc(plan_doc) -> dict:
    """The synthetic plan turned into a ``grasplan.grasps/1`` document (every grasp ok)."""
    doc = {k: json.loads(json.dumps(v)) for k, v in plan_doc.items() if k != "robot"}
    doc["schema"] = "grasplan.grasps/1"
    for g in doc["grasps"]:
        for k in ("score", "rank", "reason", "q_grasp", "q_pregrasp", "path", "pregrasp_index"):
            g.pop(k, None)
        g["status"] = "ok"
    return doc


# ------------------------------------------------------------------------------------------- CLI
def _run(args):
    from grasplan.cli import main

    return CliRunner().invoke(main, args, catch_exceptions=False)


def test_cli_bad_input_exit_3(plan_doc, tmp_path):
    plan_path = tmp_path / "plan.json"
    plan_path.write_text(json.dumps(plan_doc))
    out = tmp_path / "out.script"
    no_robot = {k: v for k, v in plan_doc.items() if k != "robot"}
    cases = {
        "not json": ("garbage", ["--format", "csv"], "not a JSON file"),
        "grasps file": (json.dumps(grasps_doc(plan_doc)), ["--format", "csv"], "this is a grasps result"),
        "missing field": (json.dumps(no_robot), ["--format", "csv"], "'robot' is a required property"),
        "other schema": (json.dumps({"schema": "other/1"}), ["--format", "csv"], "not a grasplan grasps or plan file"),
    }
    for name, (content, opts, msg) in cases.items():
        p = tmp_path / f"{name.replace(' ', '_')}.json"
        p.write_text(content)
        r = _run(["export", str(p), *opts, "-o", str(out)])
        assert r.exit_code == 3, (name, r.output)
        assert msg in r.output and not out.exists(), (name, r.output)
    r = _run(["export", str(plan_path), "--format", "urscript", "--grasp", "99", "-o", str(out)])
    assert r.exit_code == 3 and "unknown grasp id 99; planned grasps: 1, 0" in r.output and not out.exists()
    for fmt in ("joint-trajectory", "csv"):
        r = _run(["export", str(plan_path), "--format", fmt, "--grasp", str(NOT_TRIED), "-o", str(out)])
        assert r.exit_code == 3 and "not planned (status: not_tried)" in r.output and not out.exists()
    r = _run(["export", str(tmp_path / "missing.json"), "--format", "csv", "-o", str(out)])
    assert r.exit_code == 3 and "no such file" in r.output and not out.exists()


def test_cli_csv(plan_doc, tmp_path):
    plan_path = tmp_path / "plan.json"
    plan_path.write_text(json.dumps(plan_doc))
    out = tmp_path / "grasps.csv"
    r = _run(["export", str(plan_path), "--format", "csv", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert out.read_text() == render(plan_doc, "csv")[".csv"]
    assert len(out.read_text().splitlines()) == 1 + len(plan_doc["grasps"])


def test_cli_format_choices_come_from_the_registry():
    from grasplan.export import load_builtin_formats

    r = _run(["export", "--help"])
    assert r.exit_code == 0
    for name, f in load_builtin_formats().items():
        assert name in r.output and f.extension in r.output


# ------------------------------------------------------------------------------------- real robot
def independent_path_free(scene_factory, qs, opening, step=0.01):
    """Interpolate at <= step rad myself and ask a fresh scene about every configuration."""
    scene = scene_factory()
    dense = densify(np.asarray(qs), step)
    assert np.max(np.abs(np.diff(dense, axis=0))) <= step + 1e-12
    return all(scene.is_free(q, opening) for q in dense)


def test_default_scene_and_robot_from_plan(tmp_path, ur5):
    """The exporter rebuilds the robot and the CollisionScene from the plan file itself."""
    part = Path(__file__).resolve().parents[1] / "examples" / "parts" / "box.stl"
    plan = synthetic_plan(ur5, part=part)
    plan_path = tmp_path / "plan.json"
    plan_path.write_text(json.dumps(plan))
    out = tmp_path / "traj.json"
    r = _run(["export", str(plan_path), "--format", "joint-trajectory", "-o", str(out)])
    assert r.exit_code == 0, r.output
    traj = json.loads(out.read_text())
    check_trajectory(traj, plan, entry(plan, PLANNED_IDS[0]), ur5, 1.4)
    # a part that is not the planned one is refused (the collision check would be meaningless)
    other = Path(__file__).resolve().parents[1] / "examples" / "parts" / "gear.stl"
    out2 = tmp_path / "traj2.json"
    r = _run(["export", str(plan_path), "--format", "joint-trajectory", "--part", str(other), "-o", str(out2)])
    assert r.exit_code == 3 and "sha256" in r.output and not out2.exists()


@pytest.fixture(scope="module")
def tless20():
    """TLess20 planned once with the UR5 (top 3), exported in memory; its document is read back
    once by the full loader."""
    from conftest import paper_part

    path = paper_part("TLess20.stl")
    from grasplan.part.mesh import load_part
    from grasplan.config.params import PlanParams
    from grasplan.motion.planning import plan as plan_part

    result = plan_part(load_part(path), planning=PlanParams(top=3, grasp_db="off"))  # every pose in memory
    if not result.planned_ids():
        pytest.fail(f"no planned grasp for TLess20: {result.counts()}")
    doc = result.to_json(keep="all")  # every pose: the CSV of the in-memory result lists them all

    def scene_factory():
        from grasplan.motion.collision_scene import CollisionScene

        return CollisionScene(result.robot, result.gripper, result.mesh(), result.T_world_part, result.cell)

    return {"doc": doc, "robot": mini_ur5(), "result": result, "scene_factory": scene_factory}


@pytest.mark.slow
@pytest.mark.paper
def test_tless20_urscript(tless20, tmp_path):
    doc, robot, result = tless20["doc"], tless20["robot"], tless20["result"]
    loaded = load_result(doc)   # the full check of a real plan's document
    assert loaded.planned_ids() == result.planned_ids()
    out = write(result, "urscript", tmp_path / "pick.script")
    best = result.planned_ids()[0]
    assert result.select().id == best
    check_urscript(out.read_text(), doc, entry(doc, best), robot)
    # the loaded document exports the same program
    assert render(loaded, "urscript")[".script"] == out.read_text()


@pytest.mark.slow
@pytest.mark.paper
def test_tless20_joint_trajectory(tless20, tmp_path):
    from grasplan.schemas.documents import validate

    doc, robot, result = tless20["doc"], tless20["robot"], tless20["result"]
    for gid in result.planned_ids()[:2]:
        out = write(result, "joint-trajectory", tmp_path / f"traj{gid}.json", grasp_id=gid)
        traj = json.loads(out.read_text())
        validate(traj)
        g = entry(doc, gid)
        t, q, qd = check_trajectory(traj, doc, g, robot, 1.4)
        opening = min(doc["gripper"]["max_opening"], g["width"] + 0.010)
        # the fresh scene holds the part where it rests: only the segments before the jaws close on
        # it (not attached) can be checked with open jaws; once lifted the part moves with the
        # gripper (a grasp approached off the vertical drags the open jaws through the resting part)
        free = [sg for sg in traj["segments"] if not sg["attached"]]
        assert free and free[0]["start"] == 0
        assert independent_path_free(tless20["scene_factory"], q[:max(sg["end"] for sg in free) + 1], opening)
        assert np.max(np.abs(qd) / np.asarray(robot.velocity_limit)) <= 1.0


@pytest.mark.slow
@pytest.mark.paper
def test_tless20_csv(tless20):
    doc, result = tless20["doc"], tless20["result"]
    text = render(result, "csv")[".csv"]
    lines = text.splitlines()
    assert len(lines) == 1 + len(doc["grasps"])
    planned = set(result.planned_ids())
    rows = [r_ for r_ in csv.DictReader(io.StringIO(text)) if r_["status"] == "planned"]
    assert {int(r_["id"]) for r_ in rows} == planned
    by_id = {g["id"]: g for g in doc["grasps"] if g["id"] in planned}
    for r_ in rows:
        np.testing.assert_allclose([float(r_[f"q_{j}"]) for j in doc["robot"]["joint_names"]],
                                   by_id[int(r_["id"])]["q_grasp"], atol=1e-8)
