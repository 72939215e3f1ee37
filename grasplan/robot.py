"""Robot models: a YAML description (``robots/<name>.yaml``) around a URDF/SRDF pair.

A :class:`Robot` is loaded ONCE per name (:func:`load_robot` caches it) and is immutable and
shared: it holds the Pinocchio ``Model`` and collision/visual ``GeometryModel`` but no ``Data``.
Solvers (IK, collision scenes) own their scratch ``pin.Data``. :meth:`Robot.fk` and
:meth:`Robot.link_poses` use a private per-thread ``Data`` for convenience.

Frames
------
* The Pinocchio model's universe is the robot's URDF root link (``base_link`` for the UR5,
  ``panda_link0`` for the Panda). ``T_world_base`` places that root link in the world
  (identity for both shipped robots), so ``fk(q) = T_world_base @ T_base_tool(q)``.
* Extra fixed frames listed in the YAML's ``frames`` are added to the model at load time. The
  UR5 URDF of example-robot-data already defines ``tool0`` and ``base`` as ``ur_description`` does
  for the UR controller: ``tool0`` = ``wrist_3_link``
  translated (0, 0.0823, 0) and rotated -90 deg about x (z along the flange normal), ``base`` =
  ``base_link`` rotated 180 deg about z (the controller's base frame, used for URScript poses).

YAML schema (all lengths m, angles rad; angles may be written as expressions such as ``-pi/2``)::

    name: ur5                       # str, required
    description: "..."              # str, optional
    package: example-robot-data     # optional: urdf/srdf are relative to the installed package's
                                    #   robots/ folder; without it, relative to the YAML file
    urdf: ur_description/urdf/ur5_robot.urdf    # required
    srdf: ur_description/srdf/ur5.srdf          # optional: disabled collision pairs
    kind: ur                        # "ur" (closed-form IK fast path) or "generic" (CLIK only)
    tool_frame: tool0               # frame the gripper flange is mounted on (required)
    frames:                         # optional extra fixed frames added to the model
      - {name: tool0, parent: wrist_3_link, xyz: [0, 0.0823, 0], rpy: [-pi/2, 0, 0]}
    lock_joints: {}                 # optional {joint: value}: joints removed from the model
    remove_links: []                # optional links whose collision/visual geometry is dropped
    mounted_links: [base_link, shoulder_link]   # links on the table: exempt from table checks
    T_world_base: identity          # "identity" or a 4x4 nested list
    q_home: [0, -pi/2, pi/2, -pi/2, -pi/2, 0]   # required, within the URDF limits
"""
from __future__ import annotations

import importlib.metadata
import sys
import threading
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import yaml

from .config_files import available, config_number, config_vector, resolve_yaml
from .errors import ConfigError, InputError, unknown_name
from .params import DEFAULT_ROBOT
from .transforms import to_se3, xyz_rpy

_PKG_SHARE = "cmeel.prefix/share"


# --------------------------------------------------------------------------------------------
# Finding the installed example-robot-data
# --------------------------------------------------------------------------------------------
@lru_cache(maxsize=None)
def package_share_dir(package: str = "example-robot-data") -> Path:
    """The ``share`` directory holding ``<package>/robots/...`` (the ``package://`` root).

    Looks the package up in its installed-files record (cmeel wheels install under
    ``site-packages/cmeel.prefix/share``), then in every ``sys.path`` entry.
    """
    try:
        for f in importlib.metadata.files(package) or []:
            parts = Path(str(f)).parts
            if package in parts and "robots" in parts:
                full = Path(f.locate()).resolve()
                idx = len(full.parts) - len(parts) + parts.index(package)
                share = Path(*full.parts[:idx])
                if (share / package / "robots").is_dir():
                    return share
    except importlib.metadata.PackageNotFoundError:
        pass
    for entry in sys.path:
        cand = Path(entry) / _PKG_SHARE
        if (cand / package / "robots").is_dir():
            return cand
    raise ConfigError(f"package {package!r} with robot descriptions is not installed "
                      f"(pip install {package}); looked in its installed files and in sys.path")


