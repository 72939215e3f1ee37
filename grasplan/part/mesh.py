"""Stage 1: load a part's mesh, settle its units, repair what is safe to repair, refuse the rest.

STL carries no units. ``units="auto"`` decides from the size: a part whose largest extent is at
least :data:`AUTO_MM_THRESHOLD` file units is read as millimetres (a 2 m part is far beyond a
parallel-jaw gripper), otherwise as metres; the decision is reported.

Safe repairs: merging duplicate vertices, dropping degenerate (zero-area) and duplicate faces,
making the winding consistent and the normals point outwards (watertight meshes only). Anything
else (missing file, unreadable or empty mesh, NaN/inf coordinates, no area) is refused with a
:class:`~grasplan.errors.MeshError` naming the file and the problem. The file formats are read by
:mod:`grasplan.part.meshfile`, within this module's limits (:data:`MAX_TRIANGLES`, :data:`MAX_FILE_BYTES`).
"""
from __future__ import annotations

import functools
import hashlib
import os
import warnings as _warnings
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Literal, ParamSpec, TypeVar

import numpy as np

from ..errors import MeshError
from ..io import show_path
from ..geometry.meshdata import MeshData
from .meshfile import ReadLimits, read_mesh, too_many_triangles
from ..geometry.tolerance import Tolerance
from ..geometry.units import LENGTH_UNITS, UNIT_CHOICES

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from ..geometry.meshdata import TriangleMesh

Units = Literal["auto", "m", "cm", "mm", "um", "in", "ft"]
#: largest extent (file units) from which ``auto`` reads a file as millimetres
AUTO_MM_THRESHOLD = 2.0
#: parts with more triangles are refused before they are read (decimate first): time and memory of
#: ``candidates`` and ``grasps`` grow with the triangle count, and up to this many they finish
#: within a minute on two cores with margin (benchmarks/bench_large.py)
MAX_TRIANGLES = 750_000
#: mesh files larger than this (bytes) are refused before they are read
MAX_FILE_BYTES = 1 << 30
#: a part's largest extent in metres must lie in this range (outside it the units are wrong or
#: the coordinates are garbage: a parallel-jaw gripper holds neither a 0.1 mm speck nor a house)
MIN_EXTENT_M, MAX_EXTENT_M = 1e-4, 100.0
#: no vertex may lie further than this from the origin (metres): float64 keeps ~1e-12 relative
#: precision, so a part far from the origin loses its shape
MAX_COORD_M = 1e3
#: extents (metres) a gripper part plausibly has; outside it the units hint lists alternatives
PLAUSIBLE_EXTENT_M = (2e-3, 1.0)

_P = ParamSpec("_P")
_R = TypeVar("_R")


@dataclass(frozen=True)
class MeshReport:
    """What loading did to the file's mesh."""

    faces_in_file: int
    vertices_in_file: int
    merged_vertices: int
    dropped_degenerate: int
    dropped_duplicate: int
    winding_fixed: bool
    inverted_fixed: bool
    watertight: bool
    bodies: int


@dataclass(frozen=True)
class Part:
    """A loaded, cleaned part in metres (part frame = file coordinates times ``scale_to_m``).

    ``mesh`` is a :class:`grasplan.geometry.meshdata.MeshData` in metres (plain arrays, no trimesh import;
    anything trimesh-only is read from an equal ``trimesh.Trimesh`` built on first use): read-only.
    """

    path: str
    sha256: str
    scale_to_m: float
    units: str
    units_note: str
    mesh: MeshData
    report: MeshReport
    tol: Tolerance
    warnings: tuple[str, ...] = field(default=())

    @property
    def vertices(self) -> np.ndarray:
        """(n, 3) float64, metres."""
        return self.mesh.vertices

    @property
    def faces(self) -> np.ndarray:
        """(m, 3) int64."""
        return self.mesh.faces

    @property
    def triangles(self) -> int:
        """Number of faces."""
        return len(self.mesh.faces)

    def to_json(self) -> dict[str, Any]:
        """The ``part`` block shared by every output schema."""
        return {
            "path": self.path,
            "sha256": self.sha256,
            "scale_to_m": self.scale_to_m,
            "triangles": self.triangles,
        }


