"""``python -m grasplan.cli.warmup``: compile grasplan's numba kernels into numba's on-disk cache
once (``make install`` runs it), so the first ``grasplan plan`` or ``pick`` loads them instead.

The kernels (``cache=True``: :mod:`grasplan.robot.ik.ur_batch`, :mod:`grasplan.motion.pathboxes`,
:mod:`grasplan.pick.gripboxes`) are compiled for the argument types real runs pass by running
real work on a small box: a plan with the UR5 on the table and a pick from two boxes in the bin.
numba keeps the cache in ``__pycache__`` next to each module, or in ``$NUMBA_CACHE_DIR``, or
under the user's cache folder when the package folder is read-only. Always exits 0: when the
cache cannot be built it prints one line and the first run compiles instead."""
from __future__ import annotations

import os
import sys
import tempfile
import time
from collections.abc import Iterator
from types import ModuleType
from typing import Any

#: the modules holding ``cache=True`` kernels (the warm-up checks every kernel of every module it loaded)
KERNEL_MODULES = ("grasplan.robot.ik.ur_batch", "grasplan.grasps.collision_boxes", "grasplan.grasps.quality_kernels",
                  "grasplan.grasps.ranking",
                  "grasplan.motion.pathboxes", "grasplan.pick.gripboxes")
#: half extents (m) of the box the warm-up plans and picks
BOX_HALF = (0.02, 0.015, 0.01)


def kernels(modules: tuple[str, ...] | None = None) -> Iterator[tuple[str, Any]]:
    """``(module.name, dispatcher)`` of every numba kernel with ``cache=True`` defined in ``modules``
    (imported here; None: every grasplan module imported so far)."""
    import importlib

    from numba.core.dispatcher import Dispatcher

    names = modules if modules is not None else sorted(m for m in sys.modules if m.split(".")[0] == "grasplan")
    for name in names:
        mod: ModuleType = importlib.import_module(name)
        for attr, value in sorted(vars(mod).items()):
            cache = getattr(value, "_cache", None)  # numba's NullCache unless cache=True
            if isinstance(value, Dispatcher) and cache is not None and type(cache).__name__ != "NullCache" \
                    and value.py_func.__module__ == name:  # defined here, not imported from another module
                yield f"{name}.{attr}", value


def _box() -> tuple[Any, Any]:
    import numpy as np

    hx, hy, hz = BOX_HALF
    v = np.array([[x, y, z] for x in (-hx, hx) for y in (-hy, hy) for z in (-hz, hz)])
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return v, f


def run_kernels() -> None:
    """A plan and a pick of a small box: every kernel is called with the argument types of real runs."""
    from ..cell.model import load_cell
    from ..cell.resting import stable_pose
    from ..motion.planning import plan
    from ..part.mesh import part_from_arrays
    from ..pick.params import PickParams
    from ..pick.picker import Picker
    from ..piles.scene_file import Instance, Scene

    v, f = _box()
    part = part_from_arrays(v, f, path="<warm-up box>", units="m")
    plan(part, "ur5")
    picker = Picker("ur5", params=PickParams(grasps_per_instance=8))
    picker.add_part("box", part)
    T = stable_pose(part.mesh, load_cell("bin"))
    T2 = T.copy()
    T2[0, 3] += 0.08
    picker.plan(Scene(instances=(Instance("a", "box", T), Instance("b", "box", T2)), cell="bin"), max_picks=1)


def warm_up() -> str:
    """Compile (or load) every kernel through :func:`run_kernels` with grasplan's own cache moved to
    a temporary folder (the box's grasp database is not kept); the one line to print."""
    from ..cache import CACHE_ENV

    t0 = time.perf_counter()
    old = os.environ.get(CACHE_ENV)
    with tempfile.TemporaryDirectory(prefix="grasplan-warmup-") as tmp:
        os.environ[CACHE_ENV] = tmp
        try:
            run_kernels()
        finally:
            if old is None:
                os.environ.pop(CACHE_ENV, None)
            else:
                os.environ[CACHE_ENV] = old
    return _summary(list(kernels()), time.perf_counter() - t0)


def _summary(found: list[tuple[str, Any]], seconds: float) -> str:
    """The warm-up's line from numba's per-kernel cache counters (private to numba, hence the guard)."""
    try:
        compiled = [name for name, d in found if sum(d._cache_misses.values())]
        loaded = sum(sum(d._cache_hits.values()) for _, d in found)
        index = {name: d._cache._cache_file._index_path for name, d in found}
    except AttributeError:  # another numba's internals: the kernels ran, where they are kept is unknown
        return f"grasplan: numba kernels compiled or loaded in {seconds:.1f} s"
    unsaved = [name for name in compiled if not os.path.exists(index[name])]
    if unsaved:
        return (f"grasplan: numba could not store {len(unsaved)} of {len(compiled)} kernels it compiled "
                f"({', '.join(unsaved)}); each run compiles them again (set NUMBA_CACHE_DIR to a writable folder)")
    folders = sorted({os.path.dirname(p) for p in index.values()})
    return (f"grasplan: numba kernels cached in {seconds:.1f} s ({len(compiled)} compiled, {loaded} loaded from "
            f"the cache; {', '.join(folders)})")


def main() -> int:
    try:
        line = warm_up()
    except Exception as exc:  # the install goes on: the first run compiles instead
        line = (f"grasplan: numba kernels not cached ({type(exc).__name__}: {' '.join(str(exc).split())[:200]}); "
                "a plan or pick compiles them when first used (NUMBA_CACHE_DIR: a writable folder keeps them)")
    print(line, file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
