"""Reading mesh files: binary and ASCII STL and OBJ in NumPy, PLY/OFF/glTF through trimesh (a
PLY's header checked against its body first), each problem (missing, not a regular file, too
large, truncated, damaged) one :class:`MeshError` naming the file (and the line, for text
formats), never library text; :func:`count_triangles` counts a file's triangles without loading
it (robot meshes). Lengths are file units; cleaning, units and limits' values belong to
:mod:`grasplan.part.mesh`, which passes its limits in (:class:`ReadLimits`).

Rules a valid file may rely on: an ASCII STL's ``solid``/``endsolid`` name is free text; a file of
exactly 84 + 50 n bytes whose header declares n triangles is binary, whatever its header says; OBJ
vertices are numbered from 1, negative numbers count back from the last vertex defined before the
face; a PLY's element counts are whole numbers that describe its body.
"""
from __future__ import annotations

import io
import logging
import os
import re
import stat
import warnings as _warnings
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO, cast

import numpy as np

from ..errors import MeshError
from ..io import NAME_MAX_BYTES, show_path

SUPPORTED_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".glb", ".gltf")


@dataclass(frozen=True)
class ReadLimits:
    """What a file may hold: at most ``max_triangles`` triangles and ``max_bytes`` bytes."""

    max_triangles: int
    max_bytes: int
    #: what the triangle limit is called in messages
    limit_name: str = "grasplan.part.mesh.MAX_TRIANGLES"


_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
_NUM = rb"[-+]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|nan|inf(?:inity)?)"
_ASCII_VERTEX = re.compile(rb"\bvertex[ \t]+(" + _NUM + rb")[ \t]+(" + _NUM + rb")[ \t]+(" + _NUM + rb")(?=\s)",
                           re.IGNORECASE)
_ASCII_VERTEX_WORD = re.compile(rb"\bvertex\b", re.IGNORECASE)
#: the name after ``solid`` / ``endsolid`` in an ASCII STL (matched in the lower-cased file): free
#: text (spaces, hyphens, digits, even the word "vertex") up to the end of its line, or to the first
#: ``facet normal`` on a one-line file
_ASCII_NAME = re.compile(rb"solid\b((?:(?!facet[ \t]+normal\b)[^\r\n])*)")
_UTF8_BOM = b"\xef\xbb\xbf"


def too_many_triangles(src: str, n: int, limit: int, what: str = "triangles",
                       name: str = "grasplan.part.mesh.MAX_TRIANGLES") -> MeshError:
    """The error for a mesh of ``n`` triangles (or faces) over the ``limit`` (called ``name``)."""
    return MeshError(f"{src}: {n:,} {what} is more than grasplan handles (limit {limit:,} triangles, "
                     f"{name}); decimate the mesh first (e.g. quadric decimation in "
                     f"MeshLab or Blender) to at most {limit:,} triangles")


