"""The carried part against the cell before IK (grasplan/pick/world.py ``PickWorld.cell_shrunk``,
grasplan/pick/picker.py, grasplan/motion/grasp_motion.py ``lift_precheck_drop``): the picker checks the part
alone along each lift against the table and the obstacles shrunk as the robot scene's attached
part meets them, and the lift's waypoints it covers then skip those pairs in the robot scene. So
the bodies must be the scene's (the same answer for every pose, grazing ones included) and mean
what they say (a part sunk into the floor by more than ATTACHED_CONTACT_TOL hits it, one sunk by
less does not: an analytic check)."""
from __future__ import annotations

from pathlib import Path

import coal
import numpy as np

from grasplan.cell.model import load_cell
from grasplan.gripper.load import load_gripper
from grasplan.part.mesh import load_part
from grasplan.motion.lift_check import lift_precheck_drop
from grasplan.pick.world import PickWorld
from grasplan.robot.description import load_robot
from grasplan.motion.collision_scene import ATTACHED_CONTACT_TOL, CollisionScene
from grasplan.geometry.transforms import rpy_matrix

BRACKET = Path(__file__).resolve().parents[1] / "examples" / "parts" / "bracket.stl"


def _setup():
    part, cell = load_part(BRACKET), load_cell("bin")
    gripper = load_gripper("schunk_egp_c_40")
    world = PickWorld(gripper, cell)
    world.add_part("bracket", part)
    scene = CollisionScene(load_robot("ur5"), gripper, part.mesh, np.eye(4), cell).attached(np.eye(4))
    return part, cell, world, scene


def _poses(part, cell, rng, n):
    """Part poses resting near the floor and the walls: lowest vertex at the floor's top moved by
    +-0.3 mm (grazing the shrunk floor), x/y anywhere from a wall's inside to a little into it."""
    floor = next(o for o in cell.obstacles if o.name == "bin_floor")
    top = float(floor.aabb()[1][2])
    lo = np.min([o.aabb()[0] for o in cell.obstacles], axis=0)
    hi = np.max([o.aabb()[1] for o in cell.obstacles], axis=0)
    V = np.asarray(part.mesh.vertices, dtype=np.float64)
    out = []
    for _ in range(n):
        T = np.eye(4)
        T[:3, :3] = rpy_matrix(*rng.uniform(-np.pi, np.pi, 3))
        w = V @ T[:3, :3].T
        T[:2, 3] = rng.uniform(lo[:2], hi[:2]) - 0.5 * (w[:, :2].min(axis=0) + w[:, :2].max(axis=0))
        T[2, 3] = top - w[:, 2].min() + rng.uniform(-3e-4, 3e-4)
        out.append(T)
    return out, top


def test_cell_bodies_are_the_attached_scenes():
    part, cell, world, scene = _setup()
    rng = np.random.default_rng(11)
    poses, _ = _poses(part, cell, rng, 150)
    gm = scene.geom_model
    shrunk = {o.name: o for o in gm.geometryObjects if o.name.endswith("_shrunk") or "_shrunk:" in o.name}
    assert len(shrunk) == len(world.cell_shrunk) == len(cell.obstacles) + 1
    bvh = world.parts["bracket"].bvh
    req, res = coal.CollisionRequest(), coal.CollisionResult()
    T_base_world = np.linalg.inv(np.asarray(scene.robot.T_world_base))
    hits = misses = 0
    for T in poses:
        first = world.part_hits("bracket", T, np.zeros((1, 3)), world.cell_shrunk)[0]
        Tb = T_base_world @ T
        tf = coal.Transform3s(Tb[:3, :3].copy(), Tb[:3, 3].copy())
        names = []
        for name, o in shrunk.items():
            res.clear()
            M = o.placement
            if coal.collide(bvh, tf, o.geometry, coal.Transform3s(M.rotation, M.translation), req, res):
                names.append(name)
        if first < 0:
            assert not names
            misses += 1
        else:  # the scene's geometry of that body collides too
            body = world.cell_shrunk[first].name
            want = "table_shrunk" if body == "table" else body.replace("obstacle:", "obstacle_shrunk:")
            assert want in names, (body, names)
            hits += 1
    assert hits > 20 and misses > 20


def test_floor_contact_within_the_tolerance_is_free():
    part, cell, world, _ = _setup()
    rng = np.random.default_rng(3)
    poses, top = _poses(part, cell, rng, 300)
    floor = [k for k, b in enumerate(world.cell_shrunk) if b.name == "obstacle:bin_floor"][0]
    f_lo, f_hi = next(o for o in cell.obstacles if o.name == "bin_floor").aabb()
    V = np.asarray(part.mesh.vertices, dtype=np.float64)
    seen = {True: 0, False: 0}
    for T in poses:
        depth = top - float((V @ T[:3, :3].T + T[:3, 3])[:, 2].min())
        if abs(depth - ATTACHED_CONTACT_TOL) < 2e-6:
            continue  # at the boundary: rounding may go either way
        xy = (V @ T[:3, :3].T + T[:3, 3])[:, :2]
        if np.any(xy.min(axis=0) < f_lo[:2]) or np.any(xy.max(axis=0) > f_hi[:2]):
            continue  # partly beyond the floor's top face: its lowest point may not be over it
        hit = world.part_hits("bracket", T, np.zeros((1, 3)), [world.cell_shrunk[floor]])[0] >= 0
        assert hit == (depth > ATTACHED_CONTACT_TOL), depth
        seen[hit] += 1
    assert seen[True] > 20 and seen[False] > 20


def test_lift_skips_the_cell_pairs_it_covered_not_the_robots():
    _, _, _, scene = _setup()
    drop = lift_precheck_drop(scene)
    rows = scene.pair_rows()
    cell = [k for k, r in enumerate(rows) if r[3] == "attached" and r[2] in ("table", "obstacle")]
    links = [k for k, r in enumerate(rows) if r[3] == "attached" and r[2] == "part"]
    assert cell and links
    assert drop[cell].all() and not drop[links].any()
