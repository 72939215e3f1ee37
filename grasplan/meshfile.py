"""Reading mesh files: binary and ASCII STL in NumPy, OBJ/PLY/OFF/glTF through trimesh, each
problem (missing, not a regular file, too large, truncated, damaged) one :class:`MeshError` naming
the file, never library text. Lengths are file units; cleaning, units and limits' values belong to
:mod:`grasplan.mesh`, which passes its limits in (:class:`ReadLimits`).
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

import numpy as np

from .errors import MeshError
from .io import NAME_MAX_BYTES, show_path

SUPPORTED_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".glb", ".gltf")


@dataclass(frozen=True)
class ReadLimits:
    """What a file may hold: at most ``max_triangles`` triangles and ``max_bytes`` bytes."""

    max_triangles: int
    max_bytes: int
    #: what the triangle limit is called in messages
    limit_name: str = "grasplan.mesh.MAX_TRIANGLES"


_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
_NUM = rb"[-+]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|nan|inf(?:inity)?)"
_ASCII_VERTEX = re.compile(rb"\bvertex[ \t]+(" + _NUM + rb")[ \t]+(" + _NUM + rb")[ \t]+(" + _NUM + rb")(?=\s)",
                           re.IGNORECASE)
_ASCII_VERTEX_WORD = re.compile(rb"\bvertex\b", re.IGNORECASE)


def too_many_triangles(src: str, n: int, limit: int, what: str = "triangles",
                       name: str = "grasplan.mesh.MAX_TRIANGLES") -> MeshError:
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
    if data.lstrip()[:5].lower() == b"solid" and b"\0" not in data[:4096]:
        return _read_ascii_stl(data, src, lim)
    if declared < 0:
        raise MeshError(f"{src}: {size} bytes is too short for an STL file (a binary STL has an 84-byte "
                        f"header, an ASCII STL starts with 'solid'); the file is truncated or not an STL")
    need = 84 + 50 * declared
    what = "truncated" if size < need else "followed by extra data"
    raise MeshError(f"{src}: not a valid STL: as binary STL its header declares {declared:,} triangles "
                    f"({need:,} bytes) but the file has {size:,} bytes ({what}), and it is not an ASCII STL "
                    f"(no 'solid' at the start); re-export the mesh from CAD")


def _read_ascii_stl(data: bytes, src: str, lim: ReadLimits) -> tuple[np.ndarray, np.ndarray]:
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
    and images), read through :func:`grasplan.inputs.read_input_bytes`: regular files only (a FIFO,
    a device or a folder is refused before reading, so nothing blocks), at most ``max_bytes`` in all.
    The first refusal is kept in ``error`` (the caller reports it); the loader sees an ``OSError``,
    which an OBJ reader takes as "no material"."""

    def __init__(self, folder: Path, max_bytes: int):
        self.folder = folder
        self.left = max_bytes
        self.error: str | None = None

    def get(self, name: str) -> bytes:
        from .errors import InputError
        from .inputs import read_input_bytes

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


def _resolver(folder: Path, max_bytes: int):
    """A trimesh resolver (a subclass of its ``Resolver``) over :class:`_GuardedFiles`."""
    import trimesh.resolvers

    class GuardedResolver(_GuardedFiles, trimesh.resolvers.Resolver):
        pass

    return GuardedResolver(folder, max_bytes)


def _read_other(path: Path, data: bytes, src: str, lim: ReadLimits) -> tuple[np.ndarray, np.ndarray]:
    """OBJ/PLY/OFF/glTF through trimesh; any failure becomes one MeshError without library text."""
    suffix = path.suffix.lower()
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


def _open_checked(p: Path, src: str, lim: ReadLimits) -> bytes:
    """The bytes of the regular file ``p``; every OS-level problem becomes a MeshError."""
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
    if p.suffix.lower() not in SUPPORTED_SUFFIXES:
        raise MeshError(f"{src}: unsupported file type {show_path(p.suffix or '(none)', limit=20)!r}; "
                        f"use one of {', '.join(SUPPORTED_SUFFIXES)}")
    if st.st_size == 0:
        raise MeshError(f"{src}: the file is empty")
    if st.st_size > lim.max_bytes:
        raise MeshError(f"{src}: {st.st_size:,} bytes is larger than grasplan reads ({lim.max_bytes:,} bytes, "
                        f"grasplan.mesh.MAX_FILE_BYTES); decimate the mesh to at most {lim.max_triangles:,} triangles")
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
    else:
        v, f = _read_other(path, data, src, lim)
    if len(f) > lim.max_triangles:
        raise too_many_triangles(src, len(f), lim.max_triangles, name=lim.limit_name)
    return v, f, data
