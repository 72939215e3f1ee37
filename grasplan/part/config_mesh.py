"""The mesh files a gripper or cell YAML names (a jaw's shape, an obstacle), read by the part's
reader with the part's limits: :func:`read_config_mesh`."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..config.lookup import config_number
from ..errors import ConfigError, InputError
from .meshfile import ReadLimits, read_mesh


#: largest mesh file a gripper or cell YAML may name (bytes)
MAX_CONFIG_MESH_BYTES = 100_000_000


def read_config_mesh(spec: dict[str, Any], base: Path, where: str, owner: str, *,
                     max_triangles: int | None = None, limit_name: str = "grasplan.part.mesh.MAX_TRIANGLES"
                     ) -> tuple[np.ndarray, np.ndarray, Path]:
    """``(vertices (n, 3) m, faces (m, 3), path)`` of the mesh file a config YAML names in ``spec``
    (``path`` relative to ``base``, the YAML's folder; ``scale``, default 1, to metres). ``where``
    names the field in errors, ``owner`` the YAML ("gripper", "cell"). Read by the part's reader
    (:func:`grasplan.part.meshfile.read_mesh`: regular files only, the files an OBJ or glTF names read
    through the same guard, at most ``max_triangles`` triangles, refused from the header where the
    format declares a count; None: the part's limit, :data:`grasplan.part.mesh.MAX_TRIANGLES`). Any
    problem is a ConfigError naming the field and the file."""
    if not isinstance(spec.get("path"), str) or not spec["path"] or "\x00" in spec["path"]:
        raise ConfigError(f"{where}.path: expected a mesh file name relative to the {owner} YAML")
    path = Path(os.path.normpath(base / spec["path"]))
    scale = config_number(spec.get("scale", 1.0), f"{where}.scale", positive=True)
    from .mesh import MAX_TRIANGLES

    limits = ReadLimits(max_triangles=MAX_TRIANGLES if max_triangles is None else max_triangles,
                        max_bytes=MAX_CONFIG_MESH_BYTES, limit_name=limit_name)
    try:
        v, f, _ = read_mesh(path, limits)
    except InputError as exc:
        raise ConfigError(f"{where}.path: mesh file {exc} (paths are relative to the {owner} YAML)") from None
    import trimesh

    m = trimesh.Trimesh(v, f, process=True)  # merged vertices, degenerate faces dropped
    if len(m.faces) == 0:
        raise ConfigError(f"{where}.path: {path} holds no triangles")
    return np.asarray(m.vertices, dtype=np.float64) * scale, np.asarray(m.faces, dtype=np.int64), path