# --------------------------------------------------------------------------------------------
# Small YAML helpers
# --------------------------------------------------------------------------------------------
def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def parse_srdf_disabled_pairs(srdf_path: Path) -> tuple[tuple[str, str], ...]:
    """``<disable_collisions link1 link2>`` entries of an SRDF, each pair sorted."""
    try:
        root = ET.parse(srdf_path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ConfigError(f"cannot read SRDF {srdf_path}: {exc}") from None
    pairs = set()
    for el in root.iter("disable_collisions"):
        a, b = el.get("link1"), el.get("link2")
        if a and b:
            pairs.add(tuple(sorted((a, b))))
    return tuple(sorted(pairs))


# --------------------------------------------------------------------------------------------
# Robot
# --------------------------------------------------------------------------------------------
_VISUAL_LOCK = threading.Lock()


def _remove_link_geometry(gm: pin.GeometryModel, model: pin.Model, link: str) -> None:
    """Drop the geometry objects of ``gm`` attached to the frame ``link`` of ``model``."""
    names = [str(g.name) for g in gm.geometryObjects if model.frames[g.parentFrame].name == link]
    for gname in names:
        gm.removeGeometryObject(gname)


@dataclass(frozen=True, eq=False)
class Robot:
    """An immutable, shared robot model (load with :func:`load_robot`).

    Arrays are read-only float64: ``q_home``, ``lower``, ``upper``, ``velocity_limit`` (n,),
    ``T_world_base`` (4, 4). ``disabled_pairs`` holds sorted (link, link) name pairs from the
    SRDF. ``mounted_links`` are exempt from table checks; ``kind`` is ``"ur"`` or ``"generic"``.
    """

    name: str
    model: pin.Model
    collision_model: pin.GeometryModel
    joint_names: tuple[str, ...]
    q_home: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    velocity_limit: np.ndarray
    tool_frame: str
    tool_frame_id: int
    T_world_base: np.ndarray
    disabled_pairs: tuple[tuple[str, str], ...]
    urdf_path: Path
    srdf_path: Path | None
    package_dirs: tuple[str, ...]
    mounted_links: tuple[str, ...] = ()
    kind: str = "generic"
    config_path: Path | None = None
    source_yaml: str = ""                 #: the robot YAML's text (embedded in plans)
    package: str | None = None            #: the package holding the URDF/SRDF (e.g. example-robot-data)
    joint_sign: np.ndarray | None = None  #: (n,) controller angle [deg] = sign * degrees(q) + offset_deg
    joint_offset_deg: np.ndarray | None = None
    controller_base_frame: str | None = None  #: model frame of the controller's base (UR: "base")
    _tls: threading.local = field(default_factory=threading.local, repr=False, compare=False)
    #: builds the visual geometry on first use (:attr:`visual_model`): the UR5's visual meshes take
    #: 0.33 s to load, 95 % of building the robot, and only a viewer asking for them needs them
    _visual_loader: object = field(default=None, repr=False, compare=False)
    _visual: list = field(default_factory=list, repr=False, compare=False)

    # ---- basic properties -------------------------------------------------------------------
    @property
    def visual_model(self) -> pin.GeometryModel:
        """The URDF's visual geometry, built on first use (same joints, locks and removed links
        as :attr:`collision_model`)."""
        if not self._visual:
            with _VISUAL_LOCK:
                if not self._visual:
                    self._visual.append(self._visual_loader() if self._visual_loader is not None
                                        else pin.GeometryModel())
        return self._visual[0]

    @property
    def nq(self) -> int:
        return int(self.model.nq)

    @property
    def tool_joint_id(self) -> int:
        """Index of the joint the tool frame (and the gripper) moves with."""
        return int(self.model.frames[self.tool_frame_id].parentJoint)

    @property
    def T_joint_tool(self) -> np.ndarray:
        """(4, 4) placement of the tool frame in its parent joint's frame."""
        return self.model.frames[self.tool_frame_id].placement.homogeneous.copy()

    def new_data(self) -> pin.Data:
        """A fresh scratch ``pin.Data`` for a solver to own."""
        return self.model.createData()

    def _data(self) -> pin.Data:
        d = getattr(self._tls, "data", None)
        if d is None:
            d = self._tls.data = self.model.createData()
        return d

    def check_q(self, q, *, where: str = "q") -> np.ndarray:
        """``q`` as a float (n,) array; raises InputError on a wrong shape or non-finite values."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.nq,):
            raise InputError(f"{where}: expected shape ({self.nq},) for robot {self.name!r}, got {q.shape}")
        if not np.all(np.isfinite(q)):
            raise InputError(f"{where}: contains NaN/inf")
        return q

    def within_limits(self, q, *, tol: float = 1e-9) -> bool | np.ndarray:
        """True where q (n,) or (k, n) lies within [lower - tol, upper + tol]."""
        q = np.asarray(q, dtype=float)
        ok = np.all((q >= self.lower - tol) & (q <= self.upper + tol), axis=-1)
        return bool(ok) if ok.ndim == 0 else ok

    # ---- kinematics ---------------------------------------------------------------------------
    def fk(self, q) -> np.ndarray:
        """T_world_tool (4, 4) for joint vector q (n,)."""
        q = self.check_q(q)
        d = self._data()
        pin.forwardKinematics(self.model, d, q)
        M = pin.updateFramePlacement(self.model, d, self.tool_frame_id)
        return self.T_world_base @ M.homogeneous

    def fk_batch(self, qs) -> np.ndarray:
        """T_world_tool (k, 4, 4) for qs (k, n)."""
        qs = np.asarray(qs, dtype=float)
        if qs.ndim != 2 or qs.shape[1] != self.nq:
            raise InputError(f"qs: expected shape (k, {self.nq}), got {qs.shape}")
        return np.stack([self.fk(q) for q in qs]) if len(qs) else np.zeros((0, 4, 4))

    def frame_pose(self, q, frame: str) -> np.ndarray:
        """T_world_frame (4, 4) of any model frame (e.g. ``"base"`` or ``"wrist_3_link"``)."""
        q = self.check_q(q)
        if not self.model.existFrame(frame):
            raise unknown_name("frame", frame, [f.name for f in self.model.frames])
        d = self._data()
        pin.forwardKinematics(self.model, d, q)
        M = pin.updateFramePlacement(self.model, d, self.model.getFrameId(frame))
        return self.T_world_base @ M.homogeneous

    def link_poses(self, q, *, which: str = "collision") -> list[tuple[str, np.ndarray, str, np.ndarray]]:
        """For the viewer: ``[(geometry_name, T_world_geom (4,4), mesh_path, mesh_scale (3,))]``.

        ``which`` = ``"collision"`` (STL meshes, default) or ``"visual"``. ``mesh_path`` is ""
        for primitive shapes (e.g. the UR5's tiny ``ee_link`` box).
        """
        q = self.check_q(q)
        gm = {"collision": self.collision_model, "visual": self.visual_model}.get(which)
        if gm is None:
            raise InputError(f"which: expected 'collision' or 'visual', got {which!r}")
        d = self._data()
        pin.forwardKinematics(self.model, d, q)
        out = []
        for g in gm.geometryObjects:
            T = self.T_world_base @ (d.oMi[g.parentJoint] * g.placement).homogeneous
            mesh = str(g.meshPath or "")
            if mesh.upper() in ("BOX", "SPHERE", "CYLINDER", "CAPSULE", "CONE") or not Path(mesh).is_file():
                mesh = ""  # a primitive (pinocchio names it "BOX" etc.)
            out.append((g.name, T, mesh, np.array(g.meshScale, dtype=float)))
        return out

    def link_name(self, geom: pin.GeometryObject) -> str:
        """The URDF link a geometry object belongs to."""
        return self.model.frames[geom.parentFrame].name

    def to_json(self, *, source: bool = False) -> dict:
        """The ``robot`` block of a plan; with ``source`` also where the model came from (package,
        URDF/SRDF paths relative to it, the YAML text), so :func:`robot_from_json` rebuilds it."""
        out = {"name": self.name, "joint_names": list(self.joint_names),
               "T_world_base": self.T_world_base.tolist(), "q_home": self.q_home.tolist()}
        if source:
            out["source"] = {"package": self.package, "urdf": str(self.urdf_path),
                             "srdf": str(self.srdf_path) if self.srdf_path else None,
                             "yaml_path": str(self.config_path) if self.config_path else None,
                             "yaml": self.source_yaml}
        return out

    def T_world_controller_base(self) -> np.ndarray:
        """(4, 4) pose of the controller's base frame (``controller_base_frame``, else the model root)."""
        if not self.controller_base_frame:
            return self.T_world_base.copy()
        d = self.model.createData()
        pin.framesForwardKinematics(self.model, d, pin.neutral(self.model))
        return self.T_world_base @ d.oMf[self.model.getFrameId(self.controller_base_frame)].homogeneous


# --------------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------------
def available_robots() -> list[str]:
    """Names of the robot descriptions shipped in ``robots/``."""
    return available("robot")


def robot_from_json(d, *, where: str = "robot") -> "Robot":
    """Rebuild the robot a plan was made for from its embedded ``source`` (the YAML text; URDF/SRDF
    from the recorded package, else the recorded paths). Checks joint names and q_home against the
    plan's ``robot`` block."""
    import hashlib

    if not isinstance(d, dict) or not isinstance(d.get("source"), dict) or not isinstance(d["source"].get("yaml"), str):
        raise ConfigError(f"{where}: the plan embeds no robot source (written by an older grasplan?); re-run "
                          "`grasplan plan` to get a self-contained plan")
    src = d["source"]
    yaml_path = src.get("yaml_path")
    yaml_dir = Path(yaml_path).parent if isinstance(yaml_path, str) and Path(yaml_path).parent.is_dir() else None
    key = hashlib.sha256(src["yaml"].encode("utf-8", "replace")).hexdigest()
    fallback = {k: src.get(k) for k in ("urdf", "srdf") if isinstance(src.get(k), str)}
    robot = _from_json_cached(key, src["yaml"], str(yaml_dir) if yaml_dir else "", tuple(sorted(fallback.items())),
                              yaml_path if isinstance(yaml_path, str) else "")
    names = d.get("joint_names")
    if list(robot.joint_names) != names:
        raise ConfigError(f"{where}: joint_names {str(names)[:120]} do not match robot {robot.name!r} "
                          f"({', '.join(robot.joint_names)}); the plan file is inconsistent")
    if d.get("name") != robot.name:
        raise ConfigError(f"{where}: name {str(d.get('name'))[:40]!r} does not match its source ({robot.name!r})")
    try:
        qh = np.asarray(d.get("q_home"), dtype=float)
        Twb = np.asarray(d.get("T_world_base"), dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: q_home and T_world_base must be numbers") from None
    if qh.shape != robot.q_home.shape or not np.allclose(qh, robot.q_home, atol=1e-9) \
            or Twb.shape != (4, 4) or not np.allclose(Twb, robot.T_world_base, atol=1e-9):
        raise ConfigError(f"{where}: q_home / T_world_base differ from the embedded robot description")
    return robot


@lru_cache(maxsize=8)
def _from_json_cached(key: str, text: str, yaml_dir: str, fallback: tuple, yaml_path: str) -> "Robot":
    from dataclasses import replace

    robot = _build_robot_text(text, "embedded robot description", Path(yaml_dir) if yaml_dir else None, dict(fallback))
    return replace(robot, config_path=Path(yaml_path) if yaml_path else None)


def _resolve(name_or_path: str | Path) -> tuple[str, Path]:
    path = resolve_yaml("robot", name_or_path)
    return str(path), path


def load_robot(name_or_path: str | Path = DEFAULT_ROBOT) -> Robot:
    """The robot named ``name_or_path`` (``robots/<name>.yaml``) or described by a YAML file.

    Cached: the URDF/SRDF are parsed once per name/path (and file version); the same
    :class:`Robot` is returned on every later call. Raises ConfigError for an unknown name (listing the available ones) or a
    malformed file (naming the field).
    """
    key, path = _resolve(name_or_path)
    st = path.stat()
    return _load_cached(key, str(path), st.st_mtime_ns, st.st_size)


@lru_cache(maxsize=None)
def _load_cached(key: str, path: str, mtime_ns: int, size: int) -> Robot:
    return _build_robot(Path(path))


def _field(cfg: dict, name: str, where: Path, *, required: bool = True, default: Any = None):
    if name not in cfg:
        if required:
            raise ConfigError(f"{where}: missing required field {name!r}")
        return default
    return cfg[name]


def _build_robot(path: Path) -> Robot:
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read robot file {path}: {exc}") from None
    return _build_robot_text(text, path, path.parent)


def _build_robot_text(text: str, path: Path | str, yaml_dir: Path | None, urdf_fallback: dict | None = None) -> Robot:
    """Build a robot from the YAML ``text``; ``path`` labels errors, relative URDF/SRDF paths are
    resolved against ``yaml_dir`` (or, when that folder is gone, ``urdf_fallback``'s recorded paths)."""
    if len(text) > 1_000_000:
        raise ConfigError(f"{path}: robot file too large ({len(text)} bytes)")
    try:
        cfg = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"cannot read robot file {path}: not valid YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(cfg, dict):
        raise ConfigError(f"{path}: expected a mapping of fields, got {type(cfg).__name__}")
    known = {"name", "description", "package", "urdf", "srdf", "kind", "tool_frame", "frames",
             "lock_joints", "remove_links", "mounted_links", "T_world_base", "q_home",
             "controller_joint_map", "controller_base_frame"}
    extra = sorted(map(str, set(cfg) - known))
    if extra:
        raise ConfigError(f"{path}: unknown field(s) {extra}; known fields: {sorted(known)}")

    name = _field(cfg, "name", path)
    if not isinstance(name, str) or not name:
        raise ConfigError(f"{path}: field 'name' must be a non-empty string")
    kind = _field(cfg, "kind", path, required=False, default="generic")
    if kind not in ("ur", "generic"):
        raise ConfigError(f"{path}: field 'kind' must be 'ur' or 'generic', got {kind!r}")

    package = _field(cfg, "package", path, required=False)
    if package is not None:
        share = package_share_dir(str(package))
        root = share / str(package) / "robots"
        package_dirs = (str(share),)
    else:
        root = yaml_dir if yaml_dir is not None else Path(".")
        package_dirs = (str(root),)

    def _file(fname: str, required: bool) -> Path | None:
        v = _field(cfg, fname, path, required=required)
        if v is None:
            return None
        if not isinstance(v, str):
            raise ConfigError(f"{path}: field {fname!r} must be a path string")
        p = Path(v) if Path(v).is_absolute() else root / v
        if not p.is_file() and urdf_fallback and urdf_fallback.get(fname):
            p = Path(urdf_fallback[fname])
        if not p.is_file():
            raise ConfigError(f"{path}: field {fname!r}: file {p} not found")
        return p

    urdf_path = _file("urdf", True)
    srdf_path = _file("srdf", False)

    try:  # the collision geometry now; the visual geometry when first asked for (Robot.visual_model)
        model = pin.buildModelFromUrdf(str(urdf_path))
        cmodel = pin.buildGeomFromUrdf(model, str(urdf_path), pin.GeometryType.COLLISION,
                                       package_dirs=list(package_dirs))
    except Exception as exc:  # pinocchio raises ValueError/RuntimeError with its own message
        raise ConfigError(f"{path}: field 'urdf': cannot load {urdf_path}: {exc}") from None
    full_model = model

    # lock joints (e.g. the Panda's finger joints)
    lock = _field(cfg, "lock_joints", path, required=False, default={}) or {}
    if not isinstance(lock, dict):
        raise ConfigError(f"{path}: field 'lock_joints' must be a mapping joint -> value")
    if lock:
        q0 = pin.neutral(model)
        ids = []
        for jn, val in lock.items():
            if not model.existJointName(jn):
                raise ConfigError(f"{path}: field 'lock_joints': unknown joint {jn!r}; joints: "
                                  f"{', '.join(list(model.names)[1:])}")
            jid = model.getJointId(jn)
            q0[model.idx_qs[jid]] = config_number(val, f"{path}: lock_joints.{jn}")
            ids.append(jid)
        model, cmodel = pin.buildReducedModel(model, cmodel, ids, q0)

    # drop geometry of removed links (e.g. the Panda's hand)
    remove = _field(cfg, "remove_links", path, required=False, default=[]) or []
    if not isinstance(remove, list):
        raise ConfigError(f"{path}: field 'remove_links' must be a list of link names")
    for ln in remove:
        if not model.existFrame(ln):
            raise ConfigError(f"{path}: field 'remove_links': unknown link {ln!r}")
        _remove_link_geometry(cmodel, model, ln)

    # extra frames
    frames = _field(cfg, "frames", path, required=False, default=[]) or []
    if not isinstance(frames, list):
        raise ConfigError(f"{path}: field 'frames' must be a list")
    for i, fr in enumerate(frames):
        w = f"{path}: frames[{i}]"
        if not isinstance(fr, dict) or "name" not in fr or "parent" not in fr:
            raise ConfigError(f"{w}: needs 'name' and 'parent' (and optional 'xyz', 'rpy')")
        if model.existFrame(fr["parent"]) is False:
            raise ConfigError(f"{w}.parent: unknown frame {fr['parent']!r}")
        if model.existFrame(fr["name"]):
            raise ConfigError(f"{w}.name: frame {fr['name']!r} already exists in the URDF")
        pid = model.getFrameId(fr["parent"])
        parent = model.frames[pid]
        local = to_se3(xyz_rpy(config_vector(fr.get("xyz", [0, 0, 0]), f"{w}.xyz", 3),
                                 config_vector(fr.get("rpy", [0, 0, 0]), f"{w}.rpy", 3)))
        model.addFrame(pin.Frame(fr["name"], parent.parentJoint, pid, parent.placement * local,
                                 pin.FrameType.OP_FRAME))

    tool_frame = _field(cfg, "tool_frame", path)
    if not isinstance(tool_frame, str) or not model.existFrame(tool_frame):
        raise unknown_name("tool_frame", str(tool_frame), [f.name for f in model.frames],
                           hint=f"field 'tool_frame' in {path}")
    tool_frame_id = int(model.getFrameId(tool_frame))

    # a robot made only of revolute/prismatic 1-DoF joints (nq == nv) is what we support
    if model.nq != model.nv:
        raise ConfigError(f"{path}: field 'urdf': continuous/free joints are not supported (nq != nv)")
    joint_names = tuple(model.names[1:])
    lower = np.array(model.lowerPositionLimit, dtype=float)
    upper = np.array(model.upperPositionLimit, dtype=float)
    vel = np.array(model.velocityLimit, dtype=float)
    if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
        raise ConfigError(f"{path}: field 'urdf': every joint needs finite position limits")

    q_home = config_vector(_field(cfg, "q_home", path), f"{path}: field 'q_home'", model.nq)
    if np.any(q_home < lower - 1e-9) or np.any(q_home > upper + 1e-9):
        raise ConfigError(f"{path}: field 'q_home' {q_home.tolist()} is outside the joint limits "
                          f"[{lower.tolist()}, {upper.tolist()}]")

    Twb = _field(cfg, "T_world_base", path, required=False, default="identity")
    if Twb == "identity" or Twb is None:
        T_world_base = np.eye(4)
    else:
        if not isinstance(Twb, list) or len(Twb) != 4:
            raise ConfigError(f"{path}: field 'T_world_base' must be 'identity' or a 4x4 list")
        T_world_base = np.stack([config_vector(r, f"{path}: field 'T_world_base'[{i}]", 4) for i, r in enumerate(Twb)])
        R = T_world_base[:3, :3]
        if not (np.allclose(R @ R.T, np.eye(3), atol=1e-6) and np.isclose(np.linalg.det(R), 1.0, atol=1e-6)
                and np.allclose(T_world_base[3], [0, 0, 0, 1])):
            raise ConfigError(f"{path}: field 'T_world_base' is not a rigid transform")

    mounted = _field(cfg, "mounted_links", path, required=False, default=[]) or []
    if not isinstance(mounted, list):
        raise ConfigError(f"{path}: field 'mounted_links' must be a list of link names")
    for ln in mounted:
        if not model.existFrame(ln):
            raise ConfigError(f"{path}: field 'mounted_links': unknown link {ln!r}")

    disabled = parse_srdf_disabled_pairs(srdf_path) if srdf_path else ()

    cmap = _field(cfg, "controller_joint_map", path, required=False, default=None) or {}
    if not isinstance(cmap, dict) or set(cmap) - {"sign", "offset_deg"}:
        raise ConfigError(f"{path}: field 'controller_joint_map' must be {{sign: [+1/-1 per joint], offset_deg: [deg per joint]}}")
    sign = config_vector(cmap.get("sign", [1] * model.nq), f"{path}: controller_joint_map.sign", model.nq)
    if not np.all(np.isin(sign, (-1.0, 1.0))):
        raise ConfigError(f"{path}: controller_joint_map.sign: each entry must be 1 or -1, got {sign.tolist()}")
    offset = config_vector(cmap.get("offset_deg", [0] * model.nq), f"{path}: controller_joint_map.offset_deg", model.nq)
    base_frame = _field(cfg, "controller_base_frame", path, required=False, default=None)
    if base_frame is None and kind == "ur" and model.existFrame("base"):
        base_frame = "base"  # the UR controller's base frame (ur_description)
    if base_frame is not None and (not isinstance(base_frame, str) or not model.existFrame(base_frame)):
        raise unknown_name("controller_base_frame", str(base_frame), [f.name for f in model.frames],
                           hint=f"field 'controller_base_frame' in {path}")

    def visual_loader(urdf=str(urdf_path), dirs=list(package_dirs), locked=(list(ids), q0.copy()) if lock else None,
                      removed=tuple(remove), base=full_model):
        vm = pin.buildGeomFromUrdf(base, urdf, pin.GeometryType.VISUAL, package_dirs=dirs)
        if locked is not None:
            _, vm = pin.buildReducedModel(base, vm, locked[0], locked[1])
        for ln in removed:
            _remove_link_geometry(vm, model, ln)
        return vm

    return Robot(name=name, model=model, collision_model=cmodel, _visual_loader=visual_loader,
                 joint_names=joint_names, q_home=_frozen(q_home), lower=_frozen(lower),
                 upper=_frozen(upper), velocity_limit=_frozen(vel), tool_frame=tool_frame,
                 tool_frame_id=tool_frame_id, T_world_base=_frozen(T_world_base),
                 disabled_pairs=disabled, urdf_path=urdf_path, srdf_path=srdf_path,
                 package_dirs=package_dirs, mounted_links=tuple(mounted), kind=kind,
                 config_path=Path(path) if yaml_dir is not None else None, source_yaml=text,
                 package=str(package) if package is not None else None,
                 joint_sign=_frozen(sign), joint_offset_deg=_frozen(offset),
                 controller_base_frame=base_frame)
