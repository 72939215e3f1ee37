"""Finding described things (grippers, cells, robots) by name or by path to a YAML file.

A name is looked up as ``<folder>/<name>.yaml``; anything ending in ``.yaml``/``.yml``, holding a
path separator or naming an existing file is a path. An unknown name lists the available ones.
"""
from __future__ import annotations

import ast
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

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


_EXPR_NODES = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Constant, ast.Name, ast.Add, ast.Sub,
               ast.Mult, ast.Div, ast.USub, ast.UAdd, ast.Load)


def config_number(value: Any, where: str, *, positive: bool = False, nonneg: bool = False) -> float:
    """A float from a YAML scalar: a number, or an expression of numbers and ``pi`` (``-pi/2``)."""
    if isinstance(value, bool):
        raise ConfigError(f"{where}: expected a number, got {value!r}")
    if isinstance(value, (int, float)):
        out = float(value)
    elif isinstance(value, str):
        try:
            tree = ast.parse(value.strip(), mode="eval")
            if not all(isinstance(n, _EXPR_NODES) for n in ast.walk(tree)) or any(
                    isinstance(n, ast.Name) and n.id != "pi" for n in ast.walk(tree)):
                raise ValueError
            out = float(eval(compile(tree, "<yaml>", "eval"), {"__builtins__": {}}, {"pi": math.pi}))
        except Exception:
            raise ConfigError(f"{where}: cannot read {value!r} as a number (use e.g. 1.57 or -pi/2)") from None
    else:
        raise ConfigError(f"{where}: expected a number, got {value!r}")
    if not math.isfinite(out):
        raise ConfigError(f"{where}: must be finite, got {value!r}")
    if positive and out <= 0:
        raise ConfigError(f"{where}: must be > 0, got {value!r}")
    if nonneg and out < 0:
        raise ConfigError(f"{where}: must be >= 0, got {value!r}")
    return out


def config_vector(value: Any, where: str, n: int | None = 3, *, positive: bool = False) -> np.ndarray:
    """``(n,)`` float64 from a YAML list of numbers (each read by :func:`config_number`)."""
    if not isinstance(value, (list, tuple)):
        raise ConfigError(f"{where}: expected a list of {n or 'some'} numbers, got {value!r}")
    if n is not None and len(value) != n:
        raise ConfigError(f"{where}: expected a list of {n} numbers, got {len(value)}: {value!r}")
    return np.array([config_number(v, f"{where}[{i}]", positive=positive) for i, v in enumerate(value)],
                    dtype=np.float64)
