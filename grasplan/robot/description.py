"""Robot descriptions: a YAML file (``robots/<name>.yaml``) around a URDF/SRDF pair -> :class:`Robot`.

A :class:`~grasplan.robot.model.Robot` is loaded ONCE per name (:func:`load_robot` caches it) and
is immutable and shared: it holds the Pinocchio ``Model`` and collision/visual ``GeometryModel``
but no ``Data`` (frames and conventions: :mod:`grasplan.robot.model`). ``kind`` names the robot's
IK family and must be registered (:mod:`grasplan.robot.ik.registry`).
The YAML schema: :func:`load_robot`.
"""
from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..config.lookup import available, config_number, config_vector, resolve_yaml
from ..errors import ConfigError, unknown_name
from .ik.registry import IKFamily, get_family
from .ik.solve import BUILTIN_FAMILIES  # noqa: F401  (importing it registers the built-in families)
from ..config.params import DEFAULT_ROBOT
from .files import check_robot_meshes, package_share_dir, parse_srdf_disabled_pairs
from .model import DEFAULT_IK_FAMILY, Robot, read_only
from ..geometry.transforms import to_se3, xyz_rpy


def _remove_link_geometry(gm: pin.GeometryModel, model: pin.Model, link: str) -> None:
    """Drop the geometry objects of ``gm`` attached to the frame ``link`` of ``model``."""
    names = [str(g.name) for g in gm.geometryObjects if model.frames[g.parentFrame].name == link]
    for gname in names:
        gm.removeGeometryObject(gname)


# --------------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------------
def available_robots() -> list[str]:
    """Names of the robot descriptions shipped in ``robots/``."""
    return available("robot")


def robot_from_json(d: object, *, where: str = "robot") -> Robot:
    """Rebuild the robot a plan was made for from its embedded ``source`` (the YAML text; URDF/SRDF
    from the recorded package, else the recorded paths). Checks joint names and q_home against the
    plan's ``robot`` block."""
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
def _from_json_cached(key: str, text: str, yaml_dir: str, fallback: tuple[tuple[str, str], ...],
                      yaml_path: str) -> Robot:
    """The robot of an embedded YAML ``text`` (cached by its sha256 ``key``), recording ``yaml_path``."""
    robot = _build_robot_text(text, "embedded robot description", Path(yaml_dir) if yaml_dir else None, dict(fallback))
    return replace(robot, config_path=Path(yaml_path) if yaml_path else None)


def _resolve(name_or_path: str | Path) -> tuple[str, Path]:
    """``(cache key, path)`` of the robot YAML ``name_or_path`` names."""
    path = resolve_yaml("robot", name_or_path)
    return str(path), path


def load_robot(name_or_path: str | Path | Robot = DEFAULT_ROBOT) -> Robot:
    """The robot named ``name_or_path`` (``robots/<name>.yaml``) or described by a YAML file.

    YAML schema (all lengths m, angles rad; angles may be written as expressions such as ``-pi/2``)::

        name: ur5                       # str, required
        description: "..."              # str, optional
        package: example-robot-data     # optional: urdf/srdf are relative to the installed package's
                                        #   robots/ folder; without it, relative to the YAML file
        urdf: ur_description/urdf/ur5_robot.urdf    # required
        srdf: ur_description/srdf/ur5.srdf          # optional: disabled collision pairs
        kind: ur                        # IK family: "ur" (closed-form IK fast path) or "generic" (CLIK
                                        #   only, the default); any family in grasplan.robot.ik.registry
        tool_frame: tool0               # frame the gripper flange is mounted on (required)
        frames:                         # optional extra fixed frames added to the model
          - {name: tool0, parent: wrist_3_link, xyz: [0, 0.0823, 0], rpy: [-pi/2, 0, 0]}
        lock_joints: {}                 # optional {joint: value}: joints removed from the model
        remove_links: []                # optional links whose collision/visual geometry is dropped
        mounted_links: [base_link, shoulder_link]   # links on the table: exempt from table checks
        T_world_base: identity          # "identity" or a 4x4 nested list
        q_home: [0, -pi/2, pi/2, -pi/2, -pi/2, 0]   # required, within the URDF limits

    Cached: the URDF/SRDF are parsed once per name/path (and file version); the same
    :class:`Robot` is returned on every later call. Raises ConfigError for an unknown name (listing the available ones) or a
    malformed file (naming the field). A :class:`Robot` is returned as is.
    """
    if isinstance(name_or_path, Robot):
        return name_or_path
    key, path = _resolve(name_or_path)
    st = path.stat()
    return _load_cached(key, str(path), st.st_mtime_ns, st.st_size)


