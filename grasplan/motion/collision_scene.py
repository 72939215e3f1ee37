"""The robot cell's collision scene: robot links, gripper, table, obstacles and part (Pinocchio + coal).

:class:`CollisionScene` is built ONCE per (robot, gripper, part, part pose, cell), then queried thousands
of times (OMPL's validity checker), so everything is prebuilt: one ``pin.GeometryModel``
(:class:`_SceneModel`) and an ordered list of collision pairs (cheap and likely pairs first, early
stop at the first hit). Its variants (:meth:`CollisionScene.with_part_at`, :meth:`CollisionScene.attached`,
:meth:`CollisionScene.arranged` with :class:`ExtraBody` objects) share that model. All geometry is in the
robot model's frame (its URDF root link), world objects placed through ``inv(T_world_base)``. The
checks before planning (part in the table or an obstacle, ...) are :mod:`grasplan.motion.start_checks`.
"""
from __future__ import annotations

import math
import weakref
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import coal
import numpy as np
from numpy.typing import ArrayLike
import pinocchio as pin

from ..cell.model import Cell
from ..errors import InputError
from ..cell.shapes import TABLE_SIZE, obstacle_geometry, shape_geometry, shared_bvh, shared_mesh_structure, table_pose
from ..gripper.model import Gripper
from ..geometry.interpolation import STEP, interpolate_path
from ..geometry.meshdata import TriangleMesh
from ..grasps.collision_boxes import PartBoxes
from .pathboxes import scene_open
from ..robot.model import Robot
from ..geometry.transforms import check_transform, to_se3, translation

TABLE = "table"
PART = "part"
PART_ATTACHED = "part_attached"
#: the attached part may touch the table or an obstacle by this much (m) without colliding: it
#: rests on them at the grasp and at the place (IK error is ~1e-6 m)
ATTACHED_CONTACT_TOL = 1e-4


@dataclass(frozen=True, eq=False)
class ExtraBody:
    """Static geometry besides the cell and the part (e.g. the other instances of a pile and a point
    cloud's octree for ``grasplan pick``), checked against the gripper, every robot link and the
    attached part: ``name`` (the body name in reports, e.g. ``instance:b``, ``cloud``), coal
    ``geometry`` in its own frame, ``kind`` (the pair kind in reports, e.g. ``instance``, ``cloud``).
    Built once; its world pose is given per variant (:meth:`CollisionScene.arranged`), so a scene
    serves every instance of every pile of the same parts."""

    name: str
    geometry: coal.CollisionGeometry
    kind: str = "obstacle"


#: jaw openings whose finger placements a scene model keeps (a grasp's pre-grasp opening and width)
FINGER_PLACEMENTS = 8


