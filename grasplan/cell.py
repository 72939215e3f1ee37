"""The robot cell around the part: a table top and where the part rests on it.

World frame: z up. The table top is the plane ``z = table_z`` (default 0) and the table fills
``z < table_z`` (a half-space: it is infinite in x and y). The part rests on the table in a
stable pose (:func:`stable_pose`: the most probable one unless ``pose_index`` says otherwise),
its lowest point on the table top and its centre of mass above ``part_xy`` (default (0.45, 0) m).

YAML schema (``configs/cells/<name>.yaml``; metres)::

    name: table
    table_z: 0.0
    part_xy: [0.45, 0.0]
    pose_index: 0          # which stable pose, 0 = most probable

``--part-pose`` overrides the resting pose: :func:`parse_part_pose`.
"""
from __future__ import annotations

import math
import os
import re
import unicodedata
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
import yaml

from .config_files import available, config_number, packaged_file, read_yaml, resolve_yaml
from .errors import ConfigError, InputError
from .gripper import rpy_matrix
from .params import DEFAULT_CELL
from .transforms import check_transform
from .units import parse_angle_deg, parse_length

CELL_DIR = packaged_file("configs", "cells")  # the packaged cells
#: |table_z| and |part_xy| at most this (metres): a robot cell is a few metres across
MAX_CELL_COORD_M = 10.0
#: longest cell name (characters)
MAX_NAME_CHARS = 100
#: largest pose_index accepted from a file (a part has far fewer distinct resting poses)
MAX_POSE_INDEX = 100_000


@dataclass(frozen=True)
class Cell:
    """A table cell. ``table_z``: height of the table top (m); ``part_xy``: where the part's centre
    of mass rests (m); ``pose_index``: which stable pose (0 = most probable)."""

    name: str
    table_z: float = 0.0
    part_xy: tuple[float, float] = (0.45, 0.0)
    pose_index: int = 0
    source: str = ""

    def to_json(self) -> dict:
        """The ``cell`` block of the grasps output: the name and what defines the cell."""
        return {
            "name": self.name,
            "up": [0.0, 0.0, 1.0],
            "table": {"type": "half_space", "normal": [0.0, 0.0, 1.0], "z": float(self.table_z),
                      "fills": "z < table_z"},
            "part_xy": [float(self.part_xy[0]), float(self.part_xy[1])],
            "pose_index": int(self.pose_index),
        }

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
        unknown = set(d) - {"name", "up", "table", "part_xy", "pose_index", "source"}
        if unknown:
            raise ConfigError(f"{where}: unknown fields {sorted(unknown)[:5]}; the file was not written by grasplan")
        data = {"name": d.get("name"), "table_z": table.get("z", 0.0),
                "part_xy": d.get("part_xy", [0.45, 0.0]), "pose_index": d.get("pose_index", 0)}
        return cell_from_dict(data, name="cell", source=f"{where} (embedded in the result)")


def _is_up(v) -> bool:
    return (isinstance(v, (list, tuple)) and len(v) == 3
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
            and list(map(float, v)) == [0.0, 0.0, 1.0])


def available_cells() -> list[str]:
    """Names of the cells shipped in ``configs/cells/*.yaml``."""
    return available("cell")


