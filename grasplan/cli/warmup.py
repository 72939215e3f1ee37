"""``python -m grasplan.cli.warmup``: compile grasplan's kernels once (``make install`` runs it), so
the first ``grasplan plan`` or ``pick`` loads machine code instead of compiling.

The kernels (:mod:`grasplan.compiled`: :mod:`grasplan.robot.ik.ur_batch`, :mod:`grasplan.motion.pathboxes`,
:mod:`grasplan.pick.gripboxes` and others) are compiled by numba for the argument types real runs
pass, by running real work on a small box: a plan with the UR5 on the table and a pick from two
boxes in the bin. numba keeps them in its cache (``__pycache__`` next to each module, or
``$NUMBA_CACHE_DIR``, or under the user's cache folder when the package folder is read-only). Then
the same signatures are compiled ahead of time into one extension module
(:mod:`grasplan.compiled.aot`, in ``<cache>/kernels``), which a run loads without importing numba.
Always exits 0: when a step fails it prints one line and the first run compiles instead."""
from __future__ import annotations

import os
import sys
import tempfile
import time
from collections.abc import Iterator
from types import ModuleType
from typing import Any

#: the modules holding kernels (the warm-up checks every kernel of every module it loaded)
KERNEL_MODULES = ("grasplan.geometry.interpolation", "grasplan.robot.ik.ur_batch", "grasplan.robot.ik.solution_kernels",
                  "grasplan.grasps.collision_boxes",
                  "grasplan.grasps.quality_kernels", "grasplan.grasps.epsilon_kernels", "grasplan.grasps.patch_search",
                  "grasplan.grasps.ranking", "grasplan.motion.pathboxes", "grasplan.pick.gripboxes")
#: half extents (m) of the box the warm-up plans and picks
BOX_HALF = (0.02, 0.015, 0.01)


def kernels(modules: tuple[str, ...] | None = None) -> Iterator[tuple[str, Any]]:
    """``(module.name, kernel)`` of every :class:`~grasplan.compiled.jit.Kernel` defined in
    ``modules`` (imported here; None: every grasplan module imported so far)."""
    import importlib

    from ..compiled.jit import Kernel

    names = modules if modules is not None else sorted(m for m in sys.modules if m.split(".")[0] == "grasplan")
    for name in names:
        mod: ModuleType = importlib.import_module(name)
        for attr, value in sorted(vars(mod).items()):
            if isinstance(value, Kernel) and value.py_func.__module__ == name:  # defined here, not imported
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
    from ..config.params import DEFAULT_CELL, DEFAULT_GRIPPER, CandidateParams, GraspParams
    from ..grasps.placed import hold_by_pose
    from ..motion.planning import plan
    from ..part.mesh import part_from_arrays
    from ..pick.params import PickParams
    from ..pick.picker import Picker
    from ..piles.scene_file import Instance, Scene
    from ..setup.resolved import build_setup

    v, f = _box()
    part = part_from_arrays(v, f, path="<warm-up box>", units="m")
    plan(part, "ur5")
    setup = build_setup(gripper=DEFAULT_GRIPPER, cell=DEFAULT_CELL)  # the holding-poses hint of plan's CLI
    assert setup.gripper is not None and setup.cell is not None
    hold_by_pose(part, setup.gripper, setup.cell, candidates=CandidateParams(), grasps=GraspParams(), poses=[(1, 0.5)],
                 cache=False)
    picker = Picker("ur5", params=PickParams(grasps_per_instance=8))
    picker.add_part("box", part)
    T = stable_pose(part.mesh, load_cell("bin"))
    T2 = T.copy()
    T2[0, 3] += 0.08
    picker.plan(Scene(instances=(Instance("a", "box", T), Instance("b", "box", T2)), cell="bin"), max_picks=1)


def warm_up() -> str:
    """Compile (or load) every kernel through :func:`run_kernels` with numba (grasplan's own cache
    moved to a temporary folder: the box's grasp database is not kept), then build the
    ahead-of-time module from the signatures numba compiled; the lines to print."""
    from ..cache import CACHE_ENV
    from ..compiled.jit import prefer_jit

    prefer_jit()  # every kernel through numba: its signatures are what the ahead-of-time build compiles
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
    found = list(kernels(KERNEL_MODULES))
    line = _summary([(name, k.dispatcher) for name, k in found if k.dispatcher is not None], time.perf_counter() - t0)
    return line + "\n" + build_ahead_of_time(found)


def build_ahead_of_time(found: list[tuple[str, Any]]) -> str:
    """Build :mod:`grasplan.compiled.aot`'s module from the signatures numba compiled for ``found``
    (``(name, kernel)``); the line to print (a failure too: numba then serves every run)."""
    from ..compiled import aot

    t0 = time.perf_counter()
    try:
        n, variants, path = aot.build((k.name, k.py_func, k.dispatcher.nopython_signatures)
                                      for _, k in found if k.dispatcher is not None)
    except Exception as exc:  # a missing C compiler or linker: runs use numba's cache instead
        return (f"grasplan: kernels not compiled ahead of time ({type(exc).__name__}: "
                f"{' '.join(str(exc).split())[:200]}); runs load them through numba")
    return (f"grasplan: {n} kernels ({variants} signatures) compiled ahead of time in "
            f"{time.perf_counter() - t0:.1f} s: {path}")


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
