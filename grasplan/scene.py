"""The robot cell's collision scene: robot links, gripper, table and part (Pinocchio + coal).

:class:`CollisionScene` is built ONCE per (robot, gripper, part, part pose, cell) and then queried
thousands of times (OMPL's state validity checker), so everything is prebuilt: one
``pin.GeometryModel`` holding

* the robot's URDF collision meshes (``robot.collision_model``, coal BVHs),
* the gripper body shapes and the two finger shapes, attached to the tool frame's joint at
  ``T_joint_tool @ T_flange_tcp @ T_tcp_shape`` (fingers moved to the requested jaw opening),
* the table, a 20 m x 20 m x 2 m coal ``Box`` whose top face is ``z = cell.table_z`` (it fills
  z < table_z within reach: the cell's half-space),
* the part, a coal BVH (OBBRSS) of ``part_mesh`` placed at ``T_world_part``,

one ``pin.Data`` and one ``pin.GeometryData`` (owned by the scene: a scene is not thread-safe) and
an ordered list of collision pairs (cheap and likely pairs first, early stop at the first hit).

Collision pairs (geometry names are Pinocchio's ``<link>_<k>`` plus ``gripper_body_<k>``,
``finger_left`` (the -x jaw), ``finger_right`` (the +x jaw), ``table`` and ``part``):

* gripper body/fingers vs table and part;
* every robot link vs the part; every robot link vs the table except ``robot.mounted_links``
  (for the UR5 base_link and shoulder_link, for the Panda panda_link0 and panda_link1);
* gripper vs every robot link except those moving with the tool joint (the flange link: the
  UR5's wrist_3_link and ee_link, the Panda's panda_link7);
* robot self-collision: all link pairs except those on the same or adjacent joints and the SRDF's
  ``disable_collisions`` pairs.

All geometry is in the robot model's frame (its URDF root link); the world objects (table, part)
are placed there through ``inv(robot.T_world_base)``.
"""
from __future__ import annotations

import math
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from .errors import InputError
from .geometry import bvh, shape_geometry  # noqa: F401 - shape_geometry is part of this module's API
from .robot import Robot
from .transforms import check_transform

TABLE = "table"
PART = "part"
TABLE_SIZE = (20.0, 20.0, 2.0)  # m: the table box (top face at z = table_z, centred under the world origin)


def _se3(T: np.ndarray) -> pin.SE3:
    T = np.asarray(T, dtype=float)
    return pin.SE3(T[:3, :3].copy(), T[:3, 3].copy())


def _tx(x: float) -> np.ndarray:
    T = np.eye(4)
    T[0, 3] = x
    return T


