"""Which parts a batch plans, with which options: files, folders and manifests become
:class:`PartEntry` rows (:func:`discover_parts`, :func:`read_manifest`), each with its per-part
overrides read by the one interpreter of option values (:func:`grasplan.option_kinds.parse_value`,
as on the command line); :func:`make_jobs` applies them, hashes every part and option set and
names the output folders."""
from __future__ import annotations

import csv
import dataclasses
import io
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import GrasplanError, InputError
from ..io import sha256_file
from ..mesh import UNIT_CHOICES
from ..meshfile import SUPPORTED_SUFFIXES
from ..option_kinds import parse_value
from ..params import PARAM_CLASSES, option_fields
from .options import BatchOptions, options_hash

#: suffixes a folder is searched for (files named on the command line may be any mesh grasplan reads)
FOLDER_SUFFIXES = (".stl", ".obj", ".ply")
MANIFEST_SUFFIXES = (".csv", ".yaml", ".yml")
#: manifest keys that are not parameter fields
ENTRY_KEYS = ("path", "units", "robot", "gripper", "cell", "part_pose")
#: BatchOptions fields a manifest row may set besides the parameters (part_pose sets T_world_part)
_TOP_KEYS = ("units", "robot", "gripper", "cell", "T_world_part")


@dataclass(frozen=True)
class PartEntry:
    """One part to plan: ``path`` as it will be recorded (relative paths stay relative to the
    current folder), ``overrides`` (manifest options, already converted), ``origin`` (where it was
    named, for messages)."""

    path: str
    overrides: tuple[tuple[str, Any], ...] = ()
    origin: str = ""


def _entry_from_mapping(row: dict, base_dir: Path, where: str) -> PartEntry:
    keys = {str(k).strip().lower().replace("-", "_"): v for k, v in row.items() if k is not None}
    raw_path = keys.pop("path", None)
    if raw_path is None or str(raw_path).strip() == "":
        raise InputError(f"{where}: no 'path'; every manifest row needs the part's mesh file in a 'path' column")
    p = Path(str(raw_path).strip()).expanduser()
    path = p if p.is_absolute() else Path(os.path.normpath(base_dir / p))
    if not path.is_file():
        raise InputError(f"{where}: part file {path} not found (relative paths are relative to the manifest's folder)")
    known = option_fields()
    overrides: dict[str, Any] = {}
    for key, value in keys.items():
        if value is None or (isinstance(value, str) and value.strip() == ""):
            continue  # an empty cell: the batch's option
        if key in ("units", "robot", "gripper", "cell"):
            text = str(value).strip()
            if key == "units" and text not in UNIT_CHOICES:
                raise InputError(f"{where}: units {text!r}; use one of {', '.join(UNIT_CHOICES)}")
            overrides[key] = text
        elif key == "part_pose":
            from ..transforms import parse_part_pose

            pose = str(value).strip()
            pp = Path(pose).expanduser()
            if pp.suffix.lower() in (".json", ".yaml", ".yml") and not pp.is_absolute():
                pose = str(base_dir / pp)
            try:
                overrides["T_world_part"] = tuple(tuple(r) for r in parse_part_pose(pose).tolist())
            except InputError as exc:
                raise InputError(f"{where}: {exc}") from None
        elif key in known:
            _, f = known[key]
            overrides[f.name] = parse_value(f, value.strip() if isinstance(value, str) else value,
                                            where=f"{where}: ", base_dir=base_dir)
        else:
            accepted = sorted({*ENTRY_KEYS, *(f.name for _, f in known.values())})
            raise InputError(f"{where}: unknown column {key!r}; accepted: {', '.join(accepted)}")
    return PartEntry(path=str(path), overrides=tuple(sorted(overrides.items())), origin=where)


#: a manifest larger than this is refused before it is read
MAX_MANIFEST_BYTES = 50_000_000