def cell_from_dict(data, *, name: str, source: str = "") -> Cell:
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: a cell file must be a YAML mapping")
    allowed = {"name", "table_z", "part_xy", "pose_index", "description"}
    unknown = set(data) - allowed
    if unknown:
        raise ConfigError(f"{source}: unknown cell fields {sorted(unknown)}; allowed: {sorted(allowed)}")
    cname = data.get("name", name)
    if not isinstance(cname, str) or not cname or len(cname) > MAX_NAME_CHARS:
        raise ConfigError(f"{source}: name: expected a non-empty string of at most {MAX_NAME_CHARS} characters")
    if any(unicodedata.category(c)[0] in "CZ" and c != " " for c in cname):
        raise ConfigError(f"{source}: name: {cname[:40]!r} holds control or line-break characters; use letters, "
                          f"digits, spaces and punctuation")
    table_z = config_number(data.get("table_z", 0.0), "table_z", max_abs=MAX_CELL_COORD_M)
    xy = data.get("part_xy", [0.45, 0.0])
    if not isinstance(xy, (list, tuple)) or len(xy) != 2:
        raise ConfigError(f"{source}: part_xy: expected [x, y] in metres, got {xy!r}")
    part_xy = (config_number(xy[0], "part_xy[0]", max_abs=MAX_CELL_COORD_M),
               config_number(xy[1], "part_xy[1]", max_abs=MAX_CELL_COORD_M))
    pi = data.get("pose_index", 0)
    if isinstance(pi, bool) or not isinstance(pi, int) or not 0 <= pi <= MAX_POSE_INDEX:
        raise ConfigError(f"{source}: pose_index: expected an integer in 0..{MAX_POSE_INDEX}, got {str(pi)[:40]}")
    return Cell(name=cname, table_z=table_z, part_xy=part_xy, pose_index=pi, source=source)


def load_cell(name_or_path: str | os.PathLike = DEFAULT_CELL) -> Cell:
    """A cell by name (``configs/cells/<name>.yaml``) or path to a YAML file."""
    if isinstance(name_or_path, Cell):
        return name_or_path
    p = resolve_yaml("cell", name_or_path)
    data = read_yaml("cell", p)
    try:
        return cell_from_dict(data, name=p.stem, source=str(p))
    except ConfigError as exc:
        msg = str(exc)
        raise ConfigError(msg if msg.startswith(str(p)) else f"{p}: {msg}") from None


# -- stable poses ----------------------------------------------------------------------------

#: a part whose thickness along its thinnest principal axis is at most this fraction of its
#: bounding-box diagonal is flat (a plane, an n-gon, a flattened box): it lies on either side
FLAT_RELATIVE_THICKNESS = 1e-6


