"""An INDEPENDENT re-check of planned paths with python-fcl (a helper module: no tests in it).

Nothing here uses grasplan's collision code (coal, ``CollisionScene``, ``GripperCollider``,
``grasplan.cell.shapes``) or its path densifier. The geometry is rebuilt from the sources:

* robot links: the ``<collision>`` elements of the robot's URDF, read here with ElementTree
  (meshes loaded with trimesh, ``package://`` resolved against the robot's package dirs; box,
  cylinder and sphere primitives), as python-fcl BVHs / primitives. Pinocchio is used ONLY for
  forward kinematics (the world pose of each link frame);
* gripper: its body shapes and the two jaws at the current opening (``Gripper.fingers``), at
  ``FK(tool) @ T_flange_tcp``;
* the part: static at ``T_world_part`` before the ``close`` event, attached by ``T_tcp_part``
  between ``close`` and ``open`` (``Motion.gripper``), static at ``T_world_part_place`` after
  ``open``;
* table: an fcl half-space ``z <= table_z``; obstacles: fcl Box / Cylinder / Sphere / BVH from
  ``cell.obstacles``.

Rules (written from the issue, not copied from the scene): robot links vs table (except
``robot.mounted_links``), obstacles, static part; gripper vs table, obstacles, static part and
every link not riding on the tool joint; the attached part vs table, obstacles and every link not
riding on the tool joint (not the gripper, which holds it; a resting contact of at most
``part_tol`` with the table or an obstacle is allowed); robot self-collision except links on the
same or adjacent joints and the SRDF's disabled pairs. Every configuration of the path densified
at ``step`` rad (max per joint) is checked.

Use :func:`recheck_result` (a PlanResult) or :func:`recheck_motion`; both return a
:class:`Report` with ``problems`` (empty: free) and ``configs`` (how many were checked).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import fcl
import numpy as np
import pinocchio as pin
import trimesh

#: resting contact (m) the attached or released part may have with the table or an obstacle
PART_TOL = 1e-4


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _bvh(vertices, faces) -> fcl.BVHModel:
    m = fcl.BVHModel()
    m.beginModel(len(vertices), len(faces))
    m.addSubModel(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int32))
    m.endModel()
    return m


#: the same helper under its public name, for other test modules
bvh = _bvh


def fcl_tf(T) -> fcl.Transform:
    """An fcl transform of a 4x4 ``T``."""
    T = np.asarray(T, dtype=np.float64)
    return fcl.Transform(T[:3, :3], T[:3, 3])


def dense(path, step: float = 0.01) -> np.ndarray:
    """``path`` (k, n) with straight-line joint samples no more than ``step`` rad apart (every
    waypoint kept; written independently of grasplan's densifier)."""
    pts = [path[0]]
    for a, b in zip(path[:-1], path[1:]):
        k = max(1, int(np.ceil(np.max(np.abs(b - a)) / step)))
        for i in range(1, k + 1):
            pts.append(a + (b - a) * (i / k))
    return np.array(pts)


def robot_link_objects(robot, mounted=("base_link", "shoulder_link")) -> list:
    """``[(geometry index, link name, fcl object, mounted)]`` of ``robot``'s collision geometry
    (Pinocchio's geometry model gives the mesh files; the shapes are built in python-fcl here)."""
    import trimesh

    out = []
    for gi, g in enumerate(robot.collision_model.geometryObjects):
        name = robot.model.frames[g.parentFrame].name
        if g.meshPath and g.meshPath.lower().endswith((".stl", ".dae", ".obj")):
            tm = trimesh.load(g.meshPath, force="mesh")
            geom = _bvh(np.asarray(tm.vertices) * np.asarray(g.meshScale), tm.faces)
        else:
            geom = fcl.Box(*(2 * np.asarray(g.geometry.halfSide)))
        out.append((gi, name, fcl.CollisionObject(geom, fcl.Transform()), name in mounted))
    return out


class RobotLinks:
    """The robot's links as python-fcl objects (:func:`robot_link_objects`), posed by Pinocchio's
    forward kinematics only, and the TCP: what the plan and pick-and-place checkers share."""

    def __init__(self, robot, T_flange_tcp, mounted=("base_link", "shoulder_link")):
        self.model = robot.model
        self.data = robot.model.createData()
        self.gmodel = robot.collision_model
        self.gdata = pin.GeometryData(self.gmodel)
        self.T_world_base = np.asarray(robot.T_world_base)
        self.tool_id = robot.model.getFrameId(robot.tool_frame)
        self.T_flange_tcp = np.asarray(T_flange_tcp, dtype=np.float64)
        self.links = robot_link_objects(robot, mounted)  # (geometry index, name, fcl object, exempt from table)

    def posed(self, q) -> list:
        """``[(link name, fcl object at q, exempt from table)]``."""
        q = np.asarray(q, dtype=np.float64)
        pin.forwardKinematics(self.model, self.data, q)
        pin.updateGeometryPlacements(self.model, self.data, self.gmodel, self.gdata)
        for gi, _, obj, _ in self.links:
            obj.setTransform(fcl_tf(self.T_world_base @ self.gdata.oMg[gi].homogeneous))
        return [(name, obj, exempt) for _, name, obj, exempt in self.links]

    def hits(self, q, part, table, hit) -> list[tuple[str, str]]:
        """``[(link, "part" | "table")]`` the links at ``q`` touch (``hit(a, b)`` decides; links
        exempt from the table are not checked against it)."""
        out = []
        for name, obj, exempt in self.posed(q):
            if hit(obj, part):
                out.append((name, "part"))
            if not exempt and hit(obj, table):
                out.append((name, "table"))
        return out

    def fk_tcp(self, q) -> np.ndarray:
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=np.float64))
        return self.T_world_base @ self.data.oMf[self.tool_id].homogeneous @ self.T_flange_tcp


