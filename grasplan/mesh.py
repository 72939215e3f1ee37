"""Stage 1: load a part's mesh, settle its units, repair what is safe to repair, refuse the rest.

STL carries no units. ``units="auto"`` decides from the size: a part whose largest extent is at
least :data:`AUTO_MM_THRESHOLD` file units is read as millimetres (a 2 m part is far beyond a
parallel-jaw gripper), otherwise as metres; the decision is reported.

Safe repairs: merging duplicate vertices, dropping degenerate (zero-area) and duplicate faces,
making the winding consistent and the normals point outwards (watertight meshes only). Anything
else (missing file, unreadable or empty mesh, NaN/inf coordinates, no area) is refused with a
:class:`~grasplan.errors.MeshError` naming the file and the problem.
"""
from __future__ import annotations

import os
import warnings as _warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import trimesh

from .errors import MeshError
from .io import sha256_file
from .tolerance import Tolerance
from .units import LENGTH_UNITS

Units = Literal["auto", "m", "cm", "mm", "um", "in", "ft"]
UNIT_CHOICES: tuple[str, ...] = ("auto", *LENGTH_UNITS)
#: largest extent (file units) from which ``auto`` reads a file as millimetres
AUTO_MM_THRESHOLD = 2.0
SUPPORTED_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".glb", ".gltf")


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

    ``mesh`` is a :class:`trimesh.Trimesh` in metres; treat it as read-only (stages copy it).
    """

    path: str
    sha256: str
    scale_to_m: float
    units: str
    units_note: str
    mesh: trimesh.Trimesh
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
        return int(len(self.mesh.faces))

    def to_json(self) -> dict:
        """The ``part`` block shared by every output schema."""
        return {
            "path": self.path,
            "sha256": self.sha256,
            "scale_to_m": self.scale_to_m,
            "triangles": self.triangles,
        }


def decide_units(extent: float, units: str) -> tuple[float, str, str]:
    """Return ``(scale_to_m, unit, note)`` for a mesh whose largest extent is ``extent`` file units."""
    if units != "auto":
        if units not in LENGTH_UNITS:
            raise MeshError(f"unknown units {units!r}; use one of {', '.join(UNIT_CHOICES)}")
        return LENGTH_UNITS[units], units, f"units {units} (given)"
    if extent >= AUTO_MM_THRESHOLD:
        return (
            1e-3,
            "mm",
            f"units auto: largest extent {extent:.4g} -> millimetres "
            f"({extent * 1e-3:.4g} m); pass --units m if that is wrong",
        )
    return (
        1.0,
        "m",
        f"units auto: largest extent {extent:.4g} -> metres; pass --units mm if the part is really {extent:.4g} mm",
    )


def _read_mesh(path: Path) -> trimesh.Trimesh:
    try:
        with _warnings.catch_warnings():
            _warnings.simplefilter("ignore")
            loaded = trimesh.load(str(path), force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise MeshError(f"{path}: cannot read the mesh ({type(exc).__name__}: {exc}); is it a valid STL/OBJ/PLY file?") from exc
    if isinstance(loaded, trimesh.Scene):  # force='mesh' on an empty scene
        raise MeshError(f"{path}: the file holds no triangles")
    if not isinstance(loaded, trimesh.Trimesh):
        raise MeshError(f"{path}: the file holds no triangle mesh (got {type(loaded).__name__})")
    return loaded


def load_part(path: str | os.PathLike, *, units: Units | str = "auto") -> Part:
    """Load and clean a part.

    Parameters
    ----------
    path : str or PathLike
        STL (binary or ASCII), OBJ or PLY file.
    units : {"auto", "m", "cm", "mm", "um", "in", "ft"}
        Units of the file's coordinates.

    Raises
    ------
    MeshError
        Missing file, unreadable or empty mesh, NaN/inf coordinates, or no area.
    """
    p = Path(path)
    if not p.exists():
        raise MeshError(f"{p}: no such file")
    if p.is_dir():
        raise MeshError(f"{p}: is a folder, not a mesh file")
    if p.suffix.lower() not in SUPPORTED_SUFFIXES:
        raise MeshError(f"{p}: unsupported file type {p.suffix or '(none)'!r}; use one of {', '.join(SUPPORTED_SUFFIXES)}")
    if p.stat().st_size == 0:
        raise MeshError(f"{p}: the file is empty")
    raw = _read_mesh(p)
    return part_from_arrays(
        raw.vertices, raw.faces, path=str(p), sha256=sha256_file(p), units=units, source=str(p)
    )


def part_from_arrays(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    path: str = "<memory>",
    sha256: str = "",
    units: Units | str = "m",
    source: str | None = None,
) -> Part:
    """Build a cleaned :class:`Part` from ``vertices (n, 3)`` and ``faces (m, 3)`` in file units."""
    src = source or path
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0 or f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        raise MeshError(f"{src}: the mesh is empty (no triangles)")
    if f.min() < 0 or f.max() >= len(v):
        raise MeshError(f"{src}: faces reference vertices that do not exist; the file is corrupt")
    used = np.unique(f)
    if not np.all(np.isfinite(v[used])):
        bad = int((~np.isfinite(v[used])).any(axis=1).sum())
        raise MeshError(f"{src}: {bad} vertices have NaN or infinite coordinates; re-export the mesh from CAD")
    extent = float(np.ptp(v[used], axis=0).max())
    scale_to_m, unit, note = decide_units(extent, str(units))
    v_m = v * scale_to_m
    tol = Tolerance.for_mesh(v_m[used])

    mesh = trimesh.Trimesh(vertices=v_m, faces=f, process=False, validate=False)
    n_faces_in, n_verts_in = len(f), len(v)

    # 1. merge duplicate vertices (STL writes every vertex once per face)
    digits = int(max(0, np.floor(-np.log10(tol.merge))))
    mesh.merge_vertices(merge_tex=True, merge_norm=True, digits_vertex=digits)
    merged = n_verts_in - len(mesh.vertices)

    # 2. drop degenerate faces: repeated vertex index or (near) zero area
    fv = mesh.faces
    repeated = (fv[:, 0] == fv[:, 1]) | (fv[:, 1] == fv[:, 2]) | (fv[:, 0] == fv[:, 2])
    tiny = mesh.area_faces <= tol.area
    degenerate = repeated | tiny
    # 3. drop duplicate faces (same three vertices, either winding)
    keep = ~degenerate
    sorted_f = np.sort(fv, axis=1)
    _, first = np.unique(sorted_f, axis=0, return_index=True)
    unique_mask = np.zeros(len(fv), dtype=bool)
    unique_mask[first] = True
    duplicate = ~unique_mask & keep
    keep &= unique_mask
    if not keep.any():
        raise MeshError(f"{src}: the mesh has no area (all {n_faces_in} triangles are degenerate)")
    mesh.update_faces(keep)
    mesh.remove_unreferenced_vertices()
    if mesh.area <= tol.area:
        raise MeshError(f"{src}: the mesh has no area")

    # 4. consistent winding, outward normals (only meaningful on a closed mesh)
    warn: list[str] = []
    before = mesh.faces.copy()
    trimesh.repair.fix_winding(mesh)
    winding_fixed = not np.array_equal(before, mesh.faces)
    watertight = bool(mesh.is_watertight)
    inverted = False
    if watertight and mesh.volume < 0:
        mesh.invert()
        inverted = True
    bodies = int(mesh.body_count)
    if not watertight:
        warn.append(f"{src}: the mesh is not watertight; convexity and collision results near its holes are unreliable")
    if bodies > 1:
        warn.append(f"{src}: the mesh has {bodies} separate bodies; they are treated as one rigid part")
    if int(degenerate.sum()):
        warn.append(f"{src}: dropped {int(degenerate.sum())} degenerate (zero-area) triangles")
    if int(duplicate.sum()):
        warn.append(f"{src}: dropped {int(duplicate.sum())} duplicate triangles")

    report = MeshReport(
        faces_in_file=n_faces_in,
        vertices_in_file=n_verts_in,
        merged_vertices=merged,
        dropped_degenerate=int(degenerate.sum()),
        dropped_duplicate=int(duplicate.sum()),
        winding_fixed=winding_fixed,
        inverted_fixed=inverted,
        watertight=watertight,
        bodies=bodies,
    )
    return Part(
        path=path,
        sha256=sha256,
        scale_to_m=scale_to_m,
        units=unit,
        units_note=note,
        mesh=mesh,
        report=report,
        tol=tol,
        warnings=tuple(warn),
    )


def part_from_trimesh(mesh: trimesh.Trimesh, *, path: str = "<memory>", units: Units | str = "m") -> Part:
    """A :class:`Part` from an in-memory trimesh (file units given by ``units``)."""
    return part_from_arrays(mesh.vertices, mesh.faces, path=path, units=units)


def units_for_scale(scale_to_m: float) -> str:
    """The unit name whose metres-per-unit is ``scale_to_m`` (what :func:`load_part` recorded)."""
    for name, factor in LENGTH_UNITS.items():
        if np.isclose(factor, float(scale_to_m), rtol=1e-9, atol=0.0):
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
    if path is not None:
        candidates = [Path(path)]
    else:
        recorded = part_json.get("path")
        if not recorded:
            raise MeshError("the result records no part path; give the part with --part PATH")
        rp = Path(recorded)
        candidates = [rp] if rp.is_absolute() else [Path.cwd() / rp] + [Path(d) / rp for d in search_dirs]
    found = next((c for c in candidates if c.is_file()), None)
    if found is None:
        tried = ", ".join(str(c) for c in candidates)
        raise MeshError(f"part not found (tried {tried}); give the mesh the result was made from with --part PATH")
    return load_part(found, units=units_for_scale(part_json["scale_to_m"]))
