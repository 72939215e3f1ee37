"""Which parts a batch plans, with which options: files, folders and manifests become
:class:`PartEntry` rows (:func:`discover_parts`, :func:`read_manifest`), each with its per-part
overrides read by the one interpreter of option values (:func:`grasplan.config.option_kinds.parse_value`,
as on the command line); :func:`make_jobs` applies them, hashes every part and option set and
names the output folders."""
from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import os
import stat
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import ConfigError, GrasplanError, InputError
from ..io import sha256_file
from ..part.mesh import UNIT_CHOICES
from ..part.meshfile import SUPPORTED_SUFFIXES
from ..config.option_kinds import parse_value
from ..config.params import PARAM_CLASSES, option_fields
from .options import BatchOptions, options_hash

if TYPE_CHECKING:
    from ..setup.resolved import Cache, Setup, Source

#: suffixes a folder is searched for (files named on the command line may be any mesh grasplan reads)
FOLDER_SUFFIXES = (".stl", ".obj", ".ply")
MANIFEST_SUFFIXES = (".csv", ".yaml", ".yml")
#: manifest keys that are not parameter fields
ENTRY_KEYS = ("path", "units", "robot", "gripper", "cell", "part_pose")
#: BatchOptions fields a manifest row may set besides the parameters (part_pose sets T_world_part)
_TOP_KEYS = ("units", "robot", "gripper", "cell", "T_world_part")
#: the keys of a YAML manifest that is a mapping
YAML_TOP_KEYS = ("defaults", "parts")
#: the descriptions a part's options name, checked once per name before anything runs
DESCRIPTION_KINDS = ("robot", "gripper", "cell")


@dataclass(frozen=True)
class PartEntry:
    """One part to plan: ``path`` as it will be recorded (relative paths stay relative to the
    current folder), ``overrides`` (manifest options, already converted), ``origin`` (where it was
    named, for messages)."""

    path: str
    overrides: tuple[tuple[str, Any], ...] = ()
    origin: str = ""
    size: int | None = None  #: bytes, when known (the largest parts are started first)


def _key(k: Any) -> str:
    """A manifest key as it is looked up: lower case, dashes as underscores (``pose-index``)."""
    return str(k).strip().lower().replace("-", "_")


def accepted_keys(known: dict[str, Any]) -> list[str]:
    """Every key a manifest row may set (``known``: :func:`grasplan.config.params.option_fields`)."""
    return sorted({*ENTRY_KEYS, *(f.name for _, f in known.values())})


def _check_keys(keys: Iterable[Any], known: dict[str, Any], where: str, what: str = "column") -> set[str]:
    """The fields ``keys`` set (``thin`` and ``thin_spacing`` both set ``thin_spacing``); InputError
    naming a key no option has, or two keys for one field, with the accepted keys."""
    seen: dict[str, str] = {}
    for k in keys:
        key = "" if k is None else _key(k)
        if key == "" and what == "column":  # a CSV header's empty column (a trailing comma): its cells must be empty
            continue
        if key in ENTRY_KEYS:
            target = key
        elif key in known:
            target = known[key][1].name
        else:
            raise InputError(f"{where}: unknown {what} {str(k)[:80]!r}; accepted: {', '.join(accepted_keys(known))}")
        if target in seen:
            if seen[target] == str(k)[:80]:
                raise InputError(f"{where}: {what} {seen[target]!r} appears twice; give it once")
            raise InputError(f"{where}: {seen[target]!r} and {str(k)[:80]!r} both set {target}; give it once")
        seen[target] = str(k)[:80]
    return set(seen)