def _obj(geom, T) -> fcl.CollisionObject:
    T = np.asarray(T, dtype=np.float64)
    return fcl.CollisionObject(geom, fcl.Transform(T[:3, :3], T[:3, 3]))


def _move(o: fcl.CollisionObject, T) -> None:
    T = np.asarray(T, dtype=np.float64)
    o.setTransform(fcl.Transform(T[:3, :3], T[:3, 3]))


def _resolve(filename: str, package_dirs) -> Path:
    if filename.startswith("package://"):
        rel = filename[len("package://"):]
        for d in package_dirs:
            for cand in (Path(d) / rel, Path(d) / rel.split("/", 1)[-1]):
                if cand.is_file():
                    return cand
        raise FileNotFoundError(filename)
    return Path(filename.removeprefix("file://"))


def urdf_collision_links(urdf_path, package_dirs) -> dict[str, list[tuple[np.ndarray, object]]]:
    """``{link: [(T_link_geom (4, 4), fcl geometry)]}`` from the URDF's ``<collision>`` elements."""
    root = ET.parse(str(urdf_path)).getroot()
    out: dict[str, list] = {}
    for link in root.findall("link"):
        for col in link.findall("collision"):
            T = np.eye(4)
            o = col.find("origin")
            if o is not None:
                T[:3, 3] = [float(x) for x in o.get("xyz", "0 0 0").split()]
                T[:3, :3] = _rpy(*[float(x) for x in o.get("rpy", "0 0 0").split()])
            g = col.find("geometry")
            mesh, box, cyl, sph = (g.find(k) for k in ("mesh", "box", "cylinder", "sphere"))
            if mesh is not None:
                m = trimesh.load(str(_resolve(mesh.get("filename"), package_dirs)), force="mesh")
                scale = np.array([float(x) for x in mesh.get("scale", "1 1 1").split()])
                geom = _bvh(np.asarray(m.vertices) * scale, m.faces)
            elif box is not None:
                geom = fcl.Box(*[float(x) for x in box.get("size").split()])
            elif cyl is not None:
                geom = fcl.Cylinder(float(cyl.get("radius")), float(cyl.get("length")))
            elif sph is not None:
                geom = fcl.Sphere(float(sph.get("radius")))
            else:
                continue
            out.setdefault(link.get("name"), []).append((T, geom))
    return out


def _obstacle_geom(o):
    if o.kind == "box":
        return fcl.Box(*o.size)
    if o.kind == "cylinder":
        return fcl.Cylinder(float(o.radius), float(o.length))
    if o.kind == "sphere":
        return fcl.Sphere(float(o.radius))
    return _bvh(o.vertices, o.faces)


def _gripper_geom(shape):
    if hasattr(shape, "extents"):
        return fcl.Box(*np.asarray(shape.extents, dtype=float)), np.asarray(shape.T_tcp_box, dtype=float)
    return _bvh(shape.vertices, shape.faces), np.eye(4)


