"""Issue 12 part A: obstacles, bin and wall cells, checks before planning, reasons naming bodies,
``--pose-index all``. Every planned path is re-checked independently with python-fcl
(tests/fcl_recheck.py: URDF geometry, Pinocchio only for FK)."""
from __future__ import annotations

import json
import math

import fcl
import numpy as np
import pytest
import trimesh
from click.testing import CliRunner
from conftest import EXAMPLE_PARTS, paper_part
from fcl_recheck import FclWorld, recheck_result

from grasplan.cell.model import BIN_NAMES, Cell, cell_from_dict, load_cell
from grasplan.cli import main
from grasplan.grasps.collision import GripperCollider
from grasplan.errors import ConfigError, InputError
from grasplan.gripper.load import load_gripper
from grasplan.config.params import PlanParams
from grasplan.geometry.transforms import parse_place
from grasplan.motion.planning import plan
from grasplan.robot.description import load_robot
from grasplan.motion.collision_scene import CollisionScene
from grasplan.cell.resting import stable_pose
from grasplan.motion.start_checks import check_part_placement, check_start

WALL = {"name": "wall", "box": {"size": [0.02, 0.40, 0.30]}, "T": {"xyz": [0.53, 0.0, 0.15], "rpy_deg": [0, 0, 0]}}
POST = {"name": "post", "cylinder": {"radius": 0.02, "length": 0.30}, "T": {"xyz": [0.40, -0.10, 0.15]}}
BALL = {"name": "ball", "sphere": {"radius": 0.03}, "T": {"xyz": [0.5, 0.1, 0.2]}}
BIN = {"inner": [0.30, 0.20], "wall": 0.01, "height": 0.15, "T": {"xyz": [0.45, 0.0, 0.0]}}


# -- YAML parsing and validation -------------------------------------------------------------------
def test_issue_example_parses_and_round_trips(tmp_path):
    stl = tmp_path / "fixture.stl"
    trimesh.creation.box(extents=[20, 30, 10]).export(stl)  # millimetres, scaled by 0.001
    fixture = {"name": "fixture", "mesh": {"path": "fixture.stl", "scale": 0.001}, "T": {"xyz": [0.2, 0.3, 0.005]}}
    data = {"name": "demo", "obstacles": [WALL, POST, BALL, fixture], "bin": BIN,
            "retreat": {"direction": [0, 0, 2], "distance": 0.08}, "place": {"T": {"xyz": [0.45, 0.3, 0.0]}}}
    c = cell_from_dict(data, name="demo", source=str(tmp_path / "demo.yaml"), base=tmp_path)
    names = [o.name for o in c.obstacles]
    assert names == list(BIN_NAMES) + ["wall", "post", "ball", "fixture"]
    assert c.retreat_direction == (0.0, 0.0, 1.0) and c.retreat_distance == 0.08
    assert np.allclose(c.place[:3, 3], [0.45, 0.3, 0.0])
    assert c.workspace is None and "workspace" not in c.to_json()  # written only when set
    ws = cell_from_dict({**data, "workspace": {"min": [0.3, -0.1], "max": [0.6, 0.1]}}, name="demo",
                        source=str(tmp_path / "demo.yaml"), base=tmp_path)
    assert ws.workspace.to_json() == {"min": [0.3, -0.1], "max": [0.6, 0.1]} and ws != c
    assert Cell.from_json(json.loads(json.dumps(ws.to_json()))) == ws
    # the bin: the part rests on the floor's top at its centre; walls from the floor up
    assert c.rest_z == 0.0 and c.part_xy == (0.45, 0.0)
    lo, hi = c.obstacle("bin_wall_+x").aabb()
    assert np.allclose(lo, [0.60, -0.11, 0.0]) and np.allclose(hi, [0.61, 0.11, 0.15])
    lo, hi = c.obstacle("bin_floor").aabb()
    assert np.allclose(lo, [0.29, -0.11, -0.01]) and np.allclose(hi, [0.61, 0.11, 0.0])
    # the mesh is embedded (scaled) and rotations follow R = Rz(yaw) Ry(pitch) Rx(roll)
    m = c.obstacle("fixture")
    assert np.allclose(np.ptp(m.vertices, axis=0), [0.02, 0.03, 0.01])
    again = Cell.from_json(json.loads(json.dumps(c.to_json())))
    assert again == c and again is not c
    tilted = cell_from_dict({"obstacles": [{**POST, "T": {"xyz": [0, 0, 0], "rpy_deg": [90, 0, 0]}}]},
                            name="t", source="t.yaml")
    lo, hi = tilted.obstacles[0].aabb()  # roll 90 deg: the cylinder's axis (local z) along world -y
    assert np.allclose(hi - lo, [0.04, 0.30, 0.04])


