"""Scenes: many parts at known poses in a cell, the input of ``grasplan pick`` (``grasplan.scene/1``).

A scene file is YAML or JSON (JSON Schema: ``grasplan/schemas/scene.schema.json``; reference in
docs/pick.md; the format: :class:`Scene`). :func:`load_scene` checks the structure and every value
and raises :class:`~grasplan.errors.InputError` naming the field; geometric checks against the cell
and the other instances need the meshes and are the planner's
(:func:`grasplan.piles.checks.check_instances`).
"""
from __future__ import annotations

import json
import os
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, InputError
from ..config.inputs import read_input_bytes
from ..config.jsontext import DuplicateKeyError, loads_strict
from ..config.materials import MATERIAL_NAMES, material_density, resolve_material
from ..config.poses import parse_pose
from ..geometry.transforms import MAX_ANGLE_DEG, MAX_CELL_COORD_M, check_transform
from ..geometry.units import UNIT_CHOICES
from ..config.yamlfile import load_yaml_text

SCENE_SCHEMA = "grasplan.scene/1"
#: largest scene file read (bytes); most instances and parts in one scene
MAX_SCENE_BYTES = 4 << 20
MAX_INSTANCES = 500
MAX_PARTS = 100
#: ids and part names: what a robot program, a file name and a URL can carry unescaped
NAME_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.+-]{0,63}$")
NAME_RULE = "1-64 characters of letters, digits, '_', '.', '+', '-' (not starting with '.', '+' or '-')"
DEFAULT_CELL = "bin"

_TOP_KEYS = ("schema", "cell", "parts", "instances", "cloud")
_PART_KEYS = ("mesh", "units", "grasps", "material", "density", "sha256")
#: a mesh file's sha256 as a scene records it
SHA256_RE = re.compile(r"^[0-9a-f]{64}$")
_INSTANCE_KEYS = ("id", "part", "T")
_CLOUD_KEYS = ("path", "resolution")


def _readonly(T: np.ndarray) -> np.ndarray:
    a = np.array(T, dtype=np.float64)
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class ScenePart:
    """A part a scene uses: ``mesh`` (a path, absolute or relative to the scene file; None: the
    planner knows the part by ``name``), ``units`` of the mesh file, optional ``grasps`` database,
    ``material`` (a name of :data:`grasplan.config.materials.MATERIALS`) and ``density`` (kg/m^3;
    None: the planner's, default steel; given together they must agree) and the mesh file's
    ``sha256`` (64 lowercase hex: a planner refuses a mesh that differs; the service matches its
    parts by it)."""

    name: str
    mesh: str | None = None
    units: str = "auto"
    grasps: str | None = None
    material: str | None = None
    density: float | None = None
    sha256: str | None = None

    def to_json(self) -> dict:
        d: dict[str, Any] = {}
        if self.mesh is not None:
            d["mesh"] = self.mesh
        d["units"] = self.units
        if self.grasps is not None:
            d["grasps"] = self.grasps
        if self.material is not None:
            d["material"] = self.material
        if self.density is not None:
            d["density"] = float(self.density)
        if self.sha256 is not None:
            d["sha256"] = self.sha256
        return d


@dataclass(frozen=True, eq=False)
class Instance:
    """One part lying in the scene: ``id`` (unique), the ``part`` name, ``T_world_part`` (4, 4)."""

    id: str
    part: str
    T_world_part: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "T_world_part", _readonly(check_transform(self.T_world_part,
                                                                           f"instance {self.id!r}: T")))

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, Instance) and (self.id, self.part) == (other.id, other.part)
                and np.array_equal(self.T_world_part, other.T_world_part))

    def __hash__(self) -> int:
        return hash((self.id, self.part, self.T_world_part.tobytes()))

    def to_json(self) -> dict:
        return {"id": self.id, "part": self.part, "T": self.T_world_part.tolist()}


@dataclass(frozen=True)
class CloudSpec:
    """Points of what the scene does not model: a PLY/PCD/NPY file (world frame, metres) and the
    octree leaf size (m)."""

    path: str
    resolution: float = 0.005

    def to_json(self) -> dict:
        return {"path": self.path, "resolution": float(self.resolution)}


