"""Parallel-jaw gripper model: body and finger shapes in the TCP frame, loaded from YAML.

TCP frame (issue 3): origin at the midpoint of the two contacts; x = closing axis (contact 0 ->
contact 1); z = approach direction, from the gripper towards the part (the fingers point along
+z); y = z cross x.

YAML schema (``configs/grippers/<name>.yaml``; lengths in metres, angles in degrees)::

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

A finger box's inner face sits at ``x = +opening/2`` (the other finger's at ``-opening/2``).
The closing sweep of a box finger from opening ``a`` to ``b`` is exactly one box; the sweep of a
mesh finger is the convex hull of its two end placements (exact for a convex finger, a superset
otherwise).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from .config_files import (
    available,
    config_number,
    config_vector,
    packaged_file,
    read_config_mesh,
    read_yaml,
    resolve_yaml,
)
from .meshdata import convex_hull
from .errors import ConfigError
from .params import DEFAULT_GRIPPER
from .transforms import parse_pose, rpy_matrix

#: the ``configs`` folder at the repository root (next to the ``grasplan`` package)
GRIPPER_DIR = packaged_file("configs", "grippers")  # the packaged grippers
#: grip force when the YAML gives none, N (Schunk EGP-C 40: 140 N)
DEFAULT_GRIP_FORCE = 140.0
#: pre-grasp opening = min(max_opening, width + PREGRASP_CLEARANCE)
PREGRASP_CLEARANCE = 0.010
#: the closing sweep stops at width + CLOSE_CLEARANCE (1 mm per side before touching)
CLOSE_CLEARANCE = 0.002


def _rz180() -> np.ndarray:
    T = np.eye(4)
    T[0, 0] = T[1, 1] = -1.0
    return T


@dataclass(frozen=True, eq=False)
class Box:
    """A box with full side lengths ``extents`` (3,) whose centre pose in the TCP frame is
    ``T_tcp_box`` (4, 4)."""

    extents: np.ndarray
    T_tcp_box: np.ndarray

    def corners(self) -> np.ndarray:
        """(8, 3) corners in the TCP frame."""
        s = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=np.float64)
        local = s * (0.5 * np.asarray(self.extents))
        return local @ self.T_tcp_box[:3, :3].T + self.T_tcp_box[:3, 3]

    def moved(self, T: np.ndarray) -> "Box":
        """This box after the rigid motion ``T`` (4, 4) of the TCP frame."""
        return Box(np.asarray(self.extents, dtype=np.float64), np.asarray(T, dtype=np.float64) @ self.T_tcp_box)


@dataclass(frozen=True, eq=False)
class MeshShape:
    """A triangle mesh: ``vertices (n, 3)`` already expressed in the TCP frame, ``faces (m, 3)``."""

    vertices: np.ndarray
    faces: np.ndarray
    source: str = ""

    def corners(self) -> np.ndarray:
        return self.vertices

    def moved(self, T: np.ndarray) -> "MeshShape":
        T = np.asarray(T, dtype=np.float64)
        return MeshShape(self.vertices @ T[:3, :3].T + T[:3, 3], self.faces, self.source)


Shape = Box | MeshShape


@dataclass(frozen=True, eq=False)
class Gripper:
    """A parallel-jaw gripper. ``finger`` is the +x jaw at opening 0 (inner face on x = 0)."""

    name: str
    max_opening: float
    T_flange_tcp: np.ndarray
    body: tuple
    finger: Shape
    symmetric: bool = True
    source: str = ""
    grip_force: float = DEFAULT_GRIP_FORCE  #: N, datasheet gripping force = sum of both jaws (each contact: half)

    # -- finger geometry -------------------------------------------------------------------
    def fingers(self, opening: float) -> tuple[Shape, Shape]:
        """The two jaws at ``opening`` (m): inner faces at x = -opening/2 (first) and +opening/2."""
        o = float(opening)
        T = np.eye(4)
        T[0, 3] = 0.5 * o
        right = self.finger.moved(T)
        return right.moved(_rz180()), right

    def swept_fingers(self, open_from: float, close_to: float) -> tuple[Shape, Shape]:
        """The volume each jaw sweeps while the opening moves between ``open_from`` and
        ``close_to`` (either order): (-x jaw, +x jaw)."""
        lo, hi = sorted((float(open_from), float(close_to)))
        if isinstance(self.finger, Box):
            f = self.finger  # axis-aligned (enforced by the loader): the sweep is one box
            ext = np.array(f.extents, dtype=np.float64)
            cx = f.T_tcp_box[0, 3]
            T = f.T_tcp_box.copy()
            # at opening o the jaw spans x in [cx - ex/2 + o/2, cx + ex/2 + o/2]; union over o in [lo, hi]
            x0 = cx - ext[0] / 2 + lo / 2
            x1 = cx + ext[0] / 2 + hi / 2
            ext[0] = x1 - x0
            T[0, 3] = 0.5 * (x0 + x1)
            right = Box(ext, T)
            return right.moved(_rz180()), right
        return self._hull_sweep(lo, hi)

    def _hull_sweep(self, lo: float, hi: float) -> tuple[Shape, Shape]:
        a = self.fingers(lo)[1].corners()
        b = self.fingers(hi)[1].corners()
        hull = convex_hull(np.vstack([a, b]))
        right = MeshShape(np.asarray(hull.vertices, dtype=np.float64), np.asarray(hull.faces, dtype=np.int64), "finger sweep hull")
        return right.moved(_rz180()), right

    def pregrasp_opening(self, width):
        """``min(max_opening, width + 0.010)``; scalar or (n,) array."""
        return np.minimum(self.max_opening, np.asarray(width, dtype=np.float64) + PREGRASP_CLEARANCE)

    def close_to_opening(self, width):
        """Where the checked closing sweep stops: ``min(width + 0.002, pregrasp_opening(width))``."""
        w = np.asarray(width, dtype=np.float64)
        return np.minimum(w + CLOSE_CLEARANCE, self.pregrasp_opening(w))

    def to_json(self, *, definition: bool = False) -> dict:
        """The ``gripper`` block of the grasps and plan outputs; with ``definition`` also the
        resolved shapes (boxes, mesh vertices in the TCP frame), so a result file rebuilds the
        gripper without its YAML (:func:`gripper_from_json`)."""
        out = {"name": self.name, "max_opening": float(self.max_opening), "T_flange_tcp": self.T_flange_tcp.tolist(),
               "grip_force": float(self.grip_force)}
        if definition:
            out["definition"] = {"body": [_shape_json(b) for b in self.body], "finger": _shape_json(self.finger),
                                 "symmetric": bool(self.symmetric)}
        return out


# -- loading ---------------------------------------------------------------------------------

def _shape_json(shape: Shape) -> dict:
    if isinstance(shape, Box):
        return {"box": {"extents": np.asarray(shape.extents, dtype=float).tolist(), "T": shape.T_tcp_box.tolist()}}
    return {"mesh": {"vertices": np.round(shape.vertices, 9).tolist(), "faces": np.asarray(shape.faces).tolist()}}


def _shape_from_json(d, where: str) -> Shape:
    if not isinstance(d, dict) or len(d) != 1 or next(iter(d)) not in ("box", "mesh"):
        raise ConfigError(f"{where}: expected {{box: {{extents, T}}}} or {{mesh: {{vertices, faces}}}}")
    kind, spec = next(iter(d.items()))
    if not isinstance(spec, dict):
        raise ConfigError(f"{where}.{kind}: expected a mapping")
    if kind == "box":
        ext = config_vector(spec.get("extents"), f"{where}.box.extents", positive=True)
        T = parse_pose(spec.get("T"), f"{where}.box.T")
        return Box(ext, T)
    try:
        V = np.asarray(spec.get("vertices"), dtype=np.float64)
        F = np.asarray(spec.get("faces"), dtype=np.int64)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(f"{where}.mesh: vertices and faces must be numeric arrays") from None
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(F) == 0 or len(V) > 10**6:
        raise ConfigError(f"{where}.mesh: expected vertices (n, 3) and faces (m, 3)")
    if not np.all(np.isfinite(V)) or np.abs(V).max() > 10 or F.min() < 0 or F.max() >= len(V):
        raise ConfigError(f"{where}.mesh: vertices must be finite (|v| <= 10 m) and faces index them")
    return MeshShape(V, F, "embedded")


def gripper_from_json(d, *, where: str = "gripper") -> Gripper:
    """Rebuild a :class:`Gripper` from :meth:`Gripper.to_json` ``(definition=True)`` output."""
    if not isinstance(d, dict) or not isinstance(d.get("definition"), dict):
        raise ConfigError(f"{where}: the file embeds no gripper definition (written by an older grasplan?); "
                          "re-run `grasplan grasps` / `grasplan plan` to get a self-contained result")
    name = d.get("name")
    if not isinstance(name, str) or not name or len(name) > 200:
        raise ConfigError(f"{where}.name: expected a non-empty string")
    defn = d["definition"]
    body = defn.get("body")
    if not isinstance(body, list) or not body or len(body) > 64:
        raise ConfigError(f"{where}.definition.body: expected a list of 1..64 shapes")
    shapes = tuple(_shape_from_json(b, f"{where}.definition.body[{i}]") for i, b in enumerate(body))
    finger = _shape_from_json(defn.get("finger"), f"{where}.definition.finger")
    sym = defn.get("symmetric", True)
    if not isinstance(sym, bool):
        raise ConfigError(f"{where}.definition.symmetric: expected true or false")
    return Gripper(name=name, max_opening=config_number(d.get("max_opening"), f"{where}.max_opening", positive=True, max_abs=2.0),
                   T_flange_tcp=parse_pose(d.get("T_flange_tcp"), f"{where}.T_flange_tcp"), body=shapes,
                   finger=finger, symmetric=sym, source="embedded",
                   grip_force=config_number(d.get("grip_force", DEFAULT_GRIP_FORCE), f"{where}.grip_force",
                                            positive=True, max_abs=1e5))


def available_grippers() -> list[str]:
    """Names of the grippers shipped in ``configs/grippers/*.yaml``."""
    return available("gripper")


def _box(spec, field_: str, *, finger: bool) -> Box:
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


def _mesh(spec, field_: str, base: Path) -> MeshShape:
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


def _box_body_symmetric(body: tuple) -> bool:
    """True when the set of body boxes is unchanged by a 180 deg turn about the TCP z axis."""
    key = lambda b: np.round(np.concatenate([b.corners()[np.lexsort(np.round(b.corners(), 9).T)].ravel()]), 9)  # noqa: E731
    keys = sorted(tuple(key(b)) for b in body)
    turned = sorted(tuple(key(b.moved(_rz180()))) for b in body)
    return keys == turned


def gripper_from_dict(data: dict, *, base: Path, name: str, source: str = "") -> Gripper:
    """Validate a parsed gripper YAML (``base``: folder that mesh paths are relative to)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source or name}: a gripper file must be a YAML mapping")
    allowed = {"name", "max_opening", "T_flange_tcp", "body", "fingers", "symmetric", "description", "grip_force"}
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
    body = []
    for i, item in enumerate(data["body"]):
        f = f"body[{i}]"
        if not isinstance(item, dict) or len(item) != 1 or next(iter(item)) not in ("box", "mesh"):
            raise ConfigError(f"{f}: expected exactly one of {{box: ...}} or {{mesh: ...}}, got {item!r}")
        kind, spec = next(iter(item.items()))
        body.append(_box(spec, f"{f}.box", finger=False) if kind == "box" else _mesh(spec, f"{f}.mesh", base))
    fin = data["fingers"]
    if not isinstance(fin, dict) or len(fin) != 1 or next(iter(fin)) not in ("box", "mesh"):
        raise ConfigError(f"fingers: expected exactly one of {{box: ...}} or {{mesh: ...}}, got {fin!r}")
    kind, spec = next(iter(fin.items()))
    finger = _box(spec, "fingers.box", finger=True) if kind == "box" else _mesh(spec, "fingers.mesh", base)
    if isinstance(finger, MeshShape) and finger.vertices[:, 0].min() < -1e-9:
        raise ConfigError("fingers.mesh: the finger must lie in x >= 0 of its frame (inner face on x = 0)")
    if "symmetric" in data:
        if not isinstance(data["symmetric"], bool):
            raise ConfigError("symmetric: expected true or false")
        symmetric = data["symmetric"]
    else:
        symmetric = all(isinstance(b, Box) for b in body) and _box_body_symmetric(tuple(body))
    grip_force = config_number(data.get("grip_force", DEFAULT_GRIP_FORCE), "grip_force", positive=True, max_abs=1e5)
    return Gripper(name=gname, max_opening=max_opening, T_flange_tcp=T_flange_tcp, body=tuple(body),
                   finger=finger, symmetric=symmetric, source=source, grip_force=grip_force)


@lru_cache(maxsize=32)
def _load_file(path: str, mtime: float) -> Gripper:
    p = Path(path)
    data = read_yaml("gripper", p)
    try:
        return gripper_from_dict(data, base=p.parent, name=p.stem, source=str(p))
    except ConfigError as exc:
        msg = str(exc)
        raise ConfigError(msg if msg.startswith(str(p)) else f"{p}: {msg}") from None


def load_gripper(name_or_path: str | os.PathLike = DEFAULT_GRIPPER) -> Gripper:
    """A gripper by name (``configs/grippers/<name>.yaml``) or by path to a YAML file.

    Raises ConfigError for an unknown name (listing the available ones) or a malformed file
    (naming the field)."""
    if isinstance(name_or_path, Gripper):
        return name_or_path
    p = resolve_yaml("gripper", name_or_path)
    return _load_file(str(p), p.stat().st_mtime)