def _read_stl(data: bytes, src: str, lim: ReadLimits) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices (3m, 3), faces (m, 3))`` in file units from the bytes of a binary or ASCII STL."""
    size = len(data)
    declared = int(np.frombuffer(data, "<u4", count=1, offset=80)[0]) if size >= 84 else -1
    if declared >= 0 and size == 84 + 50 * declared:  # a complete binary STL (the header may say "solid")
        if declared == 0:
            raise MeshError(f"{src}: the binary STL holds no triangles (its header declares 0)")
        if declared > lim.max_triangles:
            raise too_many_triangles(src, declared, lim.max_triangles, name=lim.limit_name)
        rec = np.frombuffer(data, _STL_RECORD, count=declared, offset=84)
        v = rec["v"].reshape(-1, 3).astype(np.float64)
        return v, np.arange(len(v), dtype=np.int64).reshape(-1, 3)
    if _is_ascii_stl(data):
        return _read_ascii_stl(data, src, lim)
    raise _not_an_stl(src, size, declared)


def _is_ascii_stl(head: bytes) -> bool:
    """Whether an STL that is not a complete binary one (size 84 + 50 n) is ASCII: it starts with
    ``solid`` (after an optional UTF-8 mark and blanks) and holds no NUL in its first 4 KiB."""
    return head.removeprefix(_UTF8_BOM).lstrip()[:5].lower() == b"solid" and b"\0" not in head[:4096]


def _not_an_stl(src: str, size: int, declared: int) -> MeshError:
    """The error for an STL that is neither a complete binary STL nor an ASCII one."""
    if declared < 0:
        return MeshError(f"{src}: {size} bytes is too short for an STL file (a binary STL has an 84-byte "
                         f"header, an ASCII STL starts with 'solid'); the file is truncated or not an STL")
    need = 84 + 50 * declared
    what = "truncated" if size < need else "followed by extra data"
    return MeshError(f"{src}: not a valid STL: as binary STL its header declares {declared:,} triangles "
                     f"({need:,} bytes) but the file has {size:,} bytes ({what}), and it is not an ASCII STL "
                     f"(no 'solid' at the start); re-export the mesh from CAD")


def _blank_solid_names(data: bytes) -> bytes:
    """``data`` with the names of its ``solid NAME`` / ``endsolid NAME`` replaced by spaces (same
    length: line numbers keep their meaning), so that no name is read as a vertex."""
    low = data.lower()
    out: bytearray | None = None
    for m in _ASCII_NAME.finditer(low):
        head = m.start() - 3 if low[max(m.start() - 3, 0):m.start()] == b"end" else m.start()
        if (head > 0 and (low[head - 1:head].isalnum() or low[head - 1:head] == b"_")) or m.end(1) == m.start(1):
            continue  # inside a word, or no name
        if out is None:
            out = bytearray(data)
        out[m.start(1):m.end(1)] = b" " * (m.end(1) - m.start(1))
    return data if out is None else bytes(out)


def _read_ascii_stl(data: bytes, src: str, lim: ReadLimits) -> tuple[np.ndarray, np.ndarray]:
    data = _blank_solid_names(data.removeprefix(_UTF8_BOM))
    n_words = len(_ASCII_VERTEX_WORD.findall(data))
    if n_words > 3 * lim.max_triangles:
        raise too_many_triangles(src, n_words // 3, lim.max_triangles, name=lim.limit_name)
    rows = _ASCII_VERTEX.findall(data)
    if len(rows) != n_words:
        good = {m.start() for m in _ASCII_VERTEX.finditer(data)}
        bad = next(m for m in _ASCII_VERTEX_WORD.finditer(data) if m.start() not in good)
        line_no = data.count(b"\n", 0, bad.start()) + 1
        line = data[bad.start(): bad.start() + 80].split(b"\n")[0].decode("ascii", "replace")
        raise MeshError(f"{src}: ASCII STL line {line_no}: cannot read {line.strip()!r} as 'vertex x y z' "
                        f"(three numbers); the file is damaged, re-export it")
    if not rows:
        raise MeshError(f"{src}: the ASCII STL holds no triangles")
    if len(rows) % 3:
        raise MeshError(f"{src}: the ASCII STL has {len(rows)} vertices, not a multiple of 3 (every facet "
                        f"needs exactly 3); the file is damaged, re-export it")
    with np.errstate(all="ignore"):
        v = np.array(rows, dtype=np.bytes_).astype(np.float64)  # overflow (1e999) reads as inf
    return v, np.arange(len(v), dtype=np.int64).reshape(-1, 3)


#: OBJ statements grasplan reads: vertices ``v x y z [w | r g b]`` and faces ``f i j k ...``
#: (``i``, ``i/t``, ``i//n``, ``i/t/n``); everything else (normals, texture coordinates, groups,
#: materials, lines) is geometry-free for a part and skipped
_OBJ_KIND = re.compile(rb"^[ \t]*([vf])(?=[ \t\r\n]|$)", re.MULTILINE)
_OBJ_V = re.compile(rb"^[ \t]*v[ \t]+(" + _NUM + rb")[ \t]+(" + _NUM + rb")[ \t]+(" + _NUM + rb")(?=[ \t\r\n]|$)",
                    re.MULTILINE | re.IGNORECASE)
_OBJ_V_ANY = re.compile(rb"^[ \t]*v(?=[ \t\r\n]|$)[^\r\n]*", re.MULTILINE)
_OBJ_V_BODY = re.compile(rb"^[ \t]*v(?=[ \t\r\n]|$)([^\r\n]*)", re.MULTILINE)
_OBJ_F = re.compile(rb"^[ \t]*f(?=[ \t\r\n]|$)([^\r\n]*)", re.MULTILINE)
_OBJ_COMMENT = re.compile(rb"#[^\r\n]*")
_OBJ_CONTINUED = re.compile(rb"\\[ \t]*\r?\n")
_OBJ_REFS = re.compile(rb"/[^ \t\n]*")  # the texture / normal references of a face vertex
_OBJ_INDEX_CHARS = np.zeros(256, dtype=bool)  # the bytes a face's index list may hold
_OBJ_INDEX_CHARS[np.frombuffer(b"+-0123456789 \t\n", dtype=np.uint8)] = True
_OBJ_BAD_INDEX = re.compile(rb"(?:(?<=[ \t\n])|\A)(?![-+]?\d{1,18}(?=[ \t\n]|\Z))[^ \t\n]+")


def _obj_line(data: bytes, pattern: re.Pattern[bytes], k: int) -> tuple[int, str]:
    """Line number and text (shortened) of the ``k``-th match of ``pattern`` in ``data`` (for an
    error message: the loop stops at the line)."""
    m = next(m for i, m in enumerate(pattern.finditer(data)) if i == k)
    text = m.group(0).strip().decode("utf-8", "replace")
    return data.count(b"\n", 0, m.start()) + 1, text if len(text) <= 60 else text[:57] + "..."


def _read_obj(data: bytes, src: str, lim: ReadLimits) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices, faces)`` of an OBJ file, vectorised: polygons as triangle fans; vertex indices
    1-based, negative ones counting back from the last vertex defined before the face (the OBJ
    rule); index 0, an index past the vertices and a malformed vertex or face line are refused,
    naming the line. Line numbers count lines as joined by backslash continuations."""
    data = _OBJ_CONTINUED.sub(b" ", _OBJ_COMMENT.sub(b"", data))
    v = _obj_vertices(data, src)
    bodies = _OBJ_F.findall(data)
    if not bodies:
        raise MeshError(f"{src}: the OBJ file holds no faces ('f' lines), so no triangles")
    joined = _OBJ_REFS.sub(b"", b"\n".join(bodies))
    chars = np.frombuffer(joined, dtype=np.uint8)
    blank = (chars == 32) | (chars == 9) | (chars == 10)
    starts = np.flatnonzero(~blank & np.r_[True, blank[:-1]])
    face_of = np.searchsorted(np.flatnonzero(chars == 10), starts)  # the face line of each index
    per_face = np.bincount(face_of, minlength=len(bodies))
    if int(per_face.min()) < 3:
        line, text = _obj_line(data, _OBJ_F, int(np.argmin(per_face)))
        raise MeshError(f"{src}: OBJ line {line}: {text!r}: a face needs at least 3 vertices; the file is damaged, "
                        f"re-export it")
    n_tri = int((per_face - 2).sum())
    if n_tri > lim.max_triangles:
        raise too_many_triangles(src, n_tri, lim.max_triangles, name=lim.limit_name)
    ends = np.flatnonzero(~blank & np.r_[blank[1:], True])
    signs = np.flatnonzero((chars == 43) | (chars == 45))
    token_start = np.zeros(len(chars), dtype=bool)
    token_start[starts] = True
    after = chars[np.minimum(signs + 1, len(chars) - 1)]
    idx = None  # whole numbers of at most 18 digits, a sign only in front of a digit
    if not (np.any(ends - starts >= 19) or not _OBJ_INDEX_CHARS[chars].all() or
            not token_start[signs].all() or np.any((after < 48) | (after > 57)) or np.any(signs + 1 >= len(chars))):
        try:
            idx = np.fromstring(joined, dtype=np.int64, sep=" ")
        except ValueError:  # a token it cannot read: named below
            pass
    if idx is None or len(idx) != len(starts):
        bad = _OBJ_BAD_INDEX.search(joined)
        k = joined.count(b"\n", 0, bad.start()) if bad is not None else 0
        token = bad.group(0)[:20].decode("utf-8", "replace") if bad is not None else "?"
        line, text = _obj_line(data, _OBJ_F, k)
        raise MeshError(f"{src}: OBJ line {line}: {text!r}: {token!r} is not a vertex number (a face lists whole "
                        f"numbers, optionally as v/t/n); the file is damaged, re-export it")
    n_v = len(v)
    defined = np.full(len(idx), n_v, dtype=np.int64)
    if np.any(idx < 0):  # relative numbers: the vertices defined before each number's face
        is_v = np.frombuffer(b"".join(_OBJ_KIND.findall(data)), dtype=np.uint8) == ord("v")
        defined = np.cumsum(is_v)[~is_v][face_of]
    wrong = (idx == 0) | (idx > n_v) | (-idx > defined)
    if wrong.any():
        k = int(np.argmax(wrong))
        line, text = _obj_line(data, _OBJ_F, int(face_of[k]))
        i = int(idx[k])
        why = ("vertex 0 does not exist: OBJ numbers vertices from 1 (negative numbers count back from the "
               "last vertex defined)") if i == 0 else (
            f"vertex {i} does not exist: the file defines {n_v} (1..{n_v})" if i > 0 else
            f"vertex {i} counts back past the {int(defined[k])} vertices defined before this line")
        raise MeshError(f"{src}: OBJ line {line}: {text!r}: {why}; the file is damaged, re-export it")
    zero_based = np.where(idx > 0, idx - 1, defined + idx)
    first = np.cumsum(per_face) - per_face  # each face's first index
    face = np.repeat(np.arange(len(per_face)), per_face - 2)
    j = np.arange(n_tri) - np.repeat(np.cumsum(per_face - 2) - (per_face - 2), per_face - 2) + 1
    f = np.stack([zero_based[first[face]], zero_based[first[face] + j], zero_based[first[face] + j + 1]], axis=1)
    return v, f


