"""Errors grasplan raises for bad input.

Every error names the problem and, where possible, what would have worked. The CLI turns a
:class:`GrasplanError` into a one-line message on stderr and its ``exit_code`` (3 for bad input).
Filters never raise these for a rejected grasp: they return masks and reason codes; only the
pipeline decides what is fatal.
"""
from __future__ import annotations

from collections.abc import Iterable


class GrasplanError(Exception):
    """Base class: bad input or an impossible request. ``exit_code`` is what the CLI returns."""

    exit_code: int = 3


class InputError(GrasplanError):
    """A file or option the user gave is missing, unreadable or invalid."""


class MeshError(InputError):
    """A mesh file cannot be used (missing, unreadable, empty, non-finite, no area)."""


class ConfigError(InputError):
    """A gripper, cell or robot description is unknown or malformed."""


class PlanningError(GrasplanError):
    """A stage could not produce any usable result (e.g. no grasp survived)."""

    exit_code = 4


def unknown_name(kind: str, name: str, available: Iterable[str], *, hint: str = "") -> ConfigError:
    """An error for an unknown named thing that lists what is available.

    >>> str(unknown_name("robot", "ur6", ["ur5", "panda"]))
    "unknown robot 'ur6'; available: panda, ur5"
    """
    names = ", ".join(sorted(available)) or "(none)"
    msg = f"unknown {kind} {name!r}; available: {names}"
    if hint:
        msg += f" ({hint})"
    return ConfigError(msg)