def _fmt_len(metres: float) -> str:
    """A length for messages: millimetres below 1 m, else metres."""
    return f"{metres * 1e3:.4g} mm" if metres < 1.0 else f"{metres:.4g} m"


def units_alternatives(extent: float, *, exclude: str = "", limit: int = 3) -> list[tuple[str, float]]:
    """Units that make a part of ``extent`` file units a plausibly sized gripper part.

    Returns up to ``limit`` ``(unit, extent_m)`` pairs with ``extent_m`` in
    :data:`PLAUSIBLE_EXTENT_M`, the closest to a 50 mm part first (in log scale)."""
    rows = [(u, extent * f) for u, f in LENGTH_UNITS.items() if u != exclude]
    rows = [(u, m) for u, m in rows if PLAUSIBLE_EXTENT_M[0] <= m <= PLAUSIBLE_EXTENT_M[1]]
    rows.sort(key=lambda r: abs(np.log(r[1] / 0.05)))
    return rows[:limit]


def units_hint(extent: float, unit: str) -> str:
    """A hint naming the ``--units`` that would give a plausible size, or ``""`` when the part's
    size in ``unit`` (``extent`` file units) is already plausible."""
    metres = extent * LENGTH_UNITS[unit]
    if PLAUSIBLE_EXTENT_M[0] <= metres <= PLAUSIBLE_EXTENT_M[1]:
        return ""
    alts = units_alternatives(extent, exclude=unit)
    if not alts:
        return ""
    opts = " or ".join(f"--units {u} ({_fmt_len(m)})" for u, m in alts)
    return f"a {_fmt_len(metres)} part is unusual for a gripper; if the file is not in {unit}, pass {opts}"


def decide_units(extent: float, units: str) -> tuple[float, str, str]:
    """Return ``(scale_to_m, unit, note)`` for a mesh whose largest extent is ``extent`` file units.

    The note says what was decided and, when the resulting size is implausible for a gripper part
    (outside :data:`PLAUSIBLE_EXTENT_M`), which ``--units`` would give a plausible one."""
    if units != "auto":
        if units not in LENGTH_UNITS:
            raise MeshError(f"unknown units {units!r}; use one of {', '.join(UNIT_CHOICES)}")
        scale, unit, note = LENGTH_UNITS[units], units, f"units {units} (given)"
    elif extent >= AUTO_MM_THRESHOLD:
        scale, unit = 1e-3, "mm"
        note = (f"units auto: largest extent {extent:.4g} -> millimetres ({extent * 1e-3:.4g} m); "
                f"pass --units m if that is wrong")
    else:
        scale, unit = 1.0, "m"
        note = f"units auto: largest extent {extent:.4g} -> metres"
    hint = units_hint(extent, unit)
    if hint:
        note = f"{note}; {hint}"
    elif units == "auto" and unit == "m":
        note += f"; pass --units mm if the part is really {extent:.4g} mm"
    return scale, unit, note


def load_part(path: str | os.PathLike, *, units: Units | str = "auto") -> Part:
    """Load and clean a part.

    Parameters
    ----------
    path : str or PathLike
        STL (binary or ASCII), OBJ, PLY, OFF or glTF file, at most :data:`MAX_TRIANGLES`
        triangles and :data:`MAX_FILE_BYTES` bytes.
    units : {"auto", "m", "cm", "mm", "um", "in", "ft"}
        Units of the file's coordinates.

    Raises
    ------
    MeshError
        One message naming the file and what is wrong with it: missing, not a regular file,
        unreadable, empty, damaged or truncated, too many triangles, NaN/inf coordinates, a size
        outside [:data:`MIN_EXTENT_M`, :data:`MAX_EXTENT_M`] in the chosen units, or no area.
    """
    p = Path(os.fsdecode(path))
    v, f, data = read_mesh(p, ReadLimits(MAX_TRIANGLES, MAX_FILE_BYTES))
    digest = hashlib.sha256(data).hexdigest()
    del data  # up to MAX_FILE_BYTES: not kept while the mesh is cleaned
    return part_from_arrays(v, f, path=str(p), sha256=digest, units=units, source=show_path(p))