def _entry_from_mapping(row: dict, base_dir: Path, where: str, known: dict[str, Any] | None = None,
                        memo: dict[tuple[str, type, Any], tuple[str, Any]] | None = None) -> PartEntry:
    """The part a manifest row names, its values read as on the command line. ``memo`` (kept by
    the caller for one manifest) holds each distinct (key, value) once read: a column of 30,000
    equal cells, or a scoring file named on every row, is read once."""
    known = option_fields() if known is None else known
    memo = {} if memo is None else memo
    keys = {_key(k): v for k, v in row.items() if k is not None}
    raw_path = keys.pop("path", None)
    if raw_path is None or str(raw_path).strip() == "":
        raise InputError(f"{where}: no 'path'; every manifest row needs the part's mesh file in a 'path' column")
    p = os.path.expanduser(str(raw_path).strip())
    path = str(Path(p)) if os.path.isabs(p) else os.path.normpath(os.path.join(base_dir, p))
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        st = None
    if st is None or not stat.S_ISREG(st.st_mode):
        raise InputError(f"{where}: part file {path} not found (relative paths are relative to the manifest's folder)")
    overrides: dict[str, Any] = {}
    for key, value in keys.items():
        if value is None or (isinstance(value, str) and value.strip() == ""):
            continue  # an empty cell: the batch's option
        cell = (key, type(value), value)  # the type too: YAML's true == 1 == 1.0
        try:
            done = memo.get(cell)
        except TypeError:  # a YAML list: read every time
            done = None
        if done is None:
            done = _read_entry_value(key, value, base_dir, where, known)
            with contextlib.suppress(TypeError):
                memo[cell] = done
        overrides[done[0]] = done[1]
    return PartEntry(path=path, overrides=tuple(sorted(overrides.items())), origin=where, size=st.st_size)


def _read_entry_value(key: str, value: Any, base_dir: Path, where: str, known: dict[str, Any]) -> tuple[str, Any]:
    """(field, value) of one manifest cell (key normalised by :func:`_key`, value not empty)."""
    if key in ("units", "robot", "gripper", "cell"):
        text = str(value).strip()
        if key == "units" and text not in UNIT_CHOICES:
            raise InputError(f"{where}: units {text!r}; use one of {', '.join(UNIT_CHOICES)}")
        return key, text
    if key == "part_pose":
        from ..config.poses import parse_part_pose

        pose = str(value).strip()
        pp = Path(pose).expanduser()
        if pp.suffix.lower() in (".json", ".yaml", ".yml") and not pp.is_absolute():
            pose = str(base_dir / pp)
        try:
            return "T_world_part", tuple(tuple(r) for r in parse_part_pose(pose).tolist())
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None
    if key in known:
        _, f = known[key]
        return f.name, parse_value(f, value.strip() if isinstance(value, str) else value, where=f"{where}: ",
                                   base_dir=base_dir)
    raise InputError(f"{where}: unknown column {key!r}; accepted: {', '.join(accepted_keys(known))}")


#: a manifest larger than this is refused before it is read
MAX_MANIFEST_BYTES = 50_000_000


def _csv_rows(reader: Any, path: Path) -> Iterator[list[str]]:
    """The rows of a CSV manifest; a field longer than the csv module's limit (131,072 characters)
    or a damaged quote is an InputError naming the line."""
    while True:
        try:
            row = next(reader)
        except StopIteration:
            return
        except csv.Error as exc:
            raise InputError(f"manifest {path}:{reader.line_num}: cannot read the CSV row ({exc}); a field is "
                             "too long or a quote is not closed") from None
        yield row


def read_manifest(path: str | os.PathLike) -> list[PartEntry]:
    """Parts named by a CSV (header row with a ``path`` column) or YAML manifest.

    YAML: a list of mappings (or of bare paths), or ``{"defaults": {...}, "parts": [...]}`` where
    ``defaults`` applies to every part that does not set the key itself. Every key is checked
    (an unknown one, or one option set twice, is an InputError naming it and the accepted keys);
    the time is linear in the rows."""
    path = Path(path)
    from ..config.inputs import read_input_bytes

    data = read_input_bytes(path, what="manifest", max_bytes=MAX_MANIFEST_BYTES)  # no FIFO, no device
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"manifest {path}: not a UTF-8 text file; a manifest is CSV or YAML") from None
    known = option_fields()
    entries: list[PartEntry] = []
    if path.suffix.lower() == ".csv":
        entries = _csv_entries(path, text, known)
    else:
        entries = _yaml_entries(path, text, known)
    if not entries:
        raise InputError(f"{path}: the manifest lists no parts")
    return entries