@dataclass(frozen=True, eq=False)
class Scene:
    """Instances of parts at poses in a cell.

    ``cell``: a cell name or YAML path; ``parts``: the parts the file declares (possibly none, when
    the planner knows them by name); ``instances`` in file order; ``base``: the folder relative
    paths are resolved against (the scene file's; None: the current folder).

    In a file, lengths are metres; a pose ``T`` is ``{xyz: [m], rpy_deg: [deg]}`` with R = Rz(yaw)
    Ry(pitch) Rx(roll), as in cells, or a 4x4 row-major matrix::

        schema: grasplan.scene/1
        cell: bin                      # a cell name or path: table, bin, obstacles
        parts:
          TLess20: {mesh: parts/TLess20.stl, units: mm, material: plastic}   # optional grasps: a database
        instances:                      # T_world_part of each part, e.g. from a pose estimator
          - {id: a, part: TLess20, T: {xyz: [0.40, 0.03, 0.03], rpy_deg: [0, 0, 30]}}
          - {id: b, part: TLess20, T: [[1,0,0,0.5],[0,1,0,0],[0,0,1,0.03],[0,0,0,1]]}
        cloud: {path: scan.ply, resolution: 0.005}   # optional: points of what is not modelled

    Paths (meshes, databases, the cloud, a cell YAML) are relative to the scene file. A part named by
    a scene but not given a mesh is resolved by whoever plans it (``grasplan.Picker.add_part``, or the
    service's parts folder). ``scene drop`` names a part by its mesh file's stem as written
    (:func:`part_name`), as ``grasplan serve`` names the files of its parts folder."""

    instances: tuple[Instance, ...]
    cell: str = DEFAULT_CELL
    parts: tuple[ScenePart, ...] = ()
    cloud: CloudSpec | None = None
    source: str = ""
    base: Path | None = field(default=None)

    def __post_init__(self) -> None:
        object.__setattr__(self, "instances", tuple(self.instances))
        object.__setattr__(self, "parts", tuple(self.parts))
        ids = [i.id for i in self.instances]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise InputError(f"scene: instance ids must be unique; repeated: {', '.join(dup[:5])}")
        names = [p.name for p in self.parts]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise InputError(f"scene: part names must be unique; repeated: {', '.join(dup[:5])}")

    # -- lookups ----------------------------------------------------------------------------------
    @property
    def ids(self) -> list[str]:
        return [i.id for i in self.instances]

    def instance(self, instance_id: str) -> Instance:
        for i in self.instances:
            if i.id == instance_id:
                return i
        raise InputError(f"unknown instance {instance_id!r}; the scene has {', '.join(self.ids) or '(none)'}")

    def part(self, name: str) -> ScenePart | None:
        """The scene's declaration of part ``name``, None when the scene does not declare it."""
        return next((p for p in self.parts if p.name == name), None)

    def part_names(self) -> list[str]:
        """Names of the parts the instances use, in first-use order."""
        out: list[str] = []
        for i in self.instances:
            if i.part not in out:
                out.append(i.part)
        return out

    def resolve(self, path: str) -> Path:
        """``path`` (as written in the file) made absolute against :attr:`base`."""
        p = Path(path).expanduser()
        return p if p.is_absolute() or self.base is None else self.base / p

    # -- edits (new scenes; nothing reloads) -----------------------------------------------------
    def without(self, *ids: str) -> Scene:
        """This scene without the instances ``ids`` (e.g. the one just picked)."""
        for i in ids:
            self.instance(i)
        drop = set(ids)
        return replace(self, instances=tuple(i for i in self.instances if i.id not in drop))

    def with_poses(self, poses: Mapping[str, np.ndarray]) -> Scene:
        """This scene with new ``T_world_part`` for the instances named in ``poses``."""
        for i in poses:
            self.instance(i)
        return replace(self, instances=tuple(Instance(i.id, i.part, poses[i.id]) if i.id in poses else i
                                             for i in self.instances))

    def to_json(self) -> dict:
        """The ``grasplan.scene/1`` document (poses as 4x4 matrices), as embedded in a picks file."""
        d: dict[str, Any] = {"schema": SCENE_SCHEMA, "cell": self.cell,
                             "parts": {p.name: p.to_json() for p in self.parts},
                             "instances": [i.to_json() for i in self.instances]}
        if self.cloud is not None:
            d["cloud"] = self.cloud.to_json()
        return d


# ------------------------------------------------------------------------------------------------
# part names from mesh files: the one rule of ``scene drop``, ``clutter`` and ``serve --parts``
# ------------------------------------------------------------------------------------------------
# A part is named by its mesh file's stem exactly as written (``parts/TLess20.stl`` -> ``TLess20``);
# its instances are ``TLess20_0``, ``TLess20_1``, ... A stem that is no valid name has each character
# other than letters, digits, '_', '.', '+', '-' made '_', a leading '.', '+' or '-' prefixed by '_',
# and is cut to MAX_PART_NAME characters (so that its instance ids stay valid names): ``a b(1).STL``
# -> ``a_b_1_``. Two files that give one name are refused (name_parts), naming both files: the name
# is what a scene, a picks file and the service call the part, so it must say which mesh.

#: longest part name: an instance id is ``<name>_<k>`` with k < MAX_INSTANCES, at most 64 characters
MAX_PART_NAME = 64 - len(f"_{MAX_INSTANCES - 1}")
PART_NAME_RULE = "the mesh file's stem as written (characters other than letters, digits, '_', '.', '+', '-' made '_')"