def _obj_vertices(data: bytes, src: str) -> np.ndarray:
    """The (n, 3) coordinates of an OBJ's ``v`` lines (a 4th coordinate or a colour ignored);
    MeshError naming the first line that does not start with three numbers."""
    bodies = _OBJ_V_BODY.findall(data)
    joined = b"\n".join(bodies)
    chars = np.frombuffer(joined, dtype=np.uint8)
    blank = (chars == 32) | (chars == 9) | (chars == 10) | (chars == 13)
    starts = np.flatnonzero(~blank & np.r_[True, blank[:-1]])
    per_line = np.bincount(np.searchsorted(np.flatnonzero(chars == 10), starts), minlength=len(bodies))
    if len(bodies) and np.all(per_line == 3):  # the common case: parsed in one call
        try:
            with _warnings.catch_warnings(), np.errstate(all="ignore"):
                _warnings.simplefilter("ignore")
                v = np.fromstring(joined, dtype=np.float64, sep=" ")
            if len(v) == 3 * len(bodies):
                return v.reshape(-1, 3)
        except ValueError:  # a token that is no number: the line is found below
            pass
    rows = _OBJ_V.findall(data)
    if len(rows) != len(bodies):
        good = {m.start() for m in _OBJ_V.finditer(data)}
        k = next(i for i, m in enumerate(_OBJ_V_ANY.finditer(data)) if m.start() not in good)
        line, text = _obj_line(data, _OBJ_V_ANY, k)
        raise MeshError(f"{src}: OBJ line {line}: cannot read {text!r} as 'v x y z' (three numbers); "
                        f"the file is damaged, re-export it")
    with np.errstate(all="ignore"):
        return np.array(rows, dtype=np.bytes_).astype(np.float64) if rows else np.zeros((0, 3))


