"""Point clouds of what a scene does not model (cables, foreign objects, the unknown), as obstacles.

:func:`read_cloud` reads PLY (ASCII, binary little/big endian), PCD (ASCII, binary) and NPY files
of world-frame points in metres into ``(N, 3)`` float64; points with a non-finite coordinate (the
holes of an organised camera cloud) are dropped and counted. :func:`cloud_octree` turns the points
into a coal ``OcTree`` of the given leaf size: an occupied leaf is a solid cube, so a gripper or
link counts as colliding with the cloud when it enters a cube of ``resolution`` around a point.

No mesh library is involved: the readers are a few lines of NumPy over the bytes
:func:`grasplan.config.inputs.read_input_bytes` returns (never blocking on a FIFO, capped in size).
"""
from __future__ import annotations

import io
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError
from ..config.inputs import read_input_bytes

if TYPE_CHECKING:  # coal loads with the first octree
    import coal

#: largest cloud file read (bytes) and most points kept
MAX_CLOUD_BYTES = 1 << 30
MAX_CLOUD_POINTS = 20_000_000
#: points must lie within this distance of the world origin (m): a cloud in millimetres fails here
MAX_CLOUD_COORD_M = 10.0
#: octree leaf size bounds (m) and default
MIN_RESOLUTION_M = 5e-4
MAX_RESOLUTION_M = 0.1
DEFAULT_RESOLUTION_M = 0.005
CLOUD_SUFFIXES = (".ply", ".pcd", ".npy")

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
_PCD_TYPES = {("F", 4): "f4", ("F", 8): "f8", ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8",
              ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8"}


@dataclass(frozen=True)
class Cloud:
    """World-frame points (N, 3) float64, metres, all finite; ``dropped``: non-finite points skipped."""

    points: np.ndarray
    source: str
    dropped: int = 0


def _bad(src: str, what: str) -> InputError:
    return InputError(f"cloud {src}: {what}")


def _header(data: bytes, src: str, end_marker: bytes, limit: int = 65536) -> tuple[list[str], int]:
    k = data.find(end_marker, 0, limit)
    if k < 0:
        raise _bad(src, f"no {end_marker.decode().strip()!r} line in the first {limit} bytes; not a valid file")
    stop = data.find(b"\n", k)
    stop = len(data) if stop < 0 else stop + 1
    try:
        text = data[:stop].decode("ascii")
    except UnicodeDecodeError:
        raise _bad(src, "the header is not ASCII text") from None
    return [ln.strip() for ln in text.splitlines() if ln.strip()], stop


def _count(v: str, src: str, what: str) -> int:
    if not re.fullmatch(r"\d{1,12}", v):
        raise _bad(src, f"{what} {v[:20]!r} is not a count")
    return int(v)


def _read_ply(data: bytes, src: str) -> np.ndarray:
    if not data.startswith(b"ply"):
        raise _bad(src, "does not start with 'ply'; not a PLY file")
    lines, start = _header(data, src, b"end_header")
    fmt = None
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    for ln in lines[1:]:
        w = ln.split()
        if w[0] == "format" and len(w) >= 2:
            fmt = w[1]
        elif w[0] == "element" and len(w) == 3:
            elements.append((w[1], _count(w[2], src, f"element {w[1]}"), []))
        elif w[0] == "property" and elements:
            if len(w) >= 2 and w[1] == "list":
                elements[-1][2].append((w[-1], "list"))
            elif len(w) == 3 and w[1] in _PLY_TYPES:
                elements[-1][2].append((w[2], _PLY_TYPES[w[1]]))
            else:
                raise _bad(src, f"unknown PLY property line {ln[:60]!r}")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise _bad(src, f"PLY format {fmt!r}; expected ascii, binary_little_endian or binary_big_endian")
    names = [e[0] for e in elements]
    if "vertex" not in names:
        raise _bad(src, "has no 'element vertex'; a cloud is the vertices of a PLY file")
    k = names.index("vertex")
    name, n, props = elements[k]
    pnames = [p[0] for p in props]
    if not {"x", "y", "z"} <= set(pnames):
        raise _bad(src, f"vertex properties {pnames[:8]} lack x, y and z")
    if any(t == "list" for _, t in props):
        raise _bad(src, "vertex element with a list property; save the cloud with scalar vertex properties")
    if fmt == "ascii":
        if k != 0:
            raise _bad(src, "ASCII PLY with elements before 'vertex'; put the vertices first")
        body = data[start:].split(b"\n", n)[:n] if n else []
        try:
            rows = np.array([ln.split()[: len(props)] for ln in body], dtype=np.float64)
        except ValueError:
            raise _bad(src, f"the {n} vertex lines are not {len(props)} numbers each") from None
        if rows.shape != (n, len(props)):
            raise _bad(src, f"expected {n} vertex lines of {len(props)} numbers")
        return rows[:, [pnames.index(c) for c in "xyz"]]
    order = "<" if fmt == "binary_little_endian" else ">"
    offset = start
    for _, cnt, pr in elements[:k]:
        if any(t == "list" for _, t in pr):
            raise _bad(src, "binary PLY with a list-property element before 'vertex'; put the vertices first")
        offset += cnt * int(np.dtype([(nm, order + t) for nm, t in pr]).itemsize)
    dt = np.dtype([(nm, order + t) for nm, t in props])
    if offset + n * dt.itemsize > len(data):
        raise _bad(src, f"the file ends before its {n} vertices ({len(data)} bytes); truncated")
    rec = np.frombuffer(data, dtype=dt, count=n, offset=offset)
    return np.stack([rec[c].astype(np.float64) for c in "xyz"], axis=1)


def _read_pcd(data: bytes, src: str) -> np.ndarray:
    lines, start = _header(data, src, b"DATA")
    h: dict[str, list[str]] = {}
    for ln in lines:
        if ln.startswith("#"):
            continue
        w = ln.split()
        h[w[0].upper()] = w[1:]
    for name in ("FIELDS", "SIZE", "TYPE", "POINTS", "DATA"):
        if name not in h:
            raise _bad(src, f"PCD header lacks {name}; not a PCD file")
    fields, sizes, types = h["FIELDS"], h["SIZE"], h["TYPE"]
    counts = h.get("COUNT", ["1"] * len(fields))
    if not (len(fields) == len(sizes) == len(types) == len(counts)):
        raise _bad(src, "PCD FIELDS, SIZE, TYPE and COUNT differ in length")
    if not {"x", "y", "z"} <= set(fields):
        raise _bad(src, f"PCD fields {fields[:8]} lack x, y and z")
    n = _count(h["POINTS"][0] if h["POINTS"] else "", src, "POINTS")
    mode = (h["DATA"] or [""])[0].lower()
    if mode == "ascii":
        ncol = sum(_count(c, src, "COUNT") for c in counts)
        body = data[start:].split(b"\n", n)[:n] if n else []
        try:
            rows = np.array([ln.split()[:ncol] for ln in body], dtype=np.float64)
        except ValueError:
            raise _bad(src, f"the {n} point lines are not {ncol} numbers each") from None
        if rows.shape != (n, ncol):
            raise _bad(src, f"expected {n} point lines of {ncol} numbers")
        col = np.cumsum([0] + [int(c) for c in counts])
        return rows[:, [int(col[fields.index(c)]) for c in "xyz"]]
    if mode == "binary":
        parts: list[tuple] = []
        for f, s, t, c in zip(fields, sizes, types, counts):
            key: tuple[str, int] = (t.upper(), _count(s, src, "SIZE"))
            if key not in _PCD_TYPES:
                raise _bad(src, f"PCD field {f} has TYPE {t} SIZE {s}; not a type PCD defines")
            cnt = _count(c, src, "COUNT")
            if f == "_" or f in [p[0] for p in parts]:  # padding or repeated names: anonymous
                f = f"_pad{len(parts)}"
            parts.append((f, "<" + _PCD_TYPES[key], (cnt,)) if cnt != 1 else (f, "<" + _PCD_TYPES[key]))
        dt = np.dtype(parts)
        if start + n * dt.itemsize > len(data):
            raise _bad(src, f"the file ends before its {n} points; truncated")
        rec = np.frombuffer(data, dtype=dt, count=n, offset=start)
        return np.stack([rec[c].astype(np.float64) for c in "xyz"], axis=1)
    raise _bad(src, f"PCD DATA {mode!r} is not read; save the cloud as DATA ascii or DATA binary "
                    "(binary_compressed is not supported)")


def _read_npy(data: bytes, src: str) -> np.ndarray:
    try:
        a = np.load(io.BytesIO(data), allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise _bad(src, f"not a NumPy .npy array ({str(exc)[:80]})") from None
    if a.ndim != 2 or a.shape[1] < 3 or a.dtype.kind not in "fiu":
        raise _bad(src, f"expected an (N, 3) array of numbers (x, y, z in metres), got {a.dtype} {a.shape}")
    return np.asarray(a[:, :3], dtype=np.float64)


def read_cloud(path: str | os.PathLike) -> Cloud:
    """World-frame points of a PLY, PCD or NPY file (metres); InputError naming the file and the
    problem for anything else (another suffix, a FIFO, a truncated file, no points, coordinates
    beyond :data:`MAX_CLOUD_COORD_M` (a cloud in millimetres), too many points)."""
    p = Path(path)
    src = str(p)
    suffix = p.suffix.lower()
    if suffix not in CLOUD_SUFFIXES:
        raise _bad(src, f"unknown suffix {p.suffix!r}; a cloud is a {', '.join(CLOUD_SUFFIXES)} file")
    data = read_input_bytes(p, what="cloud", max_bytes=MAX_CLOUD_BYTES)
    reader = {".ply": _read_ply, ".pcd": _read_pcd, ".npy": _read_npy}[suffix]
    pts = reader(data, src)
    if len(pts) > MAX_CLOUD_POINTS:
        raise _bad(src, f"{len(pts)} points; at most {MAX_CLOUD_POINTS} are read (downsample the cloud)")
    finite = np.isfinite(pts).all(axis=1)
    pts = np.ascontiguousarray(pts[finite])
    if not len(pts):
        raise _bad(src, "holds no point with finite coordinates")
    far = float(np.abs(pts).max())
    if far > MAX_CLOUD_COORD_M:
        raise _bad(src, f"a point lies {far:.4g} m from the world origin (limit {MAX_CLOUD_COORD_M} m); "
                        "clouds are world-frame metres: convert a cloud in millimetres (multiply by 0.001)")
    return Cloud(points=pts, source=src, dropped=int(np.count_nonzero(~finite)))


def check_resolution(resolution: float, where: str = "cloud.resolution") -> float:
    """``resolution`` (m) as a float within [MIN_RESOLUTION_M, MAX_RESOLUTION_M]; InputError otherwise."""
    try:
        r = float(resolution)
    except (TypeError, ValueError):
        raise InputError(f"{where}: expected a length in metres, got {str(resolution)[:40]!r}") from None
    if not (MIN_RESOLUTION_M <= r <= MAX_RESOLUTION_M):
        raise InputError(f"{where}: {r:g} m is outside [{MIN_RESOLUTION_M:g}, {MAX_RESOLUTION_M:g}] m "
                         f"(the octree's leaf size; e.g. {DEFAULT_RESOLUTION_M:g})")
    return r


def cloud_octree(points: np.ndarray, resolution: float) -> coal.OcTree:
    """A coal ``OcTree`` of ``points`` (N, 3) with leaf size ``resolution`` (m): each leaf holding a
    point is occupied (a solid cube of that size)."""
    import coal

    return coal.makeOctree(np.ascontiguousarray(points, dtype=np.float64), check_resolution(resolution))