@lru_cache(maxsize=None)
def _load_cached(key: str, path: str, mtime_ns: int, size: int) -> Robot:
    """The robot of the YAML file ``path``, cached per file version (``mtime_ns``, ``size``)."""
    return _build_robot(Path(path))


def _field(cfg: dict[str, Any], name: str, where: Path | str, *, required: bool = True, default: Any = None) -> Any:
    """Field ``name`` of ``cfg``; ``default`` when absent and not ``required``, else ConfigError."""
    if name not in cfg:
        if required:
            raise ConfigError(f"{where}: missing required field {name!r}")
        return default
    return cfg[name]


def _build_robot(path: Path) -> Robot:
    """The robot described by the YAML file ``path`` (read as UTF-8 text)."""
    from ..config.inputs import read_input_bytes

    try:
        text = read_input_bytes(path, what="robot file", max_bytes=1_000_000).decode("utf-8")
    except UnicodeDecodeError:
        raise ConfigError(f"robot file {path}: not a UTF-8 text file; a robot description is YAML") from None
    return _build_robot_text(text, path, path.parent)


#: the fields a robot YAML may have
_KNOWN_FIELDS = {"name", "description", "package", "urdf", "srdf", "kind", "tool_frame", "frames",
                 "lock_joints", "remove_links", "mounted_links", "T_world_base", "q_home",
                 "controller_joint_map", "controller_base_frame"}


def _read_config(text: str, path: Path | str) -> dict[str, Any]:
    """The robot YAML ``text`` as a mapping of known fields; ConfigError naming the problem."""
    if len(text) > 1_000_000:
        raise ConfigError(f"{path}: robot file too large ({len(text)} bytes)")
    from ..errors import InputError
    from ..config.yamlfile import load_yaml_text

    try:
        cfg = load_yaml_text(text, f"robot file {path}")
    except InputError as exc:
        raise ConfigError(str(exc)) from None
    if not isinstance(cfg, dict):
        raise ConfigError(f"{path}: expected a mapping of fields, got {type(cfg).__name__}")
    extra = sorted(map(str, set(cfg) - _KNOWN_FIELDS))
    if extra:
        raise ConfigError(f"{path}: unknown field(s) {extra}; known fields: {sorted(_KNOWN_FIELDS)}")
    return cfg


def _file_root(package: object, yaml_dir: Path | None) -> tuple[Path, tuple[str, ...]]:
    """``(root, package_dirs)``: where relative URDF/SRDF paths start (the installed ``package``'s
    robots/ folder, else the YAML's folder) and the folders meshes are looked up in."""
    if package is not None:
        share = package_share_dir(str(package))
        return share / str(package) / "robots", (str(share),)
    root = yaml_dir if yaml_dir is not None else Path(".")
    return root, (str(root),)


def _robot_file(cfg: dict[str, Any], fname: str, path: Path | str, root: Path, required: bool,
                urdf_fallback: dict[str, str] | None) -> Path | None:
    """The file of field ``fname`` (``urdf``/``srdf``), relative to ``root`` (or, when not found there,
    ``urdf_fallback``'s recorded path); None for an absent optional field."""
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


def _load_urdf(urdf_path: Path, package_dirs: tuple[str, ...], path: Path | str
               ) -> tuple[pin.Model, pin.GeometryModel]:
    """The URDF's kinematic model and collision geometry (its meshes checked before Pinocchio loads
    them); the visual geometry is loaded when first asked for (:func:`_visual_loader`)."""
    check_robot_meshes(urdf_path, package_dirs, "collision", path)
    try:
        model = pin.buildModelFromUrdf(str(urdf_path))
        cmodel = pin.buildGeomFromUrdf(model, str(urdf_path), pin.GeometryType.COLLISION,
                                       package_dirs=list(package_dirs))
    except Exception as exc:  # pinocchio raises ValueError/RuntimeError with its own message
        raise ConfigError(f"{path}: field 'urdf': cannot load {urdf_path}: {exc}") from None
    return model, cmodel


