"""The export registry: one :class:`ExportFormat` per robot-program / data format.

A format is one module that ends with ``register(ExportFormat(...))``; the built-in modules are
listed once in :data:`grasplan.export.BUILTIN_MODULES`. ``grasplan export --help`` and
``--format`` choices are read from :data:`FORMATS`.
"""
from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..errors import InputError

#: joint acceleration limit of the joint trajectory when none is given, rad/s^2 (all joints): the
#: URDF has none; 1.4 rad/s^2 is the UR controller's default ``movej`` acceleration
DEFAULT_MAX_ACCEL = 1.4
#: a KRL/RAPID program name: a letter, then letters, digits or _, at most 24 characters
PROGRAM_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,23}")


@dataclass(frozen=True, kw_only=True)
class ExportOptions:
    """Options of every format (each format reads the ones it needs)."""

    grasp_id: int | None = None      #: None: the best planned grasp (per-grasp formats) / every grasp
    source: str = ""                 #: a label of the plan (its file name), recorded in headers
    program_name: str = "grasplan_pick"  #: KRL/RAPID routine and module name base (a safe identifier)
    max_accel: float = DEFAULT_MAX_ACCEL  #: joint-trajectory: rad/s^2
    velocity_scale: float = 1.0      #: joint-trajectory: fraction of the URDF velocity limits

    def __post_init__(self):
        if self.grasp_id is not None and (isinstance(self.grasp_id, bool) or not isinstance(self.grasp_id, int)
                                          or not 0 <= self.grasp_id < 2**62):
            raise InputError(f"--grasp: expected a grasp id >= 0, got {self.grasp_id!r}")
        if not PROGRAM_NAME.fullmatch(self.program_name):
            raise InputError(f"program name {self.program_name!r}: use a letter then letters, digits or _ "
                             "(at most 24 characters)")
        if not (isinstance(self.max_accel, (int, float)) and math.isfinite(self.max_accel) and 0 < self.max_accel <= 1000):
            raise InputError(f"--max-accel: expected rad/s^2 in (0, 1000], got {self.max_accel!r}")
        if not (isinstance(self.velocity_scale, (int, float)) and 0 < self.velocity_scale <= 1):
            raise InputError(f"--velocity-scale: expected a fraction in (0, 1], got {self.velocity_scale!r}")


@dataclass(frozen=True)
class ExportFormat:
    """``render(plan: PlanResult, options: ExportOptions) -> {extension: text}``: the first key is the
    file the user names with ``-o``; further keys are written next to it with the same stem."""

    name: str
    extension: str
    description: str
    render: Callable[[Any, ExportOptions], dict[str, str]]
    per_grasp: bool = True
    extra_extensions: tuple[str, ...] = ()  #: further files written next to the primary one (KRL: (".dat",))
    #: the program inside is named after the output file (KUKA loads NAME.src only with DEF NAME)
    program_named_by_file: bool = False


FORMATS: dict[str, ExportFormat] = {}


def register(fmt: ExportFormat) -> ExportFormat:
    if fmt.name in FORMATS and FORMATS[fmt.name] is not fmt:
        raise ValueError(f"export format {fmt.name!r} is registered twice")
    FORMATS[fmt.name] = fmt
    return fmt


def get_format(name: str) -> ExportFormat:
    from . import load_builtin_formats

    load_builtin_formats()
    if name not in FORMATS:
        raise InputError(f"unknown export format {name!r}; available: {', '.join(sorted(FORMATS))}")
    return FORMATS[name]
