"""The checks before planning, in one place: each refuses (exit 3) with what to change.

* :func:`check_part_placement`: a part pose (the resting pose, ``--part-pose`` or the place after
  release) reaching into the table or an obstacle (InputError with the depth in mm);
* :func:`check_start`: the part at its start pose (as above), the robot's base inside an obstacle
  and ``q_home`` in collision (ConfigError naming the bodies).

:func:`grasplan.motion.planning.plan` calls them before the grasp stage; they read the cell model
(:mod:`grasplan.cell.model`), the coal geometry (:mod:`grasplan.cell.shapes`) and the robot's collision
scene (:mod:`grasplan.motion.collision_scene`), and none of those imports this module.
"""
from __future__ import annotations

import coal
import numpy as np

from ..cell.model import Cell
from ..errors import ConfigError, InputError
from ..cell.shapes import bvh, obstacle_geometry
from ..geometry.meshdata import TriangleMesh
from .collision_scene import CollisionScene, describe_pairs

#: the part may reach into the table or an obstacle by at most this (m) before planning refuses
#: it: a part resting on a surface touches it (rounding), a part inside it is an error
PART_CONTACT_TOL = 1e-4


def check_part_placement(part_mesh: TriangleMesh, T_world_part: np.ndarray, cell: Cell, *,
                         tol: float = PART_CONTACT_TOL, what: str = "the part",
                         pose_option: str = "--part-pose") -> None:
    """Refuse a part pose that reaches into the table or an obstacle by more than ``tol`` (m).

    Raises InputError (exit 3) naming the body, the depth in mm and what to change (``pose_option``:
    the option that sets this pose, e.g. ``--part-pose`` or ``--place``). The table
    depth is exact (lowest vertex below ``table_z``); an obstacle's depth is coal's penetration
    depth (EPA) of the part mesh against the obstacle (box, cylinder, sphere shrunk by ``tol``; a
    mesh obstacle is not shrunk: touching it counts)."""
    T = np.asarray(T_world_part, dtype=np.float64)
    V = np.asarray(part_mesh.vertices, dtype=np.float64)
    z = V @ T[2, :3] + T[2, 3]
    depth = float(cell.table_z - z.min())
    if depth > tol:
        raise InputError(f"{what} reaches {depth * 1e3:.1f} mm into the table (lowest point z = {z.min():.4f} m, "
                         f"table top z = {cell.table_z:g} m): raise the pose by at least {depth * 1e3:.1f} mm "
                         f"(z of {pose_option}: {T[2, 3] + depth:.4f} m would rest it on the table) or lower the "
                         f"cell's table_z")
    if not cell.obstacles:
        return
    lo = V @ T[:3, :3].T + T[:3, 3]
    lo, hi = lo.min(axis=0), lo.max(axis=0)
    part = None
    req = coal.CollisionRequest()
    req.enable_contact = True
    req.num_max_contacts = 1
    res = coal.CollisionResult()
    for o in cell.obstacles:
        olo, ohi = o.aabb()
        if np.any(olo > hi + tol) or np.any(ohi < lo - tol):
            continue
        if part is None:
            part = bvh(V, np.asarray(part_mesh.faces))
            tp = coal.Transform3s(T[:3, :3].copy(), T[:3, 3].copy())
        geom = obstacle_geometry(o, shrink=tol)  # touching (resting on the bin floor) is not a collision
        To = np.asarray(o.T_world_obstacle)
        res.clear()
        if coal.collide(part, tp, geom, coal.Transform3s(To[:3, :3].copy(), To[:3, 3].copy()), req, res):
            d = abs(float(res.getContact(0).penetration_depth)) + tol if res.numContacts() else float("nan")
            raise InputError(f"{what} intersects obstacle {o.name!r} (penetration {d * 1e3:.1f} mm): move the part "
                             f"({pose_option}, part_xy) or the obstacle in the cell YAML")


def check_start(scene: CollisionScene, q_home: np.ndarray | None = None, *,
                part_mesh: TriangleMesh | None = None) -> None:
    """The checks before planning; each raises (exit 3) with what to change.

    1. the part (``part_mesh`` at ``scene.T_world_part``) reaches into the table or an obstacle by
       more than :data:`PART_CONTACT_TOL` (:func:`check_part_placement`,
       InputError with the depth in mm);
    2. the robot's base (its mounted links) inside an obstacle (ConfigError);
    3. ``q_home`` (default ``robot.q_home``) in collision with the jaws fully open (ConfigError
       naming the two bodies).
    """
    robot, cell = scene.robot, scene.cell
    if part_mesh is not None and cell is not None and scene.T_world_part is not None:
        check_part_placement(part_mesh, scene.T_world_part, cell)
    q = np.asarray(robot.q_home if q_home is None else q_home, dtype=np.float64)
    pairs = scene.colliding_pairs(q, float(scene.gripper.max_opening))
    if not pairs:
        return
    mounted = set(robot.mounted_links)
    base = [(a, b) for a, b, k in pairs if k == "obstacle" and (a in mounted or b in mounted)]
    if base:
        a, b = base[0]
        link, obst = (a, b) if a in mounted else (b, a)
        raise ConfigError(f"the robot's base is inside {obst} ({link} collides with it): move or shrink the "
                          f"obstacle in the cell YAML, or move the robot base (T_world_base)")
    a, b, kind = pairs[0]
    if kind == "table":
        fix = "raise the robot base or lower the cell's table_z, or change q_home in the robot YAML"
    elif kind == "obstacle":
        fix = "move the obstacle in the cell YAML or change q_home in the robot YAML"
    elif kind == "part":
        fix = "move the part (part_xy, --part-pose) or change q_home in the robot YAML"
    else:
        fix = "change q_home in the robot YAML"
    raise ConfigError(f"q_home: {describe_pairs(pairs)}: {fix}; every path starts at q_home")
