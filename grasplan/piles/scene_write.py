"""Writing ``grasplan.scene/1`` files (:mod:`grasplan.piles.scene_file` reads them).

:func:`write_scene` writes YAML (``.yaml``, ``.yml``) or JSON (``.json``) by the suffix, atomically.
Paths the scene names (part meshes, grasp databases, the cloud, a cell YAML) are written relative
to the output file's folder when they share a folder other than the root with it (a scene and its
meshes move together), else absolute; names (``cell: bin``) are kept (a cell reference is a path
or a name by :func:`grasplan.config.lookup.is_path_like`). Floats are written exactly (YAML and
JSON both round-trip Python floats), so :func:`grasplan.piles.scene_file.load_scene` reads back
the same poses bit for bit. YAML files may start with comment lines (``header``): what made the
scene, the parts' sha256 and scale; readers ignore them.
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from ..config.lookup import is_path_like
from ..errors import InputError
from .scene_file import Scene

SCENE_SUFFIXES = (".yaml", ".yml", ".json")


def relative_ref(path: str, folder: Path, *, base: Path | None = None) -> str:
    """``path`` (relative to ``base``, default the current folder) as written in a file in
    ``folder``: relative when the two share a folder other than the root, else absolute."""
    p = Path(path).expanduser()
    p = Path(os.path.abspath(p if p.is_absolute() or base is None else base / p))
    f = Path(os.path.abspath(folder))
    try:
        common = Path(os.path.commonpath([p, f]))
    except ValueError:  # different drives
        return str(p)
    if common == Path(common.anchor):
        return str(p)
    return os.path.relpath(p, f)


def rebased(scene: Scene, folder: Path) -> Scene:
    """``scene`` with its paths made relative to ``folder`` (:func:`relative_ref`), ``base`` = folder."""
    parts = tuple(replace(p, mesh=None if p.mesh is None else relative_ref(p.mesh, folder, base=scene.base),
                          grasps=None if p.grasps is None else relative_ref(p.grasps, folder, base=scene.base))
                  for p in scene.parts)
    cloud = None if scene.cloud is None else replace(scene.cloud, path=relative_ref(scene.cloud.path, folder,
                                                                                     base=scene.base))
    cell = relative_ref(scene.cell, folder, base=scene.base) if is_path_like(scene.cell, scene.base) \
        else scene.cell
    return replace(scene, parts=parts, cloud=cloud, cell=cell, base=Path(os.path.abspath(folder)))


def scene_text(scene: Scene, *, suffix: str, header: Sequence[str] = ()) -> str:
    """The file text of ``scene`` (paths as they are) in the format of ``suffix``."""
    doc = scene.to_json()
    if suffix == ".json":
        from ..io import to_json_text

        return to_json_text(doc, indent=1) + "\n"
    import yaml

    lines = "".join(f"# {' '.join(h.split())}\n" for h in header)
    return lines + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=240)


def write_scene(path: str | os.PathLike, scene: Scene, *, header: Sequence[str] = ()) -> Scene:
    """Write ``scene`` to ``path`` (module docstring); returns the scene as written (paths relative
    to the file's folder, ``base`` that folder)."""
    from ..io import write_atomic_text

    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in SCENE_SUFFIXES:
        raise InputError(f"{p}: a scene file is YAML or JSON; name it *.yaml, *.yml or *.json")
    out = rebased(scene, p.parent)
    write_atomic_text(p, scene_text(out, suffix=suffix, header=header))
    return out