def test_packaged_cells():
    wall = load_cell("wall")
    w = wall.obstacle("wall")
    lo, hi = w.aabb()
    assert lo[0] - wall.part_xy[0] == pytest.approx(0.07)  # its face 70 mm beyond the part position
    assert hi[0] - lo[0] == pytest.approx(0.02)
    b = load_cell("bin")
    assert {o.name for o in b.obstacles} == set(BIN_NAMES) and b.bin is not None
    assert b.obstacle("bin_floor").aabb()[0][2] == pytest.approx(b.table_z)  # the floor stands on the table
    assert load_cell("table").obstacles == ()


BAD = [
    ({"obstacles": [{**WALL, "colour": "red"}]}, "obstacles[0]: unknown keys ['colour']; valid: ['name', 'box'"),
    ({"obstacles": [{k: v for k, v in WALL.items() if k != "name"}]}, "obstacles[0].name: missing"),
    ({"obstacles": [{**WALL, "name": "a b"}]}, "obstacles[0].name: expected 1-64 characters"),
    ({"obstacles": [{k: v for k, v in WALL.items() if k != "T"}]}, "obstacles[0].T: missing"),
    ({"obstacles": [{"name": "x", "T": WALL["T"]}]}, "expected exactly one shape of box, cylinder, sphere, mesh"),
    ({"obstacles": [{**WALL, "sphere": {"radius": 1}}]}, "expected exactly one shape"),
    ({"obstacles": [{**WALL, "box": {"size": [0.1, 0.1]}}]}, "obstacles[0].box.size: expected a list of 3 numbers"),
    ({"obstacles": [{**WALL, "box": {"size": [0.1, -0.1, 0.1]}}]}, "obstacles[0].box.size"),
    ({"obstacles": [{**WALL, "box": {"extents": [0.1, 0.1, 0.1]}}]}, "valid: ['size']"),
    ({"obstacles": [{**POST, "cylinder": {"radius": 0.02}}]}, "obstacles[0].cylinder.length: missing"),
    ({"obstacles": [{**BALL, "sphere": {"radius": "nan"}}]}, "obstacles[0].sphere.radius"),
    ({"obstacles": [{**BALL, "sphere": {"radius": 0}}]}, "obstacles[0].sphere.radius"),
    ({"obstacles": [{**WALL, "T": {"xyz": [0, 0]}}]}, "obstacles[0].T.xyz: expected a list of 3 numbers"),
    ({"obstacles": [{**WALL, "T": {"pos": [0, 0, 0]}}]}, "obstacles[0].T: unknown keys ['pos']; valid: ['rpy_deg', 'xyz']"),
    ({"obstacles": [{**WALL, "T": {"xyz": [0, 0, 99]}}]}, "obstacles[0].T.xyz: coordinates must be within"),
    ({"obstacles": [{**WALL, "mesh": None}]}, "expected exactly one shape"),
    ({"obstacles": [{"name": "m", "mesh": {"path": "nope.stl"}, "T": {"xyz": [0, 0, 0]}}]}, "mesh file"),
    ({"obstacles": [WALL, WALL]}, "two obstacles are named 'wall'"),
    ({"obstacles": [{**WALL, "name": "bin_floor"}], "bin": BIN}, "reserved for the bin's boxes"),
    ({"obstacles": {"wall": WALL}}, "obstacles: expected a list"),
    ({"bin": {**BIN, "depth": 1}}, "bin: unknown keys ['depth']; valid: ['height', 'inner', 'T', 'wall']"),
    ({"bin": {k: v for k, v in BIN.items() if k != "wall"}}, "bin.wall: missing"),
    ({"bin": {**BIN, "inner": [0.3]}}, "bin.inner: expected a list of 2 numbers"),
    ({"bin": {**BIN, "T": {"xyz": [0.45, 0, 0], "rpy_deg": [10, 0, 0]}}}, "bin.T: the bin must stand upright"),
    ({"retreat": {"direction": [0, 0, 0]}}, "retreat.direction: must not be zero"),
    ({"retreat": {"distance": -0.1}}, "retreat.distance"),
    ({"retreat": {"speed": 1}}, "retreat: unknown keys ['speed']"),
    ({"place": {"xyz": [0, 0, 0]}}, "place: expected {T: {xyz"),
    ({"workspace": {"min": [0.3, -0.1]}}, "workspace: expected {min: [x, y], max: [x, y]}"),
    ({"workspace": {"min": [0.3], "max": [0.6, 0.1]}}, "workspace.min: expected [x, y] in metres"),
    ({"workspace": {"min": [0.6, -0.1], "max": [0.3, 0.1]}}, "must be below max"),
    ({"workspace": {"min": [0.3, "a"], "max": [0.6, 0.1]}}, "workspace.min[1]"),
    ({"shelves": []}, "unknown cell fields ['shelves']; allowed:"),
]


