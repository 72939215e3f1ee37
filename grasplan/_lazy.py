"""Lazy re-exports for package ``__init__`` files: a public name is imported from its module on
first use, so importing a package (or any module in it) loads none of its heavy siblings."""
from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any


def lazy_exports(namespace: dict[str, Any], names: dict[str, str]
                 ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for the package whose ``globals()`` is ``namespace``: each public
    name of ``names`` is imported on first use from its module (relative to the package, e.g.
    ``".pipeline"``) and kept in ``namespace``; a name mapped to the subpackage of its own name
    (``"export": ".export"``) is that subpackage."""
    package = str(namespace["__name__"])
    namespace["__lazy_exports__"] = dict(names)

    def __getattr__(name: str) -> Any:
        module = names.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        mod = importlib.import_module(module, package)
        subpackage = module.rpartition(".")[2] == name and hasattr(mod, "__path__")
        value = mod if subpackage else getattr(mod, name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted({*names, *(k for k in namespace if not k.startswith("_"))})

    return __getattr__, __dir__