def part_name(path: str | Path) -> str:
    """The name of the part whose mesh is ``path``: its stem as written (the rule above)."""
    name = re.sub(r"[^A-Za-z0-9_.+-]", "_", Path(path).stem) or "part"
    if not re.match(r"[A-Za-z0-9_]", name):
        name = "_" + name
    return name[:MAX_PART_NAME]


def name_parts(paths: Iterable[str | Path], *, where: str) -> dict[str, str | Path]:
    """``{part name: path}`` of ``paths`` in their order; InputError (exit 3) naming ``where`` and
    both files when two of them give one name."""
    out: dict[str, str | Path] = {}
    for p in paths:
        name = part_name(p)
        if name in out:
            raise InputError(f"{where}: {out[name]} and {p} both give part name {name!r} (a part's name is "
                             f"{PART_NAME_RULE}); rename one of the files")
        out[name] = p
    return out


# ------------------------------------------------------------------------------------------------
# reading
# ------------------------------------------------------------------------------------------------
def _name(v: Any, where: str) -> str:
    if isinstance(v, bool) or not isinstance(v, (str, int)):
        raise InputError(f"{where}: expected a name ({NAME_RULE}), got {str(v)[:40]!r}")
    s = str(v)
    if not NAME_RE.match(s):
        raise InputError(f"{where}: {s[:40]!r} is not a valid name ({NAME_RULE})")
    return s


def _keys(d: Any, allowed: Iterable[str], where: str, what: str) -> dict:
    if not isinstance(d, dict):
        raise InputError(f"{where}: expected {what}, got {type(d).__name__}")
    unknown = sorted(set(map(str, d)) - set(allowed))
    if unknown:
        raise InputError(f"{where}: unknown keys {unknown[:5]}; valid: {sorted(allowed)}")
    return d


def _path(v: Any, where: str) -> str:
    if not isinstance(v, str) or not v.strip() or "\x00" in v or len(v) > 4096:
        raise InputError(f"{where}: expected a file path (relative to the scene file)")
    return v


def _pose(v: Any, where: str) -> np.ndarray:
    try:
        return parse_pose(v, where, matrix=True, require_xyz=True, max_coord=MAX_CELL_COORD_M, max_deg=MAX_ANGLE_DEG)
    except ConfigError as exc:  # a scene is an input, not a configuration: the same exit code, its own type
        raise InputError(str(exc)) from None


def _material(material: Any, density: Any, where: str) -> tuple[str | None, float | None]:
    """A scene part's ``material`` and ``density`` as given (both None: the planner's), else
    :func:`scene_part_material`."""
    if material is None and density is None:
        return None, None
    return scene_part_material(material, density, where)


def scene_part_material(material: Any, density: Any, where: str) -> tuple[str, float]:
    """A scene part's ``material`` and ``density`` (either may be None) checked and resolved
    (:func:`grasplan.config.materials.resolve_material`: a known name, a density in (0, 1e5], the
    two agreeing); InputError naming the field (``where``: the part, e.g. ``scene: parts.gear``)."""
    if density is not None and (isinstance(density, bool) or not isinstance(density, (int, float))
                                or not 0 < density <= 1e5):
        raise InputError(f"{where}.density: expected kg/m^3 in (0, 1e5] (e.g. 1200 for plastic), "
                         f"got {str(density)[:40]!r}")
    if material is not None and material not in MATERIAL_NAMES:
        raise InputError(f"{where}.material: unknown material {str(material)[:40]!r}; valid: "
                         f"{', '.join(MATERIAL_NAMES)} (or give density in kg/m^3)")
    try:
        name, d = resolve_material(material, density)
    except InputError:
        raise InputError(f"{where}: material {material} ({material_density(material):g} kg/m^3) and density "
                         f"{density:g} disagree; give one of them") from None
    return name, float(d)