@pytest.mark.parametrize("data, message", BAD, ids=[m[:40] for _, m in BAD])
def test_bad_cell_fields_are_named(data, message, tmp_path):
    with pytest.raises(ConfigError) as exc:
        cell_from_dict(data, name="t", source=str(tmp_path / "t.yaml"), base=tmp_path)
    assert message in str(exc.value)


def test_bad_cell_file_through_the_cli_exits_3(tmp_path):
    y = tmp_path / "c.yaml"
    y.write_text("obstacles:\n  - {name: wall, box: {size: [0.02, 0.4]}, T: {xyz: [0.53, 0, 0.15]}}\n")
    r = CliRunner().invoke(main, ["grasps", str(EXAMPLE_PARTS / "box.stl"), "--cell", str(y), "-o",
                                  str(tmp_path / "o.json")])
    assert r.exit_code == 3 and "obstacles[0].box.size" in r.output and "Traceback" not in r.output


def test_tampered_obstacles_in_a_result_are_refused():
    doc = load_cell("wall").to_json()
    ob = doc["obstacles"][0]
    for bad in ({**ob, "box": {"size": [1, 1]}}, {**ob, "T_world_obstacle": [[2, 0, 0, 0]] * 4},
                {**ob, "cone": {}}, {k: v for k, v in ob.items() if k != "name"}):
        with pytest.raises(ConfigError):
            Cell.from_json({**doc, "obstacles": [bad]})
    assert Cell.from_json({k: v for k, v in doc.items() if k not in ("obstacles", "bin", "retreat", "place")}) \
        == Cell("wall")  # files written before issue 12 load with the defaults


def test_parse_place():
    T = parse_place("450mm, 0.3, 0, 0, 0, 90")
    assert np.allclose(T[:3, 3], [0.45, 0.3, 0.0]) and np.allclose(T[:3, 0], [0, 1, 0], atol=1e-12)
    for bad in ("1,2,3", "a,b,c,d,e,f", "0,0,0,0,0,nan", "99,0,0,0,0,0"):
        with pytest.raises(InputError, match="--place"):
            parse_place(bad)


# -- the gripper filter vs python-fcl --------------------------------------------------------------
def _fcl_obstacle(o):
    g = {"box": lambda: fcl.Box(*o.size), "cylinder": lambda: fcl.Cylinder(o.radius, o.length),
         "sphere": lambda: fcl.Sphere(o.radius)}[o.kind]()
    T = np.asarray(o.T_world_obstacle)
    return fcl.CollisionObject(g, fcl.Transform(T[:3, :3], T[:3, 3]))