def _quiet(fn: Callable[_P, _R]) -> Callable[_P, _R]:
    """Run ``fn`` with NumPy floating-point and library warnings silenced: callers get a Part or one
    MeshError, never a RuntimeWarning printed on stderr."""
    @functools.wraps(fn)
    def wrapper(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        with _warnings.catch_warnings(), np.errstate(all="ignore"):
            _warnings.simplefilter("ignore")
            return fn(*args, **kwargs)
    return wrapper


def _first_unique_rows(rows: np.ndarray, bound: int) -> np.ndarray:
    """Index of the first occurrence of each distinct row of a non-negative (n, 3) int array whose
    entries are < ``bound`` (= ``np.unique(rows, axis=0, return_index=True)[1]``, as a set)."""
    if bound < (1 << 21):  # pack a row into one int64: a 1D sort instead of a row sort
        key = (rows[:, 0] << 42) | (rows[:, 1] << 21) | rows[:, 2]
        return np.unique(key, return_index=True)[1]
    return np.unique(rows, axis=0, return_index=True)[1]


def _row_hash(q: np.ndarray) -> np.ndarray:
    """(n,) uint64 hash of the rows of an (n, 3) int64 array (splitmix64 finaliser, chained)."""
    u = q.astype(np.uint64)

    def mix(z: np.ndarray) -> np.ndarray:
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))

    with np.errstate(over="ignore"):
        h = mix(u[:, 0] + np.uint64(0x9E3779B97F4A7C15))
        h = mix(h ^ u[:, 1])
        return mix(h ^ u[:, 2])


def _group_rows(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(first, inverse)`` of the distinct rows of an (n, 3) int64 array: ``first`` (u,) the index
    of each distinct row's first occurrence, in order of first occurrence; ``inverse`` (n,) the
    position of each row's value in ``first``. Rows are sorted by a 64-bit hash (one 1D sort);
    rows sharing a hash are verified equal (a hash collision falls back to a row sort)."""
    n = len(q)
    h = _row_hash(q)
    perm = np.argsort(h, kind="stable")
    hs = h[perm]
    start = np.flatnonzero(np.r_[True, hs[1:] != hs[:-1]])
    gid_sorted = np.cumsum(np.r_[False, hs[1:] != hs[:-1]])
    qs = q[perm]
    if not np.array_equal(qs, qs[start[gid_sorted]]):  # a hash collision: exact row sort instead
        _, first, inv = np.unique(q, axis=0, return_index=True, return_inverse=True)
        inv = inv.reshape(-1)
    else:
        first = perm[start]  # stable sort: the first member of a group is its first occurrence
        inv = np.empty(n, dtype=np.int64)
        inv[perm] = gid_sorted
    order = np.argsort(first, kind="stable")  # distinct rows in order of first occurrence
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.arange(len(order))
    return first[order], rank[inv]


def merge_vertices(vertices: np.ndarray, faces: np.ndarray, referenced: np.ndarray, digits: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices, faces)`` with the referenced vertices that are equal when rounded to ``digits``
    decimals merged into their first occurrence; unreferenced vertices dropped; vertex order = order
    of first occurrence (identical to ``trimesh.Trimesh.merge_vertices(merge_tex=True,
    merge_norm=True, digits_vertex=digits)`` on a mesh without normals or texture)."""
    ref = np.flatnonzero(referenced)
    q = np.round(vertices[ref] * (10 ** digits)).astype(np.int64)
    first, inv = _group_rows(q)
    inverse = np.zeros(len(vertices), dtype=np.int64)
    inverse[ref] = inv
    return vertices[ref[first]], inverse[faces]


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Signed volume of a closed triangle mesh (positive for outward normals)."""
    t = vertices[faces]
    return float(np.einsum("fi,fi->", t[:, 0], np.cross(t[:, 1], t[:, 2]))) / 6.0


def _checked_faces(vertices: ArrayLike, faces: ArrayLike, src: str) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices (n, 3) float64, faces (m, 3) int64)``; MeshError for an empty or corrupt mesh or more
    than :data:`MAX_TRIANGLES` faces."""
    try:
        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces)
    except (TypeError, ValueError, OverflowError):
        raise MeshError(f"{src}: vertices and faces must be arrays of numbers") from None
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0 or f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        raise MeshError(f"{src}: the mesh is empty (no triangles)")
    if len(f) > MAX_TRIANGLES:
        raise too_many_triangles(src, len(f), MAX_TRIANGLES)
    if not (np.issubdtype(f.dtype, np.integer) or (np.issubdtype(f.dtype, np.floating)
                                                    and np.all(np.isfinite(f)) and np.all(f == np.round(f)))):
        raise MeshError(f"{src}: face indices must be integers; the file is corrupt")
    if f.min() < 0 or f.max() >= len(v):
        raise MeshError(f"{src}: faces reference vertices that do not exist; the file is corrupt")
    return v, f.astype(np.int64)