def _csv_entries(path: Path, text: str, known: dict[str, Any]) -> list[PartEntry]:
    """The parts of a CSV manifest (see :func:`read_manifest`)."""
    reader = csv.reader(io.StringIO(text))
    header = next(_csv_rows(reader, path), None)
    if not header or "path" not in [h.strip().lower() for h in header]:
        raise InputError(f"{path}: a CSV manifest needs a header row with a 'path' column "
                         f"(e.g. 'path,units,pose_index'); got {header}")
    _check_keys(header, known, f"{path}:1 (header)")
    names = [_key(h) for h in header]
    memo: dict[tuple[str, type, Any], tuple[str, Any]] = {}
    out = []
    for row in _csv_rows(reader, path):
        if len(row) > len(names):
            raise InputError(f"{path}:{reader.line_num}: more values than header columns")
        if all(v.strip() == "" for v in row):
            continue
        out.append(_entry_from_mapping(dict(zip(names, row)), path.parent, f"{path}:{reader.line_num}", known, memo))
    return out


def _yaml_entries(path: Path, text: str, known: dict[str, Any]) -> list[PartEntry]:
    """The parts of a YAML manifest (see :func:`read_manifest`)."""
    from ..config.yamlfile import MAX_MANIFEST_ENTRIES, load_yaml_text, structural_entries

    entries = structural_entries(text)
    if entries > MAX_MANIFEST_ENTRIES:  # the YAML reader's bound on a document's nodes
        raise InputError(f"manifest {path}: {entries:,} YAML entries (commas, colons, dashes, brackets, lines) is "
                         f"more than a YAML manifest holds (limit {MAX_MANIFEST_ENTRIES:,}, about 30,000 parts); "
                         "write it as a CSV manifest (header 'path,...', no row limit) or split it")
    doc = load_yaml_text(text, f"manifest {path}", max_entries=MAX_MANIFEST_ENTRIES)
    by_field: dict[str, tuple[str, Any]] = {}  # the defaults by the field they set: (key, value)
    if isinstance(doc, dict):
        for k in doc:
            if k not in YAML_TOP_KEYS:
                raise InputError(f"{path}: unknown top-level key {str(k)[:80]!r}; a YAML manifest mapping has "
                                 f"{' and '.join(repr(x) for x in YAML_TOP_KEYS)} (parts: the list of parts)")
        if "parts" not in doc:
            raise InputError(f"{path}: no 'parts' list; a YAML manifest mapping has 'parts' (the list of parts) and "
                             "optional 'defaults'")
        defaults = doc.get("defaults") or {}
        if not isinstance(defaults, dict):
            raise InputError(f"{path}: 'defaults' must be a mapping of option -> value")
        fields = _check_keys(defaults, known, f"{path}: defaults", what="key")
        if "path" in fields:
            raise InputError(f"{path}: defaults: 'path' is set per part, not in defaults")
        by_field = {(k if k in ENTRY_KEYS else known[k][1].name): (k, v)
                    for k, v in ((_key(k), v) for k, v in defaults.items())}
        doc = doc.get("parts")
    if not isinstance(doc, list):
        raise InputError(f"{path}: a YAML manifest is a list of parts (or a mapping with a 'parts' list); "
                         "each part is a path or a mapping with 'path' and optional options")
    out = []
    memo: dict[tuple[str, type, Any], tuple[str, Any]] = {}
    for i, item in enumerate(doc):
        row = {"path": item} if isinstance(item, str) else item
        if not isinstance(row, dict):
            raise InputError(f"{path}: parts[{i}] must be a path or a mapping with 'path', got {str(item)[:80]!r}")
        where = f"{path}: parts[{i}]"
        own = _check_keys(row, known, where, what="key")
        # a part's own key replaces the default of the same option, however either is spelled
        merged = dict(kv for f, kv in by_field.items() if f not in own) if by_field else {}
        out.append(_entry_from_mapping({**merged, **row}, path.parent, where, known, memo))
    return out


