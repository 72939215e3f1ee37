"""Lengths and angles from user input.

Inside grasplan every length is in metres and every computed angle in radians. User-facing
lengths accept a unit suffix (``0.1mm``, ``5 cm``, ``2in``); a bare number is metres. User-facing
angles are degrees (a ``deg`` suffix is accepted, ``rad`` converts).
"""
from __future__ import annotations

import math
import re

from ..errors import InputError

#: metres per unit, for lengths written with a suffix and for ``--units``
LENGTH_UNITS: dict[str, float] = {
    "m": 1.0,
    "cm": 1e-2,
    "mm": 1e-3,
    "um": 1e-6,
    "in": 0.0254,
    "ft": 0.3048,
}
#: what ``--units`` (and a mesh's ``units``) accepts: ``auto`` (mm or m by the part's size) or a unit
UNIT_CHOICES: tuple[str, ...] = ("auto", *LENGTH_UNITS)

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_LENGTH_RE = re.compile(rf"^\s*({_NUMBER})\s*([a-zA-Z]*)\s*$")


def parse_length(text: str | float | int, *, name: str = "length", allow_zero: bool = False,
                 allow_negative: bool = False) -> float:
    """Parse a length such as ``"0.1mm"`` or ``"0.05"`` (metres) and return metres.

    >>> parse_length("0.1mm")
    0.0001
    >>> parse_length("2 cm")
    0.02
    """
    if isinstance(text, (int, float)):
        value = float(text)
    else:
        m = _LENGTH_RE.match(str(text))
        if not m:
            raise InputError(
                f"{name}: cannot read {text!r} as a length; write a number in metres or with a "
                f"unit suffix, e.g. 0.1mm, 5cm, 0.05 (units: {', '.join(LENGTH_UNITS)})"
            )
        unit = m.group(2).lower() or "m"
        if unit not in LENGTH_UNITS:
            raise InputError(f"{name}: unknown length unit {m.group(2)!r} in {text!r}; use one of {', '.join(LENGTH_UNITS)}")
        value = float(m.group(1)) * LENGTH_UNITS[unit]
    if not math.isfinite(value):
        raise InputError(f"{name}: {text!r} is not a finite length")
    if value < 0 and not allow_negative:
        raise InputError(f"{name}: must be {'>= 0' if allow_zero else 'a positive length'}, got {text!r}")
    if value == 0 and not (allow_zero or allow_negative):
        raise InputError(f"{name}: must be a positive length, got {text!r}")
    return value


_ANGLE_RE = re.compile(rf"^\s*({_NUMBER})\s*(deg|°|rad)?\s*$")


def parse_angle_deg(text: str | float | int, *, name: str = "angle") -> float:
    """Parse a user angle and return **degrees** (bare number = degrees, ``rad`` suffix converts)."""
    if isinstance(text, (int, float)):
        value = float(text)
    else:
        m = _ANGLE_RE.match(str(text))
        if not m:
            raise InputError(f"{name}: cannot read {text!r} as an angle; write degrees, e.g. 15 or 15deg")
        value = float(m.group(1))
        if m.group(2) == "rad":
            value = math.degrees(value)
    if not math.isfinite(value):
        raise InputError(f"{name}: {text!r} is not a finite angle")
    return value