def scene_from_dict(doc: Any, *, source: str = "scene", base: Path | None = None) -> Scene:
    """A :class:`Scene` from a parsed ``grasplan.scene/1`` document; InputError naming the field."""
    d = _keys(doc, _TOP_KEYS, source, "a mapping with schema, cell, parts, instances and cloud")
    if d.get("schema") != SCENE_SCHEMA:
        raise InputError(f"{source}: schema must be {SCENE_SCHEMA!r}, got {str(d.get('schema'))[:40]!r}")
    cell = d.get("cell", DEFAULT_CELL)
    if not isinstance(cell, str) or not cell.strip() or len(cell) > 4096:
        raise InputError(f"{source}: cell: expected a cell name (table, bin, ...) or a cell YAML path")
    parts_in = d.get("parts") or {}
    if not isinstance(parts_in, dict):
        raise InputError(f"{source}: parts: expected a mapping of part name -> {{mesh, units, grasps, "
                         f"material, density, sha256}}")
    if len(parts_in) > MAX_PARTS:
        raise InputError(f"{source}: parts: {len(parts_in)} parts; at most {MAX_PARTS}")
    parts = []
    for key, spec in parts_in.items():
        name = _name(key, f"{source}: parts")
        w = f"{source}: parts.{name}"
        spec = _keys(spec if spec is not None else {}, _PART_KEYS, w,
                     "a mapping {mesh, units, grasps, material, density, sha256}")
        units = spec.get("units", "auto")
        if units not in UNIT_CHOICES:
            raise InputError(f"{w}.units: {str(units)[:20]!r} is not one of {', '.join(UNIT_CHOICES)}")
        material, density = _material(spec.get("material"), spec.get("density"), w)
        sha = spec.get("sha256")
        if sha is not None and not (isinstance(sha, str) and SHA256_RE.match(sha)):
            raise InputError(f"{w}.sha256: expected the mesh file's sha256 (64 lowercase hex digits), "
                             f"got {str(sha)[:70]!r}")
        parts.append(ScenePart(name=name, mesh=_path(spec["mesh"], f"{w}.mesh") if "mesh" in spec else None,
                               units=units,
                               grasps=_path(spec["grasps"], f"{w}.grasps") if "grasps" in spec else None,
                               material=material, density=density, sha256=sha))
    inst_in = d.get("instances")
    if not isinstance(inst_in, list) or not inst_in:
        raise InputError(f"{source}: instances: expected a non-empty list of {{id, part, T}}")
    if len(inst_in) > MAX_INSTANCES:
        raise InputError(f"{source}: instances: {len(inst_in)} instances; at most {MAX_INSTANCES}")
    declared = {p.name for p in parts}
    instances, seen = [], set()
    for k, item in enumerate(inst_in):
        w = f"{source}: instances[{k}]"
        item = _keys(item, _INSTANCE_KEYS, w, "a mapping {id, part, T}")
        for key in _INSTANCE_KEYS:
            if key not in item:
                raise InputError(f"{w}: missing {key!r} (each instance has an id, a part and its pose T)")
        iid = _name(item["id"], f"{w}.id")
        if iid in seen:
            raise InputError(f"{w}.id: {iid!r} is used by an earlier instance; ids must be unique")
        seen.add(iid)
        part = _name(item["part"], f"{w}.part")
        if parts and part not in declared:
            raise InputError(f"{w}.part: unknown part {part!r}; the scene's parts: {', '.join(sorted(declared))}")
        instances.append(Instance(iid, part, _pose(item["T"], f"{w}.T")))
    cloud = None
    if d.get("cloud") is not None:
        c = _keys(d["cloud"], _CLOUD_KEYS, f"{source}: cloud", "a mapping {path, resolution}")
        if "path" not in c:
            raise InputError(f"{source}: cloud: missing 'path' (a PLY, PCD or NPY file, world frame, metres)")
        from .cloud import DEFAULT_RESOLUTION_M, check_resolution

        res = c.get("resolution", DEFAULT_RESOLUTION_M)
        if isinstance(res, bool) or not isinstance(res, (int, float)):
            raise InputError(f"{source}: cloud.resolution: expected a number (m), got {str(res)[:40]!r}")
        cloud = CloudSpec(path=_path(c["path"], f"{source}: cloud.path"),
                          resolution=check_resolution(res, f"{source}: cloud.resolution"))
    return Scene(instances=tuple(instances), cell=cell, parts=tuple(parts), cloud=cloud, source=source, base=base)


def load_scene(source: str | os.PathLike | Mapping[str, Any] | Scene) -> Scene:
    """A :class:`Scene` from a scene file (YAML or JSON), a parsed document or a Scene.

    Raises InputError (exit 3) naming the file and the field for anything malformed (unknown keys,
    an instance naming an unknown part, a non-rigid or non-finite T, duplicate ids)."""
    if isinstance(source, Scene):
        return source
    if isinstance(source, Mapping):
        return scene_from_dict(dict(source), source="scene")
    p = Path(source)
    data = read_input_bytes(p, what="scene", max_bytes=MAX_SCENE_BYTES)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"scene {p}: not a UTF-8 text file; a scene is YAML or JSON") from None
    if p.suffix.lower() == ".json":
        try:
            doc = loads_strict(text)
        except DuplicateKeyError as exc:
            raise InputError(f"scene {p}: {exc}") from None
        except (json.JSONDecodeError, RecursionError) as exc:
            raise InputError(f"scene {p}: not valid JSON ({str(exc)[:80]})") from None
    else:
        doc = load_yaml_text(text, f"scene {p}")
    return scene_from_dict(doc, source=f"scene {p}", base=p.resolve().parent)