#: PLY property types and their sizes in bytes
_PLY_TYPES = {b"char": 1, b"int8": 1, b"uchar": 1, b"uint8": 1, b"short": 2, b"int16": 2, b"ushort": 2,
              b"uint16": 2, b"int": 4, b"int32": 4, b"uint": 4, b"uint32": 4, b"float": 4, b"float32": 4,
              b"double": 8, b"float64": 8}
#: a PLY header longer than this (bytes) is refused
_PLY_MAX_HEADER = 65536
_BLANK_LINE = re.compile(rb"^[ \t\r]*$", re.MULTILINE)


def _check_ply_header(data: bytes, src: str, lim: ReadLimits) -> None:
    """Refuse a PLY whose header does not describe its body, naming the header line: element
    counts that are not whole numbers >= 0 or above the limits; an ASCII body whose number of lines
    is not the sum of the counts; a binary body whose size is not what the elements take (every
    list as long as in the element's first row, as the loader reads it)."""
    end = data.find(b"end_header", 0, _PLY_MAX_HEADER)
    if not data.startswith(b"ply") or end < 0:
        raise MeshError(f"{src}: not a PLY file: it must start with 'ply' and end its header with 'end_header' "
                        f"within {_PLY_MAX_HEADER:,} bytes; re-export it")
    nl = data.find(b"\n", end)
    body = memoryview(data)[nl + 1:] if nl >= 0 else memoryview(b"")
    fmt = b""
    elements: list[tuple[int, str, bytes, int, list[tuple[bytes, ...]]]] = []  # line, text, name, count, props
    for no, raw in enumerate(data[:end].split(b"\n"), start=1):
        tok = raw.split()
        shown = raw.strip().decode("utf-8", "replace")[:60]
        if not tok:
            continue
        if tok[0] == b"format" and len(tok) >= 2:
            fmt = tok[1]
        elif tok[0] == b"element":
            if len(tok) != 3 or not re.fullmatch(rb"\d{1,18}", tok[2]):
                raise MeshError(f"{src}: PLY header line {no} {shown!r}: an element needs a name and a count, a "
                                f"whole number >= 0; the file is damaged, re-export it")
            elements.append((no, shown, tok[1], int(tok[2]), []))
        elif tok[0] == b"property" and elements:
            types = tok[2:4] if len(tok) > 1 and tok[1] == b"list" else tok[1:2]
            if len(tok) != (5 if tok[1:2] == [b"list"] else 3) or any(t not in _PLY_TYPES for t in types):
                raise MeshError(f"{src}: PLY header line {no} {shown!r}: not a property grasplan knows "
                                f"(types: {', '.join(sorted({t.decode() for t in _PLY_TYPES}))})")
            elements[-1][4].append(tuple(types))
    for no, shown, name, count, _ in elements:
        limit = lim.max_triangles if name == b"face" else 3 * lim.max_triangles if name == b"vertex" else None
        if limit is not None and count > limit:
            what = "faces" if name == b"face" else "vertices"
            raise MeshError(f"{src}: PLY header line {no} {shown!r}: {count:,} {what} is more than grasplan "
                            f"handles ({limit:,}, {lim.limit_name}{' x 3' if name == b'vertex' else ''}); decimate "
                            f"the mesh first")
    if not elements:
        return
    if fmt == b"ascii":
        lines = data.count(b"\n", nl + 1) + 1 - len(_BLANK_LINE.findall(body))
        total = sum(e[3] for e in elements)
        if lines != total:
            acc, at = 0, elements[-1]
            for e in elements:
                acc += e[3]
                if acc > lines:
                    at = e
                    break
            raise MeshError(f"{src}: PLY header line {at[0]} {at[1]!r}: the header declares {total:,} element lines "
                            f"in all, the file holds {lines:,} after the header; the counts are wrong or the file "
                            f"is truncated, re-export it")
    elif fmt in (b"binary_little_endian", b"binary_big_endian"):
        order = "<" if fmt == b"binary_little_endian" else ">"
        offset = 0
        for no, shown, name, count, props in elements:
            row = 0
            for prop in props:
                if len(prop) == 1:
                    row += _PLY_TYPES[prop[0]]
                    continue
                size = _PLY_TYPES[prop[0]]  # a list: its length, then the items
                if count and offset + row + size <= len(body):
                    kind = ("u" if prop[0].startswith(b"u") else "i") + str(size)
                    n = int(np.frombuffer(body, order + kind, count=1, offset=offset + row)[0])
                else:
                    n = 3 if name == b"face" else 0
                if n < 0:
                    raise MeshError(f"{src}: PLY header line {no} {shown!r}: its first row holds a list of {n} items; "
                                    f"the file is damaged, re-export it")
                row += size + n * _PLY_TYPES[prop[1]]
            offset += count * row
            if offset > len(body):
                raise MeshError(f"{src}: PLY header line {no} {shown!r}: {count:,} {name.decode('utf-8', 'replace')} "
                                f"elements take {count * row:,} bytes (every list as long as in the first row), past "
                                f"the {len(body):,} bytes after the header; the count is wrong, the file truncated or "
                                f"its faces of mixed sizes; re-export it with triangles")
        if offset != len(body):
            no, shown = next(((e[0], e[1]) for e in elements if e[2] == b"face"), elements[-1][:2])
            raise MeshError(f"{src}: PLY header line {no} {shown!r}: the elements the header declares take "
                            f"{offset:,} bytes, the file holds {len(body):,} after the header (a wrong count, extra "
                            f"data, or faces of mixed sizes); re-export it with triangles")


