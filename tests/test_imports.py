"""The package's structure rules, read from its source with ``ast``: no import circle (counting every
import statement: inside functions and under ``if TYPE_CHECKING:`` too), no module over 600 lines,
at most six modules at the package's root, subpackages in layers (every import between two
subpackages goes down), and docs/architecture.md listing every subpackage at its layer with its
modules. The graph code is checked on small synthetic packages first, so a passing run means
something."""
from __future__ import annotations

import ast
import subprocess
import sys
import re
from functools import lru_cache
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "grasplan"
ARCHITECTURE = PACKAGE.parent / "docs" / "architecture.md"
#: the longest a module may be (lines); the viewer's JavaScript is not Python and not counted
MAX_LINES = 600
#: modules directly in the package folder, ``__init__`` included: the rest live in subpackages
MAX_ROOT_MODULES = 6
#: the root modules' name in the subpackage graph
ROOT = "(root)"


def modules(pkg_dir: Path) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` file under the package folder ``pkg_dir``
    (a package's ``__init__.py`` is the package itself)."""
    out = {}
    for path in sorted(pkg_dir.rglob("*.py")):
        parts = path.relative_to(pkg_dir.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _imported_names(node: ast.Import | ast.ImportFrom, module: str, is_package: bool) -> list[str]:
    """The dotted names an import statement may load, relative imports resolved (``from X import y``
    may load ``X`` or its submodule ``X.y``)."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    if node.level:
        base = module.split(".") if is_package else module.split(".")[:-1]
        base = base[: len(base) - (node.level - 1)]
        target = ".".join(base + ([node.module] if node.module else []))
    else:
        target = node.module or ""
    return [target] + [f"{target}.{alias.name}" for alias in node.names]


def import_graph(pkg_dir: Path) -> dict[str, dict[str, int]]:
    """``{module: {imported module: line of the first such import}}`` within the package.

    Every ``import`` / ``from ... import`` statement anywhere in a module counts (module level,
    inside functions, under ``if TYPE_CHECKING:``). A name resolves to the longest module of the
    package it starts with; imports of the module itself or of a package containing it (its parent
    packages, loaded before it anyway) are not edges."""
    mods = modules(pkg_dir)
    graph: dict[str, dict[str, int]] = {m: {} for m in mods}
    for module, path in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        is_package = path.name == "__init__.py"
        for node in ast.walk(tree):
            if not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            for name in _imported_names(node, module, is_package):
                while name and name not in mods:
                    name = name.rpartition(".")[0]
                if name and name != module and not module.startswith(name + "."):
                    graph[module].setdefault(name, node.lineno)
    return graph


def circles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """The import circles: the strongly connected components of two or more modules (each sorted;
    Tarjan's algorithm, iterative), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    components.append(set(comp))
    return sorted(sorted(comp) for comp in components)


def circle_path(graph: dict[str, dict[str, int]], comp: list[str]) -> list[str]:
    """``[a, b, ..., a]``: a shortest circle through the component's first module (breadth-first)."""
    start = min(comp)
    parent: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(graph[v]):
                if w not in comp:
                    continue
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(parent[path[-1]])
                    return path[::-1] + [start]
                if w not in parent:
                    parent[w] = v
                    nxt.append(w)
        frontier = nxt
    raise AssertionError(f"no circle through {start} in {sorted(comp)}")  # a component always has one


def describe(graph: dict[str, dict[str, int]], comp: list[str], pkg_dir: Path) -> str:
    """``a, b: a -> b (a.py:12) -> a (b.py:3)``: the modules of a circle and one circle through them,
    with the line of each import."""
    mods = modules(pkg_dir)
    path = circle_path(graph, comp)
    steps = [path[0]] + [f"{b} ({mods[a].relative_to(pkg_dir.parent)}:{graph[a][b]})" for a, b in zip(path, path[1:])]
    return ", ".join(comp) + ": " + " -> ".join(steps)


def subpackage(module: str, pkg_dir: Path) -> str:
    """The first-level subpackage a dotted module belongs to (``grasplan.grasps.collision`` ->
    ``grasps``), or :data:`ROOT` for a module directly in the package folder."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and (pkg_dir / parts[1]).is_dir() else ROOT


def subpackage_graph(graph: dict[str, dict[str, int]], pkg_dir: Path) -> dict[str, dict[str, str]]:
    """``{subpackage: {imported subpackage: one module-level import that makes the edge}}``; the root
    modules (imported by everything) are left out of the edges."""
    out: dict[str, dict[str, str]] = {subpackage(m, pkg_dir): {} for m in graph}
    for m, deps in graph.items():
        a = subpackage(m, pkg_dir)
        for d in sorted(deps):
            b = subpackage(d, pkg_dir)
            if a != b and b != ROOT:
                out[a].setdefault(b, f"{m} -> {d}")
    return out


def layers(pgraph: dict[str, dict[str, str]]) -> dict[str, int]:
    """Each subpackage's layer: 0 when it imports no other, else one more than the highest it imports
    (the longest chain below it). AssertionError naming a circle of subpackages, when there is one."""
    found = circles({a: dict.fromkeys(b, 0) for a, b in pgraph.items()})
    assert not found, "subpackages importing each other (move the module that makes one of these imports): " + \
        "; ".join(" <-> ".join(c) + " (" + ", ".join(pgraph[x][y] for x in c for y in pgraph[x] if y in c) + ")"
                  for c in found)

    @lru_cache(maxsize=None)
    def level(p: str) -> int:
        return 1 + max((level(q) for q in pgraph[p]), default=-1)
    return {p: level(p) for p in pgraph}


def documented_layers(text: str) -> dict[str, tuple[int, set[str]]]:
    """``{subpackage: (layer, {module, ...})}`` from the rows of the layer table of
    docs/architecture.md: ``| 3 | `grasps/` | what it is | `frames`, `collision`, ... |`` (the root
    modules: ``(root)``)."""
    out = {}
    for m in re.finditer(r"^\|\s*(\d+)\s*\|\s*`([^`]+)`\s*\|[^|\n]*\|([^|\n]*)\|\s*$", text, flags=re.M):
        name = m.group(2).rstrip("/")
        out[name] = (int(m.group(1)), set(re.findall(r"`([\w./]+)`", m.group(3))))
    return out


def long_modules(pkg_dir: Path, limit: int = MAX_LINES) -> list[tuple[str, int]]:
    """``(module, lines)`` of the Python modules longer than ``limit`` lines, longest first."""
    rows = [(m, len(p.read_text(encoding="utf-8").splitlines())) for m, p in modules(pkg_dir).items()]
    return sorted(((m, n) for m, n in rows if n > limit), key=lambda r: (-r[1], r[0]))


# -- the graph code on packages whose answer is known ---------------------------------------------------

def _write(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root / "pkg"


def test_synthetic_circle_through_function_and_type_checking_imports_is_found(tmp_path):
    pkg = _write(tmp_path, {
        "pkg/__init__.py": "from .sub import d\n",
        # a -> b only inside a function, b -> c only under TYPE_CHECKING, c -> a by a relative import
        "pkg/a.py": "import os\n\n\ndef f():\n    from .b import thing\n    return thing\n",
        "pkg/b.py": "from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n    from pkg.c import C\nthing = 1\n",
        "pkg/c.py": "from . import a\nC = 2\n",
        # importing a parent package is not an edge; a submodule by 'from .. import name' is
        "pkg/sub/__init__.py": "",
        "pkg/sub/d.py": "import pkg\nfrom pkg import sub\nfrom .. import e\n",
        "pkg/e.py": "import numpy\n",
    })
    graph = import_graph(pkg)
    assert graph["pkg.a"] == {"pkg.b": 5}
    assert graph["pkg.b"] == {"pkg.c": 4}
    assert graph["pkg.c"] == {"pkg.a": 1}
    assert graph["pkg.sub.d"] == {"pkg.e": 3}
    assert graph["pkg"] == {"pkg.sub": 1, "pkg.sub.d": 1} and graph["pkg.e"] == {}
    found = circles(graph)
    assert found == [["pkg.a", "pkg.b", "pkg.c"]]
    assert describe(graph, found[0], pkg) == ("pkg.a, pkg.b, pkg.c: pkg.a -> pkg.b (pkg/a.py:5) -> pkg.c (pkg/b.py:4) "
                                              "-> pkg.a (pkg/c.py:1)")


def test_synthetic_package_without_circle_and_two_separate_circles(tmp_path):
    pkg = _write(tmp_path, {
        "pkg/__init__.py": "from . import x\n",
        "pkg/x.py": "from .y import Y\n",
        "pkg/y.py": "Y = 1\n",
    })
    assert circles(import_graph(pkg)) == []
    pkg2 = _write(tmp_path / "two", {
        "pkg/__init__.py": "",
        "pkg/p.py": "from .q import Q\n",
        "pkg/q.py": "def g():\n    import pkg.p\n",
        "pkg/r.py": "from .s import S\n",
        "pkg/s.py": "from .r import R\n",
        "pkg/t.py": "from .t import T\n",            # a module importing itself is no circle
    })
    graph = import_graph(pkg2)
    assert circles(graph) == [["pkg.p", "pkg.q"], ["pkg.r", "pkg.s"]]
    assert circle_path(graph, ["pkg.r", "pkg.s"]) == ["pkg.r", "pkg.s", "pkg.r"]


def test_synthetic_long_module_is_named(tmp_path):
    pkg = _write(tmp_path, {"pkg/__init__.py": "", "pkg/ok.py": "x = 1\n" * MAX_LINES,
                            "pkg/long.py": "x = 1\n" * (MAX_LINES + 1), "pkg/notes.js": "//\n" * 5000})
    assert long_modules(pkg) == [("pkg.long", MAX_LINES + 1)]


def test_synthetic_subpackages_in_layers_and_a_circle_between_two(tmp_path):
    pkg = _write(tmp_path, {
        "pkg/__init__.py": "", "pkg/base.py": "",
        "pkg/low/__init__.py": "", "pkg/low/a.py": "from ..base import x\n",
        "pkg/mid/__init__.py": "", "pkg/mid/b.py": "def f():\n    from ..low.a import y\n",
        "pkg/top/__init__.py": "", "pkg/top/c.py": "from ..mid.b import f\nfrom ..low.a import y\n",
    })
    pg = subpackage_graph(import_graph(pkg), pkg)
    assert pg == {ROOT: {}, "low": {}, "mid": {"low": "pkg.mid.b -> pkg.low.a"},
                  "top": {"low": "pkg.top.c -> pkg.low.a", "mid": "pkg.top.c -> pkg.mid.b"}}
    assert layers(pg) == {ROOT: 0, "low": 0, "mid": 1, "top": 2}
    (pkg / "low" / "a.py").write_text("from ..base import x\nfrom ..top.c import z\n")
    try:
        layers(subpackage_graph(import_graph(pkg), pkg))
    except AssertionError as exc:
        assert "low <-> mid <-> top" in str(exc) and "pkg.low.a -> pkg.top.c" in str(exc)
    else:
        raise AssertionError("a circle of subpackages was not found")
    doc = "| layer | subpackage | what | modules |\n|---|---|---|---|\n| 0 | `low/` | x | `a` |\n| 2 | `top/` | y | `c`, `d` |\n"
    assert documented_layers(doc) == {"low": (0, {"a"}), "top": (2, {"c", "d"})}


# -- the package itself ---------------------------------------------------------------------------------------

def test_grasplan_has_no_import_circle():
    graph = import_graph(PACKAGE)
    assert len(graph) > 40 and sum(len(e) for e in graph.values()) > 100   # the graph was really read
    found = circles(graph)
    assert not found, "import circles (imports inside functions and under TYPE_CHECKING count):\n" + "\n".join(
        describe(graph, c, PACKAGE) for c in found)


def test_no_grasplan_module_over_600_lines():
    too_long = long_modules(PACKAGE)
    assert not too_long, f"modules over {MAX_LINES} lines (split them by job): " + ", ".join(
        f"{m} ({n})" for m, n in too_long)


def test_at_most_six_modules_at_the_root():
    root = sorted(p.stem for p in PACKAGE.glob("*.py"))
    assert len(root) <= MAX_ROOT_MODULES, f"modules at the package root: {root}; move them into a subpackage"


def test_subpackages_import_only_lower_layers_and_the_docs_list_each_at_its_layer():
    graph = import_graph(PACKAGE)
    found = layers(subpackage_graph(graph, PACKAGE))
    assert max(found.values()) >= 8  # the layers were really computed
    documented = documented_layers(ARCHITECTURE.read_text(encoding="utf-8"))
    problems = []
    for pkg, layer in sorted(found.items(), key=lambda kv: (kv[1], kv[0])):
        mods = {m.split(".")[-1] if pkg == ROOT else m[len(f"grasplan.{pkg}."):]
                for m in graph if subpackage(m, PACKAGE) == pkg and m not in ("grasplan", f"grasplan.{pkg}")}
        if pkg not in documented:
            problems.append(f"{pkg}: missing (layer {layer}, modules {', '.join(sorted(mods))})")
            continue
        doc_layer, doc_mods = documented[pkg]
        if doc_layer != layer:
            problems.append(f"{pkg}: documented at layer {doc_layer}, its imports put it at {layer}")
        if doc_mods != mods:
            problems.append(f"{pkg}: modules documented {sorted(doc_mods)}, in the package {sorted(mods)}")
    problems += [f"{pkg}: documented but no such subpackage" for pkg in documented if pkg not in found]
    assert not problems, "docs/architecture.md's layer table does not match the package:\n" + "\n".join(problems)


def test_every_package_re_export_resolves_to_its_object_in_a_fresh_interpreter():
    """Each public name a package ``__init__`` lists resolves (no stale module path) and is the
    object, not a module of the same name, even after every module was imported directly."""
    script = r'''
import importlib, pkgutil, sys, types
import grasplan
infos = list(pkgutil.walk_packages(grasplan.__path__, "grasplan."))
for info in infos:
    importlib.import_module(info.name)
bad, checked = [], 0
for info in [i for i in infos if i.ispkg] + [types.SimpleNamespace(name="grasplan")]:
    pkg = importlib.import_module(info.name)
    for name in getattr(pkg, "__lazy_exports__", {}):
        checked += 1
        try:
            value = getattr(pkg, name)
        except Exception as exc:
            bad.append(f"{info.name}.{name}: {type(exc).__name__}: {exc}")
            continue
        if isinstance(value, types.ModuleType) and not hasattr(value, "__path__"):
            bad.append(f"{info.name}.{name} is the module {value.__name__}, not the object it names")
print("\n".join(bad) or f"{checked} names")
sys.exit(1 if bad or checked < 100 else 0)
'''
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr[-3000:]


#: the longest a function or method may be (lines, decorators excluded): longer ones are split into named steps
MAX_FUNCTION_LINES = 100
#: the longest a module docstring may be (lines): it says what the module is; rationale goes to functions and docs
MAX_DOCSTRING_LINES = 15
#: code comments and docstrings say what code does, not which issue or day changed it
HISTORY = re.compile(r"\bissue\s*#?\d+", re.I)


def long_functions(pkg_dir: Path, limit: int = MAX_FUNCTION_LINES) -> list[tuple[str, int]]:
    """``(module:function, lines)`` for every function in the package longer than ``limit`` lines."""
    out = []
    for name, path in modules(pkg_dir).items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = (node.end_lineno or node.lineno) - node.lineno + 1
                if n > limit:
                    out.append((f"{name}:{node.name}", n))
    return out


def long_docstrings(pkg_dir: Path, limit: int = MAX_DOCSTRING_LINES) -> list[tuple[str, int]]:
    """``(module, lines)`` for every module docstring longer than ``limit`` lines."""
    out = []
    for name, path in modules(pkg_dir).items():
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8")), clean=False)
        if doc and doc.count("\n") + 1 > limit:
            out.append((name, doc.count("\n") + 1))
    return out


def history_lines(pkg_dir: Path) -> list[str]:
    """``module:line: text`` of every line naming an issue number."""
    return [f"{name}:{i}: {line.strip()}" for name, path in modules(pkg_dir).items()
            for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1) if HISTORY.search(line)]


def test_synthetic_long_function_docstring_and_history_are_named(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text('"""' + "line\n" * 20 + '"""\n')
    body = "\n".join(f"    x{i} = {i}" for i in range(120))
    (pkg / "m.py").write_text(f'"""Short."""\n# fixed in issue 12\ndef long():\n{body}\n\ndef short():\n    return 1\n')
    assert [n for n, _ in long_functions(pkg)] == ["pkg.m:long"]
    assert long_docstrings(pkg) == [("pkg", 21)]
    assert history_lines(pkg) == ["pkg.m:2: # fixed in issue 12"]


def test_no_grasplan_function_over_100_lines():
    found = long_functions(PACKAGE)
    assert not found, "functions over 100 lines (split them into named steps): " + ", ".join(
        f"{m} ({n})" for m, n in found)


def test_module_docstrings_say_what_the_module_is_in_at_most_15_lines():
    found = long_docstrings(PACKAGE)
    assert not found, "module docstrings over 15 lines (move rationale into the functions it explains): " + ", ".join(
        f"{m} ({n})" for m, n in found)


def test_no_issue_history_in_code():
    found = history_lines(PACKAGE)
    assert not found, "code comments tell history (say what the code does instead):\n" + "\n".join(found)
