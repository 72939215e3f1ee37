"""grasplan's compiled kernels: one Python definition each, run ahead-of-time compiled when the
install built them (:mod:`grasplan.compiled.aot`), else just-in-time by numba.

A kernel module decorates its loops with :func:`kernel` (numba's ``njit`` options, e.g.
``cache=True, nogil=True``) and imports no numba itself. A call of a :class:`Kernel` runs the
ahead-of-time build's version when one was built for exactly these argument types (dtype,
dimensions, memory layout, writeability; Python ``int``, ``float`` and ``bool`` scalars), else
numba's dispatcher, which numba builds (importing numba, loading or compiling the kernel) on first
use. A process that never falls back never imports numba: that saves a cold ``grasplan plan``
numba's import and its LLVM start-up (about 1 s). A kernel called from inside another kernel is
numba's: :func:`_setup_numba` teaches numba's typing that a :class:`Kernel` is its dispatcher.

:func:`prefer_jit` makes every later call numba's (the service: its threads run kernels without
the GIL, which numba's dispatchers release and the ahead-of-time module does not).
"""
from __future__ import annotations

import functools
import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from . import aot

#: printed on stderr, once per process, when a grasplan kernel is compiled rather than loaded from
#: numba's on-disk cache (``__pycache__`` next to the module, or ``$NUMBA_CACHE_DIR``)
COMPILE_MESSAGE = ("grasplan: compiling its numba kernels once (10-40 s; later runs load them from "
                   "the cache) ...")

_STATE = {"prefer_jit": False, "numba_ready": False}


class Kernel:
    """A compiled loop: ``py_func`` (plain Python, the one definition) and numba's ``njit``
    ``options``; called like the function. ``name`` is ``module.qualname``."""

    def __init__(self, py_func: Callable[..., Any], options: dict[str, Any]) -> None:
        self.py_func = py_func
        self.options = dict(options)
        self.name = f"{py_func.__module__}.{py_func.__qualname__}"
        self._jit: Any = None
        #: ``(argument check, compiled function)`` per ahead-of-time variant; None until first used
        self._aot: tuple[tuple[Callable[[Any], bool], Callable[..., Any]], ...] | None = None
        functools.update_wrapper(self, py_func)
        _KERNELS.append(self)

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        if kwargs:  # the compiled variants take positional arguments only
            return self.jit()(*args, **kwargs)
        variants = self._aot
        if variants is None:
            variants = self._aot = () if _STATE["prefer_jit"] else tuple(
                (v.accepts, v.function) for v in aot.variants(self.name))
        for accepts, function in variants:
            if accepts(args):
                return function(*args)
        return self.jit()(*args)

    @property
    def dispatcher(self) -> Any:
        """numba's dispatcher if this process made it (:meth:`jit`), else None."""
        return self._jit

    def jit(self) -> Any:
        """numba's dispatcher of this kernel (made on first use; numba imported then)."""
        if self._jit is None:
            _setup_numba()
            import numba

            self._jit = numba.njit(**self.options)(self.py_func)
        return self._jit

    def __repr__(self) -> str:
        return f"<grasplan kernel {self.name}>"


#: every kernel defined (module-level functions: a fixed, small set)
_KERNELS: list[Kernel] = []


def kernel(**options: Any) -> Callable[[Callable[..., Any]], Kernel]:
    """Decorator: the function as a :class:`Kernel` with numba ``njit`` ``options``."""
    def wrap(py_func: Callable[..., Any]) -> Kernel:
        return Kernel(py_func, options)
    return wrap


def prefer_jit() -> None:
    """Every later kernel call goes to numba's dispatcher (which releases the GIL with ``nogil``)."""
    _STATE["prefer_jit"] = True
    for k in _KERNELS:
        k._aot = ()


def _setup_numba() -> None:
    """Once per process, before numba compiles a grasplan kernel: a :class:`Kernel` named inside
    another kernel types as its numba dispatcher; :data:`COMPILE_MESSAGE` is printed at the first
    cold compile; numba gets a cache folder when it has none (:func:`ensure_cache_dir`)."""
    if _STATE["numba_ready"]:
        return
    from numba.core import event as numba_event
    from numba.core import types
    from numba.core.typing.typeof import typeof_impl

    @typeof_impl.register(Kernel)
    def _typeof_kernel(val: Kernel, c: Any) -> Any:
        return types.Dispatcher(val.jit())

    numba_event.register("numba:compile", _compile_notice(numba_event.Listener))
    ensure_cache_dir()
    _STATE["numba_ready"] = True


def _compile_notice(base: type) -> Any:
    """A numba event listener writing :data:`COMPILE_MESSAGE` at the first compile of a grasplan
    kernel (numba signals a compile only on a cache miss: a warm cache says nothing)."""
    class Notice(base):
        told = False

        def on_start(self, event: Any) -> None:
            if self.told:
                return
            dispatcher = (event.data or {}).get("dispatcher")
            module = getattr(getattr(dispatcher, "py_func", None), "__module__", "") or ""
            if module.split(".")[0] == "grasplan":
                self.told = True
                print(COMPILE_MESSAGE, file=sys.stderr, flush=True)

        def on_end(self, event: Any) -> None:
            pass

    return Notice()


def _writable(folder: Path) -> bool:
    """Whether a file can be created in ``folder`` (made if missing), as numba's locators test it."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            return True
    except OSError:
        return False


def ensure_cache_dir(writable: Callable[[Path], bool] = _writable) -> Path | None:
    """The folder numba's cache is sent to when neither of its own places is ``writable`` (the
    kernels' ``__pycache__`` of a read-only install, ``~/.cache/numba`` of an account without a
    writable home): ``$TMPDIR/grasplan-numba-<uid>`` (set as ``numba.config.CACHE_DIR``); None when
    numba has a place (or ``$NUMBA_CACHE_DIR`` is set). Without it numba refuses to define a cached
    kernel at all ("no locator available")."""
    from numba.core import config  # the module numba reads CACHE_DIR from when a cached kernel is defined
    from numba.misc.appdirs import AppDirs

    if getattr(config, "CACHE_DIR", ""):  # set at run time from $NUMBA_CACHE_DIR (no static attribute)
        return None
    if writable(Path(__file__).resolve().parent / "__pycache__"):
        return None
    if writable(Path(AppDirs(appname="numba", appauthor=False).user_cache_dir)):
        return None
    folder = Path(tempfile.gettempdir()) / f"grasplan-numba-{os.getuid() if hasattr(os, 'getuid') else 0}"
    setattr(config, "CACHE_DIR", str(folder))
    return folder