def _declared_faces(data: bytes, suffix: str) -> int:
    """A cheap lower bound on the triangle count of an OBJ/PLY/OFF file (``-1`` if unknown)."""
    if suffix == ".obj":
        return data.count(b"\nf ") + data.startswith(b"f ")
    if suffix == ".ply":
        m = re.search(rb"element\s+face\s+(\d{1,18})", data[:65536])
        return int(m.group(1)) if m else -1
    if suffix == ".off":
        m = re.match(rb"\s*C?N?OFF\s+(\d{1,18})\s+(\d{1,18})", data[:4096])
        return int(m.group(2)) if m else -1
    return -1


class _GuardedFiles:
    """The files a mesh loader opens on its own (an OBJ's ``mtllib`` and textures, a glTF's buffers
    and images), read through :func:`grasplan.config.inputs.read_input_bytes`: regular files only (a FIFO,
    a device or a folder is refused before reading, so nothing blocks), at most ``max_bytes`` in all.
    The first refusal is kept in ``error`` (the caller reports it); the loader sees an ``OSError``,
    which an OBJ reader takes as "no material"."""

    def __init__(self, folder: Path, max_bytes: int):
        self.folder = folder
        self.left = max_bytes
        self.error: str | None = None

    def get(self, name: str) -> bytes:
        from ..errors import InputError
        from ..config.inputs import read_input_bytes

        text = str(name)
        try:
            if "\x00" in text or len(text) > 4096 or "://" in text:
                raise InputError(f"{show_path(text, limit=60)}: not a file name next to the mesh")
            data = read_input_bytes(self.folder / text, what="a file the mesh names",
                                    max_bytes=max(0, self.left))
        except InputError as exc:
            self.error = self.error or str(exc)
            raise FileNotFoundError(str(exc)) from None
        self.left -= len(data)
        return data

    __getitem__ = get

    def namespaced(self, namespace: str) -> _GuardedFiles:
        return type(self)(self.folder / namespace, self.left)

    def keys(self) -> list[str]:
        return []

    def write(self, name: str, data: bytes) -> None:
        raise OSError("read-only")