@dataclass
class Report:
    configs: int = 0
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems


class FclWorld:
    """python-fcl model of one robot + gripper + cell + part. Build once, check many paths."""

    def __init__(self, robot, gripper, cell, part_mesh, *, part_tol: float = PART_TOL):
        self.robot, self.gripper, self.cell, self.part_tol = robot, gripper, cell, float(part_tol)
        self.data = robot.model.createData()
        model = robot.model
        used = {robot.link_name(g) for g in robot.collision_model.geometryObjects}  # after remove_links
        self.links = []  # (link name, frame id, parent joint, T_link_geom, fcl object)
        for name, geoms in urdf_collision_links(robot.urdf_path, robot.package_dirs).items():
            if name not in used or not model.existFrame(name):
                continue
            fid = model.getFrameId(name)
            for T, geom in geoms:
                self.links.append((name, fid, model.frames[fid].parentJoint, T, _obj(geom, np.eye(4))))
        if not self.links:
            raise RuntimeError("no URDF collision geometry found")
        parents = model.parents
        disabled = {tuple(sorted(p)) for p in robot.disabled_pairs}
        self.self_pairs = []
        for i, a in enumerate(self.links):
            for b in self.links[i + 1:]:
                ja, jb = a[2], b[2]
                if ja == jb or parents[ja] == jb or parents[jb] == ja or tuple(sorted((a[0], b[0]))) in disabled:
                    continue
                self.self_pairs.append((a, b))
        self.tool_joint = model.frames[robot.tool_frame_id].parentJoint
        self.mounted = set(robot.mounted_links)
        self.body = [(f"gripper:body_{k}", *_gripper_geom(s)) for k, s in enumerate(gripper.body)]
        self.body = [(n, _obj(g, np.eye(4)), T) for n, g, T in self.body]
        z = float(cell.table_z)
        self.table = fcl.CollisionObject(fcl.Halfspace(np.array([0.0, 0.0, 1.0]), z))
        self.table_rest = fcl.CollisionObject(fcl.Halfspace(np.array([0.0, 0.0, 1.0]), z - self.part_tol))
        self.obstacles = [(f"obstacle:{o.name}", _obj(_obstacle_geom(o), o.T_world_obstacle))
                          for o in getattr(cell, "obstacles", ())]
        self.part = _obj(_bvh(part_mesh.vertices, part_mesh.faces), np.eye(4))
        self.req = fcl.CollisionRequest(num_max_contacts=8, enable_contact=True)

    # -- one configuration -------------------------------------------------------------------
    def _hit(self, a, b, *, resting: bool = False) -> bool:
        res = fcl.CollisionResult()
        if not fcl.collide(a, b, self.req, res):
            return False
        if not resting:
            return True
        return max((abs(c.penetration_depth) for c in res.contacts), default=np.inf) > self.part_tol

    def check(self, q, opening: float, part_mode: str, T_part: np.ndarray) -> list[str]:
        """Colliding pairs at q: ``part_mode`` in {"static", "attached", "none"}; ``T_part`` =
        T_world_part (static) or T_tcp_part (attached)."""
        r = self.robot
        pin.forwardKinematics(r.model, self.data, np.asarray(q, dtype=float))
        pin.updateFramePlacements(r.model, self.data)
        links = []
        for name, fid, joint, T, o in self.links:
            _move(o, r.T_world_base @ self.data.oMf[fid].homogeneous @ T)
            links.append((name, joint, o))
        T_world_tcp = r.T_world_base @ self.data.oMf[r.tool_frame_id].homogeneous @ np.asarray(
            self.gripper.T_flange_tcp, dtype=float)
        grip = []
        for name, o, T in self.body:
            _move(o, T_world_tcp @ T)
            grip.append((name, o))
        for name, shape in zip(("gripper:finger_left", "gripper:finger_right"), self.gripper.fingers(opening)):
            g, T = _gripper_geom(shape)
            grip.append((name, _obj(g, T_world_tcp @ T)))
        hits: list[str] = []
        env = [("table", self.table)] + self.obstacles
        for name, o in grip:
            for en, eo in env:
                if self._hit(o, eo):
                    hits.append(f"{name} vs {en}")
        for name, joint, o in links:
            for en, eo in env:
                if en == "table" and name in self.mounted:
                    continue
                if self._hit(o, eo):
                    hits.append(f"{name} vs {en}")
        if part_mode == "static":
            _move(self.part, T_part)
            for name, o in grip + [(n, o) for n, _, o in links]:
                if self._hit(o, self.part):
                    hits.append(f"{name} vs part")
        elif part_mode == "attached":
            _move(self.part, T_world_tcp @ T_part)
            for en, eo in [("table", self.table_rest)] + self.obstacles:
                if self._hit(self.part, eo, resting=en != "table"):
                    hits.append(f"part (attached) vs {en}")
            for name, joint, o in links:
                if joint != self.tool_joint and self._hit(self.part, o):
                    hits.append(f"part (attached) vs {name}")
        for name, joint, o in links:
            if joint != self.tool_joint:
                for gn, go in grip:
                    if self._hit(o, go):
                        hits.append(f"{gn} vs {name}")
        for a, b in self.self_pairs:
            if self._hit(a[4], b[4]):
                hits.append(f"{a[0]} vs {b[0]}")
        return hits


