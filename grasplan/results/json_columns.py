"""Column-wise JSON: a table's rows as Python values for ``json.dumps`` and as the very text
``json.dumps`` writes for them, both from one definition of each field.

A :class:`Record` (a JSON object per row) is a tuple of :class:`Field` (key, column, the rows that
have it). Columns (:class:`Column`): :class:`Numbers` (int / float arrays of any row shape, rounded
or not, null where a test says), :class:`Strings`, :class:`Bools`, :class:`Names` (codes into a
tuple of names), :class:`Items` (a fixed-length JSON list of columns), a nested :class:`Record`
(null where a test says) and :class:`Spread` (per-row objects whose keys join the enclosing
record). :func:`join_rows` turns a record's pieces into the text of its rows.
:mod:`grasplan.results.writer` builds the per-grasp record of the grasps/1 and plan/1 files from these.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol, Union

import numpy as np

from ..io import to_json_text

#: a piece of row text: the same str for every row, or an (n,) object array of str
Piece = Union[str, np.ndarray]
#: rows (n,) int -> (n,) bool
RowMask = Callable[[np.ndarray], np.ndarray]


class Column(Protocol):
    """What every column answers for rows ``rows`` (int indices into its arrays):

    * ``values(rows)``: the Python values; ``json.dumps`` of each is that row's JSON;
    * ``pieces(rows)``: the same text as pieces, str constants and (n,) object arrays of str, whose
      row-wise concatenation is each row's JSON (no per-row Python work for numeric columns: each
      distinct number is formatted once);
    * ``encodable(rows)``: whether json writes every value (finite numbers, strings it can order);
      when not, the caller goes through ``values`` so json raises exactly what it would.
    """

    def values(self, rows: np.ndarray) -> list[Any]: ...

    def pieces(self, rows: np.ndarray) -> list[Piece]: ...

    def encodable(self, rows: np.ndarray) -> bool: ...


# ------------------------------------------------------------------------------------------------
# text helpers
# ------------------------------------------------------------------------------------------------
def number_texts(a: np.ndarray) -> np.ndarray:
    """Object array (a's shape) of the text json writes for each element: ``float.__repr__`` /
    ``int.__repr__`` of the Python number ``tolist`` gives."""
    a = np.asarray(a)
    flat = a.ravel()
    if flat.dtype.kind == "f":
        flat = flat.astype(np.float64)  # tolist would give these Python floats too
    if not flat.size:
        return np.zeros(a.shape, dtype=object)
    # poses repeat few distinct numbers: format each distinct bit pattern once (bits, not values:
    # -0.0 and 0.0 are written differently)
    key = flat.view(np.int64) if flat.dtype == np.float64 else flat
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    texts = np.array(list(map(repr, flat[first].tolist())), dtype=object)
    return texts[inv.reshape(-1)].reshape(a.shape)


def string_texts(values: np.ndarray) -> np.ndarray:
    """Object array of the JSON text of each value, encoded once per distinct value (TypeError:
    values np.unique cannot order or json cannot encode)."""
    if not len(values):
        return np.zeros(0, dtype=object)
    u, inv = np.unique(values, return_inverse=True)
    return np.array([to_json_text(v) for v in u.tolist()], dtype=object)[inv.reshape(-1)]


def _nested(out: list[Piece], texts: np.ndarray) -> None:
    """Append to ``out`` the pieces of the JSON lists of ``texts`` (n, *shape) row by row."""
    if texts.ndim == 1:
        out.append(texts)
        return
    out.append("[")
    for j in range(texts.shape[1]):
        if j:
            out.append(", ")
        _nested(out, texts[:, j])
    out.append("]")


def _masked(mask: np.ndarray, piece: Piece) -> np.ndarray:
    """``piece`` where ``mask``, "" elsewhere, as an (n,) object array."""
    return np.where(mask, piece, "").astype(object)


def _merged(pieces: list[Piece]) -> list[Piece]:
    """Adjacent str constants joined into one."""
    out: list[Piece] = []
    for p in pieces:
        if isinstance(p, str) and out and isinstance(out[-1], str):
            out[-1] += p
        else:
            out.append(p)
    return out


def _piece_matrix(pieces: list[Piece], n: int) -> np.ndarray:
    """(n, len(pieces)) object array: row i holds row i's piece of each piece in order."""
    P = np.empty((n, len(pieces)), dtype=object)
    for j, p in enumerate(pieces):
        P[:, j] = p
    return P


def _row_texts(pieces: list[Piece], n: int) -> list[str]:
    """Each of the n rows' text: the pieces concatenated per row."""
    return ["".join(r) for r in _piece_matrix(pieces, n).tolist()]


def join_rows(pieces: list[Piece], n: int) -> str:
    """The n rows' text: the pieces concatenated per row, rows separated by ", "."""
    return "".join(_piece_matrix(_merged([*pieces, ", "]), n).ravel().tolist())[:-2]


# ------------------------------------------------------------------------------------------------
# columns
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Numbers:
    """Numbers ``data[rows]`` (each row a number or nested lists of its shape); ``decimals``: rounded
    first (``np.round``); ``null``: the rows written ``null`` (one number per row only)."""

    data: np.ndarray
    decimals: int | None = None
    null: RowMask | None = None

    def _select(self, rows: np.ndarray) -> np.ndarray:
        a = self.data[rows]
        return a if self.decimals is None else np.round(a, self.decimals)

    def values(self, rows: np.ndarray) -> list[Any]:
        v = self._select(rows).tolist()
        if self.null is not None:
            for k in np.flatnonzero(self.null(rows)).tolist():
                v[k] = None
        return v

    def pieces(self, rows: np.ndarray) -> list[Piece]:
        texts = number_texts(self._select(rows))
        out: list[Piece] = []
        if self.null is None:
            _nested(out, texts)
            return out
        if texts.ndim > 1:  # each row's nested list as one text, then null where the test says
            _nested(out, texts)
            texts = np.array(_row_texts(out, len(rows)), dtype=object)
        return [np.where(self.null(rows), "null", texts).astype(object)]

    def encodable(self, rows: np.ndarray) -> bool:
        a = self._select(rows)
        if self.null is not None:
            a = a[~self.null(rows)]
        return a.dtype.kind not in "fc" or bool(np.all(np.isfinite(a)))


@dataclass(frozen=True)
class Strings:
    """Strings ``data[rows]`` (``as_str``: converted with ``astype(str)`` first)."""

    data: np.ndarray
    as_str: bool = False

    def _select(self, rows: np.ndarray) -> np.ndarray:
        a = self.data[rows]
        return a.astype(str) if self.as_str else a

    def values(self, rows: np.ndarray) -> list[Any]:
        return self._select(rows).tolist()

    def pieces(self, rows: np.ndarray) -> list[Piece]:
        return [string_texts(self._select(rows))]

    def encodable(self, rows: np.ndarray) -> bool:
        if self.as_str:
            return True  # strings always sort and encode
        a = self.data[rows]
        if a.dtype.kind == "U" or set(map(type, a.tolist())) <= {str}:
            return True
        try:
            string_texts(a)
        except TypeError:  # values np.unique cannot order, or json cannot encode: not plain strings
            return False
        return True


@dataclass(frozen=True)
class Bools:
    """``true`` where ``data[rows]`` is non-zero, ``false`` elsewhere."""

    data: np.ndarray

    def values(self, rows: np.ndarray) -> list[Any]:
        return [bool(x) for x in self.data[rows].tolist()]

    def pieces(self, rows: np.ndarray) -> list[Piece]:
        return [np.where(self.data[rows] != 0, "true", "false").astype(object)]

    def encodable(self, rows: np.ndarray) -> bool:
        return True


@dataclass(frozen=True)
class Names:
    """``names[code]`` for the integer codes ``codes[rows]`` (Python indexing: -len..len-1)."""

    codes: np.ndarray
    names: tuple[str, ...]

    def values(self, rows: np.ndarray) -> list[Any]:
        return [self.names[c] for c in self.codes[rows].tolist()]

    def pieces(self, rows: np.ndarray) -> list[Piece]:
        texts = np.array([to_json_text(s) for s in self.names], dtype=object)
        c = self.codes[rows].astype(np.int64)
        n = len(self.names)
        # rows whose code is out of range are never written (encodable says so); index them safely
        return [texts[np.where((c >= -n) & (c < n), c, 0)]]

    def encodable(self, rows: np.ndarray) -> bool:
        c = self.codes[rows]
        n = len(self.names)
        return not c.size or bool(c.min() >= -n and c.max() < n)


@dataclass(frozen=True)
class Items:
    """A JSON list of one value of each column per row."""

    columns: tuple[Column, ...]

    def values(self, rows: np.ndarray) -> list[Any]:
        return [list(t) for t in zip(*(c.values(rows) for c in self.columns))]

    def pieces(self, rows: np.ndarray) -> list[Piece]:
        out: list[Piece] = ["["]
        for j, c in enumerate(self.columns):
            if j:
                out.append(", ")
            out += c.pieces(rows)
        out.append("]")
        return out

    def encodable(self, rows: np.ndarray) -> bool:
        return all(c.encodable(rows) for c in self.columns)


class JSONObject(Protocol):
    def to_json(self) -> dict[str, Any]: ...


@dataclass(frozen=True)
class Spread:
    """The keys of ``objects[row].to_json()`` joined into the enclosing record: the field is
    ``Field(None, spread, present=spread.has)`` (the rows without an object have none of those keys)."""

    objects: Mapping[int, JSONObject]

    def has(self, rows: np.ndarray) -> np.ndarray:
        keys = np.fromiter((int(k) for k in self.objects), dtype=np.int64, count=len(self.objects))
        return np.isin(rows, keys)

    def values(self, rows: np.ndarray) -> list[Any]:
        return [self.objects[int(r)].to_json() for r in rows.tolist()]

    def pieces(self, rows: np.ndarray) -> list[Piece]:
        texts = np.full(len(rows), "", dtype=object)
        for k in np.flatnonzero(self.has(rows)).tolist():
            inner = to_json_text(self.objects[int(rows[k])].to_json())[1:-1]
            texts[k] = ", " + inner if inner else ""
        return [texts]

    def encodable(self, rows: np.ndarray) -> bool:
        return True  # json raises the same error from both paths


@dataclass(frozen=True)
class Field:
    """``key`` (None: a :class:`Spread`) with the value of ``column``, on the rows where ``present``
    (None: every row)."""

    key: str | None
    column: Column
    present: RowMask | None = None


@dataclass(frozen=True)
class Record:
    """A JSON object per row: its fields in order, none on the rows where ``null`` (written ``null``).
    The first field is a key every row has."""

    fields: tuple[Field, ...]
    null: RowMask | None = None

    def __post_init__(self) -> None:
        if not self.fields or self.fields[0].key is None or self.fields[0].present is not None:
            raise ValueError("a Record's first field must be a key that every row has")
        if any(f.key is None and f.present is None for f in self.fields):
            raise ValueError("a Spread field needs present= (its column's has): the rows without an object")

    def _live(self, rows: np.ndarray) -> np.ndarray:
        return np.ones(len(rows), dtype=bool) if self.null is None else ~np.asarray(self.null(rows), dtype=bool)

    def values(self, rows: np.ndarray) -> list[Any]:
        live = np.flatnonzero(self._live(rows))
        sub = rows[live]
        objs: list[dict[str, Any]] = [{} for _ in range(len(sub))]
        for f in self.fields:  # field by field, so each dict's keys come in the fields' order
            at = None if f.present is None else np.flatnonzero(f.present(sub))
            vals = f.column.values(sub if at is None else sub[at])
            targets = objs if at is None else [objs[k] for k in at.tolist()]
            if f.key is None:
                for d, v in zip(targets, vals):
                    d.update(v)
            else:
                key = f.key
                for d, v in zip(targets, vals):
                    d[key] = v
        if len(live) == len(rows):
            return list(objs)
        out: list[Any] = [None] * len(rows)
        for k, d in zip(live.tolist(), objs):
            out[k] = d
        return out

    def pieces(self, rows: np.ndarray) -> list[Piece]:
        out: list[Piece] = []
        for j, f in enumerate(self.fields):
            own: list[Piece] = [] if f.key is None else [("{" if j == 0 else ", ") + to_json_text(f.key) + ": "]
            own += f.column.pieces(rows)
            if f.present is not None:
                m = f.present(rows)
                own = [_masked(m, p) for p in own]
            out += own
        out = _merged([*out, "}"])
        if self.null is None:
            return out
        live = self._live(rows)
        nulled: list[Piece] = [np.where(live, out[0], "null").astype(object)]
        return nulled + [_masked(live, p) for p in out[1:]]

    def encodable(self, rows: np.ndarray) -> bool:
        sub = rows[self._live(rows)]
        return all(f.column.encodable(sub if f.present is None else sub[f.present(sub)]) for f in self.fields)


# ------------------------------------------------------------------------------------------------
# blocks: JSON objects whose lists are columns
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Listed:
    """The JSON list of a column's rows ``0 .. n-1``: a leaf of a block (a dict whose values are
    :class:`Listed`, nested blocks or plain JSON values)."""

    column: Column
    n: int

    def values(self) -> list[Any]:
        return self.column.values(np.arange(self.n))

    def text(self) -> str:
        rows = np.arange(self.n)
        if not self.column.encodable(rows):
            return to_json_text(self.values())  # json raises what it raises for the values
        return "[" + join_rows(self.column.pieces(rows), self.n) + "]"


def block_values(block: Mapping[str, Any]) -> dict[str, Any]:
    """``block`` with its :class:`Listed` leaves as Python lists (what ``json.dumps`` takes)."""
    return {k: v.values() if isinstance(v, Listed) else block_values(v) if isinstance(v, Mapping) else v
            for k, v in block.items()}


def block_text(block: Mapping[str, Any]) -> str:
    """``json.dumps(block_values(block))``, each column's numbers formatted once per distinct value."""
    return "{" + ", ".join(f"{to_json_text(str(k))}: " + (v.text() if isinstance(v, Listed) else block_text(v)
                                                           if isinstance(v, Mapping) else to_json_text(v))
                           for k, v in block.items()) + "}"