def test_gripper_filter_obstacles_agree_with_python_fcl():
    """Random TCP poses around a box, a tilted cylinder and a sphere (far from the part and above
    the table): collision_obstacle exactly when python-fcl finds a gripper shape (body, swept
    jaws) touching an obstacle; the reason names the element and the obstacle."""
    g = load_gripper()
    cell = cell_from_dict({"obstacles": [
        {"name": "blk", "box": {"size": [0.05, 0.04, 0.03]}, "T": {"xyz": [0.2, 0.2, 0.3], "rpy_deg": [20, 10, 30]}},
        {"name": "pipe", "cylinder": {"radius": 0.015, "length": 0.08}, "T": {"xyz": [0.2, -0.2, 0.3],
                                                                               "rpy_deg": [0, 70, 0]}},
        {"name": "ball", "sphere": {"radius": 0.02}, "T": {"xyz": [-0.2, 0.0, 0.3]}}]}, name="t", source="t.yaml")
    part = trimesh.creation.box(extents=[0.02, 0.02, 0.02])
    T_world_part = np.eye(4)
    T_world_part[:3, 3] = [0.8, 0.8, 0.01]
    col = GripperCollider(part, g, cell, T_world_part)
    rng = np.random.default_rng(3)
    n = 600
    from scipy.spatial.transform import Rotation

    centres = np.array([[0.2, 0.2, 0.3], [0.2, -0.2, 0.3], [-0.2, 0.0, 0.3]])[rng.integers(0, 3, n)]
    T_world_tcp = np.tile(np.eye(4), (n, 1, 1))
    T_world_tcp[:, :3, :3] = Rotation.random(n, random_state=4).as_matrix()
    T_world_tcp[:, :3, 3] = centres + rng.uniform(-0.09, 0.09, (n, 3))
    width = rng.uniform(0.005, 0.04, n)
    T_part_tcp = np.linalg.inv(T_world_part) @ T_world_tcp
    status, elem, body = col.check_detail(T_part_tcp, width)
    reasons = col.reasons(status, elem, body)
    obst = [(f"obstacle:{o.name}", _fcl_obstacle(o)) for o in cell.obstacles]
    req = fcl.CollisionRequest()
    n_hit = 0
    for k in range(n):
        shapes = list(g.body) + list(g.swept_fingers(g.pregrasp_opening(width[k]), g.close_to_opening(width[k])))
        mine = None
        for si, s in enumerate(shapes):
            T = T_world_tcp[k] @ s.T_tcp_box
            box = fcl.CollisionObject(fcl.Box(*s.extents), fcl.Transform(T[:3, :3], T[:3, 3]))
            for name, o in obst:
                if fcl.collide(box, o, req, fcl.CollisionResult()):
                    mine = mine or (si, name)
        below = status[k] == "collision_table"
        if below:
            continue
        assert (status[k] == "collision_obstacle") == (mine is not None), k
        if mine is not None:
            n_hit += 1
            assert reasons[k].startswith("grasp stage: gripper:") and "hits obstacle:" in reasons[k]
    assert 60 <= n_hit <= n - 60  # both outcomes exercised


# -- the robot scene: obstacles, attached part, variants --------------------------------------------
@pytest.fixture(scope="module")
def ur5():
    return load_robot("ur5")


def test_scene_with_obstacles_agrees_with_python_fcl(ur5):
    """Random configurations in the bin cell: the scene's colliding body pairs (kinds table,
    obstacle, part) equal python-fcl's (fcl_recheck.FclWorld, geometry from the URDF)."""
    g = load_gripper()
    cell = load_cell("bin")
    part = trimesh.creation.box(extents=[0.04, 0.03, 0.05])
    T_wp = stable_pose(part, cell)
    scene = CollisionScene(ur5, g, part, T_wp, cell)
    world = FclWorld(ur5, g, cell, part)
    rng = np.random.default_rng(7)
    from scipy.spatial.transform import Rotation

    from grasplan.robot.ik.solve import solve_ik

    qs = list(rng.uniform(ur5.lower, ur5.upper, size=(60, ur5.nq)))
    while len(qs) < 180:  # the gripper near the bin's walls and floor, tilted
        T = np.eye(4)
        T[:3, :3] = np.diag([1.0, -1.0, -1.0]) @ Rotation.from_rotvec(rng.uniform(-0.7, 0.7, 3)).as_matrix()
        T[:3, 3] = rng.uniform([0.26, -0.15, 0.0], [0.64, 0.15, 0.2])
        res = solve_ik(ur5, T @ np.linalg.inv(g.T_flange_tcp), max_solutions=1, n_random_seeds=2)
        if res.ok:
            qs.append(res.q[0])
    n_obst = 0
    for q in qs:
        opening = float(rng.uniform(0, g.max_opening))
        mine = {f"{a} vs {b}" for a, b, kind in scene.colliding_pairs(q, opening) if kind != "self"}
        theirs = {h for h in world.check(q, opening, "static", T_wp)
                  if h.split(" vs ")[1] in ("table", "part") or h.split(" vs ")[1].startswith("obstacle:")}
        assert mine == theirs, q.tolist()
        n_obst += any("obstacle:" in h for h in mine)
    assert 20 <= n_obst < len(qs) - 20


