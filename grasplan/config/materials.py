"""Part materials: the one default density and the names ``--material`` takes.

Every command that needs a part's mass (``plan``, ``grasps``, ``database``, ``simulate``, ``pick``,
``scene drop``, ``clutter``) defaults to :data:`DEFAULT_MATERIAL` (steel, :data:`DEFAULT_DENSITY`):
a grasp predicted to hold a steel part holds the same part in any lighter material. ``--material
NAME`` sets the density from :data:`MATERIALS`; ``--density`` gives it in kg/m^3 (recorded as
:data:`CUSTOM` when no material has that density); giving both is refused unless they agree;
``--mass`` (where a command has it) overrides both. :func:`resolve_material` is that rule.
"""
from __future__ import annotations

import math
from typing import Any

from ..errors import InputError

#: typical densities, kg/m^3 (handbook values at room temperature, e.g. the Engineering ToolBox and
#: CRC Handbook tables: carbon steel 7850, stainless 304 8000, aluminium 2700, brass 8500, cast
#: iron 7200, titanium 4500, generic engineering plastic ~1200, ABS 1050, POM 1410, PA 6 1140,
#: PLA 1240, softwood ~600); no two share a density, so a density names at most one material
MATERIALS: dict[str, float] = {
    "steel": 7850.0,
    "stainless": 8000.0,
    "cast_iron": 7200.0,
    "aluminium": 2700.0,
    "titanium": 4500.0,
    "brass": 8500.0,
    "plastic": 1200.0,
    "abs": 1050.0,
    "pom": 1410.0,
    "pa": 1140.0,
    "pla": 1240.0,
    "wood": 600.0,
}
#: the default material of every command, and its density (kg/m^3)
DEFAULT_MATERIAL = "steel"
DEFAULT_DENSITY = MATERIALS[DEFAULT_MATERIAL]
#: the material recorded for a density that is no material's (``--density`` alone, or ``--mass``)
CUSTOM = "custom"
MATERIAL_NAMES = tuple(MATERIALS)
MATERIAL_HELP = (f"Part material, for its typical density ({', '.join(MATERIAL_NAMES)}); giving both "
                 f"--material and --density is refused unless they agree.")


def material_density(name: str, *, option: str = "--material") -> float:
    """The density (kg/m^3) of material ``name``; InputError listing the valid names."""
    key = str(name).strip().lower()
    if key not in MATERIALS:
        raise InputError(f"{option}: unknown material {str(name)[:40]!r}; valid: {', '.join(MATERIAL_NAMES)} "
                         f"(or give --density in kg/m^3)")
    return MATERIALS[key]


def material_of(density: float) -> str:
    """The material whose density is ``density`` exactly, else :data:`CUSTOM`."""
    return next((n for n, d in MATERIALS.items() if d == density), CUSTOM)


def resolve_material(material: Any, density: Any, *, where: str = "") -> tuple[str, Any]:
    """``(material name, density)`` from what was given (None: not given): the material's density,
    or ``density`` named by :func:`material_of`, or the default (steel). A material and a density
    that disagree: InputError naming both (``where`` prefixes the option names, e.g. a scene
    part). A density that is no number is returned as it is (the caller's range check names it)."""
    if material is None or (isinstance(material, str) and material == CUSTOM and density is not None):
        if density is None:
            return DEFAULT_MATERIAL, DEFAULT_DENSITY
        ok = isinstance(density, (int, float)) and not isinstance(density, bool) and math.isfinite(density)
        return (material_of(float(density)) if ok else CUSTOM), (float(density) if ok else density)
    if not isinstance(material, str):
        raise InputError(f"{where}--material: expected a material name ({', '.join(MATERIAL_NAMES)}), "
                         f"got {str(material)[:40]!r}")
    d = material_density(material, option=f"{where}--material")
    if density is not None and not (isinstance(density, (int, float)) and not isinstance(density, bool)
                                    and math.isclose(float(density), d, rel_tol=1e-9)):
        raise InputError(f"{where}--material {material} ({d:g} kg/m^3) and {where}--density {density} disagree; "
                         f"give one of them")
    return material.strip().lower(), d