def _csv_rows(reader: csv.DictReader, path: Path) -> Iterable[dict]:
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
    ``defaults`` applies to every part that does not set the key itself."""
    path = Path(path)
    base = path.parent
    from ..inputs import read_input_bytes

    data = read_input_bytes(path, what="manifest", max_bytes=MAX_MANIFEST_BYTES)  # no FIFO, no device
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"manifest {path}: not a UTF-8 text file; a manifest is CSV or YAML") from None
    entries: list[PartEntry] = []
    if path.suffix.lower() == ".csv":
        reader = csv.DictReader(io.StringIO(text))
        if not reader.fieldnames or "path" not in [h.strip().lower() for h in reader.fieldnames]:
            raise InputError(f"{path}: a CSV manifest needs a header row with a 'path' column "
                             f"(e.g. 'path,units,pose_index'); got {reader.fieldnames}")
        for row in _csv_rows(reader, path):
            if None in row:
                raise InputError(f"{path}:{reader.line_num}: more values than header columns")
            if all((v or "").strip() == "" for v in row.values()):
                continue
            entries.append(_entry_from_mapping(row, base, f"{path}:{reader.line_num}"))
    else:
        from ..yamlfile import load_yaml_text

        doc = load_yaml_text(text, f"manifest {path}")
        defaults: dict = {}
        if isinstance(doc, dict):
            defaults = doc.get("defaults") or {}
            if not isinstance(defaults, dict):
                raise InputError(f"{path}: 'defaults' must be a mapping of option -> value")
            doc = doc.get("parts")
        if not isinstance(doc, list):
            raise InputError(f"{path}: a YAML manifest is a list of parts (or a mapping with a 'parts' list); "
                             "each part is a path or a mapping with 'path' and optional options")
        for i, item in enumerate(doc):
            row = {"path": item} if isinstance(item, str) else item
            if not isinstance(row, dict):
                raise InputError(f"{path}: parts[{i}] must be a path or a mapping with 'path', got {item!r}")
            entries.append(_entry_from_mapping({**defaults, **row}, base, f"{path}: parts[{i}]"))
    if not entries:
        raise InputError(f"{path}: the manifest lists no parts")
    return entries


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


def make_jobs(entries: Sequence[PartEntry], options: BatchOptions) -> list[PartJob]:
    """Hash every part file (streamed) and every option set; name the output folders.

    Raises InputError / ConfigError for a bad per-part option or an unknown robot/gripper/cell."""
    hashes: dict[BatchOptions, str] = {}
    pre = []
    for e in entries:
        try:
            opts = apply_overrides(options, e.overrides)
        except GrasplanError as exc:
            raise type(exc)(f"{e.origin}: {exc}") from None
        if opts not in hashes:
            hashes[opts] = options_hash(opts)
        try:
            sha = sha256_file(e.path)
        except OSError as exc:
            raise InputError(f"{e.path}: cannot read the part ({exc.strerror})") from None
        pre.append((e, opts, sha))
    # folder names: <stem>-<sha8>, plus -<opt8> where one file meets several option sets
    option_sets: dict[tuple[str, str], set[str]] = {}
    for e, opts, sha in pre:
        option_sets.setdefault((Path(e.path).stem, sha[:8]), set()).add(hashes[opts])
    jobs: list[PartJob] = []
    first: dict[tuple[str, str], str] = {}
    for e, opts, sha in pre:
        stem = _safe_stem(Path(e.path).stem)
        h = hashes[opts]
        name = f"{stem}-{sha[:8]}"
        if len(option_sets[(Path(e.path).stem, sha[:8])]) > 1:
            name += f"-{h[:8]}"
        key = (sha, h)
        jobs.append(PartJob(path=e.path, sha256=sha, dir_name=name, options=opts, options_hash=h,
                            duplicate_of=first.get(key)))
        first.setdefault(key, e.path)
    return jobs


def _safe_stem(stem: str) -> str:
    keep = "".join(c if c.isalnum() or c in "-_." else "_" for c in stem).strip(".") or "part"
    return keep[:80]