def _extent(v: np.ndarray, referenced: np.ndarray, src: str) -> tuple[float, float]:
    """``(largest extent, largest |coordinate|)`` of the referenced vertices, file units; MeshError for
    NaN/inf coordinates, an overflowing extent or a single point."""
    used = np.flatnonzero(referenced)  # = np.unique(f), in O(n)
    vu = v[used]
    if not np.all(np.isfinite(vu)):
        bad = int((~np.isfinite(vu)).any(axis=1).sum())
        raise MeshError(f"{src}: {bad} vertices have NaN or infinite coordinates; re-export the mesh from CAD")
    with np.errstate(over="ignore", invalid="ignore"):
        extent = float(np.ptp(vu, axis=0).max())
        reach = float(np.abs(vu).max())
    if not np.isfinite(extent):
        raise MeshError(f"{src}: coordinates up to {reach:.3g} overflow (the part would be infinitely large); "
                        f"the file is corrupt, re-export it")
    if extent == 0.0:
        raise MeshError(f"{src}: all {len(used)} vertices are the same point: the mesh has no area")
    return extent, reach


def _checked_units(extent: float, reach: float, units: str, src: str) -> tuple[float, str, str]:
    """:func:`decide_units`, then MeshError when the part's size in metres lies outside
    [:data:`MIN_EXTENT_M`, :data:`MAX_EXTENT_M`] (naming the ``--units`` that would fit) or a vertex lies
    more than :data:`MAX_COORD_M` from the origin."""
    scale_to_m, unit, note = decide_units(extent, units)
    size_m, reach_m = extent * scale_to_m, reach * scale_to_m
    if not (MIN_EXTENT_M <= size_m <= MAX_EXTENT_M):
        alts = units_alternatives(extent, exclude=unit)
        fix = ("; if the file is not in " + unit + ", pass " +
               " or ".join(f"--units {u} ({_fmt_len(m)})" for u, m in alts)) if alts else \
            "; the coordinates are probably garbage: re-export the mesh from CAD"
        raise MeshError(f"{src}: the part is {_fmt_len(size_m)} across in {unit} ({note.split(';')[0]}); grasplan "
                        f"handles parts from {MIN_EXTENT_M * 1e3:g} mm to {MAX_EXTENT_M:g} m{fix}")
    if reach_m > MAX_COORD_M:
        raise MeshError(f"{src}: the part lies {reach_m:.3g} m from the origin (limit {MAX_COORD_M:g} m): far "
                        f"from the origin floating point loses its shape; move it near the origin in CAD")
    return scale_to_m, unit, note


@dataclass(frozen=True)
class _Cleaned:
    """The mesh after merging vertices and dropping bad faces: ``mesh``, vertices ``merged``, and
    masks (over the merged mesh's faces) of the ``degenerate`` and ``duplicate`` faces dropped."""

    mesh: MeshData
    merged: int
    degenerate: np.ndarray
    duplicate: np.ndarray