class _SceneModel:
    """The geometry shared by a scene and its variants (built once): one ``pin.GeometryModel`` of

    * the robot's URDF collision meshes (``robot.collision_model``, coal BVHs),
    * the gripper body shapes and the two finger shapes, attached to the tool frame's joint at
      ``T_joint_tool @ T_flange_tcp @ T_tcp_shape`` (fingers moved to the requested jaw opening),
    * the table, a 20 m x 20 m x 2 m coal ``Box`` with its top face at ``z = cell.table_z`` (a
      half-space within reach),
    * the cell's obstacles (``cell.obstacles``: boxes, cylinders, spheres, mesh BVHs; the bin's floor
      and walls among them), built by :func:`grasplan.cell.shapes.obstacle_geometry`,
    * the part twice: static, a coal BVH (OBBRSS) of ``part_mesh`` at ``T_world_part``, and attached,
      the same BVH on the tool joint at ``T_tcp_part`` (:meth:`CollisionScene.attached`),
    * the extra bodies (:class:`ExtraBody`)."""

    def __init__(self, robot: Robot, gripper: Gripper, part_mesh: TriangleMesh | None, cell: Cell | None,
                 margin: float, extras: Sequence[ExtraBody] = ()):
        self.robot, self.gripper, self.cell, self.margin = robot, gripper, cell, float(margin)
        model = robot.model
        self.model = model
        self.T_base_world = np.linalg.inv(robot.T_world_base)
        gm = pin.GeometryModel()
        self.robot_ids: list[int] = []
        for g in robot.collision_model.geometryObjects:
            self.robot_ids.append(gm.addGeometryObject(pin.GeometryObject(g)))
        self.j_tool = j_tool = robot.tool_joint_id
        self.f_tool = f_tool = robot.tool_frame_id
        T_joint_tcp = robot.T_joint_tool @ np.asarray(gripper.T_flange_tcp, dtype=float)
        self.T_joint_tcp = T_joint_tcp
        # fingertips that move along z with the opening (Robotiq 2F): z of the jaws at o vs at 0
        self.finger_dz = (lambda o: float(gripper.tcp_offset(o)) - float(gripper.tcp_offset(0.0))) \
            if getattr(gripper, "moving_tcp", False) else (lambda o: 0.0)
        self.body: dict[int, str] = {}
        for k, shape in enumerate(gripper.body):
            geom, T_tcp_g = shape_geometry(shape)
            go = pin.GeometryObject(f"gripper_body_{k}", j_tool, f_tool, to_se3(T_joint_tcp @ T_tcp_g), geom)
            gid = gm.addGeometryObject(go)
            self.body[gid] = f"gripper:body_{k}"
        self.gripper_ids = list(self.body)
        f0 = gripper.fingers(0.0)
        if len(f0) != 2:
            raise InputError("gripper.fingers(opening) must return two shapes (-x jaw, +x jaw)")
        self.finger_ids: list[int] = []
        self.finger_T0: list[np.ndarray] = []
        for name, shape in zip(("finger_left", "finger_right"), f0):
            geom, T_tcp_g = shape_geometry(shape)
            self.finger_T0.append(T_tcp_g)
            go = pin.GeometryObject(name, j_tool, f_tool, to_se3(T_joint_tcp @ T_tcp_g), geom)
            gid = gm.addGeometryObject(go)
            self.finger_ids.append(gid)
            self.body[gid] = f"gripper:{name}"
        self.gripper_ids_all = self.gripper_ids + self.finger_ids
        self.env_ids: dict[str, int] = {}
        self.obstacle_ids: list[int] = []
        if cell is not None:
            z = float(cell.table_z)
            # a coal Halfspace would be exact, but coal cannot prune BVH nodes against it (every
            # triangle of every link gets tested, ~150 us per link); a box TABLE_SIZE wide and deep
            # with its top face on the table plane is the same solid within reach of any arm
            T_world_table = table_pose(z)
            gid = gm.addGeometryObject(pin.GeometryObject(TABLE, 0, 0, to_se3(self.T_base_world @ T_world_table),
                                                          coal.Box(*TABLE_SIZE)))
            self.env_ids[TABLE] = gid
            self.body[gid] = TABLE
            for o in cell.obstacles:
                gid = gm.addGeometryObject(pin.GeometryObject(
                    f"obstacle:{o.name}", 0, 0, to_se3(self.T_base_world @ np.asarray(o.T_world_obstacle)),
                    obstacle_geometry(o)))
                self.obstacle_ids.append(gid)
                self.body[gid] = f"obstacle:{o.name}"
        self.has_part = part_mesh is not None
        if part_mesh is not None:
            self.part_vf = (np.asarray(part_mesh.vertices), np.asarray(part_mesh.faces))
            part_bvh = shared_bvh(*self.part_vf)
            gid = gm.addGeometryObject(pin.GeometryObject(PART, 0, 0, pin.SE3.Identity(), part_bvh))
            self.env_ids[PART] = gid
            self.body[gid] = PART
            gid = gm.addGeometryObject(pin.GeometryObject(PART_ATTACHED, j_tool, f_tool, to_se3(T_joint_tcp), part_bvh))
            self.env_ids[PART_ATTACHED] = gid
            self.body[gid] = PART
            # what the attached part is checked against: the table and the obstacles shrunk by
            # ATTACHED_CONTACT_TOL (coal has no negative security margin for BVHs)
            self.attached_env: list[int] = []
            if cell is not None:
                tol = ATTACHED_CONTACT_TOL
                gid = gm.addGeometryObject(pin.GeometryObject(
                    "table_shrunk", 0, 0, to_se3(self.T_base_world @ table_pose(z, tol)), coal.Box(*TABLE_SIZE)))
                self.attached_env.append(gid)
                self.body[gid] = TABLE
                for o in cell.obstacles:
                    gid = gm.addGeometryObject(pin.GeometryObject(
                        f"obstacle_shrunk:{o.name}", 0, 0, to_se3(self.T_base_world @ np.asarray(o.T_world_obstacle)),
                        obstacle_geometry(o, shrink=tol)))
                    self.attached_env.append(gid)
                    self.body[gid] = f"obstacle:{o.name}"
        # extra bodies: placed per variant (identity until then; inactive unless placed)
        self.extra_ids: dict[str, int] = {}
        self.extra_kind: dict[str, str] = {}
        for e in extras:
            if e.name in self.extra_ids:
                raise InputError(f"extra body {e.name!r} given twice")
            gid = gm.addGeometryObject(pin.GeometryObject(f"extra:{e.name}", 0, 0, pin.SE3.Identity(), e.geometry))
            self.extra_ids[e.name] = gid
            self.extra_kind[e.name] = e.kind
            self.body[gid] = e.name
        self.gm = gm
        for g in gm.geometryObjects:  # the broad phase of scenes with extras reads them
            g.geometry.computeLocalAABB()
        for r in self.robot_ids:
            self.body[r] = self.link(r)
        self._build_pairs()
        self.opening: float | None = None
        self._finger_placements: dict[float, tuple[pin.SE3, ...]] = {}
        self.owner: weakref.ref[CollisionScene] | None = None  # the variant placed (weak: no reference cycle)

    def link(self, gid: int) -> str:
        return self.model.frames[self.gm.geometryObjects[gid].parentFrame].name

    def _build_pairs(self) -> None:
        """The ordered pairs (geometry names: Pinocchio's ``<link>_<k>`` plus ``gripper_body_<k>``,
        ``finger_left`` (-x jaw), ``finger_right`` (+x jaw), ``table``, ``obstacle:<name>``, ``part``,
        ``part_attached``): gripper body/fingers vs static part, table and obstacles; every robot
        link vs the static part and every obstacle, and vs the table except ``robot.mounted_links``
        (UR5: base_link, shoulder_link); the attached part vs table, obstacles and the robot links not
        moving with the tool joint; gripper vs every robot link except those moving with the tool
        joint (the flange link: the UR5's wrist_3_link and ee_link, the Panda's panda_link7); robot
        self-collision: all link pairs except those on the same or adjacent joints and the SRDF's
        ``disable_collisions`` pairs; each extra body vs the gripper, the robot links and the
        attached part."""
        gm, model, robot = self.gm, self.model, self.robot
        disabled = set(robot.disabled_pairs)
        mounted = set(robot.mounted_links)
        parents = model.parents
        env = self.env_ids
        pairs: list[tuple[int, int]] = []
        kinds: list[str] = []
        group: list[str] = []  # "static" (static part), "attached" (attached part), "" (always)
        extra_of: list[str] = []  # the extra body of the pair ("" none)

        def add(a: int, b: int, kind: str, grp: str = "", extra: str = "") -> None:
            pairs.append((a, b))
            kinds.append(kind)
            group.append(grp)
            extra_of.append(extra)

        # 1. gripper vs environment (most likely hits near a grasp)
        if PART in env:
            for g in self.gripper_ids_all:
                add(g, env[PART], PART, "static")
        if TABLE in env:
            for g in self.gripper_ids_all:
                add(g, env[TABLE], TABLE)
        for o in self.obstacle_ids:
            for g in self.gripper_ids_all:
                add(g, o, "obstacle")
        for name, x in self.extra_ids.items():
            for g in self.gripper_ids_all:
                add(g, x, self.extra_kind[name], "", name)
        # 2. the attached part vs table, obstacles, extras
        if PART_ATTACHED in env:
            for o in self.attached_env:
                add(env[PART_ATTACHED], o, TABLE if self.body[o] == TABLE else "obstacle", "attached")
            for name, x in self.extra_ids.items():
                add(env[PART_ATTACHED], x, self.extra_kind[name], "attached", name)
        # 3. robot links vs table, obstacles, then vs the part
        if TABLE in env:
            for r in self.robot_ids:
                if self.link(r) not in mounted:
                    add(r, env[TABLE], TABLE)
        for o in self.obstacle_ids:
            for r in self.robot_ids:
                add(r, o, "obstacle")
        for name, x in self.extra_ids.items():
            for r in self.robot_ids:
                add(r, x, self.extra_kind[name], "", name)
        if PART in env:
            for r in self.robot_ids:
                add(r, env[PART], PART, "static")
            for r in self.robot_ids:
                if gm.geometryObjects[r].parentJoint != self.j_tool:
                    add(r, env[PART_ATTACHED], PART, "attached")
        # 4. gripper vs robot links (not those moving with the tool joint)
        for r in self.robot_ids:
            if gm.geometryObjects[r].parentJoint != self.j_tool:
                for g in self.gripper_ids_all:
                    add(r, g, "self")
        # 5. robot self-collision
        ids = self.robot_ids
        for i, a in enumerate(ids):
            ja = gm.geometryObjects[a].parentJoint
            for b in ids[i + 1:]:
                jb = gm.geometryObjects[b].parentJoint
                if ja == jb or parents[ja] == jb or parents[jb] == ja:
                    continue
                if tuple(sorted((self.link(a), self.link(b)))) in disabled:
                    continue
                add(a, b, "self")
        for a, b in pairs:
            gm.addCollisionPair(pin.CollisionPair(a, b))
        self.pairs = pairs
        self.kinds = kinds
        self.group = np.array(group)
        self.extra_of = np.array(extra_of, dtype=object)
        self.geom_names = [(gm.geometryObjects[a].name, gm.geometryObjects[b].name) for a, b in pairs]
        self.body_names = [(self.body[a], self.body[b]) for a, b in pairs]
        #: geometries whose placement changes within a variant: the jaws, the carried part
        self.moving_ids = {*self.finger_ids, *(self.env_ids[k] for k in (PART_ATTACHED,) if k in self.env_ids)}

    def part_tree(self) -> tuple[tuple[int, int], PartBoxes] | None:
        """The part's geometries (static, attached) and its triangles' box hierarchy, shared per mesh."""
        if not self.has_part:
            return None
        return (self.env_ids[PART], self.env_ids[PART_ATTACHED]), shared_mesh_structure("part_boxes", *self.part_vf,
                                                                                         PartBoxes)

    def set_opening(self, o: float) -> None:
        if o == self.opening:
            return
        placed = self._finger_placements.get(o)
        if placed is None:
            placed = tuple(to_se3(self.T_joint_tcp @ translation(sign * o / 2, z=self.finger_dz(o)) @ T0)
                           for sign, T0 in zip((-1.0, 1.0), self.finger_T0))
            if len(self._finger_placements) >= FINGER_PLACEMENTS:
                del self._finger_placements[next(iter(self._finger_placements))]
            self._finger_placements[o] = placed
        for gid, M in zip(self.finger_ids, placed):
            self.gm.geometryObjects[gid].placement = M
        self.opening = o