if TYPE_CHECKING:  # what _resolver builds (trimesh loads with the first mesh that needs it)
    import trimesh.resolvers

    class _GuardedResolver(_GuardedFiles, trimesh.resolvers.Resolver): ...


def _resolver(folder: Path, max_bytes: int) -> _GuardedResolver:
    """A trimesh resolver (a subclass of its ``Resolver``) over :class:`_GuardedFiles`."""
    import trimesh.resolvers

    class GuardedResolver(_GuardedFiles, trimesh.resolvers.Resolver):
        pass

    return cast("_GuardedResolver", GuardedResolver(folder, max_bytes))  # the same bases, declared above


def _read_other(path: Path, data: bytes, src: str, lim: ReadLimits) -> tuple[np.ndarray, np.ndarray]:
    """OBJ/PLY/OFF/glTF through trimesh; any failure becomes one MeshError without library text."""
    suffix = path.suffix.lower()
    if suffix == ".ply":
        _check_ply_header(data, src, lim)
    declared = _declared_faces(data, suffix)
    if declared > lim.max_triangles:
        raise too_many_triangles(src, declared, lim.max_triangles, "faces", name=lim.limit_name)
    kind = suffix.lstrip(".").upper()
    import trimesh

    log = logging.getLogger("trimesh")
    was_disabled, log.disabled = log.disabled, True
    files = _resolver(path.parent, lim.max_bytes)
    try:
        with _warnings.catch_warnings(), np.errstate(all="ignore"):
            _warnings.simplefilter("ignore")
            loaded = trimesh.load(io.BytesIO(data), file_type=suffix.lstrip("."), force="mesh", process=False,
                                  resolver=files)
        if isinstance(loaded, trimesh.Scene):  # force='mesh' on an empty scene
            raise MeshError(f"{src}: the {kind} file holds no triangles")
        if not isinstance(loaded, trimesh.Trimesh):
            raise MeshError(f"{src}: the {kind} file holds no triangle mesh")
        v = np.asarray(loaded.vertices, dtype=np.float64)
        f = np.asarray(loaded.faces, dtype=np.int64)
    except MeshError:
        raise
    except Exception:  # trimesh raises many types for damaged files; their text is internal
        if files.error is not None:  # a glTF buffer that is a FIFO, missing, too large
            raise MeshError(f"{src}: {files.error}") from None
        raise MeshError(f"{src}: cannot read the file as {kind}: it is damaged, truncated or not a valid {kind} file; "
                        f"re-export it (binary STL is the most reliable)") from None
    finally:
        log.disabled = was_disabled
    if f.ndim != 2 or len(f) == 0:
        raise MeshError(f"{src}: the {kind} file holds no triangles")
    return v, f