def test_attached_and_released_variants(ur5):
    g = load_gripper()
    cell = load_cell("table")
    part = trimesh.creation.box(extents=[0.03, 0.03, 0.06])
    T_wp = stable_pose(part, cell)
    scene = CollisionScene(ur5, g, part, T_wp, cell)
    # a grasp from above: TCP 15 mm below the part's top, z of the TCP down
    T_world_tcp = np.eye(4)
    T_world_tcp[:3, :3] = np.diag([1.0, -1.0, -1.0])
    top = float((part.vertices @ T_wp[:3, :3].T + T_wp[:3, 3])[:, 2].max())
    T_world_tcp[:3, 3] = [T_wp[0, 3], T_wp[1, 3], top - 0.015]
    from grasplan.robot.ik.solve import solve_ik

    q = solve_ik(ur5, T_world_tcp @ np.linalg.inv(g.T_flange_tcp)).q[0]
    T_tcp_part = np.linalg.inv(T_world_tcp) @ T_wp
    att = scene.attached(T_tcp_part)
    assert att.is_free(q, 0.04)  # the part rests on the table: contact within ATTACHED_CONTACT_TOL
    assert scene.colliding_pairs(q, 0.0)  # closed jaws inside the static part
    assert att.is_free(q, 0.0)  # the attached part is not checked against the jaws holding it
    # 2 mm lower: the attached part is pushed into the table
    T_low = T_world_tcp.copy()
    T_low[2, 3] -= 0.002
    q_low = solve_ik(ur5, T_low @ np.linalg.inv(g.T_flange_tcp)).q[0]
    assert att.colliding_pairs(q_low, 0.04) == [("part", "table", "table")]
    # the static part elsewhere: the gripper at q no longer touches it even closed
    T_far = T_wp.copy()
    T_far[1, 3] += 0.3
    away = scene.with_part_at(T_far)
    assert away.is_free(q, 0.0) and not scene.is_free(q, 0.0) and away.is_free(q, 0.0)  # variants switch back and forth
    assert att.first_collision(q_low, 0.04) == "part vs table"


# -- checks before planning -------------------------------------------------------------------------
def test_part_pose_7_7_mm_in_the_table_is_refused(tmp_path):
    box = EXAMPLE_PARTS / "box.stl"
    r = CliRunner().invoke(main, ["plan", str(box), "--robot", "ur5", "--part-pose", "0.45,0,-2.7mm,0,0,0",
                                  "-o", str(tmp_path / "p.json")])
    # the example box is 30 x 20 x 10 mm, centred on its frame: its bottom at -2.7 - 5 = -7.7 mm
    assert r.exit_code == 3, r.output
    assert "7.7 mm into the table" in r.output and "--part-pose" in r.output
    assert not (tmp_path / "p.json").exists()


def test_part_in_an_obstacle_is_refused():
    part = trimesh.creation.box(extents=[0.04, 0.04, 0.04])
    cell = load_cell("wall")
    T = stable_pose(part, cell)
    check_part_placement(part, T, cell)  # 50 mm from the wall: fine
    T[0, 3] += 0.06  # 10 mm into the plate
    with pytest.raises(InputError, match=r"intersects obstacle 'wall' \(penetration 10.0 mm\)"):
        check_part_placement(part, T, cell)


