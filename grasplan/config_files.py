"""Finding described things (grippers, cells, robots) by name or by path to a YAML file.

A name is looked up as ``<folder>/<name>.yaml``; anything ending in ``.yaml``/``.yml``, holding a
path separator or naming an existing file is a path. An unknown name lists the available ones.
"""
from __future__ import annotations

import os
from pathlib import Path

from .errors import ConfigError, unknown_name

#: the repository's top-level folders of descriptions (next to the ``grasplan`` package)
REPO_ROOT = Path(__file__).resolve().parents[1]
CONFIG_DIR = REPO_ROOT / "configs"
ROBOTS_DIR = REPO_ROOT / "robots"


def available(folder: Path) -> list[str]:
    """Names of the ``*.yaml`` descriptions in ``folder``, sorted."""
    return sorted(p.stem for p in Path(folder).glob("*.yaml"))


def resolve_yaml(kind: str, name_or_path: str | os.PathLike, folder: Path) -> Path:
    """The YAML file for ``name_or_path`` (absolute path); raises ConfigError naming what exists."""
    s = str(name_or_path)
    p = Path(s)
    if s.endswith((".yaml", ".yml")) or "/" in s or os.sep in s or p.is_file():
        if not p.is_file():
            raise ConfigError(f"{kind} file {p} not found; available {kind}s: {', '.join(available(folder)) or '(none)'}")
        return p.resolve()
    candidate = Path(folder) / f"{s}.yaml"
    if not candidate.is_file():
        raise unknown_name(kind, s, available(folder), hint=f"or give a path to a {kind} YAML")
    return candidate.resolve()
