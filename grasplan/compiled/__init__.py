"""Compiled kernels: one Python definition each (:func:`~grasplan.compiled.jit.kernel`), run from
the install's ahead-of-time build (:mod:`.aot`) when it fits the arguments, else by numba's JIT."""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "Kernel": ".jit", "kernel": ".jit", "prefer_jit": ".jit", "COMPILE_MESSAGE": ".jit",
})