def _clean(v_m: np.ndarray, f: np.ndarray, referenced: np.ndarray, tol: Tolerance, src: str) -> _Cleaned:
    """Safe repairs 1-3: merge duplicate vertices (STL writes every vertex once per face: vertices
    equal when rounded to ``tol.merge`` decimals, kept in order of first use, as trimesh's
    merge_vertices), drop degenerate faces (a repeated vertex index or (near) zero area) and
    duplicate faces (the same three vertices, either winding). MeshError when no area is left."""
    digits = int(max(0, np.floor(-np.log10(tol.merge))))
    v_keep, fv = merge_vertices(v_m, f, referenced, digits)
    merged = len(v_m) - len(v_keep)
    full = MeshData(v_keep, fv)
    repeated = (fv[:, 0] == fv[:, 1]) | (fv[:, 1] == fv[:, 2]) | (fv[:, 0] == fv[:, 2])
    tiny = full.area_faces <= tol.area
    degenerate = repeated | tiny
    keep = ~degenerate
    first = _first_unique_rows(np.sort(fv, axis=1), len(v_keep))
    unique_mask = np.zeros(len(fv), dtype=bool)
    unique_mask[first] = True
    duplicate = ~unique_mask & keep
    keep &= unique_mask
    if not keep.any():
        raise MeshError(f"{src}: the mesh has no area (all {len(f)} triangles are degenerate)")
    mesh = full.with_faces(keep)  # unreferenced vertices dropped, order kept
    if mesh.area <= tol.area:
        raise MeshError(f"{src}: the mesh has no area")
    return _Cleaned(mesh, merged, degenerate, duplicate)


def _orient(mesh: MeshData) -> tuple[MeshData, bool, bool, bool]:
    """Safe repair 4: ``(mesh, winding_fixed, inverted_fixed, watertight)``, the winding made consistent
    (trimesh's fix_winding, and its import, only for a mesh whose winding is inconsistent) and the
    normals pointing outwards (only meaningful on a closed mesh)."""
    winding_fixed = False
    if not mesh.is_winding_consistent:
        import trimesh

        tm = trimesh.Trimesh(vertices=mesh.vertices.copy(), faces=mesh.faces.copy(), process=False, validate=False)
        trimesh.repair.fix_winding(tm)
        winding_fixed = not np.array_equal(np.asarray(tm.faces), mesh.faces)
        if winding_fixed:
            mesh = MeshData(mesh.vertices, np.asarray(tm.faces, dtype=np.int64))
    watertight = bool(mesh.is_watertight)
    inverted = False
    if watertight and signed_volume(mesh.vertices, mesh.faces) < 0:
        mesh = MeshData(mesh.vertices, mesh.faces[:, ::-1])
        inverted = True
    return mesh, winding_fixed, inverted, watertight


def _input_sha256(vertices: ArrayLike, faces: ArrayLike) -> str:
    """The sha256 of an in-memory part's input arrays (float64 vertices, int64 faces, little-endian)."""
    h = hashlib.sha256(np.ascontiguousarray(vertices, dtype="<f8").tobytes())
    h.update(np.ascontiguousarray(faces, dtype="<i8").tobytes())
    return h.hexdigest()


