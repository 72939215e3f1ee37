"""CollisionScene: pair selection, opening, paths, and a cross-check against python-fcl."""
from __future__ import annotations

import math

import fcl
import numpy as np
import pytest
import trimesh

from grasplan.cell.model import load_cell
from grasplan.errors import InputError
from grasplan.gripper.load import load_gripper
from grasplan.robot.ik.solve import solve_ik
from grasplan.part.mesh import load_part
from grasplan.robot.description import load_robot
from grasplan.motion.collision_scene import CollisionScene
from grasplan.cell.resting import stable_pose


@pytest.fixture(scope="module")
def cellparts(example_part):
    part = load_part(example_part("bracket.stl"), units="mm")
    cell = load_cell()
    return part, cell, stable_pose(part.mesh, cell)


@pytest.fixture(scope="module")
def gripper():
    return load_gripper("long_stroke_50")


@pytest.fixture(scope="module", params=["ur5", "panda"])
def scene(request, cellparts, gripper):
    part, cell, T = cellparts
    return CollisionScene(load_robot(request.param), gripper, part.mesh, T, cell)


def _tcp_above(x, y, z):
    """TCP pose pointing straight down (approach -z world), closing axis along world x."""
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = [x, y, z]
    return T


def _q_for_tcp(robot, gripper, T_world_tcp):
    res = solve_ik(robot, T_world_tcp @ np.linalg.inv(gripper.T_flange_tcp), max_solutions=4)
    assert res.ok, res.reason
    return res.q[0]


def test_home_is_free_and_pairs_follow_the_rules(scene):
    r = scene.robot
    assert scene.is_free(r.q_home, 0.05) and scene.first_collision(r.q_home, 0.05) is None
    pairs = set(scene.pair_names)
    link = {g.name: r.link_name(g) for g in r.collision_model.geometryObjects}
    for a, b in pairs:
        if a in link and b in link:  # self pairs: no SRDF-disabled pair
            assert tuple(sorted((link[a], link[b]))) not in r.disabled_pairs
        if b == "table":
            assert link.get(a) not in r.mounted_links
    # every non-mounted link is checked against the table and every link against the part
    for g, ln in link.items():
        assert ((g, "table") in pairs) == (ln not in r.mounted_links)
        assert (g, "part") in pairs
    # the gripper is not checked against the links that carry it
    tool_joint = r.tool_joint_id
    for g in r.collision_model.geometryObjects:
        assert ((g.name, "gripper_body_0") in pairs) == (g.parentJoint != tool_joint)
    for g in ("gripper_body_0", "finger_left", "finger_right"):
        assert (g, "table") in pairs and (g, "part") in pairs


def test_gripper_into_table_and_part(cellparts, gripper):
    part, cell, T_wp = cellparts
    r = load_robot("ur5")
    scene = CollisionScene(r, gripper, part.mesh, T_wp, cell)
    # fingertips 8 mm beyond the TCP: TCP 5 mm above the table puts them 3 mm into it
    q = _q_for_tcp(r, gripper, _tcp_above(0.3, 0.3, 0.005))
    assert scene.collision_kind(q, 0.05) == "table"
    assert "table" in scene.first_collision(q, 0.05)
    q = _q_for_tcp(r, gripper, _tcp_above(0.3, 0.3, 0.02))
    assert scene.is_free(q, 0.05)
    # a 60 x 60 x 40 mm block: TCP 10 mm below its top, the jaws closed, is inside it
    block = trimesh.creation.box(extents=[0.06, 0.06, 0.04])
    T_wb = np.eye(4)
    T_wb[:3, 3] = [0.45, -0.1, 0.02]
    scene_b = CollisionScene(r, gripper, block, T_wb, cell)
    q = _q_for_tcp(r, gripper, _tcp_above(0.45, -0.1, 0.03))
    assert scene_b.collision_kind(q, 0.0) == "part"
    assert "part" in scene_b.first_collision(q, 0.0)
    # and 5 cm above the block it is free
    q = _q_for_tcp(r, gripper, _tcp_above(0.45, -0.1, 0.09))
    assert scene_b.is_free(q, 0.0)


def test_opening_moves_the_fingers(gripper):
    """A 20 mm wide bar between the jaws: open (50 mm) is free, closed to 10 mm is not."""
    r = load_robot("ur5")
    bar = trimesh.creation.box(extents=[0.020, 0.010, 0.030])
    T_wp = np.eye(4)
    T_wp[:3, 3] = [0.45, 0.1, 0.015]
    scene = CollisionScene(r, gripper, bar, T_wp, load_cell())
    q = _q_for_tcp(r, gripper, _tcp_above(0.45, 0.1, 0.02))
    assert scene.is_free(q, 0.05)
    hit = scene.first_collision(q, 0.01)
    assert hit is not None and "finger" in hit and "part" in hit
    assert scene.is_free(q, 0.03)  # back open: the cached finger placement follows
    with pytest.raises(InputError):
        scene.is_free(q, 0.2)


def test_self_collision_detected():
    r = load_robot("ur5")
    scene = CollisionScene(r, load_gripper("long_stroke_50"), None, None, None)
    q = np.array([0.0, -1.0, 3.1, 0.0, 0.0, 0.0])  # forearm folded back onto the upper arm region
    kinds = {k for *_, k in scene.colliding_pairs(q, 0.05)}
    assert kinds == {"self"}
    assert not scene.is_free(q, 0.05)


