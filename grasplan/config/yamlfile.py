"""The one YAML reader of grasplan: every YAML input (cells, grippers, robots, scoring, manifests,
scenes, pose files) is parsed here, bounded in time and memory, and every problem is an
:class:`~grasplan.errors.InputError` (exit 3) naming the file and the field
(:func:`load_yaml_text` for a text, :func:`read_yaml_file` for a file).
"""
from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import yaml

from ..errors import InputError
from .inputs import read_input_bytes

#: most alias uses in one document, and most nodes the document may expand to through them
MAX_ALIASES = 1000
MAX_EXPANDED_NODES = 200_000
#: most structural characters (``, : - [ { ?`` and line breaks) in one document, counted before
#: parsing: a bound on its node count that keeps any document within about 2 s to read (a YAML
#: batch manifest gets :data:`MAX_MANIFEST_ENTRIES`)
MAX_ENTRIES = 50_000
MAX_MANIFEST_ENTRIES = 200_000
_STRUCTURE = ",:-[{?\n"
#: deepest nesting of sequences and mappings
MAX_DEPTH = 100
#: default byte limit of a YAML input
DEFAULT_MAX_BYTES = 1_000_000


class _Loader(yaml.SafeLoader):
    """SafeLoader without implicit timestamps, counting aliases, refusing duplicate keys."""

    def __init__(self, stream: str):
        super().__init__(stream)
        self.aliases = 0
        self.depth = 0

    def compose_node(self, parent: yaml.Node | None, index: object) -> yaml.Node | None:
        if self.depth >= MAX_DEPTH:
            mark = self.peek_event().start_mark
            raise _Refused(f"nested deeper than {MAX_DEPTH} levels (line {mark.line + 1})")
        if self.check_event(yaml.AliasEvent):
            self.aliases += 1
            if self.aliases > MAX_ALIASES:
                mark = self.peek_event().start_mark
                raise _Refused(f"more than {MAX_ALIASES} aliases (line {mark.line + 1}); "
                               "expand them or split the file")
        self.depth += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self.depth -= 1


class _CLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """libyaml's parser and composer (C: a 1 MB document composes in well under a second, where
    the pure-Python parser needs minutes; libyaml refuses nesting deeper than 1000 itself), then
    the shape checks of :func:`_check_shape` in Python."""


# timestamps stay strings: no config field is a date, and datetime construction errors on 2001-13-45
_Loader.yaml_implicit_resolvers = _CLoader.yaml_implicit_resolvers = {
    k: [(tag, rx) for tag, rx in v if tag != "tag:yaml.org,2002:timestamp"]
    for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
#: the loader used: the C one when PyYAML was built with libyaml
LOADER: type = _CLoader if getattr(yaml, "__with_libyaml__", False) else _Loader


def _check_shape(root: yaml.Node) -> None:
    """Refuse nesting deeper than :data:`MAX_DEPTH` and more than :data:`MAX_ALIASES` alias uses
    (a node reached again is an alias) in a composed document (iterative: no recursion)."""
    stack: list[tuple[yaml.Node, int]] = [(root, 1)]
    seen: set[int] = set()
    aliases = 0
    while stack:
        node, depth = stack.pop()
        if id(node) in seen:
            aliases += 1
            if aliases > MAX_ALIASES:
                raise _Refused(f"more than {MAX_ALIASES} aliases (line {node.start_mark.line + 1}); "
                               "expand them or split the file")
            continue
        seen.add(id(node))
        if depth > MAX_DEPTH:
            raise _Refused(f"nested deeper than {MAX_DEPTH} levels (line {node.start_mark.line + 1})")
        if isinstance(node, yaml.SequenceNode):
            stack += [(c, depth + 1) for c in node.value]
        elif isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                stack += [(k, depth + 1), (v, depth + 1)]


class _Refused(Exception):
    pass


def _expanded(node: yaml.Node, memo: dict[int, int]) -> int:
    """Number of nodes ``node`` stands for once every alias is expanded (memoised per node)."""
    key = id(node)
    if key in memo:
        return memo[key]
    memo[key] = 1  # a recursive alias counts once (construction keeps it a reference)
    n = 1
    if isinstance(node, yaml.SequenceNode):
        for c in node.value:
            n += _expanded(c, memo)
    elif isinstance(node, yaml.MappingNode):
        for k, v in node.value:
            n += _expanded(k, memo) + _expanded(v, memo)
    n = min(n, MAX_EXPANDED_NODES + 1)
    memo[key] = n
    return n


def _path_of(root: yaml.Node, target: yaml.Node) -> str:
    """``a.b[2].c`` of ``target`` in the tree under ``root`` ("" when not found)."""
    stack: list[tuple[yaml.Node, str]] = [(root, "")]
    seen: set[int] = set()
    while stack:
        node, path = stack.pop()
        if node is target:
            return path
        if id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, yaml.SequenceNode):
            stack += [(c, f"{path}[{i}]") for i, c in enumerate(node.value)]
        elif isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                name = k.value if isinstance(k, yaml.ScalarNode) else "?"
                stack.append((v, f"{path}.{name}" if path else str(name)))
                stack.append((k, path))
    return ""


