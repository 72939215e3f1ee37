"""The cache folder: work that depends only on its inputs, kept between runs.

``$GRASPLAN_CACHE_DIR`` or ``~/.cache/grasplan``. Subfolders: ``coacd/`` (convex decompositions,
:mod:`grasplan.sim.simulate`), ``graspdb/`` (grasp databases, :mod:`grasplan.grasps.graspdb`, and
beside each the other resting poses' holding grasps per cell, :func:`grasplan.grasps.placed.hold_by_pose`). Every entry is
named by a sha256 of what it was computed from and written atomically, so a stale or foreign
entry is never read and two processes filling the cache at once cannot corrupt it; deleting the
folder only costs the recomputation.
"""
from __future__ import annotations

import os
from pathlib import Path

#: the environment variable that moves the cache
CACHE_ENV = "GRASPLAN_CACHE_DIR"


def cache_dir() -> Path:
    """``$GRASPLAN_CACHE_DIR`` or ``~/.cache/grasplan``."""
    env = os.environ.get(CACHE_ENV)
    return Path(env).expanduser() if env else Path.home() / ".cache" / "grasplan"
