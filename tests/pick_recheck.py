"""An INDEPENDENT python-fcl re-check of planned picks (a helper module: no tests in it).

Built on :mod:`tests.fcl_recheck` (URDF links from the URDF, gripper shapes, the cell's table
half-space and obstacles, the part static or attached, all in python-fcl; Pinocchio only for
forward kinematics). The pile is added as obstacles written here from the scene: every other
instance present when the pick was planned as a python-fcl BVH of its mesh at its pose, and every
point of the cloud as the cube of its octree leaf (``floor(p / resolution)`` cells). The rules:

* transit and approach (jaws at the pick's opening, the instance static): robot links and gripper
  against table, bin, obstacles, the instance, every other instance and the cloud; self-collision;
* lift (jaws at the contact width, the instance attached by ``T_tcp_part``): the same, plus the
  carried instance against table, bin, every other instance, the cloud and the links not on the
  tool joint. Within the first ``lift_contact`` metres of TCP travel from the grasp (FK) the carried
  instance may touch the table, the bin or a neighbour (it rests on them); nothing else may touch.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from fcl_recheck import FclWorld, Report, densify

from grasplan.cell import Obstacle


def pile_obstacles(instances, meshes, *, exclude: str, cloud=None, resolution: float = 0.005) -> list[Obstacle]:
    """Obstacles for every instance but ``exclude`` (mesh at its pose) and the cloud's leaf cubes."""
    out = []
    for inst in instances:
        if inst.id == exclude:
            continue
        m = meshes[inst.part]
        out.append(Obstacle(f"instance_{inst.id}", "mesh", np.asarray(inst.T_world_part),
                            vertices=np.asarray(m.vertices), faces=np.asarray(m.faces)))
    if cloud is not None:
        cells = np.unique(np.floor(np.asarray(cloud) / resolution).astype(np.int64), axis=0)
        for k, c in enumerate(cells):
            T = np.eye(4)
            T[:3, 3] = (c + 0.5) * resolution
            out.append(Obstacle(f"cloud_{k}", "box", T, size=(resolution,) * 3))
    return out


def recheck_pick(robot, gripper, cell, pick, instances, meshes, *, cloud=None, resolution: float = 0.005,
                 lift_contact: float = 0.002, step: float = 0.01) -> Report:
    """Re-check one :class:`grasplan.pick.Pick` against the pile ``instances`` present when it was planned."""
    obstacles = pile_obstacles(instances, meshes, exclude=pick.instance, cloud=cloud, resolution=resolution)
    world = FclWorld(robot, gripper, replace(cell, obstacles=tuple(cell.obstacles) + tuple(obstacles)),
                     meshes[pick.part])
    m = pick.motion
    path = np.asarray(m.path)
    g0, g1 = m.segment("approach")
    l0, l1 = m.segment("lift")
    T_tcp_part = np.asarray(m.T_tcp_part)
    rep = Report()
    from fcl_recheck import RobotLinks

    tcp = RobotLinks(robot, gripper.T_flange_tcp)
    T_grasp = tcp.fk_tcp(path[l0])
    states = [(0, g1, pick.opening, "static", pick.T_world_part), (l0, l1, pick.width, "attached", T_tcp_part)]
    if m.segment("transfer") is not None:  # carried to the place, lowered, released, retreat
        d1 = m.segment("descend")[1]
        r0, r1 = m.segment("retreat")
        states += [(l1, d1, pick.width, "attached", T_tcp_part),
                   (r0, r1, pick.opening, "static", np.asarray(m.T_world_part_place))]
    for k, (s, e, opening, mode, T) in enumerate(states):
        qs, _ = densify(path[s:e + 1], step)
        for q in qs:
            rep.configs += 1
            hits = world.check(q, opening, mode, T)
            if mode == "attached":
                here = tcp.fk_tcp(q)[:3, 3]
                travel = float(np.linalg.norm(here - T_grasp[:3, 3]))
                if k == 1 and travel <= lift_contact + 1e-9:
                    hits = [h for h in hits if not (h.startswith("part (attached) vs ")
                                                    and (h.endswith("vs table") or " vs obstacle:" in h))]
            if hits:
                rep.problems.append(f"{mode} q={np.round(q, 4).tolist()}: " + ", ".join(hits[:3]))
                break
    return rep
