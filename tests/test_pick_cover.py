"""The approach's gripper pairs skipped after the Cartesian sweep (grasplan/pick/cover.py): at every
configuration the sweep covers, each skipped pair (a gripper shape against the world, the grasped
part included) is free for coal, so the robot scene's answer with those pairs off is its answer with
every pair; configurations off the sweep are not covered."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin

from grasplan.cell.model import load_cell
from grasplan.gripper.load import load_gripper
from grasplan.robot.ik.solve import solve_ik
from grasplan.geometry.interpolation import interpolate_path
from grasplan.part.mesh import load_part
from grasplan.pick.cover import APPROACH_PAD, covered_check
from grasplan.motion.grasp_motion import line_path
from grasplan.pick.world import INSTANCE_PREFIX, PickWorld
from grasplan.robot.description import load_robot
from grasplan.motion.collision_scene import CollisionScene, ExtraBody
from grasplan.piles.scene_file import Instance
from grasplan.geometry.transforms import rpy_matrix

BRACKET = Path(__file__).resolve().parents[1] / "examples" / "parts" / "bracket.stl"


def test_covered_configurations_skip_only_free_pairs():
    rng = np.random.default_rng(31)
    robot, gripper, cell = load_robot("ur5"), load_gripper("long_stroke_50"), load_cell("bin")
    part = load_part(BRACKET)
    world = PickWorld(gripper, cell)
    g = world.add_part("bracket", part)
    insts = []
    for j in range(4):
        T = np.eye(4)
        T[:3, :3] = rpy_matrix(0.0, 0.0, rng.uniform(-np.pi, np.pi))
        T[:3, 3] = [0.42 + 0.03 * j, 0.04 * (j % 2) - 0.02, 0.025]
        insts.append(Instance(f"i{j}", "bracket", T))
    world.set_instances(insts)
    extras = [ExtraBody(INSTANCE_PREFIX + i.id, g.bvh, "instance") for i in insts[1:]]
    scene = CollisionScene(robot, gripper, part.mesh, np.eye(4), cell, extras=extras).arranged(
        insts[0].T_world_part, {INSTANCE_PREFIX + i.id: i.T_world_part for i in insts[1:]})
    T_ft = np.asarray(gripper.T_flange_tcp, dtype=np.float64)
    n_cov = n_swept = n_none = n_skipped_hit = 0
    for _ in range(80):
        T = np.eye(4)
        T[:3, :3] = rpy_matrix(np.pi + rng.normal(0, 0.15), rng.normal(0, 0.15), rng.uniform(-np.pi, np.pi))
        T[:3, 3] = insts[0].T_world_part[:3, 3] + [*rng.normal(0, 0.01, 2), rng.uniform(0.0, 0.05)]
        T_pre = T.copy()
        T_pre[:3, 3] -= 0.05 * T[:3, 2]
        opening = float(rng.uniform(0.02, 0.05))
        swept = world.gripper_swept_free(T_pre, T, opening, APPROACH_PAD)
        if swept is None:
            n_none += 1
            continue
        n_swept += 1
        covered, drop = covered_check(robot, T_ft, scene, swept)
        for q in solve_ik(robot, T @ np.linalg.inv(T_ft), max_solutions=2).q:
            back, _ = line_path(robot, T, T_pre, q, max_dev=0.002, T_flange_tcp=T_ft)
            if back is None:
                continue
            qs = interpolate_path(back)
            cov = covered(qs)
            assert cov.all()  # the approach's own configurations lie inside the sweep
            far = qs + rng.normal(0.0, 0.05, qs.shape)  # and others mostly not
            assert not covered(far).all()
            scene.set_opening(opening)
            for qk in np.vstack([qs, far[covered(far)]]):
                pin.updateGeometryPlacements(scene.model, scene.data, scene.geom_model, scene.geom_data, qk)
                hits = [p for p in drop.tolist() if pin.computeCollision(scene.geom_model, scene.geom_data, p)]
                assert not hits, [scene.pair_rows()[p][:2] for p in hits]
                assert scene.path_free(qk[None], opening, reduced=(covered, drop)) == scene.is_free_exhaustive(qk, opening)
                n_cov += 1
    for _ in range(40):  # a grasp whose closed jaws meet the grasped part: its sweep is never free
        T = np.eye(4)
        T[:3, :3] = rpy_matrix(np.pi, 0.0, rng.uniform(-np.pi, np.pi))
        T[:3, 3] = insts[0].T_world_part[:3, 3] + [0.0, 0.0, rng.uniform(-0.01, 0.01)]
        T_pre = T.copy()
        T_pre[:3, 3] -= 0.05 * T[:3, 2]
        if world.gripper_at_hits(T[None], 0.0, world.bodies(None))[0] >= 0:
            assert world.gripper_swept_free(T_pre, T, 0.0, APPROACH_PAD) is None
            n_skipped_hit += 1
    assert n_cov > 200 and n_swept > 10 and n_none > 5 and n_skipped_hit > 5
