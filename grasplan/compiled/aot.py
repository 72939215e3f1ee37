"""The ahead-of-time build of grasplan's kernels: one extension module compiled by numba's ``pycc``
from the kernels' own Python, for the argument types real runs pass, so a run loads machine code
without importing numba.

``python -m grasplan.cli.warmup`` (``make install``) runs a plan and a pick, reads the signatures
numba compiled for each kernel and calls :func:`build`. The module and its ``manifest.json`` live
beside this module in ``_built/`` (or ``~/.cache/grasplan/kernels``, or ``$GRASPLAN_KERNELS_DIR``:
:func:`folders`). The manifest names the sha256 of every
kernel module's source, the Python and NumPy the module was built for, and each kernel's exported
variants with their argument types, and the CPU it was compiled for (:func:`cpu_id`: the build
uses this CPU's instructions, as numba's JIT does). :func:`load` uses the module only when all of
these match the running install and machine. A variant runs only on arguments of exactly its types (:meth:`Variant.accepts`),
because a compiled module does not check them. ``GRASPLAN_AOT=0`` turns the build off for a process.
"""
from __future__ import annotations

import importlib.util
import json
import os
import shutil
import sysconfig
import tempfile
import time
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..io import sha256_doc, sha256_file

#: the manifest's format; another value is not read
FORMAT = 1
#: the environment variable that turns the ahead-of-time kernels off (``0``)
AOT_ENV = "GRASPLAN_AOT"
#: the environment variable naming the one folder of the build
KERNELS_ENV = "GRASPLAN_KERNELS_DIR"
#: the build's folder beside this module, and the manifest's name
BUILT, MANIFEST = "_built", "manifest.json"
#: argument kinds of a spec: an array, a Python or NumPy int64, float64 or bool scalar
ARRAY, INT, FLOAT, BOOL = "array", "int64", "float64", "bool"
#: the CPU id of a build that runs on any CPU of its architecture
GENERIC = "generic"
_SCALAR_TYPES = {INT: (int, np.int64), FLOAT: (float, np.float64), BOOL: (bool, np.bool_)}

#: one argument: ``(kind, dtype, ndim, layout, readonly)`` (the last four for arrays only)
Spec = tuple[str, Any, int, str, bool]


@dataclass(frozen=True)
class Variant:
    """One compiled signature of a kernel: ``function`` (from the extension module) and the types
    of its arguments."""

    function: Callable[..., Any]
    specs: tuple[Spec, ...]
    _check: Callable[[Sequence[Any]], bool] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_check", _checker(self.specs))

    @property
    def accepts(self) -> Callable[[Sequence[Any]], bool]:
        """``accepts(args)``: whether ``args`` have exactly the types this variant was compiled for:
        arrays of its dtype and dimensions, aligned, C- or F-contiguous where its layout says so,
        and writeable unless it only reads them; scalars of its kind (``int`` is not a ``bool``
        here)."""
        return self._check


def _checker(specs: tuple[Spec, ...]) -> Callable[[Sequence[Any]], bool]:
    """:meth:`Variant.accepts` for ``specs`` as straight-line code (one test per argument, no loop:
    it runs before every call of a compiled kernel)."""
    n = len(specs)
    names = [f"a{i}" for i in range(n)]
    lines = ["def check(args):", f"    if len(args) != {n}:", "        return False"]
    if n:
        lines.append(f"    {', '.join(names)}, = args")
    env: dict[str, Any] = {"ndarray": np.ndarray}
    for i, (kind, dtype, ndim, layout, readonly) in enumerate(specs):
        a = names[i]
        if kind == ARRAY:
            env[f"D{i}"] = dtype
            need = ["f.aligned"] + ([] if readonly else ["f.writeable"]) + \
                {"C": ["f.c_contiguous"], "F": ["f.f_contiguous"]}.get(layout, [])
            lines += [f"    if {a}.__class__ is not ndarray or {a}.ndim != {int(ndim)}:", "        return False",
                      # builtin dtypes are singletons: ``is`` answers most calls before ``==``
                      f"    if {a}.dtype is not D{i} and {a}.dtype != D{i}:", "        return False",
                      f"    f = {a}.flags", f"    if not ({' and '.join(need)}):", "        return False"]
        else:
            env[f"S{i}"] = _SCALAR_TYPES[kind]
            lines += [f"    if {a}.__class__ not in S{i}:", "        return False"]
    lines.append("    return True")
    exec("\n".join(lines), env)
    check: Callable[[Sequence[Any]], bool] = env["check"]
    return check