def _principal_axes(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """``(axes (3, 3) rows, thickness along each axis (3,), bounding-box diagonal)`` of ``(n, 3)``
    vertices; axes sorted from the widest to the thinnest spread."""
    V = np.asarray(vertices, dtype=np.float64)
    c = V - V.mean(axis=0)
    _, _, axes = np.linalg.svd(c, full_matrices=False)
    axes = np.vstack([axes, np.zeros((3 - len(axes), 3))]) if len(axes) < 3 else axes
    spread = np.ptp(c @ axes.T, axis=0)
    diag = float(np.linalg.norm(np.ptp(V, axis=0)))
    return axes, spread, diag


def _flatness(mesh: trimesh.Trimesh) -> tuple[np.ndarray | None, float]:
    """``(unit plane normal (3,) or None, diagonal)``: the normal when the part is flat."""
    axes, spread, diag = _principal_axes(mesh.vertices)
    if diag <= 0 or spread[1] <= FLAT_RELATIVE_THICKNESS * diag:
        raise InputError("the part is a line or a point (all its vertices are collinear): it has no resting pose "
                         "on a table; check the mesh")
    if spread[2] > FLAT_RELATIVE_THICKNESS * diag:
        return None, diag
    n = axes[2] / np.linalg.norm(axes[2])
    n = n if n[np.argmax(np.abs(n))] > 0 else -n  # deterministic sign
    return n + 0.0, diag


def centre_of_mass(mesh: trimesh.Trimesh) -> np.ndarray:
    """``(3,)`` the part's centre of mass, part frame (m): of the solid when the mesh is closed
    with positive volume, else of its convex hull, and of the surface (area-weighted) when the
    part is flat (a hull with no volume)."""
    if mesh.is_watertight and mesh.volume > 0:
        return np.asarray(mesh.center_mass, dtype=np.float64)
    normal, _ = _flatness(mesh)
    if normal is None:
        hull = mesh.convex_hull
        if hull.volume > 0:
            return np.asarray(hull.center_mass, dtype=np.float64)
    w = np.asarray(mesh.area_faces, dtype=np.float64)
    return (np.asarray(mesh.triangles_center) * w[:, None]).sum(axis=0) / w.sum()


def _resting_rotation(down: np.ndarray) -> np.ndarray:
    """``R_world_part (k, 3, 3)`` turning the part-frame unit normals ``down (k, 3)`` to -z (the
    construction of ``trimesh.poses.compute_stable_poses``)."""
    z = -np.asarray(down, dtype=np.float64)
    x = np.stack([-z[:, 1], z[:, 0], np.zeros(len(z))], axis=1)
    nx = np.linalg.norm(x, axis=1)
    x = np.where(nx[:, None] > 0, x / np.where(nx > 0, nx, 1.0)[:, None], [1.0, 0.0, 0.0])
    y = np.cross(z, x)
    y /= np.linalg.norm(y, axis=1)[:, None]
    return np.stack([x, y, z], axis=1)


def _solid_angle(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Solid angle (sr) of triangles seen from the origin; ``a, b, c (k, 3)`` (Van Oosterom and
    Strackee 1983)."""
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    num = np.abs(np.einsum("ij,ij->i", a, np.cross(b, c)))
    den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb
           + np.einsum("ij,ij->i", b, c) * la)
    return 2.0 * np.arctan2(num, den)


#: the com projected within this fraction of the part's diagonal of a hull face's edge is on it
_ON_EDGE = 1e-9


def _topple(hull: trimesh.Trimesh, com: np.ndarray, diag: float) -> tuple[np.ndarray, np.ndarray]:
    """The quasi-static toppling model of Goldberg et al. (1999) on a convex hull, vectorised.

    Each hull face ``i`` gets the probability that the part dropped at a uniformly random
    orientation lands on it (solid angle of the face seen from ``com`` / 4 pi). A face is stable
    when ``com`` projects inside it; otherwise the part topples across the edge the projected
    ``com`` lies beyond, onto the neighbouring face. Following the toppling pointers (pointer
    jumping: ceil(log2 k) + 1 rounds, so bounded even if rounding made a cycle) gives each face's
    resting face. ``com`` (3,) and ``diag`` (the part's bounding-box diagonal) in metres.
    Returns ``(rest (k,) int, prob (k,))``.
    """
    T = np.asarray(hull.triangles, dtype=np.float64)          # (k, 3, 3)
    N = np.asarray(hull.face_normals, dtype=np.float64)       # (k, 3)
    F = np.asarray(hull.faces, dtype=np.int64)
    k = len(F)
    prob = _solid_angle(T[:, 0] - com, T[:, 1] - com, T[:, 2] - com) / (4.0 * np.pi)
    p = com - np.einsum("ij,ij->i", N, com - T[:, 0])[:, None] * N  # com projected on each face's plane
    # signed areas of (v_k, v_k+1, p) against the face normal: all >= 0 <=> p inside the face
    vk, vk1 = T, np.roll(T, -1, axis=1)
    edge_side = np.einsum("ikj,ij->ik", np.cross(vk1 - vk, p[:, None, :] - vk), N)
    edge_len = np.linalg.norm(vk1 - vk, axis=2)
    stable = (edge_side >= -_ON_EDGE * diag * edge_len).all(axis=1)  # on an edge (rounding) counts as inside
    # wedge of local edge j seen from the face centroid: p between the rays centroid->v_j and
    # centroid->v_j+1 (the faces are counter-clockwise about their outward normal)
    ctr = T.mean(axis=1)
    left = np.einsum("ikj,ij->ik", np.cross(vk - ctr[:, None], (p - ctr)[:, None, :]), N)
    right = np.einsum("ikj,ij->ik", np.cross(vk1 - ctr[:, None], (p - ctr)[:, None, :]), N)
    edge = np.argmax(np.minimum(left, -right), axis=1)        # the edge the com lies beyond
    # neighbour across each (face, local edge): the other face holding the same undirected edge
    a, b = F, np.roll(F, -1, axis=1)
    key = (np.minimum(a, b) * (F.max() + 1) + np.maximum(a, b)).ravel()
    order = np.argsort(key, kind="stable")
    neighbour = np.full(3 * k, -1, dtype=np.int64)
    pair = key[order[:-1]] == key[order[1:]]
    i0, i1 = order[:-1][pair], order[1:][pair]
    neighbour[i0], neighbour[i1] = i1 // 3, i0 // 3
    succ = np.where(stable, np.arange(k), neighbour.reshape(k, 3)[np.arange(k), edge])
    succ = np.where(succ < 0, np.arange(k), succ)            # an open hull edge: stays (never for qhull)
    for _ in range(int(np.ceil(np.log2(max(k, 2)))) + 1):
        succ = succ[succ]
    # a face not reaching a stable one is in a toppling cycle, which only rounding makes (the com
    # projected onto the edge between coplanar faces): it rests on the face it reached
    return succ, prob


def stable_poses(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """Quasi-static resting poses of ``mesh`` on a plane: the toppling model of Goldberg et al.
    (the model of ``trimesh.poses.compute_stable_poses`` with ``sigma = 0``: no random
    perturbation of the centre of mass), vectorised and bounded (:func:`_topple`): deterministic.

    A flat part (thinner than :data:`FLAT_RELATIVE_THICKNESS` of its size: a plane, an n-gon, a
    flattened box) lies on either side of its plane (its largest face), probability 1/2 each. A
    part whose vertices are collinear is refused (InputError).

    Returns ``(R (k, 3, 3), prob (k,))``, most probable first (ties: by the resting normal in the
    part frame, so the order is deterministic). ``R`` is ``R_world_part``: it turns the part so
    that it rests on its face; the translation is left to :func:`stable_pose`.
    """
    with np.errstate(all="ignore"):
        normal, diag = _flatness(mesh)
        if normal is not None:
            downs, probs = np.stack([normal, -normal]), np.array([0.5, 0.5])
        else:
            downs, probs = _hull_poses(mesh, diag)
    R = _resting_rotation(downs)
    down = np.round(np.einsum("kji,j->ki", R, [0.0, 0.0, -1.0]), 6) + 0.0  # resting normal, part frame
    order = np.lexsort((down[:, 2], down[:, 1], down[:, 0], -np.round(probs, 9)))
    return R[order], probs[order] / probs.sum()


def _hull_poses(mesh: trimesh.Trimesh, diag: float) -> tuple[np.ndarray, np.ndarray]:
    """``(resting normals (k, 3), prob (k,))`` of a part with volume, from its convex hull."""
    try:
        hull = mesh.convex_hull
    except Exception:  # qhull refuses (near-)degenerate input; the flatness test should have caught it
        raise InputError("the part is too thin to compute its resting poses (its convex hull is degenerate); "
                         "give the pose with --part-pose x,y,z,roll,pitch,yaw") from None
    com = centre_of_mass(mesh)
    inside = np.einsum("ij,ij->i", com - hull.triangles_center, hull.face_normals)
    if len(hull.faces) < 4 or not np.all(inside < -FLAT_RELATIVE_THICKNESS * diag):
        raise InputError("the part's centre of mass is not inside its convex hull (the mesh is too thin or "
                         "degenerate) so it has no defined resting pose; give the pose with --part-pose "
                         "x,y,z,roll,pitch,yaw")
    rest, prob = _topple(hull, com, diag)
    ok = np.isfinite(prob) & (prob > 0)
    # faces of one hull facet (same normal to 3 decimals) are one pose; sum their probabilities
    N = np.asarray(hull.face_normals, dtype=np.float64)
    sinks = rest[ok]
    total = np.bincount(sinks, weights=prob[ok], minlength=len(N))
    faces = np.flatnonzero(total > 0)
    keys = np.round(N[faces], 3) + 0.0
    _, first, group = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    group = group.ravel()
    p = np.bincount(group, weights=total[faces])
    normals = N[faces[first]]
    keep = p > 0
    return normals[keep], p[keep]


def stable_pose(part_mesh: trimesh.Trimesh, cell: Cell | None = None) -> np.ndarray:
    """``T_world_part`` (4, 4): the part resting on the table in stable pose ``cell.pose_index``
    (0 = most probable), lowest point on ``z = table_z``, centre of mass above ``cell.part_xy``."""
    cell = cell or Cell("table")
    R, prob = stable_poses(part_mesh)
    if len(R) == 0:
        raise InputError("the part has no stable resting pose on a plane (is the mesh degenerate?)")
    if cell.pose_index >= len(R):
        raise ConfigError(f"pose_index {cell.pose_index}: the part has only {len(R)} stable poses (0..{len(R) - 1})")
    return place_on_table(part_mesh, R[cell.pose_index], cell)


def place_on_table(part_mesh: trimesh.Trimesh, R_world_part: np.ndarray, cell: Cell) -> np.ndarray:
    """``T_world_part`` (4, 4) with rotation ``R_world_part`` (3, 3), lowest point at ``table_z``,
    centre of mass (:func:`centre_of_mass`) above ``part_xy`` (metres)."""
    com = centre_of_mass(part_mesh)
    T = np.eye(4)
    T[:3, :3] = R_world_part
    z_min = float((np.asarray(part_mesh.vertices) @ R_world_part[2]).min())  # lowest point of the turned part
    c = R_world_part @ com
    T[:3, 3] = [cell.part_xy[0] - c[0], cell.part_xy[1] - c[1], cell.table_z - z_min]
    return T


_POSE_SPLIT = re.compile(r"\s*,\s*")


def parse_part_pose(text: str | os.PathLike) -> np.ndarray:
    """``T_world_part`` from ``--part-pose``.

    Either ``"x,y,z,roll,pitch,yaw"`` (lengths with optional units, bare = metres; angles in
    degrees; R = R_z(yaw) R_y(pitch) R_x(roll)) or a JSON/YAML file holding a 4x4 row-major
    matrix (top level, or under the key ``T_world_part``). The pose is used as given: the part
    may float above or sink into the table (the collision check does not move it)."""
    s = str(text)
    if len(s) > 4096 or "\x00" in s:
        raise InputError("--part-pose: expected 'x,y,z,roll,pitch,yaw' or a JSON/YAML file with T_world_part")
    p = Path(s)
    try:
        is_file = p.is_file()
    except OSError:  # e.g. a name too long for the file system: not a file
        is_file = False
    if p.suffix.lower() in (".json", ".yaml", ".yml") or is_file:
        if not is_file:
            raise InputError(f"--part-pose: file {p} not found")
        try:
            if p.stat().st_size > 1_000_000:
                raise InputError(f"--part-pose: {p} is too large for a pose file")
            data = yaml.safe_load(p.read_text())  # YAML is a superset of JSON
        except (yaml.YAMLError, UnicodeDecodeError, OSError) as exc:
            raise InputError(f"--part-pose: {p} is not a readable JSON/YAML file ({str(exc).splitlines()[0][:80]})") from None
        if isinstance(data, dict):
            if "T_world_part" not in data:
                raise InputError(f"--part-pose: {p} has no key 'T_world_part' (a 4x4 row-major matrix)")
            data = data["T_world_part"]
        return check_transform(data, f"--part-pose {p}")
    parts = _POSE_SPLIT.split(s.strip())
    if len(parts) != 6:
        raise InputError(f"--part-pose: expected 'x,y,z,roll,pitch,yaw' (m or with units; degrees) or a JSON/YAML file, got {s!r}")
    xyz = [parse_length(v, name=f"--part-pose {n}", allow_negative=True) for v, n in zip(parts[:3], "xyz")]
    rpy = [math.radians(parse_angle_deg(v, name=f"--part-pose {n}")) for v, n in zip(parts[3:], ("roll", "pitch", "yaw"))]
    T = np.eye(4)
    T[:3, :3] = rpy_matrix(*rpy)
    T[:3, 3] = xyz
    return T