def _checked_stat(p: Path, src: str, lim: ReadLimits, suffixes: tuple[str, ...] = SUPPORTED_SUFFIXES) -> int:
    """The size of the regular, non-empty file ``p`` of at most ``lim.max_bytes`` bytes whose
    suffix is one of ``suffixes``; every OS-level problem becomes a MeshError."""
    if "\x00" in str(p):
        raise MeshError(f"{src}: a path cannot contain a NUL character")
    too_long = [c for c in p.parts if len(os.fsencode(c)) > NAME_MAX_BYTES]
    if too_long:
        raise MeshError(f"{src}: the name {show_path(too_long[0], limit=60)} is {len(os.fsencode(too_long[0]))} "
                        f"bytes long; file systems allow at most {NAME_MAX_BYTES}: rename the file")
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise MeshError(f"{src}: no such file") from None
    except PermissionError:
        raise MeshError(f"{src}: permission denied (cannot look into its folder)") from None
    except OSError as exc:
        raise MeshError(f"{src}: cannot open the file ({exc.strerror or 'operating-system error'})") from None
    if stat.S_ISDIR(st.st_mode):
        raise MeshError(f"{src}: is a folder, not a mesh file; give the STL/OBJ/PLY file inside it")
    if not stat.S_ISREG(st.st_mode):
        kind = ("a named pipe (FIFO)" if stat.S_ISFIFO(st.st_mode) else "a socket" if stat.S_ISSOCK(st.st_mode)
                else "a device" if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else "not a regular file")
        raise MeshError(f"{src}: is {kind}, not a mesh file; save the mesh to a regular file first")
    if p.suffix.lower() not in suffixes:
        raise MeshError(f"{src}: unsupported file type {show_path(p.suffix or '(none)', limit=20)!r}; "
                        f"use one of {', '.join(suffixes)}")
    if st.st_size == 0:
        raise MeshError(f"{src}: the file is empty")
    if st.st_size > lim.max_bytes:
        raise MeshError(f"{src}: {st.st_size:,} bytes is larger than grasplan reads ({lim.max_bytes:,} bytes, "
                        f"grasplan.part.mesh.MAX_FILE_BYTES); decimate the mesh to at most {lim.max_triangles:,} triangles")
    return int(st.st_size)


def _open_checked(p: Path, src: str, lim: ReadLimits) -> bytes:
    """The bytes of the regular file ``p`` (:func:`_checked_stat`); every OS-level problem becomes a MeshError."""
    _checked_stat(p, src, lim)
    try:
        with open(p, "rb") as fh:
            return fh.read(lim.max_bytes + 1)
    except PermissionError:
        raise MeshError(f"{src}: permission denied; make the file readable (chmod +r)") from None
    except OSError as exc:
        raise MeshError(f"{src}: cannot read the file ({exc.strerror or 'operating-system error'})") from None