_LOADED: dict[str, tuple[Variant, ...]] | None = None
_WHY = {"text": "not loaded yet"}


def variants(name: str) -> tuple[Variant, ...]:
    """The compiled variants of kernel ``name`` (``module.qualname``) in this process's build (the
    cache's, loaded on first use; none when there is no usable build)."""
    global _LOADED
    if _LOADED is None:
        _LOADED = load()
    return _LOADED.get(name, ())


def status() -> str:
    """Why this process uses the ahead-of-time build or not (one line)."""
    return _WHY["text"]


def folders() -> list[Path]:
    """Where :func:`load` looks, in order: ``$GRASPLAN_KERNELS_DIR`` alone when set, else beside
    this module (``grasplan/compiled/_built``, the install's own), then ``~/.cache/grasplan/kernels``
    (an install whose folder is read-only). The build belongs to the install, not to
    ``$GRASPLAN_CACHE_DIR``'s grasp databases, so moving those does not lose it."""
    env = os.environ.get(KERNELS_ENV)
    if env:
        return [Path(env).expanduser()]
    return [Path(__file__).resolve().parent / BUILT, Path.home() / ".cache" / "grasplan" / "kernels"]


def build_folder() -> Path:
    """Where :func:`build` writes by default: the first of :func:`folders` that is writable."""
    for where in folders():
        try:
            where.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryFile(dir=where):
                return where
        except OSError:
            continue
    raise OSError(f"no writable folder for the ahead-of-time kernels among {', '.join(map(str, folders()))} "
                  f"(set {KERNELS_ENV} to one)")


def _source_file(module: str) -> Path:
    """The source file of grasplan module ``module`` (found without importing it)."""
    root = Path(__file__).resolve().parents[1]
    return root.joinpath(*module.split(".")[1:]).with_suffix(".py")


def _platform() -> dict[str, str]:
    """What a build is only valid for: the interpreter's extension suffix and NumPy's version."""
    return {"ext_suffix": str(sysconfig.get_config_var("EXT_SUFFIX")), "numpy": np.__version__}


def cpu_id() -> str:
    """This CPU's model and instruction-set flags (sha256 of ``/proc/cpuinfo``'s first ``model
    name`` and ``flags`` lines), or ``"generic"`` where there is no such file. A build for
    ``"generic"`` runs on any CPU of the architecture; one for a CPU id only on a CPU with that
    id (it uses the CPU's instructions, as numba's JIT does)."""
    try:
        text = Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace")
    except OSError:
        return GENERIC
    keep: dict[str, str] = {}
    for line in text.splitlines():
        if not line.strip() and keep:
            break  # the first processor's block is enough
        key, _, value = line.partition(":")
        key = key.strip()
        if key in ("model name", "flags", "Features", "CPU part") and key not in keep:
            keep[key] = " ".join(value.split())
    if not keep:
        return GENERIC
    return sha256_doc(keep)[:16]


