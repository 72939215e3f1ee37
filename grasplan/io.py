"""Output files: atomic writes and JSON encoding shared by every command.

No command ever leaves a half-written output: everything is written to a temporary file in the
destination folder and renamed into place.
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np


def sha256_file(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _default(o: Any):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"cannot write {type(o).__name__} to JSON")


def to_json_text(data: Any, *, indent: int | None = None) -> str:
    """JSON text; NumPy arrays become nested lists. NaN/inf are refused (invalid JSON)."""
    return json.dumps(data, default=_default, indent=indent, allow_nan=False)


def write_atomic_bytes(path: str | os.PathLike, payload: bytes) -> Path:
    """Write ``payload`` to ``path`` via a temporary file + rename; returns the path."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=parent)
    try:
        # mkstemp creates 0600; give the file the permissions a plain open() would (umask applied)
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)
        with os.fdopen(fd, "wb") as f:
            f.write(payload)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def write_atomic_text(path: str | os.PathLike, text: str) -> Path:
    return write_atomic_bytes(path, text.encode("utf-8"))


def write_json(path: str | os.PathLike, data: Any, *, indent: int | None = None) -> Path:
    """Serialise first (so an encoding error writes nothing), then write atomically."""
    return write_atomic_text(path, to_json_text(data, indent=indent))


def read_json(path: str | os.PathLike) -> Any:
    with open(path, "rb") as f:
        return json.load(f)
