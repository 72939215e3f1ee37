"""The benchmarks name only what grasplan has: every ``from grasplan... import`` in benchmarks/*.py
and examples/*.py (at the top or inside a function, where a run would only fail late) resolves."""
from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FILES = sorted([*ROOT.glob("benchmarks/*.py"), *ROOT.glob("examples/*.py")])


def _imports(path: Path) -> list[tuple[int, str, str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return [(n.lineno, n.module, a.name) for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
            and n.module and n.module.split(".")[0] == "grasplan" and n.level == 0 for a in n.names]


@pytest.mark.parametrize("path", FILES, ids=[p.relative_to(ROOT).as_posix() for p in FILES])
def test_every_grasplan_name_a_script_imports_exists(path):
    missing = []
    for line, module, name in _imports(path):
        mod = importlib.import_module(module)
        if not hasattr(mod, name):
            try:
                importlib.import_module(f"{module}.{name}")
            except ImportError:
                missing.append(f"{path.name}:{line}: {module}.{name}")
    assert not missing, missing


def test_the_check_sees_a_missing_name(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("def f():\n    from grasplan.sim.drop import no_such_name\n")
    assert _imports(bad) == [(2, "grasplan.sim.drop", "no_such_name")]
    assert not hasattr(importlib.import_module("grasplan.sim.drop"), "no_such_name")