def test_path_free_interpolates_at_step(cellparts, gripper):
    part, cell, T_wp = cellparts
    r = load_robot("ur5")
    scene = CollisionScene(r, gripper, part.mesh, T_wp, cell)
    rng = np.random.default_rng(0)
    found = 0
    for _ in range(400):
        a, b = rng.uniform(-math.pi, math.pi, size=(2, 6))
        a[2], b[2] = np.clip([a[2], b[2]], -3.0, 3.0)
        if not (scene.is_free(a, 0.05) and scene.is_free(b, 0.05)):
            continue
        n = int(math.ceil(np.max(np.abs(b - a)) / 0.01))
        dense = all(scene.is_free(a + (b - a) * i / n, 0.05) for i in range(n + 1))
        assert scene.path_free(np.stack([a, b]), 0.05, step=0.01) == dense
        found += not dense
        if found >= 3:
            break
    assert found >= 3  # some segments had free ends but a collision in between
    # a coarser step cannot see more than the fine one
    assert scene.path_free(np.stack([r.q_home, r.q_home]), 0.05)
    with pytest.raises(InputError):
        scene.path_free(np.zeros((2, 5)), 0.05)


# ---- independent check: python-fcl ------------------------------------------------------------
def _fcl_bvh(vertices, faces):
    m = fcl.BVHModel()
    m.beginModel(len(vertices), len(faces))
    m.addSubModel(np.asarray(vertices, dtype=float), np.asarray(faces, dtype=np.int32))
    m.endModel()
    return m


def _fcl_obj(geom, T):
    return fcl.CollisionObject(geom, fcl.Transform(T[:3, :3], T[:3, 3]))


class FclCheck:
    """Robot links (collision meshes via trimesh), gripper boxes, table half-space and part in
    python-fcl, placed by Pinocchio FK; returns the set of colliding (object, env) pairs."""

    def __init__(self, robot, gripper, part_mesh, T_world_part, cell):
        import pinocchio as pin
        self.pin = pin
        self.robot = robot
        self.gripper = gripper
        self.data = robot.model.createData()
        self.links = []
        for g in robot.collision_model.geometryObjects:
            geo = g.geometry
            if hasattr(geo, "halfSide"):  # the UR5's ee_link box primitive
                geom = fcl.Box(*(2 * np.asarray(geo.halfSide)))
            else:
                mesh = trimesh.load(g.meshPath, force="mesh")
                geom = _fcl_bvh(np.asarray(mesh.vertices) * np.asarray(g.meshScale), mesh.faces)
            self.links.append((g.name, robot.link_name(g), g.parentJoint, g.placement.homogeneous, geom))
        self.table = fcl.CollisionObject(fcl.Halfspace(np.array([0.0, 0.0, 1.0]), float(cell.table_z)))
        self.part = _fcl_obj(_fcl_bvh(part_mesh.vertices, part_mesh.faces), T_world_part)

    def collisions(self, q, opening):
        pin, r = self.pin, self.robot
        pin.forwardKinematics(r.model, self.data, q)
        objs = []
        for name, link, joint, placement, geom in self.links:
            objs.append((name, link, _fcl_obj(geom, self.data.oMi[joint].homogeneous @ placement)))
        T_world_tcp = r.fk(q) @ self.gripper.T_flange_tcp
        shapes = list(zip([f"gripper_body_{k}" for k in range(len(self.gripper.body))], self.gripper.body))
        shapes += list(zip(("finger_left", "finger_right"), self.gripper.fingers(opening)))
        for name, box in shapes:
            objs.append((name, None, _fcl_obj(fcl.Box(*box.extents), T_world_tcp @ box.T_tcp_box)))
        hits = set()
        req = fcl.CollisionRequest()
        for name, link, o in objs:
            if link not in r.mounted_links and fcl.collide(o, self.table, req, fcl.CollisionResult()):
                hits.add((name, "table"))
            if fcl.collide(o, self.part, req, fcl.CollisionResult()):
                hits.add((name, "part"))
        return hits


@pytest.mark.parametrize("robot_name", ["ur5", "panda"])
def test_scene_agrees_with_python_fcl(robot_name, cellparts, gripper):
    part, cell, T_wp = cellparts
    r = load_robot(robot_name)
    scene = CollisionScene(r, gripper, part.mesh, T_wp, cell)
    ref = FclCheck(r, gripper, part.mesh, T_wp, cell)
    rng = np.random.default_rng(42)
    qs = list(rng.uniform(r.lower, r.upper, size=(150, r.nq)))
    # and configurations with the gripper close to the part, where part collisions happen
    c = T_wp[:3, :3] @ part.mesh.center_mass + T_wp[:3, 3]
    while len(qs) < 260:
        T = _tcp_above(*(c + rng.uniform([-0.06, -0.06, -0.02], [0.06, 0.06, 0.08])))
        Rz = trimesh.transformations.rotation_matrix(rng.uniform(-math.pi, math.pi), [0, 0, 1])
        Rt = trimesh.transformations.rotation_matrix(rng.uniform(-0.6, 0.6), [1, 0, 0])
        T[:3, :3] = T[:3, :3] @ Rz[:3, :3] @ Rt[:3, :3]
        res = solve_ik(r, T @ np.linalg.inv(gripper.T_flange_tcp), max_solutions=1, n_random_seeds=2)
        if res.ok:
            qs.append(res.q[0])
    n_part = n_table = 0
    for i, q in enumerate(qs):
        opening = float(rng.uniform(0.0, gripper.max_opening))
        mine = {(a, b) for a, b, kind in scene.colliding_geometries(q, opening) if kind in ("table", "part")}
        theirs = ref.collisions(q, opening)
        assert mine == theirs, f"config {i} q={q.tolist()} opening={opening}"
        n_part += any(b == "part" for _, b in mine)
        n_table += any(b == "table" for _, b in mine)
    # the sample exercised both kinds and free configurations
    assert n_part >= 10 and n_table >= 30 and n_table < len(qs)