def read_mesh(path: Path, lim: ReadLimits) -> tuple[np.ndarray, np.ndarray, bytes]:
    """``(vertices, faces, raw bytes)`` of a mesh file, in file units, within the limits ``lim``
    (checked before the triangles are read where the format declares a count)."""
    src = show_path(path)
    data = _open_checked(path, src, lim)
    if path.suffix.lower() == ".stl":
        v, f = _read_stl(data, src, lim)
    elif path.suffix.lower() == ".obj":
        v, f = _read_obj(data, src, lim)
    else:
        v, f = _read_other(path, data, src, lim)
    if len(f) > lim.max_triangles:
        raise too_many_triangles(src, len(f), lim.max_triangles, name=lim.limit_name)
    return v, f, data


#: mesh files whose triangles :func:`count_triangles` counts without loading them: the part formats
#: with a count in their header or a line per face, and Collada (robot descriptions' visual meshes)
COUNTED_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".dae")
#: Collada primitives and their ``count`` attribute (triangles, or polygons: at least one triangle each)
_DAE_COUNT = re.compile(rb"<(?:triangles|polylist|polygons|tristrips|trifans)\b[^>]*?\bcount\s*=\s*[\"'](\d{1,18})[\"']")
_CHUNK = 1 << 20


def _stream_count(fh: BinaryIO, needles: tuple[bytes, ...], pattern: re.Pattern[bytes] | None = None, *, lower: bool = False) -> int:
    """Occurrences of ``needles`` (or the sum of ``pattern``'s first group) in the rest of ``fh``,
    read in chunks of 1 MiB (memory bounded whatever the file's size); ``lower``: case-insensitive."""
    overlap = 4096 if pattern is not None else max(map(len, needles)) - 1
    total, carry = 0, b""
    while True:
        chunk = fh.read(_CHUNK)
        buf = carry + (chunk.lower() if lower else chunk)
        stop = len(buf) if not chunk else max(len(buf) - overlap, 0)  # matches starting before stop count now
        if pattern is not None:
            total += sum(int(m.group(1)) for m in pattern.finditer(buf, 0, len(buf)) if m.start() < stop)
        else:
            total += sum(buf.count(n, 0, stop + len(n) - 1) for n in needles)
        if not chunk:
            return total
        carry = buf[stop:]


def count_triangles(path: Path, lim: ReadLimits, *, suffixes: tuple[str, ...] = COUNTED_SUFFIXES) -> int:
    """The triangle count of a mesh file without loading its triangles: from the header (binary
    STL, OFF; PLY, whose header is also checked against its body: a loader trusting a wrong count
    may crash) or one streaming pass (ASCII STL facets, OBJ face lines, Collada primitive counts;
    a polygon counts as one triangle: a lower bound). MeshError naming the file for one that is not
    a regular file, has another suffix, is larger than ``lim.max_bytes``, is no STL at all, or
    holds more than ``lim.max_triangles`` triangles."""
    src = show_path(path)
    size = _checked_stat(path, src, lim, suffixes)
    suffix = path.suffix.lower()
    try:
        with open(path, "rb") as fh:
            head = fh.read(65536)
            fh.seek(0)
            if suffix == ".stl":
                declared = int(np.frombuffer(head, "<u4", count=1, offset=80)[0]) if len(head) >= 84 else -1
                if size != 84 + 50 * declared and not _is_ascii_stl(head):
                    raise _not_an_stl(src, size, declared)
                n = declared if size == 84 + 50 * declared else _stream_count(fh, (b"endfacet",), lower=True)
            elif suffix == ".obj":
                n = _stream_count(fh, (b"\nf ", b"\nf\t")) + head.startswith((b"f ", b"f\t"))
            elif suffix == ".dae":
                n = _stream_count(fh, (), _DAE_COUNT)
            elif suffix == ".ply":  # its header must describe its body (a loader trusting it may crash)
                data = fh.read(lim.max_bytes + 1)
                _check_ply_header(data, src, lim)
                n = _declared_faces(data, suffix)
            else:
                n = _declared_faces(head, suffix)
                if n < 0:
                    raise MeshError(f"{src}: the {suffix[1:].upper()} header declares no face count; the file is "
                                    f"damaged, re-export it")
    except PermissionError:
        raise MeshError(f"{src}: permission denied; make the file readable (chmod +r)") from None
    except OSError as exc:
        raise MeshError(f"{src}: cannot read the file ({exc.strerror or 'operating-system error'})") from None
    if n > lim.max_triangles:
        raise too_many_triangles(src, n, lim.max_triangles, name=lim.limit_name)
    return n