def test_q_home_in_collision_names_both_bodies(ur5):
    g = load_gripper()
    cell = cell_from_dict({"table_z": 0.1}, name="raised", source="raised.yaml")
    part = trimesh.creation.box(extents=[0.04, 0.04, 0.04])
    scene = CollisionScene(ur5, g, part, stable_pose(part, cell), cell)
    with pytest.raises(ConfigError, match=r"q_home: upper_arm_link collides with table: .*change q_home"):
        check_start(scene, part_mesh=part)


def test_base_inside_an_obstacle(ur5):
    g = load_gripper()
    cell = cell_from_dict({"obstacles": [{"name": "pillar", "box": {"size": [0.3, 0.3, 0.3]},
                                          "T": {"xyz": [0, 0, 0.1]}}]}, name="p", source="p.yaml")
    part = trimesh.creation.box(extents=[0.04, 0.04, 0.04])
    with pytest.raises(ConfigError, match=r"robot's base is inside obstacle:pillar \(base_link"):
        check_start(CollisionScene(ur5, g, part, stable_pose(part, cell), cell), part_mesh=part)


def test_checks_run_in_plan_before_the_grasp_stage(ur5, tmp_path):
    y = tmp_path / "raised.yaml"
    y.write_text("name: raised\ntable_z: 0.1\npart_xy: [0.45, 0.0]\n")
    r = CliRunner().invoke(main, ["plan", str(EXAMPLE_PARTS / "box.stl"), "--robot", "ur5", "--cell", str(y),
                                  "-o", str(tmp_path / "p.json")])
    assert r.exit_code == 3 and "q_home: upper_arm_link collides with table" in r.output, r.output


# -- planning with obstacles, every path re-checked with python-fcl -----------------------------------
def _assert_rechecked(res, minimum: int):
    st = res.grasps.status.astype(str)
    assert int(np.count_nonzero(st == "planned")) >= minimum, dict(zip(*np.unique(st, return_counts=True)))
    reports = recheck_result(res)
    assert len(reports) >= minimum
    for i, rep in reports.items():
        assert rep.configs > 10 and rep.ok, (i, rep.problems)


def test_obstacle_across_the_approach_turns_the_grasp_into_collision_obstacle(tmp_path):
    part = EXAMPLE_PARTS / "box.stl"
    free = plan(part, "ur5", cell="table", planning=PlanParams(top=1))
    _assert_rechecked(free, 1)
    gid = next(iter(free.motions))
    m = free.motions[gid]
    # a 4 mm plate across the approach, 40 mm up the approach axis from the grasp TCP
    T_world_tcp = free.T_world_part @ free.grasps.T_part_tcp[gid]
    centre = T_world_tcp @ [0, 0, -0.04, 1]
    rpy = np.degrees(trimesh.transformations.euler_from_matrix(T_world_tcp, "sxyz"))
    y = tmp_path / "plate.yaml"
    y.write_text(json.dumps({"name": "plate", "obstacles": [{"name": "plate", "box": {"size": [0.08, 0.08, 0.004]},
                                                             "T": {"xyz": centre[:3].tolist(), "rpy_deg": rpy.tolist()}}]}))
    blocked = plan(part, "ur5", cell=str(y), planning=PlanParams(top=3))
    assert np.allclose(blocked.grasps.T_part_tcp[gid], free.grasps.T_part_tcp[gid])  # the same grasp
    st = str(blocked.grasps.status[gid])
    if st == "collision_obstacle":
        assert "hits obstacle:plate" in blocked.grasps.reason[gid] and "gripper:" in blocked.grasps.reason[gid]
    else:  # planned on another path: it must differ and be free of the plate
        assert st == "planned" and not np.array_equal(blocked.motions[gid].path, m.path)
    # the old path crosses the plate: the independent check says so
    world = FclWorld(blocked.robot, blocked.gripper, blocked.cell, blocked.mesh())
    rep = recheck_result(free, [gid], world=world)[gid]
    assert not rep.ok and "obstacle:plate" in rep.problems[0]
    for i, rep in recheck_result(blocked).items():  # whatever else planned is free of the plate
        assert rep.ok, (i, rep.problems)