def _lock_joints(cfg: dict[str, Any], path: Path | str, model: pin.Model, cmodel: pin.GeometryModel
                 ) -> tuple[pin.Model, pin.GeometryModel, tuple[list[int], np.ndarray] | None]:
    """Field ``lock_joints`` (e.g. the Panda's finger joints): the reduced model and geometry, and
    ``(joint ids, configuration)`` they were locked at (None when nothing is locked)."""
    lock = _field(cfg, "lock_joints", path, required=False, default={}) or {}
    if not isinstance(lock, dict):
        raise ConfigError(f"{path}: field 'lock_joints' must be a mapping joint -> value")
    if not lock:
        return model, cmodel, None
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
    return model, cmodel, (list(ids), q0.copy())


def _remove_links(cfg: dict[str, Any], path: Path | str, model: pin.Model, cmodel: pin.GeometryModel) -> list[str]:
    """Field ``remove_links`` (e.g. the Panda's hand): their geometry dropped from ``cmodel``; the links."""
    remove = _field(cfg, "remove_links", path, required=False, default=[]) or []
    if not isinstance(remove, list):
        raise ConfigError(f"{path}: field 'remove_links' must be a list of link names")
    for ln in remove:
        if not model.existFrame(ln):
            raise ConfigError(f"{path}: field 'remove_links': unknown link {ln!r}")
        _remove_link_geometry(cmodel, model, ln)
    return remove


def _add_frames(cfg: dict[str, Any], path: Path | str, model: pin.Model) -> None:
    """Field ``frames``: extra fixed frames added to ``model``."""
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