class CollisionScene:
    """Robot + gripper + table + obstacles + part collision checks. Build once, query many times.
    Variants share the geometry and differ in their scratch data (``pin.Data``, ``pin.GeometryData``:
    a scene is not thread-safe, its variants are independent objects) and in which pairs are active.

    Parameters
    ----------
    robot : Robot
    gripper : Gripper
        ``body`` (shapes), ``fingers(opening)`` -> (-x jaw, +x jaw) shapes, ``T_flange_tcp`` (4, 4)
        and ``max_opening`` (m) (see :mod:`grasplan.gripper`).
    part_mesh : TriangleMesh in the part frame (m) (a MeshData or a trimesh), or None for no part.
    T_world_part : (4, 4) part pose in the world.
    cell : Cell (``table_z`` (m) and ``obstacles``, :mod:`grasplan.cell.model`), or None for no table.
    margin : security margin (m) applied to every pair (0: exact contact).
    """

    def __init__(self, robot: Robot, gripper: Gripper, part_mesh: TriangleMesh | None = None,
                 T_world_part: np.ndarray | None = None, cell: Cell | None = None, *, margin: float = 0.0,
                 extras: Sequence[ExtraBody] = ()):
        if part_mesh is not None and T_world_part is None:
            raise InputError("T_world_part (4, 4) is required with a part mesh")
        shared = _SceneModel(robot, gripper, part_mesh, cell, margin, extras)
        self._check_finger_model(gripper)
        T_wp = check_transform(T_world_part, "T_world_part") if part_mesh is not None else None
        self._init_variant(shared, "static" if part_mesh is not None else "none", T_wp, None, {})

    def _init_variant(self, shared: _SceneModel, mode: str, T_world_part: np.ndarray | None, T_tcp_part: np.ndarray | None,
                      extras: Mapping[str, np.ndarray]) -> None:
        self._shared = shared
        self.robot, self.gripper, self.cell, self.margin = shared.robot, shared.gripper, shared.cell, shared.margin
        self.model = shared.model
        self.geom_model = shared.gm
        self.T_joint_tcp = shared.T_joint_tcp
        self.mode = mode
        self.T_world_part = None if T_world_part is None else np.array(T_world_part, dtype=np.float64)
        self.T_tcp_part = None if T_tcp_part is None else np.array(T_tcp_part, dtype=np.float64)
        self.extras = {k: np.array(v, dtype=np.float64) for k, v in extras.items()}
        unknown = sorted(set(self.extras) - set(shared.extra_ids))
        if unknown:
            raise InputError(f"unknown extra bodies {unknown[:5]}; the scene has {sorted(shared.extra_ids)[:20]}")
        self.data = shared.model.createData()
        gd = pin.GeometryData(shared.gm)
        active = np.ones(len(shared.pairs), dtype=bool)
        if mode != "static":
            active &= shared.group != "static"
        if mode != "attached":
            active &= shared.group != "attached"
        if shared.extra_ids:
            placed = np.array([e == "" or e in self.extras for e in shared.extra_of], dtype=bool)
            active &= placed
        for k in np.flatnonzero(~active):
            gd.deactivateCollisionPair(int(k))
        for req in gd.collisionRequests:
            req.security_margin = shared.margin
            # contacts on, as in grasplan.grasps.collision: coal 3.0 with enable_contact = False missed a
            # 51 micrometre box-into-mesh penetration; EPA only runs on pairs already in collision
            req.enable_contact = True
            req.num_max_contacts = 1
        self._gd = gd
        self._active = active
        self._gd_active = active.copy()  # the pairs ``gd`` has active (:meth:`switch_pairs` is lazy)
        self._broadphase: pin.BroadPhaseManager_SSaPCollisionManager | None = None
        self._placements: dict[int, pin.SE3] = {}
        env = shared.env_ids
        if self.T_world_part is not None and PART in env:
            self._placements[env[PART]] = to_se3(shared.T_base_world @ self.T_world_part)
        if self.T_tcp_part is not None and PART_ATTACHED in env:
            self._placements[env[PART_ATTACHED]] = to_se3(shared.T_joint_tcp @ self.T_tcp_part)
        for name, T in self.extras.items():
            self._placements[shared.extra_ids[name]] = to_se3(shared.T_base_world @ check_transform(
                T, f"extra body {name!r}: T_world"))
        self._apply()
        self.set_opening(float(shared.gripper.max_opening))

    # -- variants ---------------------------------------------------------------------------------
    def _variant(self, mode: str, T_world_part: np.ndarray | None, T_tcp_part: np.ndarray | None) -> CollisionScene:
        other = CollisionScene.__new__(CollisionScene)
        other._init_variant(self._shared, mode, T_world_part, T_tcp_part, self.extras)
        return other

    def attached(self, T_tcp_part: np.ndarray) -> CollisionScene:
        """This scene with the part in the jaws: part pose = FK(TCP) @ ``T_tcp_part`` (4, 4),
        checked against the table, the obstacles, the placed extras and the robot links not moving
        with the tool joint (not the gripper: it is rigidly held); the static part is gone. A resting
        contact of at most :data:`ATTACHED_CONTACT_TOL` with the table or a box, cylinder or sphere
        obstacle is not a collision (they are checked against copies shrunk by that much). Shares the
        geometry (cheap); has its own scratch data."""
        if not self._shared.has_part:
            raise InputError("attached(): the scene has no part mesh to attach")
        return self._variant("attached", None, check_transform(T_tcp_part, "T_tcp_part"))

    def with_part_at(self, T_world_part: np.ndarray) -> CollisionScene:
        """This scene with the part static at ``T_world_part`` (4, 4) (e.g. after release at the
        place). Shares the geometry (cheap); has its own scratch data."""
        if not self._shared.has_part:
            raise InputError("with_part_at(): the scene has no part mesh")
        return self._variant("static", check_transform(T_world_part, "T_world_part"), None)

    def arranged(self, T_world_part: np.ndarray | None, extras: Mapping[str, np.ndarray]) -> CollisionScene:
        """A variant with the part static at ``T_world_part`` (None: no part) and the extra bodies
        named in ``extras`` at their world poses (4, 4); extras not named are not checked.
        Shares the geometry (cheap); has its own scratch data."""
        if T_world_part is not None and not self._shared.has_part:
            raise InputError("arranged(): the scene has no part mesh")
        other = CollisionScene.__new__(CollisionScene)
        other._init_variant(self._shared, "static" if T_world_part is not None else "none",
                            None if T_world_part is None else check_transform(T_world_part, "T_world_part"),
                            None, extras)
        return other

    def switch_pairs(self, pairs: np.ndarray, on: bool) -> None:
        """Switch the pairs ``pairs`` (indices into :meth:`pair_rows`) of this variant off or back on
        (Pinocchio's data learns it when next read, :attr:`geom_data`: off and on again is free)."""
        self._active[pairs] = on

    @property
    def geom_data(self) -> pin.GeometryData:
        """This variant's ``pin.GeometryData``, its active pairs those of :attr:`_active`."""
        for k in np.flatnonzero(self._active != self._gd_active).tolist():
            (self._gd.activateCollisionPair if self._active[k] else self._gd.deactivateCollisionPair)(k)
            self._gd_active[k] = self._active[k]
        return self._gd

    def pair_rows(self) -> list[tuple[str, str, str, str, str]]:
        """Every pair: ``(body, body, kind, group (static, attached, ""), extra body name or "")``."""
        sh = self._shared
        return [(*sh.body_names[k], sh.kinds[k], str(sh.group[k]), str(sh.extra_of[k])) for k in range(len(sh.pairs))]

    def move_attached(self, T_tcp_part: np.ndarray) -> None:
        """Set the attached part's ``T_tcp_part`` (4, 4) of this ``attached`` variant in place
        (no new scratch data: the planner holds one attached variant and moves the part per grasp)."""
        if self.mode != "attached":
            raise InputError("move_attached(): only an attached() variant holds a part in the jaws")
        self.T_tcp_part = check_transform(T_tcp_part, "T_tcp_part").astype(np.float64)
        sh = self._shared
        self._placements[sh.env_ids[PART_ATTACHED]] = to_se3(sh.T_joint_tcp @ self.T_tcp_part)
        if sh.owner is not None and sh.owner() is self:
            sh.owner = None
        self._apply()

    # ------------------------------------------------------------------------------------------
    def _check_finger_model(self, gripper: Gripper) -> None:
        """The fingers move as x translations of their opening-0 pose (+ a moving TCP's z offset)."""
        o = float(gripper.max_opening)
        dz = float(gripper.tcp_offset(o)) - float(gripper.tcp_offset(0.0)) if getattr(gripper, "moving_tcp", False) else 0.0
        # ignores: shape0 is shape's finger at opening 0, the same kind (hasattr narrows shape alone)
        for sign, shape0, shape in zip((-1.0, 1.0), gripper.fingers(0.0), gripper.fingers(o)):
            if hasattr(shape, "T_tcp_box"):
                exp = translation(sign * o / 2, z=dz) @ np.asarray(shape0.T_tcp_box, dtype=float)  # type: ignore[union-attr]
                ok = np.allclose(exp, np.asarray(shape.T_tcp_box, dtype=float), atol=1e-9)
            else:
                v0 = np.asarray(shape0.vertices, dtype=float)  # type: ignore[union-attr]
                ok = np.allclose(v0 + [sign * o / 2, 0, dz], np.asarray(shape.vertices, dtype=float), atol=1e-9)
            if not ok:
                raise InputError("gripper.fingers(opening): the jaws must move along the TCP x axis by "
                                 "-opening/2 (first jaw) and +opening/2 (second jaw)")

    def _apply(self) -> None:
        """Put this variant's part placements into the shared geometry model (another one's may be there)."""
        sh = self._shared
        if sh.owner is not None and sh.owner() is self:
            return
        for gid, M in self._placements.items():
            sh.gm.geometryObjects[gid].placement = M
        sh.owner = weakref.ref(self)

    @property
    def pair_names(self) -> list[tuple[str, str]]:
        """The checked pairs of this variant, in checking order: (geometry name, geometry name)."""
        return [n for n, on in zip(self._shared.geom_names, self._active) if on]

    def set_opening(self, opening: float) -> None:
        """Move the finger geometry to jaw ``opening`` (m); cheap, cached for repeated calls."""
        o = float(opening)
        if o == self._shared.opening:
            return
        if not (math.isfinite(o) and 0.0 <= o <= float(self.gripper.max_opening) + 1e-9):
            raise InputError(f"opening: {o!r} m is outside [0, {self.gripper.max_opening}]")
        self._shared.set_opening(o)

    # ------------------------------------------------------------------------------------------
    def _prep(self, q: ArrayLike, opening: float | None) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape != (self.model.nq,):
            raise InputError(f"q: expected shape ({self.model.nq},), got {q.shape}")
        self.set_opening(self.gripper.max_opening if opening is None else opening)
        self._apply()
        return q

    def _hits(self, q: ArrayLike, opening: float | None, stop: bool) -> list[int]:
        q = self._prep(q, opening)
        if not pin.computeCollisions(self.model, self.data, self.geom_model, self.geom_data, q, stop):
            return []
        return [k for k, res in enumerate(self.geom_data.collisionResults) if self._active[k] and res.isCollision()]

    def _collides(self, q: np.ndarray) -> bool:
        """Any active pair in collision at q (early stop), without the boxes (:meth:`configs_free`
        falls back to it for a model they cannot serve). A scene with extra bodies (many pairs)
        goes through a broad phase first: coal's sweep and prune (SSaP) over the placed geometries
        (Pinocchio's ``BroadPhaseManager``; only the active pairs whose world boxes overlap reach
        the narrow phase; the same answer, several times faster with a pile)."""
        gd = self.geom_data  # its active pairs brought up to date, for the broad phase too
        if not self._shared.extra_ids:
            return bool(pin.computeCollisions(self.model, self.data, self.geom_model, gd, q, True))
        if self._broadphase is None:
            self._broadphase = pin.BroadPhaseManager_SSaPCollisionManager(self.model, self.geom_model, gd)
        return bool(pin.computeCollisions(self.model, self.data, self._broadphase, q, True))

    def is_free(self, q: ArrayLike, opening: float | None = None) -> bool:
        """True when configuration q (n,) with the jaws at ``opening`` (m; default max_opening)
        collides with nothing (early stop at the first colliding pair)."""
        q = self._prep(q, opening)
        return self.configs_free(q[None])

    def is_free_exhaustive(self, q: ArrayLike, opening: float | None = None) -> bool:
        """:meth:`is_free` checking every active pair (no broad phase): the reference of the tests."""
        q = self._prep(q, opening)
        return not pin.computeCollisions(self.model, self.data, self.geom_model, self.geom_data, q, True)

    def first_collision(self, q: ArrayLike, opening: float | None = None) -> str | None:
        """``"<body> vs <body>"`` of the first colliding pair in checking order, or None."""
        hits = self._hits(q, opening, True)
        if not hits:
            return None
        a, b = self._shared.body_names[hits[0]]
        return f"{a} vs {b}"

    def colliding_pairs(self, q: ArrayLike, opening: float | None = None) -> list[tuple[str, str, str]]:
        """All colliding pairs (no early stop), by body: [(body, body, kind)], kind in
        {"table", "part", "obstacle", "self"}; a body hit by several of its geometries is listed once.
        Body names: the robot link name, ``gripper:<element>`` (``gripper:body_0``,
        ``gripper:finger_left``, ``gripper:finger_right``), ``part``, ``table``, ``obstacle:<name>``."""
        out: list[tuple[str, str, str]] = []
        for k in self._hits(q, opening, False):
            row = (*self._shared.body_names[k], self._shared.kinds[k])
            if row not in out:
                out.append(row)
        return out

    def colliding_geometries(self, q: ArrayLike, opening: float | None = None) -> list[tuple[str, str, str]]:
        """As :meth:`colliding_pairs` but with Pinocchio's geometry names (``<link>_<k>``)."""
        return [(*self._shared.geom_names[k], self._shared.kinds[k]) for k in self._hits(q, opening, False)]

    def collision_kind(self, q: ArrayLike, opening: float | None = None) -> str | None:
        """None when free, else the kind of the first hit: "table", "part", "obstacle" or "self"."""
        hits = self._hits(q, opening, True)
        return self._shared.kinds[hits[0]] if hits else None

    def path_free(self, qs: ArrayLike, opening: float | None = None, *, step: float = STEP,
                  reduced: tuple[Callable[[np.ndarray], np.ndarray], np.ndarray] | None = None) -> bool:
        """True when the piecewise-linear joint path qs (k, n) is collision-free, checked at every
        waypoint and at interpolated configurations so that no joint moves more than ``step`` rad
        between two (:func:`~grasplan.geometry.interpolation.interpolate_path`, in path order:
        the boxes bound whole stretches); coal checks those :func:`grasplan.motion.pathboxes.scene_open` cannot clear. ``reduced =
        (covered, drop)``: at the configurations where ``covered(qs)`` (bool per row) holds, the
        pairs ``drop`` (indices into :meth:`pair_rows`) were decided free before and are skipped."""
        qs = np.asarray(qs, dtype=float)
        if qs.ndim != 2 or qs.shape[1] != self.model.nq:
            raise InputError(f"qs: expected shape (k, {self.model.nq}), got {qs.shape}")
        if not step > 0:
            raise InputError(f"step: expected > 0 rad, got {step}")
        self.set_opening(self.gripper.max_opening if opening is None else opening)
        self._apply()
        every = interpolate_path(qs, step=step)
        if reduced is not None:  # the covered configurations with the pairs ``drop`` off
            covered, drop = reduced
            cov = np.asarray(covered(every), dtype=bool)
            if cov.any():
                self.switch_pairs(drop, False)
                try:
                    if not self.configs_free(every[cov]):
                        return False
                finally:
                    self.switch_pairs(drop, True)
                every = every[~cov]
        return self.configs_free(every)

    def configs_free(self, qs: np.ndarray) -> bool:
        """Every configuration of ``qs`` (k, n) free with the pairs now active: coal only for the
        pairs whose oriented boxes do not lie apart (:func:`grasplan.motion.pathboxes.scene_open`), the
        others cannot collide; without the boxes, every pair through the broad phase."""
        if (found := scene_open(self, qs)) is None:
            return not any(map(self._collides, qs))
        starts, pair_ids = found
        return not any(self.pairs_collide(qs[k], pair_ids[starts[k]:starts[k + 1]])
                       for k in np.flatnonzero(starts[1:] > starts[:-1]).tolist())

    def pairs_collide(self, q: np.ndarray, pair_ids: np.ndarray) -> bool:
        """Any of the pairs ``pair_ids`` (indices into :meth:`pair_rows`) in collision at ``q``
        (coal's narrow phase alone, jaws as they are; early stop)."""
        m, d, gm, gd = self.model, self.data, self.geom_model, self._gd  # the narrow phase: activation plays no part
        pin.updateGeometryPlacements(m, d, gm, gd, q)
        return any(pin.computeCollision(gm, gd, p) for p in pair_ids.tolist())

    def path_collisions(self, qs: ArrayLike, opening: float | None = None, *, step: float = STEP
                        ) -> tuple[int, list[tuple[str, str, str]]] | None:
        """``(row of the path densified at step, colliding_pairs)`` of the first colliding
        configuration, or None (for reasons; :meth:`path_free` decides)."""
        dense = interpolate_path(np.asarray(qs, dtype=float), step=step)
        for k, q in enumerate(dense):
            if not self.is_free(q, opening):
                return k, self.colliding_pairs(q, opening)
        return None


def describe_pairs(pairs: list[tuple[str, str, str]], limit: int = 3) -> str:
    """``"upper_arm_link collides with table; ..."`` for :meth:`CollisionScene.colliding_pairs` rows."""
    rows = [f"{a} collides with {b}" for a, b, _ in pairs[:limit]]
    more = f" (+{len(pairs) - limit} more)" if len(pairs) > limit else ""
    return "; ".join(rows) + more