class CollisionScene:
    """Robot + gripper + table + part collision checks. Build once, query many times.

    Parameters
    ----------
    robot : Robot
    gripper : object with ``body`` (shapes), ``fingers(opening)`` -> (-x jaw, +x jaw) shapes,
        ``T_flange_tcp`` (4, 4) and ``max_opening`` (m) (see :mod:`grasplan.gripper`).
    part_mesh : trimesh.Trimesh in the part frame (m), or None for no part.
    T_world_part : (4, 4) part pose in the world.
    cell : object with ``table_z`` (m), or None for no table.
    margin : security margin (m) applied to every pair (0: exact contact).
    """

    def __init__(self, robot: Robot, gripper: Any, part_mesh: Any = None, T_world_part=None,
                 cell: Any = None, *, margin: float = 0.0):
        self.robot = robot
        self.gripper = gripper
        self.cell = cell
        self.margin = float(margin)
        model = robot.model
        self.model = model
        self.data = model.createData()
        T_base_world = np.linalg.inv(robot.T_world_base)
        gm = pin.GeometryModel()
        self._robot_ids: list[int] = []
        for g in robot.collision_model.geometryObjects:
            self._robot_ids.append(gm.addGeometryObject(pin.GeometryObject(g)))
        j_tool = robot.tool_joint_id
        f_tool = robot.tool_frame_id
        T_joint_tcp = robot.T_joint_tool @ np.asarray(gripper.T_flange_tcp, dtype=float)
        self.T_joint_tcp = T_joint_tcp
        # gripper body
        self._gripper_ids: list[int] = []
        for k, shape in enumerate(gripper.body):
            geom, T_tcp_g = shape_geometry(shape)
            go = pin.GeometryObject(f"gripper_body_{k}", j_tool, f_tool, _se3(T_joint_tcp @ T_tcp_g), geom)
            self._gripper_ids.append(gm.addGeometryObject(go))
        # fingers: geometry at opening 0, moved along x by -+ opening/2
        f0 = gripper.fingers(0.0)
        if len(f0) != 2:
            raise InputError("gripper.fingers(opening) must return two shapes (-x jaw, +x jaw)")
        self._finger_ids: list[int] = []
        self._finger_T0: list[np.ndarray] = []
        for name, shape in zip(("finger_left", "finger_right"), f0):
            geom, T_tcp_g = shape_geometry(shape)
            self._finger_T0.append(T_tcp_g)
            go = pin.GeometryObject(name, j_tool, f_tool, _se3(T_joint_tcp @ T_tcp_g), geom)
            self._finger_ids.append(gm.addGeometryObject(go))
        self._check_finger_model(gripper)
        self._gripper_ids_all = self._gripper_ids + self._finger_ids
        # world objects on the universe joint
        self._env_ids: dict[str, int] = {}
        if cell is not None:
            z = float(getattr(cell, "table_z", 0.0))
            # a coal Halfspace would be exact, but coal cannot prune BVH nodes against it (every
            # triangle of every link gets tested, ~150 us per link); a box TABLE_SIZE wide and deep
            # with its top face on the table plane is the same solid within reach of any arm
            T_world_table = np.eye(4)
            T_world_table[2, 3] = z - TABLE_SIZE[2] / 2
            box = coal.Box(*TABLE_SIZE)
            self._env_ids[TABLE] = gm.addGeometryObject(
                pin.GeometryObject(TABLE, 0, 0, _se3(T_base_world @ T_world_table), box))
        if part_mesh is not None:
            if T_world_part is None:
                raise InputError("T_world_part (4, 4) is required with a part mesh")
            T_wp = check_transform(T_world_part, "T_world_part")
            self.T_world_part = T_wp
            part_bvh = bvh(np.asarray(part_mesh.vertices), np.asarray(part_mesh.faces))
            self._env_ids[PART] = gm.addGeometryObject(
                pin.GeometryObject(PART, 0, 0, _se3(T_base_world @ T_wp), part_bvh))
        else:
            self.T_world_part = None
        self.geom_model = gm
        self._build_pairs()
        self.geom_data = pin.GeometryData(gm)
        for req in self.geom_data.collisionRequests:
            req.security_margin = self.margin
            # contacts on, as in grasplan.collision: coal 3.0 with enable_contact = False missed a
            # 51 micrometre box-into-mesh penetration; EPA only runs on pairs already in collision
            req.enable_contact = True
            req.num_max_contacts = 1
        self._opening: float | None = None
        self.set_opening(float(gripper.max_opening))

    # ------------------------------------------------------------------------------------------
    def _check_finger_model(self, gripper) -> None:
        """The fingers move as pure x translations of their opening-0 pose (checked once)."""
        o = float(gripper.max_opening)
        for sign, shape0, shape in zip((-1.0, 1.0), gripper.fingers(0.0), gripper.fingers(o)):
            if hasattr(shape, "T_tcp_box"):
                exp = _tx(sign * o / 2) @ np.asarray(shape0.T_tcp_box, dtype=float)
                ok = np.allclose(exp, np.asarray(shape.T_tcp_box, dtype=float), atol=1e-9)
            else:
                v0 = np.asarray(shape0.vertices, dtype=float)
                ok = np.allclose(v0 + [sign * o / 2, 0, 0], np.asarray(shape.vertices, dtype=float), atol=1e-9)
            if not ok:
                raise InputError("gripper.fingers(opening): the jaws must move along the TCP x axis by "
                                 "-opening/2 (first jaw) and +opening/2 (second jaw)")

    def _link(self, gid: int) -> str:
        return self.model.frames[self.geom_model.geometryObjects[gid].parentFrame].name

    def _build_pairs(self) -> None:
        gm, model, robot = self.geom_model, self.model, self.robot
        disabled = set(robot.disabled_pairs)
        mounted = set(robot.mounted_links)
        j_tool = robot.tool_joint_id
        parents = model.parents
        env = self._env_ids
        pairs: list[tuple[int, int]] = []
        kinds: list[str] = []

        def add(a, b, kind):
            pairs.append((a, b))
            kinds.append(kind)

        # 1. gripper vs environment (most likely hits near a grasp)
        for name in (PART, TABLE):
            if name in env:
                for g in self._gripper_ids_all:
                    add(g, env[name], name)
        # 2. robot links vs table, then vs part
        if TABLE in env:
            for r in self._robot_ids:
                if self._link(r) not in mounted:
                    add(r, env[TABLE], TABLE)
        if PART in env:
            for r in self._robot_ids:
                add(r, env[PART], PART)
        # 3. gripper vs robot links (not those moving with the tool joint)
        for r in self._robot_ids:
            if gm.geometryObjects[r].parentJoint != j_tool:
                for g in self._gripper_ids_all:
                    add(r, g, "self")
        # 4. robot self-collision
        ids = self._robot_ids
        for i, a in enumerate(ids):
            ja = gm.geometryObjects[a].parentJoint
            for b in ids[i + 1:]:
                jb = gm.geometryObjects[b].parentJoint
                if ja == jb or parents[ja] == jb or parents[jb] == ja:
                    continue
                if tuple(sorted((self._link(a), self._link(b)))) in disabled:
                    continue
                add(a, b, "self")
        for a, b in pairs:
            gm.addCollisionPair(pin.CollisionPair(a, b))
        self._pair_kinds = kinds
        self._pair_names = [(gm.geometryObjects[a].name, gm.geometryObjects[b].name) for a, b in pairs]

    @property
    def pair_names(self) -> list[tuple[str, str]]:
        """The checked pairs, in checking order: (geometry name, geometry name)."""
        return list(self._pair_names)

    def set_opening(self, opening: float) -> None:
        """Move the finger geometry to jaw ``opening`` (m); cheap, cached for repeated calls."""
        o = float(opening)
        if o == self._opening:
            return
        if not (math.isfinite(o) and 0.0 <= o <= float(self.gripper.max_opening) + 1e-9):
            raise InputError(f"opening: {o!r} m is outside [0, {self.gripper.max_opening}]")
        for sign, gid, T0 in zip((-1.0, 1.0), self._finger_ids, self._finger_T0):
            self.geom_model.geometryObjects[gid].placement = _se3(self.T_joint_tcp @ _tx(sign * o / 2) @ T0)
        self._opening = o

    # ------------------------------------------------------------------------------------------
    def _prep(self, q, opening) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape != (self.model.nq,):
            raise InputError(f"q: expected shape ({self.model.nq},), got {q.shape}")
        self.set_opening(self.gripper.max_opening if opening is None else opening)
        return q

    def is_free(self, q, opening: float | None = None) -> bool:
        """True when configuration q (n,) with the jaws at ``opening`` (m; default max_opening)
        collides with nothing (early stop at the first colliding pair)."""
        q = self._prep(q, opening)
        return not pin.computeCollisions(self.model, self.data, self.geom_model, self.geom_data, q, True)

    def first_collision(self, q, opening: float | None = None) -> str | None:
        """``"<geom> vs <geom>"`` of the first colliding pair in checking order, or None."""
        q = self._prep(q, opening)
        if not pin.computeCollisions(self.model, self.data, self.geom_model, self.geom_data, q, True):
            return None
        for k, res in enumerate(self.geom_data.collisionResults):
            if res.isCollision():
                a, b = self._pair_names[k]
                return f"{a} vs {b}"
        return "unknown"  # not reached: computeCollisions reported a hit

    def colliding_pairs(self, q, opening: float | None = None) -> list[tuple[str, str, str]]:
        """All colliding pairs (no early stop): [(geom, geom, kind)], kind in
        {"table", "part", "self"}."""
        q = self._prep(q, opening)
        pin.computeCollisions(self.model, self.data, self.geom_model, self.geom_data, q, False)
        return [(*self._pair_names[k], self._pair_kinds[k])
                for k, res in enumerate(self.geom_data.collisionResults) if res.isCollision()]

    def collision_kind(self, q, opening: float | None = None) -> str | None:
        """None when free, else the kind of the first hit: "table", "part" or "self"."""
        q = self._prep(q, opening)
        if not pin.computeCollisions(self.model, self.data, self.geom_model, self.geom_data, q, True):
            return None
        for k, res in enumerate(self.geom_data.collisionResults):
            if res.isCollision():
                return self._pair_kinds[k]
        return "self"

    def path_free(self, qs, opening: float | None = None, *, step: float = 0.01) -> bool:
        """True when the piecewise-linear joint path qs (k, n) is collision-free, checked at every
        waypoint and at interpolated configurations so that no joint moves more than ``step`` rad
        between two checks (segment i is split into ceil(max|dq| / step) equal parts)."""
        qs = np.asarray(qs, dtype=float)
        if qs.ndim != 2 or qs.shape[1] != self.model.nq:
            raise InputError(f"qs: expected shape (k, {self.model.nq}), got {qs.shape}")
        if not step > 0:
            raise InputError(f"step: expected > 0 rad, got {step}")
        self.set_opening(self.gripper.max_opening if opening is None else opening)
        m, d, gm, gd = self.model, self.data, self.geom_model, self.geom_data
        for q in qs:  # waypoints first: cheap rejection
            if pin.computeCollisions(m, d, gm, gd, q, True):
                return False
        for a, b in zip(qs[:-1], qs[1:]):
            n = int(math.ceil(float(np.max(np.abs(b - a))) / step - 1e-12))
            if n <= 1:
                continue
            # coarse-to-fine order (bisection) finds a collision in the middle early
            for i in _bisection_order(n):
                q = a + (b - a) * (i / n)
                if pin.computeCollisions(m, d, gm, gd, q, True):
                    return False
        return True


def _bisection_order(n: int) -> list[int]:
    """Indices 1..n-1 in coarse-to-fine order (midpoint first)."""
    out: list[int] = []
    seen = {0, n}
    level = [(0, n)]
    while level:
        nxt = []
        for lo, hi in level:
            if hi - lo < 2:
                continue
            mid = (lo + hi) // 2
            if mid not in seen:
                seen.add(mid)
                out.append(mid)
            nxt.append((lo, mid))
            nxt.append((mid, hi))
        level = nxt
    return out
