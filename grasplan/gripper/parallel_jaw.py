"""The ``parallel_jaw`` gripper kind: two jaws that move apart along the TCP x axis.

Reads :class:`~grasplan.gripper.model.Gripper` from its YAML (:func:`from_yaml`, whose docstring
gives the schema) and from its ``to_json(definition=True)`` block (:func:`from_json`), and
registers itself (:mod:`grasplan.gripper.registry`).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..config.lookup import config_number, config_vector
from ..part.config_mesh import read_config_mesh
from ..errors import ConfigError
from ..config.poses import parse_pose
from ..geometry.transforms import rpy_matrix
from .model import DEFAULT_GRIP_FORCE, PARALLEL_JAW, Box, Gripper, MeshShape, Shape, rz180, shape_from_json
from .registry import GripperKind, register

#: the fields of a parallel-jaw gripper YAML
YAML_FIELDS = {"kind", "name", "max_opening", "T_flange_tcp", "body", "fingers", "symmetric", "description",
               "grip_force", "mass", "com", "stroke"}
#: kg and m: bounds of a gripper's mass and of its centre of mass (|c| per axis) in the flange frame
MAX_MASS_KG = 100.0
MAX_COM_M = 1.0


def stroke_from(data: dict[str, Any], where: str, max_opening: float) -> float | None:
    """The optional ``stroke`` (m, in (0, max_opening]); ConfigError naming the field otherwise."""
    if data.get("stroke") is None:
        return None
    stroke = config_number(data["stroke"], f"{where}stroke", positive=True, max_abs=2.0)
    if stroke > max_opening + 1e-12:
        raise ConfigError(f"{where}stroke: {stroke} m is more than max_opening {max_opening} m; the jaws travel "
                          "at most from max_opening to closed")
    return stroke


def mass_from(data: dict[str, Any], where: str) -> dict[str, Any]:
    """``{"mass": kg or None, "com": (3,) or None}`` from a gripper YAML / JSON mapping: ``mass`` in
    (0, 100] kg and ``com`` (three finite numbers, each within 1 m of the flange) come together;
    ConfigError naming the field otherwise."""
    if "mass" not in data and "com" not in data:
        return {"mass": None, "com": None}
    if "mass" not in data or "com" not in data:
        missing = "com" if "mass" in data else "mass"
        raise ConfigError(f"{where}{missing}: missing: give 'mass' (kg) and 'com' ([x, y, z] in the flange frame, m) "
                          "together, or neither")
    mass = config_number(data["mass"], f"{where}mass", positive=True, max_abs=MAX_MASS_KG)
    com = config_vector(data["com"], f"{where}com", 3)
    if np.any(np.abs(com) > MAX_COM_M):
        raise ConfigError(f"{where}com: {com.tolist()} is more than {MAX_COM_M} m from the flange; expected the "
                          "centre of mass [x, y, z] in the flange frame, in metres")
    com = np.array(com, dtype=np.float64)
    com.setflags(write=False)
    return {"mass": mass, "com": com}


def box_from_yaml(spec: object, field_: str, *, finger: bool) -> Box:
    """A body box ``{size, center, rpy_deg}`` or a finger box ``{size, center_y, center_z}`` (axis-
    aligned, inner face on x = 0 at opening 0)."""
    if not isinstance(spec, dict):
        raise ConfigError(f"{field_}: expected a mapping with 'size' and a centre, got {spec!r}")
    allowed = {"size", "center_y", "center_z", "rpy_deg"} if finger else {"size", "center", "rpy_deg"}
    unknown = set(spec) - allowed
    if unknown:
        raise ConfigError(f"{field_}: unknown keys {sorted(unknown)}; allowed: {sorted(allowed)}")
    if "size" not in spec:
        raise ConfigError(f"{field_}.size: missing (full side lengths [x, y, z] in metres)")
    size = config_vector(spec["size"], f"{field_}.size", positive=True)
    T = np.eye(4)
    if "rpy_deg" in spec:
        T[:3, :3] = rpy_matrix(*np.radians(config_vector(spec["rpy_deg"], f"{field_}.rpy_deg")))
    if finger:
        if "center_z" not in spec:
            raise ConfigError(f"{field_}.center_z: missing (z of the finger box centre in the TCP frame, m)")
        if "rpy_deg" in spec:
            raise ConfigError(f"{field_}.rpy_deg: finger boxes are axis-aligned in the TCP frame; use a mesh finger")
        # inner face on x = 0 at opening 0: centre at x = size_x / 2
        T[:3, 3] = [size[0] / 2, config_number(spec.get("center_y", 0.0), f"{field_}.center_y"), config_number(spec["center_z"], f"{field_}.center_z")]
    else:
        if "center" not in spec:
            raise ConfigError(f"{field_}.center: missing (box centre [x, y, z] in the TCP frame, m)")
        T[:3, 3] = config_vector(spec["center"], f"{field_}.center")
    return Box(size, T)


def mesh_from_yaml(spec: object, field_: str, base: Path) -> MeshShape:
    """A mesh shape ``{path, scale, T}`` (or just the path), its vertices moved into the TCP frame."""
    if isinstance(spec, str):
        spec = {"path": spec}
    if not isinstance(spec, dict) or "path" not in spec:
        raise ConfigError(f"{field_}: expected {{path: file.stl, scale: 1.0, T: ...}}, got {spec!r}")
    unknown = set(spec) - {"path", "scale", "T"}
    if unknown:
        raise ConfigError(f"{field_}: unknown keys {sorted(unknown)}; allowed: path, scale, T")
    T = parse_pose(spec["T"], f"{field_}.T") if "T" in spec else np.eye(4)
    v, f, path = read_config_mesh(spec, base, field_, "gripper")
    if not np.all(np.isfinite(v)) or np.abs(v).max() > 10.0:
        raise ConfigError(f"{field_}.path: {path} has non-finite or huge coordinates (|v| <= 10 m after scale)")
    v = v @ T[:3, :3].T + T[:3, 3]
    return MeshShape(v, f, str(path))


def box_body_symmetric(body: tuple[Box, ...]) -> bool:
    """True when the set of body boxes is unchanged by a 180 deg turn about the TCP z axis."""
    key = lambda b: np.round(np.concatenate([b.corners()[np.lexsort(np.round(b.corners(), 9).T)].ravel()]), 9)  # noqa: E731
    keys = sorted(tuple(key(b)) for b in body)
    turned = sorted(tuple(key(b.moved(rz180()))) for b in body)
    return keys == turned


def from_yaml(data: dict[str, Any], *, base: Path, name: str, source: str = "") -> Gripper:
    """Validate a parsed parallel-jaw gripper YAML (``base``: folder that mesh paths are relative to).

    The schema (``configs/grippers/<name>.yaml``; lengths in metres, angles in degrees)::

        kind: parallel_jaw               # optional (the default kind)
        name: schunk_egp_c_40            # optional, defaults to the file stem
        max_opening: 0.050               # > 0
        T_flange_tcp:                    # either a 4x4 row-major matrix ...
          xyz: [0, 0, 0.127]             # ... or xyz (m) + rpy (deg, extrinsic x-y-z = R_z R_y R_x)
          rpy_deg: [0, 0, 0]
        body:                            # list of shapes, fixed in the TCP frame
          - box: {size: [0.060, 0.040, 0.095], center: [0, 0, -0.0795]}
          - mesh: {path: body.stl, scale: 0.001, T: {xyz: [...], rpy_deg: [...]}}  # path relative to the YAML
        fingers:                         # ONE finger, the +x jaw; the -x jaw is it rotated 180 deg about z
          box: {size: [0.008, 0.016, 0.040], center_y: 0.0, center_z: -0.012}
          # or mesh: {path: finger.stl, scale: 1.0, T: ...}: in the mesh frame the jaw's inner face
          #   is the plane x = 0 and the jaw extends towards +x; it is placed at x = +opening/2.
        symmetric: true                  # optional: body invariant under a 180 deg turn about z
                                         # (default: computed for box bodies, false with meshes)
        grip_force: 140                  # optional, N (both jaws together)
        stroke: 0.012                    # optional, m: the jaws' travel (both together), <= max_opening;
                                         #   they close to max_opening - stroke at the narrowest
                                         #   (default: fully, stroke = max_opening)
        mass: 0.32                       # optional, kg: the gripper with its fingers (datasheet)
        com: [0, 0, 0.04]                # with mass: centre of mass in the FLANGE frame, m (RAPID tload,
                                         #   the simulation's load); without it the exports say the load
                                         #   is unknown

    A finger box's inner face sits at ``x = +opening/2`` (the other finger's at ``-opening/2``).
    """
    allowed = YAML_FIELDS
    unknown = set(data) - allowed
    if unknown:
        raise ConfigError(f"{source}: unknown gripper fields {sorted(unknown)}; allowed: {sorted(allowed)}")
    for req in ("max_opening", "T_flange_tcp", "body", "fingers"):
        if req not in data:
            raise ConfigError(f"{source}: missing field {req!r}")
    gname = data.get("name", name)
    if not isinstance(gname, str) or not gname:
        raise ConfigError(f"{source}: name: expected a non-empty string")
    max_opening = config_number(data["max_opening"], "max_opening", positive=True)
    T_flange_tcp = parse_pose(data["T_flange_tcp"], "T_flange_tcp")
    if not isinstance(data["body"], list) or not data["body"]:
        raise ConfigError(f"{source}: body: expected a non-empty list of {{box: ...}} or {{mesh: ...}}")
    body: list[Shape] = []
    for i, item in enumerate(data["body"]):
        f = f"body[{i}]"
        if not isinstance(item, dict) or len(item) != 1 or next(iter(item)) not in ("box", "mesh"):
            raise ConfigError(f"{f}: expected exactly one of {{box: ...}} or {{mesh: ...}}, got {item!r}")
        kind, spec = next(iter(item.items()))
        body.append(box_from_yaml(spec, f"{f}.box", finger=False) if kind == "box" else mesh_from_yaml(spec, f"{f}.mesh", base))
    fin = data["fingers"]
    if not isinstance(fin, dict) or len(fin) != 1 or next(iter(fin)) not in ("box", "mesh"):
        raise ConfigError(f"fingers: expected exactly one of {{box: ...}} or {{mesh: ...}}, got {fin!r}")
    kind, spec = next(iter(fin.items()))
    finger = box_from_yaml(spec, "fingers.box", finger=True) if kind == "box" else mesh_from_yaml(spec, "fingers.mesh", base)
    if isinstance(finger, MeshShape) and finger.vertices[:, 0].min() < -1e-9:
        raise ConfigError("fingers.mesh: the finger must lie in x >= 0 of its frame (inner face on x = 0)")
    if "symmetric" in data:
        if not isinstance(data["symmetric"], bool):
            raise ConfigError("symmetric: expected true or false")
        symmetric = data["symmetric"]
    else:
        boxes = tuple(b for b in body if isinstance(b, Box))
        symmetric = len(boxes) == len(body) and box_body_symmetric(boxes)
    grip_force = config_number(data.get("grip_force", DEFAULT_GRIP_FORCE), "grip_force", positive=True, max_abs=1e5)
    return Gripper(name=gname, max_opening=max_opening, T_flange_tcp=T_flange_tcp, body=tuple(body),
                   finger=finger, symmetric=symmetric, source=source, grip_force=grip_force, stroke=stroke_from(data, "", max_opening), **mass_from(data, ""))


def from_json(d: dict[str, Any], *, where: str) -> Gripper:
    """Rebuild a :class:`Gripper` from its :meth:`Gripper.to_json` ``(definition=True)`` block."""
    name = d.get("name")
    if not isinstance(name, str) or not name or len(name) > 200:
        raise ConfigError(f"{where}.name: expected a non-empty string")
    defn = d.get("definition")
    if not isinstance(defn, dict):
        raise ConfigError(f"{where}.definition: expected the gripper's shapes (body, finger, symmetric)")
    body = defn.get("body")
    if not isinstance(body, list) or not body or len(body) > 64:
        raise ConfigError(f"{where}.definition.body: expected a list of 1..64 shapes")
    shapes = tuple(shape_from_json(b, f"{where}.definition.body[{i}]") for i, b in enumerate(body))
    finger = shape_from_json(defn.get("finger"), f"{where}.definition.finger")
    sym = defn.get("symmetric", True)
    if not isinstance(sym, bool):
        raise ConfigError(f"{where}.definition.symmetric: expected true or false")
    max_opening = config_number(d.get("max_opening"), f"{where}.max_opening", positive=True, max_abs=2.0)
    return Gripper(name=name, max_opening=max_opening, stroke=stroke_from(d, f"{where}.", max_opening),
                   T_flange_tcp=parse_pose(d.get("T_flange_tcp"), f"{where}.T_flange_tcp"), body=shapes,
                   finger=finger, symmetric=sym, source="embedded",
                   grip_force=config_number(d.get("grip_force", DEFAULT_GRIP_FORCE), f"{where}.grip_force",
                                            positive=True, max_abs=1e5), **mass_from(d, f"{where}."))


KIND = register(GripperKind(
    name=PARALLEL_JAW, model=Gripper, from_yaml=from_yaml, from_json=from_json,
    description="two jaws moving apart along the TCP x axis (box or mesh body and fingers)"))
