"""Strict JSON reading shared by every reader of JSON input (scenes, plans, picks, service bodies).

:func:`loads_strict` is :func:`json.loads` that refuses an object holding one key twice: JSON
parsers silently keep the last value (YAML refuses it), so a scene whose instance names ``"T"``
twice would be planned with whichever pose the parser kept. The caller wraps
:class:`DuplicateKeyError` into its own error with the file or field it read.
"""
from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any


class DuplicateKeyError(ValueError):
    """A JSON object names one key twice (``key`` holds it)."""

    def __init__(self, key: str) -> None:
        self.key = key
        shown = key if len(key) <= 40 else key[:37] + "..."
        super().__init__(f"duplicate key {json.dumps(shown)} in one JSON object (a parser would keep only the "
                         f"last value); write each key once")


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out = dict(pairs)
    if len(out) != len(pairs):
        seen: set[str] = set()
        for k, _ in pairs:
            if k in seen:
                raise DuplicateKeyError(k)
            seen.add(k)
    return out


def loads_strict(text: str | bytes, *, parse_float: Callable[[str], Any] | None = None,
                 parse_int: Callable[[str], Any] | None = None,
                 parse_constant: Callable[[str], Any] | None = None) -> Any:
    """``json.loads(text)`` refusing duplicate keys (:class:`DuplicateKeyError`); the number
    hooks are :func:`json.loads`'s. Other errors are json's own (``json.JSONDecodeError``,
    ``RecursionError``, ``ValueError``)."""
    return json.loads(text, object_pairs_hook=_no_duplicates, parse_float=parse_float, parse_int=parse_int,
                      parse_constant=parse_constant)