def _joint_limits(cfg: dict[str, Any], path: Path | str, model: pin.Model
                  ) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(joint_names, lower, upper, velocity_limit, q_home)``: a robot made only of revolute/prismatic
    1-DoF joints (nq == nv) with finite position limits, and its field ``q_home`` within them."""
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
    return joint_names, lower, upper, vel, q_home


def _world_base(cfg: dict[str, Any], path: Path | str) -> np.ndarray:
    """Field ``T_world_base``: ``identity`` or a rigid 4x4 transform."""
    Twb = _field(cfg, "T_world_base", path, required=False, default="identity")
    if Twb == "identity" or Twb is None:
        return np.eye(4)
    if not isinstance(Twb, list) or len(Twb) != 4:
        raise ConfigError(f"{path}: field 'T_world_base' must be 'identity' or a 4x4 list")
    T_world_base = np.stack([config_vector(r, f"{path}: field 'T_world_base'[{i}]", 4) for i, r in enumerate(Twb)])
    R = T_world_base[:3, :3]
    if not (np.allclose(R @ R.T, np.eye(3), atol=1e-6) and np.isclose(np.linalg.det(R), 1.0, atol=1e-6)
            and np.allclose(T_world_base[3], [0, 0, 0, 1])):
        raise ConfigError(f"{path}: field 'T_world_base' is not a rigid transform")
    return T_world_base


def _mounted_links(cfg: dict[str, Any], path: Path | str, model: pin.Model) -> list[str]:
    """Field ``mounted_links``: links of ``model`` standing on the table."""
    mounted = _field(cfg, "mounted_links", path, required=False, default=[]) or []
    if not isinstance(mounted, list):
        raise ConfigError(f"{path}: field 'mounted_links' must be a list of link names")
    for ln in mounted:
        if not model.existFrame(ln):
            raise ConfigError(f"{path}: field 'mounted_links': unknown link {ln!r}")
    return mounted


def _controller(cfg: dict[str, Any], path: Path | str, model: pin.Model, family: IKFamily
                ) -> tuple[np.ndarray, np.ndarray, str | None]:
    """``(joint_sign, joint_offset_deg, controller_base_frame)``: fields ``controller_joint_map`` and
    ``controller_base_frame`` (default: the IK family's, e.g. the UR controller's ``base``, when the
    model has that frame)."""
    cmap = _field(cfg, "controller_joint_map", path, required=False, default=None) or {}
    if not isinstance(cmap, dict) or set(cmap) - {"sign", "offset_deg"}:
        raise ConfigError(f"{path}: field 'controller_joint_map' must be {{sign: [+1/-1 per joint], offset_deg: [deg per joint]}}")
    sign = config_vector(cmap.get("sign", [1] * model.nq), f"{path}: controller_joint_map.sign", model.nq)
    if not np.all(np.isin(sign, (-1.0, 1.0))):
        raise ConfigError(f"{path}: controller_joint_map.sign: each entry must be 1 or -1, got {sign.tolist()}")
    offset = config_vector(cmap.get("offset_deg", [0] * model.nq), f"{path}: controller_joint_map.offset_deg", model.nq)
    base_frame = _field(cfg, "controller_base_frame", path, required=False, default=None)
    if base_frame is None and family.controller_base_frame and model.existFrame(family.controller_base_frame):
        base_frame = family.controller_base_frame
    if base_frame is not None and (not isinstance(base_frame, str) or not model.existFrame(base_frame)):
        raise unknown_name("controller_base_frame", str(base_frame), [f.name for f in model.frames],
                           hint=f"field 'controller_base_frame' in {path}")
    return sign, offset, base_frame


def _visual_loader(urdf_path: Path, package_dirs: tuple[str, ...], locked: tuple[list[int], np.ndarray] | None,
                   removed: tuple[str, ...], full_model: pin.Model, model: pin.Model, path: Path | str
                   ) -> Callable[[], pin.GeometryModel]:
    """A loader of the robot's visual geometry, reduced (``locked``) and with the ``removed`` links'
    geometry dropped as the collision geometry was."""
    urdf, dirs = str(urdf_path), list(package_dirs)

    def load() -> pin.GeometryModel:
        check_robot_meshes(Path(urdf), dirs, "visual", path)
        vm = pin.buildGeomFromUrdf(full_model, urdf, pin.GeometryType.VISUAL, package_dirs=dirs)
        if locked is not None:
            _, vm = pin.buildReducedModel(full_model, vm, locked[0], locked[1])
        for ln in removed:
            _remove_link_geometry(vm, model, ln)
        return vm

    return load


def _build_robot_text(text: str, path: Path | str, yaml_dir: Path | None,
                      urdf_fallback: dict[str, str] | None = None) -> Robot:
    """Build a robot from the YAML ``text``; ``path`` labels errors, relative URDF/SRDF paths are
    resolved against ``yaml_dir`` (or, when that folder is gone, ``urdf_fallback``'s recorded paths)."""
    cfg = _read_config(text, path)
    name = _field(cfg, "name", path)
    if not isinstance(name, str) or not name:
        raise ConfigError(f"{path}: field 'name' must be a non-empty string")
    kind = _field(cfg, "kind", path, required=False, default=DEFAULT_IK_FAMILY)
    family = get_family(kind, where=f"field 'kind' in {path}")
    package = _field(cfg, "package", path, required=False)
    root, package_dirs = _file_root(package, yaml_dir)
    urdf_path = _robot_file(cfg, "urdf", path, root, True, urdf_fallback)
    if urdf_path is None:
        raise ConfigError(f"{path}: field 'urdf' must be a path string, got null")
    srdf_path = _robot_file(cfg, "srdf", path, root, False, urdf_fallback)
    full_model, cmodel = _load_urdf(urdf_path, package_dirs, path)
    model, cmodel, locked = _lock_joints(cfg, path, full_model, cmodel)
    remove = _remove_links(cfg, path, model, cmodel)
    _add_frames(cfg, path, model)
    tool_frame = _field(cfg, "tool_frame", path)
    if not isinstance(tool_frame, str) or not model.existFrame(tool_frame):
        raise unknown_name("tool_frame", str(tool_frame), [f.name for f in model.frames],
                           hint=f"field 'tool_frame' in {path}")
    tool_frame_id = int(model.getFrameId(tool_frame))
    joint_names, lower, upper, vel, q_home = _joint_limits(cfg, path, model)
    T_world_base = _world_base(cfg, path)
    mounted = _mounted_links(cfg, path, model)
    disabled = parse_srdf_disabled_pairs(srdf_path) if srdf_path else ()
    sign, offset, base_frame = _controller(cfg, path, model, family)
    return Robot(name=name, model=model, collision_model=cmodel,
                 _visual_loader=_visual_loader(urdf_path, package_dirs, locked, tuple(remove), full_model, model, path),
                 joint_names=joint_names, q_home=read_only(q_home), lower=read_only(lower),
                 upper=read_only(upper), velocity_limit=read_only(vel), tool_frame=tool_frame,
                 tool_frame_id=tool_frame_id, T_world_base=read_only(T_world_base),
                 disabled_pairs=disabled, urdf_path=urdf_path, srdf_path=srdf_path,
                 package_dirs=package_dirs, mounted_links=tuple(mounted), kind=family.name,
                 config_path=Path(path) if yaml_dir is not None else None, source_yaml=text,
                 package=str(package) if package is not None else None,
                 joint_sign=read_only(sign), joint_offset_deg=read_only(offset),
                 controller_base_frame=base_frame)