@pytest.mark.parametrize("cell", ["bin", "wall"])
@pytest.mark.parametrize("name", ["TLess20.stl", "SileanePepper.stl"])
def test_bin_and_wall_cells_plan_five_checked_grasps(cell, name):
    res = plan(paper_part(name), "ur5", cell=cell, planning=PlanParams(top=5))
    _assert_rechecked(res, 5)
    st = res.grasps.status.astype(str)
    if cell == "bin" or name == "TLess20.stl":
        # the obstacles did reject gripper poses (on SileanePepper in the wall cell every pose that
        # reaches the wall is already rejected by the part or the table, which take precedence)
        assert np.count_nonzero(st == "collision_obstacle") > 0
    rej = res.grasps.reason[st == "collision_obstacle"]
    assert all(r.startswith("grasp stage: gripper:") and "obstacle:" in r for r in rej[:50])


def test_plan_file_with_obstacles_stands_alone(tmp_path):
    import grasplan

    res = plan(EXAMPLE_PARTS / "box.stl", "ur5", cell="wall", planning=PlanParams(top=1))
    out = res.write(tmp_path / "p.json")
    again = grasplan.load_result(out)
    assert again.cell == res.cell and again.cell.obstacle("wall").kind == "box"
    assert recheck_result(again)[next(iter(again.motions))].ok


# -- resting poses ------------------------------------------------------------------------------------
def test_pose_index_all_and_the_exit_4_hint(tmp_path):
    """A 100 x 60 x 12 mm plate: lying flat (poses 0, 1) nothing can be grasped (60 mm > the 50 mm
    jaws, the 12 mm edge is on the table); on its long edge (poses 2, 3: 5.4 % each) it can."""
    stl = tmp_path / "plate.stl"
    trimesh.creation.box(extents=[0.1, 0.06, 0.012]).export(stl)
    runner = CliRunner()
    r = runner.invoke(main, ["plan", str(stl), "--units", "m", "--robot", "ur5", "--gripper", "long_stroke_50", "--top", "2",
                             "-o", str(tmp_path / "one.json")])
    assert r.exit_code == 4, r.output
    assert "other resting poses with collision-free grasps: 2 (5 %)" in r.output and "--pose-index all" in r.output
    r = runner.invoke(main, ["plan", str(stl), "--units", "m", "--robot", "ur5", "--gripper", "long_stroke_50", "--top", "2", "--pose-index", "all",
                             "-o", str(tmp_path / "all.json")])
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "all.json").read_text())
    poses = {p["pose_index"]: p for p in doc["poses"]["poses"]}
    from grasplan.part.stability import stable_poses

    prob = stable_poses(trimesh.load(stl))[1]
    assert set(poses) == {k for k, pr in enumerate(prob) if pr >= 0.02} and min(prob) < 0.02 <= prob[3]
    assert poses[0]["planned"] == 0 and poses[2]["planned"] == 2
    assert doc["poses"]["chosen"] in (2, 3) and doc["counts"]["planned"] == 2
    import grasplan

    for p in poses.values():
        res = grasplan.load_result(tmp_path / p["file"])
        assert np.allclose(res.T_world_part, p["T_world_part"])
        assert res.counts()["planned"] == p["planned"]
    assert grasplan.load_result(tmp_path / "all.json").counts()["planned"] == 2
    r = runner.invoke(main, ["plan", str(stl), "--units", "m", "--pose-index", "some", "-o", str(tmp_path / "x.json")])
    assert r.exit_code == 2 and "neither a whole number nor 'all'" in r.output


def test_cylinder_and_sphere_obstacle_bounds_are_exact():
    c = cell_from_dict({"obstacles": [POST, BALL]}, name="t", source="t.yaml")
    for o in c.obstacles:
        v = o.world_mesh().vertices
        lo, hi = o.aabb()
        assert np.all(v >= lo - 1e-9) and np.all(v <= hi + 1e-9)
        assert np.allclose(v.min(axis=0), lo, atol=2e-3 * math.pi) and np.allclose(v.max(axis=0), hi, atol=2e-3 * math.pi)
