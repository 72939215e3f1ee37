"""The options of a batch part (:class:`BatchOptions`: everything that decides its result) and
their hash (:func:`options_hash`: a rerun skips a part whose finished result has the same one)."""
from __future__ import annotations

import hashlib
import json
import uuid
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..errors import InputError
from ..io import sha256_file
from ..part.mesh import UNIT_CHOICES
from ..results.compact import DEFAULT_KEEP, check_keep
from ..config.params import (
    ALL_POSES, DEFAULT_CELL, DEFAULT_GRIPPER, DEFAULT_ROBOT, CandidateParams, GraspParams, PlanParams
)
from .layout import OPTIONS_SCHEMA

if TYPE_CHECKING:
    from ..setup.resolved import Setup


@dataclass(frozen=True, kw_only=True)
class BatchOptions:
    """Everything that decides a part's result (the options hash is computed from it).

    ``robot``, ``gripper``, ``cell``: names or YAML paths; ``units``: of the mesh files (see
    :func:`grasplan.part.mesh.load_part`); ``T_world_part``: 4x4 row-major nested tuple (m), the part's
    pose instead of its stable resting pose (``--part-pose``), or None; ``exports``:
    :data:`grasplan.export.FORMATS` names written next to ``plan.json``; ``view``: write ``view.html``.
    The place (``--place``), the scoring file (``--scoring``) and ``--pose-index all`` are fields
    of the parameter classes (``planning.place``, ``grasps.scoring``, ``grasps.pose_index``).
    """

    robot: str = DEFAULT_ROBOT
    gripper: str = DEFAULT_GRIPPER
    cell: str = DEFAULT_CELL
    units: str = "auto"
    candidates: CandidateParams = field(default_factory=CandidateParams)
    grasps: GraspParams = field(default_factory=GraspParams)
    planning: PlanParams = field(default_factory=PlanParams)
    T_world_part: tuple[tuple[float, ...], ...] | None = None
    exports: tuple[str, ...] = ()
    view: bool = True
    keep: str = DEFAULT_KEEP  #: what plan.json keeps (grasplan.results.compact)

    def __post_init__(self) -> None:
        if self.units not in UNIT_CHOICES:
            raise InputError(f"units {self.units!r}: use one of {', '.join(UNIT_CHOICES)}")
        if self.T_world_part is not None:
            from ..geometry.transforms import check_transform

            T = check_transform(self.T_world_part, "part pose T_world_part")
            object.__setattr__(self, "T_world_part", tuple(tuple(float(x) for x in r) for r in T))
            if self.grasps.pose_index == ALL_POSES:
                raise InputError("--pose-index all: the resting poses replace --part-pose; give one or the other")
        check_exports(self.exports)
        check_keep(self.keep)

    def to_json(self) -> dict[str, Any]:
        """The options as JSON (``done.json``, ``summary.json``, the hash and the workers): the
        parameter classes' :meth:`~grasplan.config.params.CandidateParams.options_json`, so a place is
        included (a plan file records it in ``cell.place``) and a scoring file as its weights."""
        return {**self.plain_json(), "candidates": self.candidates.options_json(),
                "grasps": self.grasps.options_json(), "planning": self.planning.options_json()}

    def plain_json(self) -> dict[str, Any]:
        """:meth:`to_json` but the three parameter sets."""
        return {"robot": self.robot, "gripper": self.gripper, "cell": self.cell, "units": self.units,
                "T_world_part": None if self.T_world_part is None else [list(r) for r in self.T_world_part],
                "exports": list(self.exports), "view": self.view,
                **({"keep": self.keep} if self.keep != DEFAULT_KEEP else {})}  # the default keeps older hashes

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> BatchOptions:
        return cls(robot=data["robot"], gripper=data["gripper"], cell=data["cell"], units=data["units"],
                   candidates=CandidateParams.from_json(data["candidates"]),
                   grasps=GraspParams.from_json(data["grasps"]), planning=PlanParams.from_json(data["planning"]),
                   T_world_part=data.get("T_world_part"), exports=tuple(data["exports"]), view=bool(data["view"]),
                   keep=str(data.get("keep", DEFAULT_KEEP)))