def load(where: Path | None = None) -> dict[str, tuple[Variant, ...]]:
    """``{kernel name: variants}`` from the build in ``where`` (default: the first of
    :func:`folders` holding a manifest); empty when there is none, when it is turned off, built
    for other sources, another Python, NumPy or CPU, or damaged (:func:`status` says which)."""
    if os.environ.get(AOT_ENV, "1") == "0":
        _WHY["text"] = f"ahead-of-time kernels turned off ({AOT_ENV}=0)"
        return {}
    if where is None:
        where = next((f for f in folders() if (f / MANIFEST).is_file()), folders()[0])
    try:
        manifest = json.loads((where / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        _WHY["text"] = f"no ahead-of-time kernels in {where} ({type(exc).__name__}); numba compiles or loads them"
        return {}
    try:
        return _load(where, manifest)
    except (ImportError, OSError, KeyError, TypeError, ValueError, AttributeError) as exc:
        _WHY["text"] = (f"ahead-of-time kernels in {where} could not be loaded ({type(exc).__name__}: {exc}); "
                        "`python -m grasplan.cli.warmup` rebuilds them")
        return {}


def _load(where: Path, manifest: Any) -> dict[str, tuple[Variant, ...]]:
    """:func:`load` of a parsed ``manifest``; raises on a damaged one."""
    stale = _stale(manifest)
    if stale:
        _WHY["text"] = f"ahead-of-time kernels in {where} not used: {stale}; `python -m grasplan.cli.warmup` rebuilds them"
        return {}
    spec = importlib.util.spec_from_file_location(str(manifest["module"]), where / str(manifest["file"]))
    if spec is None or spec.loader is None:
        raise ImportError(f"no loader for {manifest['file']}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = {str(name): tuple(Variant(getattr(module, export), tuple(_spec_from_json(s) for s in specs))
                            for export, specs in entries)
           for name, entries in manifest["kernels"].items()}
    _WHY["text"] = f"ahead-of-time kernels from {where / manifest['file']} ({len(out)} kernels)"
    return out


def _stale(manifest: dict[str, Any]) -> str:
    """What in ``manifest`` does not match the running install ('' when all does)."""
    if manifest.get("format") != FORMAT:
        return f"manifest format {manifest.get('format')!r}, not {FORMAT}"
    for key, value in _platform().items():
        if manifest.get(key) != value:
            return f"built for {key} {manifest.get(key)!r}, this is {value!r}"
    if manifest.get("cpu") not in (GENERIC, cpu_id()):
        return "built for another CPU"
    for module, digest in manifest.get("sources", {}).items():
        path = _source_file(module)
        if not path.is_file() or sha256_file(path) != digest:
            return f"{module} changed since the build"
    return ""


def _spec_from_json(s: list[Any]) -> Spec:
    kind, dtype, ndim, layout, readonly = s
    kinds = {k: k for k in (ARRAY, INT, FLOAT, BOOL)}  # the module's own strings: ``is`` compares them
    return (kinds[kind], np.dtype(dtype) if kind == ARRAY else None, int(ndim), str(layout), bool(readonly))


def spec_of(numba_type: Any) -> list[Any] | None:
    """The JSON spec of one argument's numba type; None for a type :class:`Variant` cannot check."""
    from numba.core import types
    from numba.np.numpy_support import as_dtype

    if isinstance(numba_type, types.Array):
        if not numba_type.aligned or numba_type.layout not in ("C", "F", "A"):
            return None
        return [ARRAY, as_dtype(numba_type.dtype).str, numba_type.ndim, numba_type.layout, not numba_type.mutable]
    for kind, t in ((BOOL, types.boolean), (INT, types.int64), (FLOAT, types.float64)):
        if numba_type == t:
            return [kind, None, 0, "", False]
    return None


def build(kernels: Iterable[tuple[str, Callable[..., Any], Sequence[Any]]], where: Path | None = None
          ) -> tuple[int, int, Path]:
    """Compile ``(name, py_func, numba signatures)`` of each kernel into one extension module in
    ``where`` (default :func:`build_folder`), with its manifest; ``(kernels, variants, module path)``.
    Signatures with an argument :class:`Variant` cannot check are left to numba. Written atomically:
    the new module under a name of its own, then the manifest; older modules are removed."""
    with warnings.catch_warnings():  # pycc is pending deprecation in numba, with no replacement yet
        warnings.simplefilter("ignore")
        from numba.pycc import CC

    where = build_folder() if where is None else where
    where.mkdir(parents=True, exist_ok=True)
    entries: dict[str, list[list[Any]]] = {}
    exports: list[tuple[str, Any, Callable[..., Any]]] = []
    modules: set[str] = set()
    for name, py_func, signatures in kernels:
        for sig in signatures:
            specs = [spec_of(t) for t in sig.args]
            if any(s is None for s in specs):
                continue
            export = f"k{len(exports)}"
            exports.append((export, sig, py_func))
            entries.setdefault(name, []).append([export, specs])
            modules.add(py_func.__module__)
    sources = {m: sha256_file(_source_file(m)) for m in sorted(modules)}
    cpu = cpu_id()
    digest = sha256_doc([sources, _platform(), cpu, entries])
    name = f"grasplan_kernels_{digest[:16]}"
    with tempfile.TemporaryDirectory(prefix="build-", dir=where) as tmp:
        cc = CC(name, source_module="grasplan.compiled.aot")
        cc.output_dir = tmp
        cc.target_cpu = "" if cpu == GENERIC else "host"  # "": the architecture's generic CPU
        for export, sig, py_func in exports:
            cc.export(export, sig)(py_func)
        cc.compile()
        built = Path(tmp) / cc.output_file
        target = where / built.name
        shutil.move(str(built), target)
    manifest = {"format": FORMAT, **_platform(), "cpu": cpu, "sources": sources, "module": name, "file": target.name,
                "kernels": entries, "built": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    tmp_manifest = where / f".{MANIFEST}.{os.getpid()}"
    tmp_manifest.write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    os.replace(tmp_manifest, where / MANIFEST)
    for old in where.glob("grasplan_kernels_*"):
        if old.name != target.name:
            old.unlink(missing_ok=True)
    return len(entries), len(exports), target

