"""The cell model: the robot cell around the part (a table top, obstacles, an optional bin, where
the part rests, and where the part goes after the grasp: retreat, place), read from its YAML
(``configs/cells/<name>.yaml``; the schema: docs/cells.md) and from the ``cell`` block of a result.

World frame: z up, metres, degrees. The table top is the plane ``z = table_z`` and the table fills
``z < table_z``. The part rests on the table in a stable pose (:func:`grasplan.cell.resting.stable_pose`:
the most probable one unless ``pose_index`` says otherwise), its lowest point on the table top and
its centre of mass above ``part_xy`` (default (0.45, 0) m); with a ``bin``, on the bin floor's top,
``part_xy`` then an offset from the floor's centre (default (0, 0)). Obstacles are boxes,
cylinders (axis = local z), spheres and meshes (a path relative to the YAML), each at a pose ``T``
(its centre; a mesh: its file origin) with R = Rz(yaw) Ry(pitch) Rx(roll). ``--part-pose``
overrides the resting pose (:func:`grasplan.config.poses.parse_part_pose`), ``--place`` the place
(:func:`grasplan.geometry.transforms.parse_place`); :func:`grasplan.motion.start_checks.check_part_placement`
refuses a part inside the table or an obstacle.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import os
import re
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

if TYPE_CHECKING:  # imported where a trimesh is built (obstacle primitives, mesh files)
    import trimesh

from ..config.lookup import available, config_number, config_vector, packaged_file, read_yaml, resolve_yaml
from ..config.params import DEFAULT_CELL
from ..config.poses import parse_pose
from ..errors import ConfigError
from ..geometry.transforms import MAX_CELL_COORD_M, check_transform
from ..part.config_mesh import read_config_mesh
from .regions import DEFAULT_RETREAT_DIRECTION, DEFAULT_RETREAT_DISTANCE, Workspace, retreat_from

CELL_DIR = packaged_file("configs", "cells")  # the packaged cells
#: longest cell name (characters)
MAX_NAME_CHARS = 100
#: largest pose_index accepted from a file (a part has far fewer distinct resting poses)
MAX_POSE_INDEX = 100_000
#: most obstacles in one cell, and most triangles of all its mesh obstacles together: what a plan
#: honours in seconds and well under 1 GB (docs/cells.md); more is refused up front
MAX_OBSTACLES = 250
MAX_CELL_TRIANGLES = 250_000
#: most triangles of one mesh obstacle
MAX_OBSTACLE_FACES = MAX_CELL_TRIANGLES
#: longest obstacle dimension (m)
MAX_OBSTACLE_SIZE_M = 10.0
#: the obstacle names the bin's boxes get (reserved)
BIN_NAMES = ("bin_floor", "bin_wall_+x", "bin_wall_-x", "bin_wall_+y", "bin_wall_-y")
OBSTACLE_KINDS = ("box", "cylinder", "sphere", "mesh")
_NAME_RE = re.compile(r"^[A-Za-z0-9_+\-.]{1,64}$")


def _readonly(a: Any) -> np.ndarray:
    a = np.array(a, dtype=np.float64)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class Obstacle:
    """One fixed obstacle of the cell (metres). ``kind`` in :data:`OBSTACLE_KINDS`:

    * ``box``: ``size`` (3,) full side lengths, centred on its frame;
    * ``cylinder``: ``radius``, ``length`` along the local z axis, centred on its frame;
    * ``sphere``: ``radius``, centred on its frame;
    * ``mesh``: ``vertices`` (V, 3) (already scaled, in the obstacle frame) and ``faces`` (F, 3).

    ``T_world_obstacle`` (4, 4) places it. Equality compares the geometry and pose."""

    name: str
    kind: str
    T_world_obstacle: np.ndarray
    size: tuple[float, float, float] | None = None
    radius: float | None = None
    length: float | None = None
    vertices: np.ndarray | None = None
    faces: np.ndarray | None = None

    def _key(self) -> tuple:
        return (self.name, self.kind, self.size, self.radius, self.length,
                np.asarray(self.T_world_obstacle).tobytes(),
                None if self.vertices is None else np.asarray(self.vertices).tobytes(),
                None if self.faces is None else np.asarray(self.faces).tobytes())

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Obstacle) and self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    @property
    def body(self) -> str:
        """The body name in collision reports: ``obstacle:<name>``."""
        return f"obstacle:{self.name}"

    def _missing(self, what: str) -> ValueError:
        return ValueError(f"obstacle {self.name!r} ({self.kind}): {what} is not set; build obstacles with "
                          f"load_cell or cell_from_dict")

    def box_size(self) -> tuple[float, float, float]:
        """A box's full side lengths (m)."""
        if self.size is None:
            raise self._missing("size")
        return self.size

    def dimension(self, name: str) -> float:
        """A cylinder's or sphere's ``radius`` or a cylinder's ``length`` (m)."""
        v = {"radius": self.radius, "length": self.length}[name]
        if v is None:
            raise self._missing(name)
        return float(v)

    def mesh_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """A mesh obstacle's ``(vertices (V, 3) m, faces (F, 3))`` in its own frame."""
        if self.vertices is None or self.faces is None:
            raise self._missing("vertices and faces")
        return np.asarray(self.vertices), np.asarray(self.faces)

    def local_mesh(self) -> trimesh.Trimesh:
        """A triangle mesh of the shape in its own frame (cylinder: 64 sides; sphere: icosphere 3)."""
        import trimesh

        if self.kind == "box":
            return trimesh.creation.box(extents=self.box_size())
        if self.kind == "cylinder":
            return trimesh.creation.cylinder(radius=self.dimension("radius"), height=self.dimension("length"),
                                             sections=64)
        if self.kind == "sphere":
            return trimesh.creation.icosphere(subdivisions=3, radius=self.dimension("radius"))
        return trimesh.Trimesh(*self.mesh_arrays(), process=False)

    def world_mesh(self) -> trimesh.Trimesh:
        """:meth:`local_mesh` placed at ``T_world_obstacle`` (for viewers and exports)."""
        m = self.local_mesh()
        m.apply_transform(np.asarray(self.T_world_obstacle))
        return m

    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lo (3,), hi (3,))`` world axis-aligned bounds (exact for box, cylinder, sphere, mesh)."""
        T = np.asarray(self.T_world_obstacle)
        R, t = T[:3, :3], T[:3, 3]
        if self.kind == "box":
            h = np.abs(R) @ (0.5 * np.asarray(self.box_size()))
        elif self.kind == "sphere":
            h = np.full(3, self.dimension("radius"))
        elif self.kind == "cylinder":
            # disc of radius r about local z, extruded by length/2 along local z
            z = R[:, 2]
            h = (self.dimension("radius") * np.sqrt(np.clip(1.0 - z * z, 0.0, None))
                 + 0.5 * self.dimension("length") * np.abs(z))
        else:
            w = self.mesh_arrays()[0] @ R.T + t
            return w.min(axis=0), w.max(axis=0)
        return t - h, t + h

    def to_json(self) -> dict:
        shape: dict
        if self.kind == "box":
            shape = {"size": [float(x) for x in self.box_size()]}
        elif self.kind == "cylinder":
            shape = {"radius": self.dimension("radius"), "length": self.dimension("length")}
        elif self.kind == "sphere":
            shape = {"radius": self.dimension("radius")}
        else:
            v, f = self.mesh_arrays()
            shape = {"vertices": v.tolist(), "faces": f.tolist()}
        return {"name": self.name, self.kind: shape, "T_world_obstacle": np.asarray(self.T_world_obstacle).tolist()}


@dataclass(frozen=True, eq=False)
class BinSpec:
    """An open box the part rests in: ``inner`` (x, y) inner floor size, ``wall`` thickness (also
    the floor's), ``height`` of the walls above the floor's top, ``T_world_bin`` (4, 4) the centre
    of the floor's top (z up: only a yaw is allowed). Its five boxes are :meth:`obstacles`."""

    inner: tuple[float, float]
    wall: float
    height: float
    T_world_bin: np.ndarray

    def __eq__(self, other: object) -> bool:
        return isinstance(other, BinSpec) and (self.inner, self.wall, self.height) == (
            other.inner, other.wall, other.height) and np.array_equal(self.T_world_bin, other.T_world_bin)

    def __hash__(self) -> int:
        return hash((self.inner, self.wall, self.height, np.asarray(self.T_world_bin).tobytes()))

    def obstacles(self) -> tuple[Obstacle, ...]:
        """Floor and four walls as boxes named :data:`BIN_NAMES` (walls from the floor's top up)."""
        ix, iy = self.inner
        w, h = self.wall, self.height
        boxes = [  # (size, centre in the bin frame)
            ((ix + 2 * w, iy + 2 * w, w), (0.0, 0.0, -w / 2)),
            ((w, iy + 2 * w, h), (ix / 2 + w / 2, 0.0, h / 2)),
            ((w, iy + 2 * w, h), (-ix / 2 - w / 2, 0.0, h / 2)),
            ((ix, w, h), (0.0, iy / 2 + w / 2, h / 2)),
            ((ix, w, h), (0.0, -iy / 2 - w / 2, h / 2)),
        ]
        out = []
        for name, (size, c) in zip(BIN_NAMES, boxes):
            T = np.eye(4)
            T[:3, 3] = c
            out.append(Obstacle(name, "box", _readonly(np.asarray(self.T_world_bin) @ T),
                                size=(float(size[0]), float(size[1]), float(size[2]))))
        return tuple(out)

    def to_bin(self, points_world: np.ndarray) -> np.ndarray:
        """Points (..., 3) from the world into the bin frame (origin the floor's top centre, z up)."""
        T = np.asarray(self.T_world_bin, dtype=np.float64)
        return (np.asarray(points_world, dtype=np.float64) - T[:3, 3]) @ T[:3, :3]

    def wall_gaps(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """How far (m) the points (k, 3, world) keep from each inner wall, in the order of
        ``BIN_NAMES[1:]`` (+x, -x, +y, -y; negative beyond it), and each wall's inward normal
        (4, 3, world)."""
        p = self.to_bin(points_world)
        hx, hy = 0.5 * self.inner[0], 0.5 * self.inner[1]
        gaps = np.array([hx - p[:, 0].max(), hx + p[:, 0].min(), hy - p[:, 1].max(), hy + p[:, 1].min()])
        R = np.asarray(self.T_world_bin, dtype=np.float64)[:3, :3]
        return gaps, np.stack([-R[:, 0], R[:, 0], -R[:, 1], R[:, 1]])

    def to_json(self) -> dict:
        return {"inner": [float(x) for x in self.inner], "wall": float(self.wall), "height": float(self.height),
                "T_world_bin": np.asarray(self.T_world_bin).tolist()}


@dataclass(frozen=True, eq=False)
class Cell:
    """A robot cell (metres). ``table_z``: height of the table top; ``part_xy``: where the part's
    centre of mass rests, world x, y (with a bin: already the floor centre plus the YAML's
    offset); ``pose_index``: which stable pose (0 = most probable); ``obstacles``: every fixed
    obstacle, the bin's five boxes included; ``bin``: the bin (for display and the resting
    height) or None; ``retreat_direction`` (3,) unit world vector and ``retreat_distance`` (m):
    the lift after the grasp; ``place``: ``T_world_part`` (4, 4) after release, or None."""

    name: str
    table_z: float = 0.0
    part_xy: tuple[float, float] = (0.45, 0.0)
    pose_index: int = 0
    source: str = ""
    obstacles: tuple[Obstacle, ...] = ()
    bin: BinSpec | None = None
    retreat_direction: tuple[float, float, float] = DEFAULT_RETREAT_DIRECTION
    retreat_distance: float = DEFAULT_RETREAT_DISTANCE
    place: np.ndarray | None = field(default=None)
    workspace: Workspace | None = None

    def _key(self) -> tuple:
        return (self.name, self.table_z, self.part_xy, self.pose_index, self.obstacles, self.bin,
                self.retreat_direction, self.retreat_distance,
                None if self.place is None else np.asarray(self.place).tobytes(), self.workspace)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Cell) and self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    @property
    def rest_z(self) -> float:
        """Height (m) of the surface the part rests on: the bin floor's top, else the table top."""
        return float(self.bin.T_world_bin[2, 3]) if self.bin is not None else float(self.table_z)

    def obstacle(self, name: str) -> Obstacle:
        for o in self.obstacles:
            if o.name == name:
                return o
        raise KeyError(name)

    def to_json(self) -> dict:
        """The ``cell`` block of the grasps output: the name and what defines the cell (the
        obstacles with their geometry, so a plan file stands alone)."""
        return {
            "name": self.name,
            "up": [0.0, 0.0, 1.0],
            "table": {"type": "half_space", "normal": [0.0, 0.0, 1.0], "z": float(self.table_z),
                      "fills": "z < table_z"},
            "part_xy": [float(self.part_xy[0]), float(self.part_xy[1])],
            "pose_index": int(self.pose_index),
            "obstacles": [o.to_json() for o in self.obstacles],
            "bin": None if self.bin is None else self.bin.to_json(),
            "retreat": {"direction": [float(x) for x in self.retreat_direction],
                        "distance": float(self.retreat_distance)},
            "place": None if self.place is None else {"T_world_part": np.asarray(self.place).tolist()},
        } | ({} if self.workspace is None else {"workspace": self.workspace.to_json()})

    @classmethod
    def from_json(cls, d: dict) -> Cell:
        """Rebuild a cell from exactly what :meth:`to_json` writes (a result file's ``cell`` block),
        with the same range checks as a cell YAML. Raises ConfigError (exit 3) naming the field."""
        where = "cell"
        if not isinstance(d, dict):
            raise ConfigError(f"{where}: expected the cell block of a grasplan result (a mapping), "
                              f"got {type(d).__name__}")
        for key in ("up",):
            if key in d and not _is_up(d[key]):
                raise ConfigError(f"{where}.{key}: grasplan cells have z up ([0, 0, 1]), got {str(d[key])[:60]}")
        table = d.get("table", {})
        if not isinstance(table, dict):
            raise ConfigError(f"{where}.table: expected a mapping with 'z', got {str(table)[:60]}")
        if table.get("type", "half_space") != "half_space" or not _is_up(table.get("normal", [0.0, 0.0, 1.0])):
            raise ConfigError(f"{where}.table: only a half-space table with normal [0, 0, 1] is supported")
        allowed = {"name", "up", "table", "part_xy", "pose_index", "source", "obstacles", "bin", "retreat", "place",
                   "workspace"}
        unknown = set(d) - allowed
        if unknown:
            raise ConfigError(f"{where}: unknown fields {sorted(unknown)[:5]}; the file was not written by grasplan "
                              f"(valid: {sorted(allowed)})")
        data = {"name": d.get("name"), "table_z": table.get("z", 0.0),
                "part_xy": d.get("part_xy", [0.45, 0.0]), "pose_index": d.get("pose_index", 0)}
        c = cell_from_dict(data, name="cell", source=f"{where} (embedded in the result)")
        obs = d.get("obstacles", [])
        if not isinstance(obs, list) or len(obs) > MAX_OBSTACLES:
            raise ConfigError(f"{where}.obstacles: expected a list of at most {MAX_OBSTACLES} obstacles")
        obstacles = tuple(_obstacle_from_json(o, f"{where}.obstacles[{i}]") for i, o in enumerate(obs))
        total = sum(len(o.faces) for o in obstacles if o.faces is not None)
        if total > MAX_CELL_TRIANGLES:
            raise ConfigError(f"{where}.obstacles: {total} mesh triangles; at most {MAX_CELL_TRIANGLES} together "
                              "(grasplan.cell.model.MAX_CELL_TRIANGLES)")
        _check_unique([o.name for o in obstacles], f"{where}.obstacles", reserved=())
        b = d.get("bin")
        bin_ = None if b is None else _bin_from_json(b, f"{where}.bin")
        direction, distance = retreat_from(d.get("retreat", {}), f"{where}.retreat")
        place = d.get("place")
        if place is not None:
            if not isinstance(place, dict) or set(place) != {"T_world_part"}:
                raise ConfigError(f"{where}.place: expected {{T_world_part: 4x4}} or null")
            place = _readonly(check_transform(place["T_world_part"], f"{where}.place.T_world_part", error=ConfigError))
        ws = None if d.get("workspace") is None else Workspace.from_config(d["workspace"], f"{where}.workspace")
        return Cell(name=c.name, table_z=c.table_z, part_xy=c.part_xy, pose_index=c.pose_index, source=c.source,
                    obstacles=obstacles, bin=bin_, retreat_direction=direction, retreat_distance=distance,
                    place=place, workspace=ws)


def _is_up(v: Any) -> bool:
    return (isinstance(v, (list, tuple)) and len(v) == 3
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
            and list(map(float, v)) == [0.0, 0.0, 1.0])


def available_cells() -> list[str]:
    """Names of the cells shipped in ``configs/cells/*.yaml``."""
    return available("cell")


# -- obstacles, bin, retreat, place: parsing ------------------------------------------------------

def _check_unique(names: list[str], where: str, reserved: tuple[str, ...]) -> None:
    seen: set[str] = set()
    for n in names:
        if n in reserved:
            raise ConfigError(f"{where}: the name {n!r} is reserved for the bin's boxes ({', '.join(reserved)}); "
                              f"rename the obstacle")
        if n in seen:
            raise ConfigError(f"{where}: two obstacles are named {n!r}; obstacle names must be unique")
        seen.add(n)


def _pose_yaml(v: Any, where: str) -> np.ndarray:
    """``T: {xyz: [m], rpy_deg: [deg]}`` of a cell YAML -> (4, 4) (:func:`grasplan.config.poses.parse_pose`)."""
    return parse_pose(v, where, matrix=False, require_xyz=True, max_coord=MAX_CELL_COORD_M, max_deg=3600)


def _obstacle_name(v: Any, where: str) -> str:
    if not isinstance(v, str) or not _NAME_RE.match(v):
        raise ConfigError(f"{where}.name: expected 1-64 characters of letters, digits, '_', '-', '+', '.', "
                          f"got {str(v)[:40]!r}")
    return v


def _positive(v: Any, where: str) -> float:
    x = config_number(v, where, positive=True, max_abs=MAX_OBSTACLE_SIZE_M)
    if not x > 0:
        raise ConfigError(f"{where}: expected a length > 0 m, got {x}")
    return x


def _shape_fields(kind: str, spec: Any, where: str, *, base: Path | None, max_faces: int = MAX_OBSTACLE_FACES) -> dict:
    """The shape's fields (size / radius, length / vertices, faces) from a YAML or JSON mapping."""
    valid = {"box": ["size"], "cylinder": ["length", "radius"], "sphere": ["radius"],
             "mesh": ["path", "scale"] if base is not None else ["faces", "vertices"]}[kind]
    if not isinstance(spec, dict):
        raise ConfigError(f"{where}: expected a mapping with {', '.join(valid)}, got {str(spec)[:60]!r}")
    unknown = set(spec) - set(valid)
    if unknown:
        raise ConfigError(f"{where}: unknown keys {sorted(map(str, unknown))}; valid: {valid}")
    required = [k for k in valid if k != "scale"]
    missing = [k for k in required if k not in spec]
    if missing:
        what = {"size": "full side lengths [x, y, z] in metres", "radius": "metres", "length": "metres, along local z",
                "path": "a mesh file relative to the cell YAML", "vertices": "(V, 3) metres", "faces": "(F, 3) indices"}
        raise ConfigError(f"{where}.{missing[0]}: missing ({what[missing[0]]})")
    if kind == "box":
        size = config_vector(spec["size"], f"{where}.size", positive=True)
        if size.max() > MAX_OBSTACLE_SIZE_M:
            raise ConfigError(f"{where}.size: each side at most {MAX_OBSTACLE_SIZE_M} m")
        return {"size": tuple(float(x) for x in size)}
    if kind == "cylinder":
        return {"radius": _positive(spec["radius"], f"{where}.radius"), "length": _positive(spec["length"], f"{where}.length")}
    if kind == "sphere":
        return {"radius": _positive(spec["radius"], f"{where}.radius")}
    if base is not None:  # YAML: a file
        v, f, _ = read_config_mesh(spec, base, where, "cell", max_triangles=max_faces,
                                   limit_name="grasplan.cell.model.MAX_CELL_TRIANGLES, all mesh obstacles together")
    else:
        try:
            v = np.asarray(spec["vertices"], dtype=np.float64)
            f = np.asarray(spec["faces"], dtype=np.int64)
        except (TypeError, ValueError, OverflowError):
            raise ConfigError(f"{where}: vertices and faces must be lists of numbers") from None
        if v.ndim != 2 or v.shape[1:] != (3,) or f.ndim != 2 or f.shape[1:] != (3,) or len(f) == 0:
            raise ConfigError(f"{where}: expected vertices (V, 3) and faces (F, 3), got {v.shape} and {f.shape}")
        if f.min() < 0 or f.max() >= len(v):
            raise ConfigError(f"{where}.faces: vertex index out of range 0..{len(v) - 1}")
    if len(f) > max_faces:
        raise ConfigError(f"{where}: {len(f)} triangles; the mesh obstacles of a cell may have at most "
                          f"{MAX_CELL_TRIANGLES} together (grasplan.cell.model.MAX_CELL_TRIANGLES; {max_faces} left for this "
                          f"one): simplify the meshes")
    if not np.all(np.isfinite(v)) or np.abs(v).max() > MAX_OBSTACLE_SIZE_M:
        raise ConfigError(f"{where}: non-finite or huge coordinates (|v| <= {MAX_OBSTACLE_SIZE_M} m after scale; "
                          f"is 'scale' right?)")
    return {"vertices": _readonly(v), "faces": np.asarray(f, dtype=np.int64)}


def _obstacle_from_yaml(item: Any, where: str, base: Path, max_faces: int = MAX_OBSTACLE_FACES) -> Obstacle:
    valid = ["name", *OBSTACLE_KINDS, "T"]
    if not isinstance(item, dict):
        raise ConfigError(f"{where}: expected a mapping {{name: ..., box|cylinder|sphere|mesh: ..., T: ...}}, "
                          f"got {str(item)[:60]!r}")
    unknown = set(item) - set(valid)
    if unknown:
        raise ConfigError(f"{where}: unknown keys {sorted(map(str, unknown))}; valid: {valid}")
    if "name" not in item:
        raise ConfigError(f"{where}.name: missing (each obstacle needs a unique name)")
    name = _obstacle_name(item["name"], where)
    kinds = [k for k in OBSTACLE_KINDS if k in item]
    if len(kinds) != 1:
        raise ConfigError(f"{where} ({name}): expected exactly one shape of box, cylinder, sphere, mesh; got "
                          f"{kinds or 'none'}")
    if "T" not in item:
        raise ConfigError(f"{where}.T: missing (the obstacle's pose {{xyz: [x, y, z] m, rpy_deg: [r, p, y] deg}})")
    kind = kinds[0]
    fields = _shape_fields(kind, item[kind], f"{where}.{kind}", base=base, max_faces=max_faces)
    return Obstacle(name, kind, _readonly(_pose_yaml(item["T"], f"{where}.T")), **fields)


def _obstacle_from_json(item: Any, where: str) -> Obstacle:
    if not isinstance(item, dict):
        raise ConfigError(f"{where}: expected a mapping")
    unknown = set(item) - {"name", *OBSTACLE_KINDS, "T_world_obstacle"}
    kinds = [k for k in OBSTACLE_KINDS if k in item]
    if unknown or len(kinds) != 1 or "name" not in item or "T_world_obstacle" not in item:
        raise ConfigError(f"{where}: expected {{name, one of {list(OBSTACLE_KINDS)}, T_world_obstacle}}")
    name = _obstacle_name(item["name"], where)
    T = check_transform(item["T_world_obstacle"], f"{where}.T_world_obstacle", error=ConfigError)
    if np.abs(T[:3, 3]).max() > MAX_CELL_COORD_M:
        raise ConfigError(f"{where}.T_world_obstacle: position beyond {MAX_CELL_COORD_M} m")
    return Obstacle(name, kinds[0], _readonly(T), **_shape_fields(kinds[0], item[kinds[0]], f"{where}.{kinds[0]}",
                                                                   base=None))


def _bin_fields(inner: Any, wall: Any, height: Any, T: Any, where: str) -> BinSpec:
    ix = config_vector(inner, f"{where}.inner", 2, positive=True)
    if not np.all(ix > 0) or ix.max() > MAX_OBSTACLE_SIZE_M:
        raise ConfigError(f"{where}.inner: expected [x, y] inner floor size, each > 0 and <= {MAX_OBSTACLE_SIZE_M} m")
    w = _positive(wall, f"{where}.wall")
    h = _positive(height, f"{where}.height")
    if abs(T[2, 2] - 1.0) > 1e-9:
        raise ConfigError(f"{where}.T: the bin must stand upright (only a yaw: rpy_deg [0, 0, yaw])")
    return BinSpec((float(ix[0]), float(ix[1])), w, h, _readonly(T))


def _bin_from_yaml(b: Any, where: str) -> BinSpec:
    valid = ["height", "inner", "T", "wall"]
    if not isinstance(b, dict):
        raise ConfigError(f"{where}: expected {{inner: [x, y], wall: m, height: m, T: {{xyz: [...]}}}}, "
                          f"got {str(b)[:60]!r}")
    unknown = set(b) - set(valid)
    if unknown:
        raise ConfigError(f"{where}: unknown keys {sorted(map(str, unknown))}; valid: {valid}")
    for k, what in (("inner", "[x, y] inner floor size in metres"), ("wall", "wall and floor thickness in metres"),
                    ("height", "wall height above the floor's top in metres"),
                    ("T", "the centre of the floor's top {xyz: [x, y, z], rpy_deg: [0, 0, yaw]}")):
        if k not in b:
            raise ConfigError(f"{where}.{k}: missing ({what})")
    return _bin_fields(b["inner"], b["wall"], b["height"], _pose_yaml(b["T"], f"{where}.T"), where)


def _bin_from_json(b: Any, where: str) -> BinSpec:
    if not isinstance(b, dict) or set(b) != {"inner", "wall", "height", "T_world_bin"}:
        raise ConfigError(f"{where}: expected {{inner, wall, height, T_world_bin}} or null")
    T = check_transform(b["T_world_bin"], f"{where}.T_world_bin", error=ConfigError)
    return _bin_fields(b["inner"], b["wall"], b["height"], T, where)


def _place_yaml(p: Any, where: str) -> np.ndarray:
    if not isinstance(p, dict) or set(p) != {"T"}:
        raise ConfigError(f"{where}: expected {{T: {{xyz: [x, y, z], rpy_deg: [r, p, y]}}}} (the part's pose "
                          f"after release, world frame), got {str(p)[:60]!r}")
    return _readonly(_pose_yaml(p["T"], f"{where}.T"))


def cell_from_dict(data: Any, *, name: str, source: str = "", base: Path | None = None) -> Cell:
    """Validate a parsed cell YAML (``base``: the folder mesh paths are relative to)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: a cell file must be a YAML mapping")
    allowed = {"name", "table_z", "part_xy", "pose_index", "description", "obstacles", "bin", "retreat", "place",
               "workspace"}
    unknown = set(data) - allowed
    if unknown:
        raise ConfigError(f"{source}: unknown cell fields {sorted(map(str, unknown))}; allowed: {sorted(allowed)}")
    cname = data.get("name", name)
    if not isinstance(cname, str) or not cname or len(cname) > MAX_NAME_CHARS:
        raise ConfigError(f"{source}: name: expected a non-empty string of at most {MAX_NAME_CHARS} characters")
    if any(unicodedata.category(c)[0] in "CZ" and c != " " for c in cname):
        raise ConfigError(f"{source}: name: {cname[:40]!r} holds control or line-break characters; use letters, "
                          f"digits, spaces and punctuation")
    table_z = config_number(data.get("table_z", 0.0), "table_z", max_abs=MAX_CELL_COORD_M)
    bin_ = _bin_from_yaml(data["bin"], "bin") if data.get("bin") is not None else None
    xy = data.get("part_xy", [0.0, 0.0] if bin_ is not None else [0.45, 0.0])
    if not isinstance(xy, (list, tuple)) or len(xy) != 2:
        raise ConfigError(f"{source}: part_xy: expected [x, y] in metres, got {xy!r}")
    part_xy = (config_number(xy[0], "part_xy[0]", max_abs=MAX_CELL_COORD_M),
               config_number(xy[1], "part_xy[1]", max_abs=MAX_CELL_COORD_M))
    if bin_ is not None:  # an offset from the floor's centre, in the bin frame
        off = np.asarray(bin_.T_world_bin) @ [part_xy[0], part_xy[1], 0.0, 1.0]
        part_xy = (float(off[0]), float(off[1]))
    pi = data.get("pose_index", 0)
    if isinstance(pi, bool) or not isinstance(pi, int) or not 0 <= pi <= MAX_POSE_INDEX:
        raise ConfigError(f"{source}: pose_index: expected an integer in 0..{MAX_POSE_INDEX}, got {str(pi)[:40]}")
    obs = data.get("obstacles", []) or []
    if not isinstance(obs, list):
        raise ConfigError("obstacles: expected a list of {name, box|cylinder|sphere|mesh, T} mappings")
    if len(obs) > MAX_OBSTACLES:
        raise ConfigError(f"obstacles: {len(obs)} obstacles; a cell may have at most {MAX_OBSTACLES} "
                          f"(grasplan.cell.model.MAX_OBSTACLES): merge small ones into meshes or boxes")
    folder = base if base is not None else Path(source).parent if source else Path(".")
    obstacles, left = [], MAX_CELL_TRIANGLES
    for i, o in enumerate(obs):  # the triangle budget is shared: a mesh is refused from its header when over it
        ob = _obstacle_from_yaml(o, f"obstacles[{i}]", folder, max_faces=left)
        left -= len(ob.faces) if ob.faces is not None else 0
        obstacles.append(ob)
    _check_unique([o.name for o in obstacles], "obstacles", reserved=BIN_NAMES if bin_ is not None else ())
    if bin_ is not None:
        obstacles = list(bin_.obstacles()) + obstacles
    direction, distance = retreat_from(data.get("retreat", {}) or {}, "retreat")
    place = _place_yaml(data["place"], "place") if data.get("place") is not None else None
    ws = Workspace.from_config(data["workspace"], "workspace") if data.get("workspace") is not None else None
    return Cell(name=cname, table_z=table_z, part_xy=part_xy, pose_index=pi, source=source,
                obstacles=tuple(obstacles), bin=bin_, retreat_direction=direction, retreat_distance=distance,
                place=place, workspace=ws)


#: the name of the cell that is nothing but the part: ``--cell none``
NO_CELL_NAME = "none"
#: the part alone in its own frame: no obstacles, the table 10 m below the origin (grasps checked
#: against the part only, as grasplan.grasps.graspdb needs them); nothing is planned in it
NO_CELL = Cell(name=NO_CELL_NAME, table_z=-MAX_CELL_COORD_M, part_xy=(0.0, 0.0),
               source="the part alone in its own frame: no table, no obstacles")


def load_cell(name_or_path: str | os.PathLike | Cell = DEFAULT_CELL) -> Cell:
    """A cell by name (``configs/cells/<name>.yaml``; ``none``: :data:`NO_CELL`) or path to a YAML
    file; a :class:`Cell` is returned as is."""
    if isinstance(name_or_path, Cell):
        return name_or_path
    if isinstance(name_or_path, str) and name_or_path == NO_CELL_NAME:
        return NO_CELL
    p = resolve_yaml("cell", name_or_path)
    data = read_yaml("cell", p)
    try:
        return cell_from_dict(data, name=p.stem, source=str(p), base=p.parent)
    except ConfigError as exc:
        msg = str(exc)
        raise ConfigError(msg if msg.startswith(str(p)) else f"{p}: {msg}") from None