def export_formats() -> dict[str, Any]:
    """The export registry, name -> format (``.extension``, ``.per_grasp``): :data:`grasplan.export.FORMATS`."""
    from ..results.export_registry import load_builtin_formats

    return load_builtin_formats()


def export_file(fmt: Any) -> str:
    """The file a format is written to in a part's folder: ``export-<name><extension>`` (never
    ``plan.json``, whatever the format's extension); a program named after its file (KRL, RAPID)
    gets a valid program name instead: ``export_<name><extension>`` (``export_krl.src`` + ``.dat``)."""
    if getattr(fmt, "program_named_by_file", False):
        return f"export_{fmt.name.replace('-', '_')}{fmt.extension}"
    return f"export-{fmt.name}{fmt.extension}"


def check_exports(names: Iterable[str]) -> tuple[str, ...]:
    """Validate export names against the registry; InputError listing the available ones."""
    names = tuple(names)
    if not names:
        return names
    available = export_formats()
    unknown = [n for n in names if n not in available]
    if unknown:
        raise InputError(f"--export: unknown format(s) {', '.join(unknown)}; available: {', '.join(available)}")
    from ..results.export_registry import program_options

    for n in names:  # the per-part file name must be one the format can write (a KRL program name)
        program_options(n, export_file(available[n]), {})
    if len(set(names)) != len(names):
        raise InputError(f"--export: format listed twice in {','.join(names)}")
    return names


def _config_fingerprint(kind: str, name: str, setup: Setup | None = None) -> str:
    """sha256 of the YAML a name resolves to on this machine (so editing a gripper redoes its parts):
    the file ``setup`` loaded it from when given, else the name looked up."""
    source = None if setup is None else setup.source(kind)
    if source is not None and source.path is not None:
        return sha256_file(source.path)
    from ..config.lookup import resolve_yaml

    return sha256_file(resolve_yaml(kind, name))


#: the canonical JSON the options hash is computed from: sorted keys, no spaces
_SEP = (",", ":")


def _canonical(value: Any) -> str:
    return json.dumps(value, sort_keys=True, separators=_SEP)


#: stands in a document for a member whose JSON is already encoded (random: no option value holds it)
_SLOT = f"grasplan-encoded-{uuid.uuid4().hex}-"


def _canonical_with(doc: dict[str, Any], encoded: dict[str, str]) -> str:
    """:func:`_canonical` of ``doc`` where the values of the keys in ``encoded`` are given already
    encoded (the same text: JSON with sorted keys is the concatenation of its members' JSON)."""
    text = _canonical({k: _SLOT + k if k in encoded else v for k, v in doc.items()})
    for k, value in encoded.items():
        text = text.replace(f'"{_SLOT}{k}"', value, 1)  # keys are plain ASCII names
    return text


def options_hash(options: BatchOptions, *, fingerprints: dict[tuple[str, Any], str] | None = None,
                 setup: Setup | None = None) -> str:
    """sha256 (hex) of the canonical JSON of ``options``, the grasplan version and the robot,
    gripper and cell YAML contents. Raises ConfigError for an unknown robot/gripper/cell.

    ``fingerprints``: a dict kept by the caller across calls, so each (kind, name) is read and
    each parameter set encoded once however many option sets share them (the hash is the same).
    ``setup``: the options' robot, gripper and cell already resolved (their YAMLs are hashed)."""
    from .. import __version__

    memo: dict[tuple[str, Any], str] = {} if fingerprints is None else fingerprints
    configs = {}
    for k in ("robot", "gripper", "cell"):
        key = (k, getattr(options, k))
        if key not in memo:
            memo[key] = _config_fingerprint(k, getattr(options, k), setup)
        configs[k] = memo[key]
    params = {}
    for attr in ("candidates", "grasps", "planning"):
        key = (attr, getattr(options, attr))
        if key not in memo:
            memo[key] = _canonical(getattr(options, attr).options_json())
        params[attr] = memo[key]
    opts = _canonical_with({**options.plain_json(), **dict.fromkeys(params)}, params)  # == _canonical(to_json())
    text = _canonical_with({"schema": OPTIONS_SCHEMA, "grasplan": __version__, "configs": configs, "options": None},
                           {"options": opts})
    return hashlib.sha256(text.encode()).hexdigest()