def densify(path: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """``(configs (m, n), source segment index (m,))``: every segment of ``path`` split into
    ceil(max|dq| / step) equal parts (its own implementation, not grasplan's)."""
    path = np.asarray(path, dtype=np.float64)
    qs, seg = [path[0]], [0]
    for i in range(len(path) - 1):
        a, b = path[i], path[i + 1]
        n = max(1, int(math.ceil(float(np.max(np.abs(b - a))) / step - 1e-12)))
        for k in range(1, n + 1):
            qs.append(a + (b - a) * (k / n))
            seg.append(i)
    return np.array(qs), np.array(seg)


def recheck_motion(world: FclWorld, motion, *, T_world_part: np.ndarray, pregrasp_opening: float,
                   step: float = 0.01, max_problems: int = 5) -> Report:
    """Check every configuration of ``motion.path`` densified at ``step`` rad. The state (jaw
    opening, where the part is) changes at the ``Motion.gripper`` events; a waypoint holding an
    event is checked in the state before and after it."""
    path = np.asarray(motion.path, dtype=np.float64)
    events = sorted(getattr(motion, "gripper", ()) or (), key=lambda e: e.index)
    T_tcp_part = getattr(motion, "T_tcp_part", None)
    T_place = getattr(motion, "T_world_part_place", None)
    # states: list of (first waypoint, last waypoint, opening, part_mode, T_part)
    states = []
    start, opening, mode, T = 0, float(pregrasp_opening), "static", np.asarray(T_world_part, dtype=float)
    for ev in events:
        states.append((start, int(ev.index), opening, mode, T))
        start, opening = int(ev.index), float(ev.width)
        if ev.action == "close":
            if T_tcp_part is None:
                raise ValueError("a close event needs Motion.T_tcp_part")
            mode, T = "attached", np.asarray(T_tcp_part, dtype=float)
        elif ev.action == "open":
            if T_place is not None:
                mode, T = "static", np.asarray(T_place, dtype=float)
            else:
                mode, T = "none", np.eye(4)
    states.append((start, len(path) - 1, opening, mode, T))
    rep = Report()
    for s, e, o, m, Tp in states:
        if e < s:
            continue
        qs, _ = densify(path[s:e + 1], step)
        for q in qs:
            rep.configs += 1
            hits = world.check(q, o, m, Tp)
            if hits:
                rep.problems.append(f"waypoints {s}..{e} (opening {o * 1e3:.1f} mm, part {m}): q={np.round(q, 4).tolist()}: "
                                    + ", ".join(hits[:3]))
                if len(rep.problems) >= max_problems:
                    return rep
                break  # one problem per state is enough
    return rep


def recheck_result(result, grasp_ids=None, *, step: float = 0.01, world: FclWorld | None = None) -> dict[int, Report]:
    """``{grasp id: Report}`` for the planned grasps of a PlanResult (all, or ``grasp_ids``)."""
    world = world or FclWorld(result.robot, result.gripper, result.cell, result.mesh())
    ids = sorted(result.motions) if grasp_ids is None else list(grasp_ids)
    width = np.asarray(result.grasps.width, dtype=np.float64)
    out = {}
    for i in ids:
        m = result.motions[i]
        w = width[result.grasps.index_of(i)]  # motions are keyed by grasp id, the table by row
        out[i] = recheck_motion(world, m, T_world_part=result.T_world_part,
                                pregrasp_opening=float(result.gripper.pregrasp_opening(w)), step=step)
    return out