def discover_parts(inputs: Sequence[str | os.PathLike]) -> list[PartEntry]:
    """Expand files, folders (recursive, sorted) and manifests into parts, in the order given.

    Raises InputError when an input does not exist, a manifest is malformed, or nothing is found."""
    if not inputs:
        raise InputError("no parts given; name mesh files, folders or a CSV/YAML manifest")
    out: list[PartEntry] = []
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            found = sorted(q for q in p.rglob("*") if q.is_file() and q.suffix.lower() in FOLDER_SUFFIXES
                           and not any(part.startswith(".") for part in q.relative_to(p).parts))
            out += [PartEntry(path=str(q), origin=str(p)) for q in found]
        elif p.is_file() and p.suffix.lower() in MANIFEST_SUFFIXES:
            out += read_manifest(p)
        elif p.is_file() and p.suffix.lower() in SUPPORTED_SUFFIXES:
            out.append(PartEntry(path=str(p), origin="command line"))
        elif p.is_file():
            raise InputError(f"{p}: not a mesh ({', '.join(SUPPORTED_SUFFIXES)}) or a manifest "
                             f"({', '.join(MANIFEST_SUFFIXES)})")
        else:
            raise InputError(f"{p}: no such file or folder")
    if not out:
        raise InputError(f"no parts found in {', '.join(map(str, inputs))} (folders are searched recursively "
                         f"for {', '.join(FOLDER_SUFFIXES)})")
    return out


def apply_overrides(options: BatchOptions, overrides: Iterable[tuple[str, Any]]) -> BatchOptions:
    """``options`` with a manifest row's overrides (each param class re-validates itself)."""
    rest = dict(overrides)
    if not rest:
        return options
    new: dict[str, Any] = {k: rest.pop(k) for k in _TOP_KEYS if k in rest}
    for attr, cls in zip(("candidates", "grasps", "planning"), PARAM_CLASSES):
        names = {f.name for f in dataclasses.fields(cls)}
        mine = {k: v for k, v in rest.items() if k in names}
        if mine:
            new[attr] = dataclasses.replace(getattr(options, attr), **mine)
    return dataclasses.replace(options, **new)


# --------------------------------------------------------------------------------------------- jobs
@dataclass(frozen=True)
class PartJob:
    """A part with everything needed to plan it: ``dir_name`` under OUTDIR, its options and hash."""

    path: str
    sha256: str
    dir_name: str
    options: BatchOptions
    options_hash: str
    duplicate_of: str | None = None  #: path of an earlier part with the same file and options
    size: int | None = None  #: bytes, when known
    #: its robot, gripper and cell, resolved and loaded once by the batch (shared by the jobs naming them)
    setup: Setup | None = field(default=None, compare=False, repr=False)


def make_jobs(entries: Sequence[PartEntry], options: BatchOptions) -> list[PartJob]:
    """Hash every part file (streamed) and every option set; name the output folders. Every
    robot, gripper and cell description named is resolved and loaded once (:func:`check_description`),
    so a file that is not one is refused here, before anything runs; each job holds the
    :class:`~grasplan.setup.resolved.Setup` of its three. Linear in the entries.

    Raises InputError / ConfigError for a bad per-part option or an unknown or unusable robot,
    gripper or cell (naming the manifest line and the field, or the option)."""
    fingerprints: dict[tuple[str, Any], str] = {}
    loaded: Cache = {}
    setups: dict[tuple[str, str, str], Setup] = {}
    by_overrides: dict[tuple[tuple[str, Any], ...], tuple[BatchOptions, str, Setup]] = {}
    hashed: dict[str, str] = {}  # a file named on many rows is read once
    pre = []
    for e in entries:
        try:
            shared = by_overrides.get(e.overrides)
        except TypeError:  # a value that cannot be a dict key: no sharing
            shared = None
        if shared is None:
            shared = _option_set(e, options, loaded, setups, fingerprints)
            with contextlib.suppress(TypeError):
                by_overrides[e.overrides] = shared
        sha = hashed.get(e.path)
        if sha is None:
            try:
                sha = hashed[e.path] = sha256_file(e.path)
            except OSError as exc:
                raise InputError(f"{e.path}: cannot read the part ({exc.strerror})") from None
        pre.append((e, shared, sha, _stem(e.path)))
    # folder names: <stem>-<sha8>, plus -<opt8> where one file meets several option sets
    option_sets: dict[tuple[str, str], set[str]] = {}
    for e, (opts, h, setup), sha, stem in pre:
        option_sets.setdefault((stem, sha[:8]), set()).add(h)
    jobs: list[PartJob] = []
    first: dict[tuple[str, str], str] = {}
    for e, (opts, h, setup), sha, stem in pre:
        name = f"{_safe_stem(stem)}-{sha[:8]}"
        if len(option_sets[(stem, sha[:8])]) > 1:
            name += f"-{h[:8]}"
        key = (sha, h)
        jobs.append(PartJob(path=e.path, sha256=sha, dir_name=name, options=opts, options_hash=h,
                            duplicate_of=first.get(key), size=e.size, setup=setup))
        first.setdefault(key, e.path)
    return jobs