@_quiet
def part_from_arrays(
    vertices: ArrayLike,
    faces: ArrayLike,
    *,
    path: str = "<memory>",
    sha256: str = "",
    units: Units | str = "m",
    source: str | None = None,
) -> Part:
    """Build a cleaned :class:`Part` from ``vertices (n, 3)`` and ``faces (m, 3)`` in file units.

    ``source`` is how messages name the input (default ``path``). Raises :class:`MeshError` for
    an empty or corrupt mesh, more than :data:`MAX_TRIANGLES` faces, NaN/inf coordinates, a
    largest extent outside [:data:`MIN_EXTENT_M`, :data:`MAX_EXTENT_M`] metres, a vertex more than
    :data:`MAX_COORD_M` from the origin, or no area. ``sha256`` default: :func:`_input_sha256`."""
    src = source or show_path(path)
    v, f = _checked_faces(vertices, faces, src)
    referenced = np.zeros(len(v), dtype=bool)
    referenced[f.reshape(-1)] = True
    extent, reach = _extent(v, referenced, src)
    scale_to_m, unit, note = _checked_units(extent, reach, str(units), src)
    v_m = v * scale_to_m
    tol = Tolerance.for_mesh(v_m[np.flatnonzero(referenced)])
    cleaned = _clean(v_m, f, referenced, tol, src)
    mesh, winding_fixed, inverted, watertight = _orient(cleaned.mesh)
    bodies = int(mesh.body_count)
    n_degenerate, n_duplicate = int(cleaned.degenerate.sum()), int(cleaned.duplicate.sum())
    hint = units_hint(extent, unit)
    warn = [f"{src}: {hint}"] if hint else []
    if not watertight:
        warn.append(f"{src}: the mesh is not watertight; convexity and collision results near its holes are unreliable")
    if bodies > 1:
        warn.append(f"{src}: the mesh has {bodies} separate bodies; they are treated as one rigid part")
    if n_degenerate:
        warn.append(f"{src}: dropped {n_degenerate} degenerate (zero-area) triangles")
    if n_duplicate:
        warn.append(f"{src}: dropped {n_duplicate} duplicate triangles")
    report = MeshReport(faces_in_file=len(f), vertices_in_file=len(v), merged_vertices=cleaned.merged,
                        dropped_degenerate=n_degenerate, dropped_duplicate=n_duplicate, winding_fixed=winding_fixed,
                        inverted_fixed=inverted, watertight=watertight, bodies=bodies)
    return Part(path=path, sha256=sha256 or _input_sha256(vertices, faces), scale_to_m=scale_to_m, units=unit,
                units_note=note, mesh=mesh, report=report, tol=tol, warnings=tuple(warn))


def part_from_trimesh(mesh: TriangleMesh, *, path: str = "<memory>", units: Units | str = "m") -> Part:
    """A :class:`Part` from an in-memory mesh, e.g. a ``trimesh.Trimesh`` (file units given by ``units``)."""
    return part_from_arrays(mesh.vertices, mesh.faces, path=path, units=units)


def units_for_scale(scale_to_m: float) -> str:
    """The unit name whose metres-per-unit is ``scale_to_m`` (what :func:`load_part` recorded)."""
    for name, factor in LENGTH_UNITS.items():
        if np.isfinite(float(scale_to_m)) and np.isclose(factor, float(scale_to_m), rtol=1e-9, atol=0.0):
            return name
    raise MeshError(f"scale_to_m = {scale_to_m!r} is not one grasplan reads files in ({', '.join(LENGTH_UNITS)}); "
                    f"the result file is corrupt")


def load_recorded_part(part_json: dict, *, path: str | os.PathLike | None = None,
                       search_dirs: tuple[str | os.PathLike, ...] = ()) -> Part:
    """Load the part a result file was made from, at the scale it recorded.

    Parameters
    ----------
    part_json : dict
        A result's ``part`` block (``path``, ``scale_to_m``; ``sha256`` is left to the caller,
        who decides whether a different file is an error or a warning).
    path : path, optional
        The mesh to use instead of the recorded path (``--part``).
    search_dirs : paths
        Where a relative recorded path is also looked for, after the current folder (e.g. the
        result file's folder).
    """
    if not isinstance(part_json, dict):
        raise MeshError("the result's part block is not a mapping; the result file is corrupt")
    scale = part_json.get("scale_to_m")
    if isinstance(scale, bool) or not isinstance(scale, (int, float)):
        raise MeshError(f"part.scale_to_m = {str(scale)[:40]} is not a number; the result file is corrupt")
    if path is not None:
        candidates = [Path(path)]
    else:
        recorded = part_json.get("path")
        if not recorded or not isinstance(recorded, str):
            raise MeshError("the result records no part path; give the part with --part PATH")
        rp = Path(recorded)
        candidates = [rp] if rp.is_absolute() else [Path.cwd() / rp] + [Path(d) / rp for d in search_dirs]
    found = next((c for c in candidates if os.path.isfile(c)), None)  # never raises (long names)
    if found is None:
        tried = ", ".join(show_path(c) for c in candidates)
        raise MeshError(f"part not found (tried {tried}); give the mesh the result was made from with --part PATH")
    return load_part(found, units=units_for_scale(scale))