def _construct(loader: Any, root: yaml.Node, where: str) -> Any:
    failing: list[yaml.Node] = []

    def guarded(fn: Callable[..., Any]) -> Callable[..., Any]:
        def wrapper(self: Any, node: yaml.Node, *a: Any, **k: Any) -> Any:
            try:
                return fn(self, node, *a, **k)
            except (_Refused, RecursionError):
                raise
            except Exception:
                failing.append(node)
                raise
        return wrapper

    ctor = loader.construct_object
    loader.construct_object = guarded(type(loader).construct_object).__get__(loader)
    try:
        return loader.construct_document(root)
    except (_Refused, RecursionError):
        raise
    except Exception as exc:  # noqa: BLE001 - any constructor failure (KeyError for !!bool maybe, ...) is bad input
        node = failing[0] if failing else None
        field = _path_of(root, node) if node is not None else ""
        at = f"line {node.start_mark.line + 1}" if node is not None else "?"
        shown = node.value if isinstance(node, yaml.ScalarNode) else ""
        shown = f" {str(shown)[:40]!r}" if shown else ""
        tag = f" ({node.tag.rsplit(':', 1)[-1]})" if node is not None and node.tag else ""
        first = "not a valid value of that type" if isinstance(exc, (KeyError, AttributeError)) else \
            (str(exc).splitlines() or ["invalid value"])[0][:100]
        raise InputError(f"{where}: {field or 'value'} ({at}): cannot read{shown}{tag}: {first}") from None
    finally:
        loader.construct_object = ctor


def _check_duplicates(root: yaml.Node, where: str) -> None:
    stack, seen = [root], set()
    while stack:
        node = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, yaml.MappingNode):
            keys: dict[str, int] = {}
            for k, v in node.value:
                if isinstance(k, yaml.ScalarNode) and k.tag != "tag:yaml.org,2002:merge":
                    if k.value in keys:
                        field = _path_of(root, v)
                        raise InputError(f"{where}: duplicate key {k.value[:40]!r} at {field or 'top level'} "
                                         f"(lines {keys[k.value]} and {k.start_mark.line + 1}); each key once")
                    keys[k.value] = k.start_mark.line + 1
                stack += [k, v]
        elif isinstance(node, yaml.SequenceNode):
            stack += node.value


def structural_entries(text: str) -> int:
    """What the entry limit counts in a YAML text: commas, colons, dashes, brackets and line breaks."""
    return sum(text.count(c) for c in _STRUCTURE)


def load_yaml_text(text: str, where: str, *, max_entries: int = MAX_ENTRIES) -> Any:
    """The Python value of the YAML ``text``; ``where`` names the input in errors (``"cell /path/x.yaml"``).

    What it guarantees beyond ``yaml.safe_load``:

    * **size**: at most ``max_entries`` structural characters (:func:`structural_entries`), counted
      before parsing (and the caller's byte limit: :func:`read_yaml_file` reads files through
      :func:`grasplan.config.inputs.read_input_bytes`, so a FIFO or a device is refused before reading);
    * **time**: libyaml's C parser and composer when PyYAML has them (1 MB in about a second; the
      pure-Python parser needs minutes for a long flow list), the checks below in Python;
    * **aliases**: a document whose aliases would expand to more than :data:`MAX_EXPANDED_NODES`
      nodes (a "billion laughs" bomb: 1 KB of nested anchors, 9^9 leaves) is refused after composing,
      before anything walks it; at most :data:`MAX_ALIASES` alias uses;
    * **values**: scalars PyYAML cannot construct (``!!float abc``, ``!!bool maybe``, ``!!timestamp x``,
      an integer of 5000 digits) are errors naming the field; dates are not special (``2001-13-45`` is
      the string it looks like, which the field's own check then refuses);
    * **duplicate keys** are refused, naming the key (YAML says keys are unique; PyYAML keeps the last);
    * **nesting** deeper than Python's stack is an error, not a crash.
    """
    entries = structural_entries(text)
    if entries > max_entries:
        raise InputError(f"{where}: {entries:,} entries (commas, colons, dashes, brackets, lines) is more than a "
                         f"grasplan YAML input holds (limit {max_entries:,}); split the file")
    try:
        loader = LOADER(text)  # the reader refuses control characters here already
    except yaml.YAMLError as exc:
        problem = getattr(exc, "reason", None) or (str(exc).splitlines() or ["not readable"])[0]
        raise InputError(f"{where}: not valid YAML: {str(problem)[:120]} (control characters are not allowed)") from None
    try:
        root = loader.get_single_node()
        if root is None:
            return None
        _check_shape(root)
        if _expanded(root, {}) > MAX_EXPANDED_NODES:
            raise _Refused(f"its aliases expand to more than {MAX_EXPANDED_NODES} nodes (an alias bomb?); "
                           "write the values out")
        _check_duplicates(root, where)
        return _construct(loader, root, where)
    except _Refused as exc:
        raise InputError(f"{where}: {exc}") from None
    except yaml.YAMLError as exc:
        first = (str(exc).splitlines() or ["syntax error"])[0]
        mark = getattr(exc, "problem_mark", None)
        at = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        problem = getattr(exc, "problem", None) or first
        if "maximum nesting depth" in str(problem):  # libyaml's own limit (1000)
            problem = f"nested deeper than {MAX_DEPTH} levels"
        raise InputError(f"{where}: not valid YAML{at}: {str(problem)[:120]}") from None
    except RecursionError:
        raise InputError(f"{where}: YAML nested too deeply") from None
    finally:
        loader.dispose()


def read_yaml_file(path: str | os.PathLike, *, what: str, max_bytes: int = DEFAULT_MAX_BYTES,
                   max_entries: int = MAX_ENTRIES) -> Any:
    """:func:`load_yaml_text` of the UTF-8 file ``path`` (a regular file of at most ``max_bytes``);
    ``what`` names the input (``"cell"``, ``"scoring"``)."""
    data = read_input_bytes(path, what=what, max_bytes=max_bytes)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{what} {path}: not a UTF-8 text file; {what.removesuffix(' file')} files are YAML") from None
    return load_yaml_text(text, f"{what} {path}", max_entries=max_entries)