def _option_set(e: PartEntry, options: BatchOptions, loaded: Cache, setups: dict[tuple[str, str, str], Setup],
                fingerprints: dict[tuple[str, Any], str]) -> tuple[BatchOptions, str, Setup]:
    """The options of entry ``e`` (``options`` with its overrides), their hash and their setup;
    each description is checked and loaded once (``loaded``), each setup built once (``setups``)."""
    from ..setup.resolved import build_setup

    try:
        opts = apply_overrides(options, e.overrides)
    except GrasplanError as exc:
        raise type(exc)(f"{e.origin}: {exc}") from None
    own = {k for k, _ in e.overrides}
    for kind in DESCRIPTION_KINDS:
        name = getattr(opts, kind)
        if (kind, name) not in loaded:
            check_description(kind, name, f"{e.origin}: {kind}" if kind in own else f"--{kind}", loaded)
    triple = (opts.robot, opts.gripper, opts.cell)
    setup = setups.get(triple)
    if setup is None:  # every description is in ``loaded`` now: nothing is read again
        setup = setups[triple] = build_setup(robot=opts.robot, gripper=opts.gripper, cell=opts.cell, cache=loaded)
    return opts, options_hash(opts, fingerprints=fingerprints, setup=setup), setup


def check_description(kind: str, name: str, where: str, cache: Cache | None = None) -> Source:
    """Load the ``kind`` description ``name`` as a worker will (``kind``: robot, gripper or cell;
    :func:`grasplan.setup.resolved.load_description`, kept in ``cache``) and return its source;
    a name no folder holds, or a file that is not such a description (``/etc/passwd``, a JSON or
    binary file, an empty file), is a ConfigError (exit 3) naming ``where`` (the manifest line and
    field, or the option), the file and what would work."""
    from ..config.lookup import available, is_path_like, resolve_yaml
    from ..setup.resolved import load_description

    try:
        return load_description(kind, name, cache)[1]
    except (GrasplanError, OSError, ValueError, RecursionError, MemoryError) as exc:
        msg = str(exc) or type(exc).__name__
        try:
            shown = str(resolve_yaml(kind, name)) if is_path_like(name) else repr(name)
        except (GrasplanError, OSError, ValueError):
            shown = repr(name)
        if msg.startswith("unknown "):  # an unknown name: the message lists the names
            raise ConfigError(f"{where}: {msg}") from None
        raise ConfigError(f"{where}: {shown} is not a usable {kind} description ({msg}); give a {kind} YAML file "
                          f"or a name: {', '.join(available(kind))}") from None


def _stem(path: str) -> str:
    """``Path(path).stem`` (the name without its last suffix; ``.hidden`` and ``name.`` kept whole)."""
    name = os.path.basename(path.rstrip("/")) or path
    i = name.rfind(".")
    return name[:i] if 0 < i < len(name) - 1 else name


def _safe_stem(stem: str) -> str:
    keep = "".join(c if c.isalnum() or c in "-_." else "_" for c in stem).strip(".") or "part"
    return keep[:80]
