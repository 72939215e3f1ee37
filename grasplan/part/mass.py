"""Mass properties of a part: uniform density, centre of mass and inertia from its closed mesh.

A watertight mesh is integrated as it is (divergence theorem over its triangles,
:func:`grasplan.geometry.meshdata.polyhedron_integrals`); a mesh that is not watertight has no defined
volume, so its convex hull is used instead and a warning says so (the hull over-estimates the
volume of a concave part and moves the centre of mass).

Units: kg, m, kg/m^3, kg m^2. The inertia is about the centre of mass, in the part frame's axes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config.materials import CUSTOM, DEFAULT_DENSITY, material_of
from ..errors import InputError
from ..geometry.meshdata import TriangleMesh, convex_hull, polyhedron_integrals
from ..geometry.tolerance import Tolerance

__all__ = ["DEFAULT_DENSITY", "MassProperties", "mass_properties"]


@dataclass(frozen=True)
class MassProperties:
    """Rigid-body properties of a part of uniform density.

    Attributes
    ----------
    mass : float
        kg.
    com : (3,) float64
        Centre of mass in the part frame, m.
    inertia : (3, 3) float64
        Inertia tensor about ``com``, part-frame axes, kg m^2 (symmetric positive definite).
    volume : float
        m^3 of the body integrated (the mesh, or its convex hull).
    density : float
        kg/m^3 (``mass / volume`` when the mass was given).
    watertight_used : bool
        True when the mesh itself was integrated, False when its convex hull was.
    warnings : tuple of str
    material : str
        The material named (``--material``), the one whose density it is, or ``custom``
        (:mod:`grasplan.config.materials`); "" when not known (an older record).
    """

    mass: float
    com: np.ndarray
    inertia: np.ndarray
    volume: float
    density: float
    watertight_used: bool
    warnings: tuple[str, ...] = ()
    material: str = ""

    def record(self) -> dict:
        """The few numbers a grasps/plan file records under ``part``: ``mass_kg``, ``com`` (m, part
        frame), ``density`` (kg/m^3), ``material`` (when known) and ``mass_from`` ("mesh" or
        "convex_hull")."""
        return {"mass_kg": float(self.mass), "com": [float(x) for x in self.com], "density": float(self.density),
                **({"material": self.material} if self.material else {}),
                "mass_from": "mesh" if self.watertight_used else "convex_hull"}

    def to_json(self) -> dict:
        return {"mass": float(self.mass), "com": self.com.tolist(), "inertia": self.inertia.tolist(),
                "volume": float(self.volume), "density": float(self.density),
                **({"material": self.material} if self.material else {}),
                "watertight_used": bool(self.watertight_used)}


def _positive(value: float, name: str, fix: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a number, got {value!r} ({fix})") from None
    if not math.isfinite(v) or v <= 0:
        raise InputError(f"{name}: must be a finite number > 0, got {value!r} ({fix})")
    return v


def mass_properties(mesh: TriangleMesh, *, density: float = DEFAULT_DENSITY,
                    mass: float | None = None, material: str | None = None) -> MassProperties:
    """Mass, centre of mass and inertia of ``mesh`` (part frame, metres) at uniform density.

    Parameters
    ----------
    mesh : TriangleMesh
        The part, metres. Not watertight: its convex hull is used, with a warning.
    density : float
        kg/m^3 (default 7850, steel). Ignored when ``mass`` is given.
    mass : float, optional
        kg; sets the density to ``mass / volume``.
    material : str, optional
        The material's name as recorded (:attr:`MassProperties.material`); default: the one whose
        density is ``density`` (``custom`` for none, or when ``mass`` is given).

    Raises
    ------
    InputError
        Non-positive density or mass, or a body without volume (flat or degenerate mesh).
    """
    density = _positive(density, "density", "give kg/m^3, e.g. 7850 for steel, 2700 for aluminium")
    if material is None:
        material = CUSTOM if mass is not None else material_of(density)
    if mass is not None:
        mass = _positive(mass, "mass", "give the part's mass in kg")
    if not hasattr(mesh, "faces") or len(mesh.faces) == 0:
        raise InputError("mass properties: the part mesh has no triangles; give a closed triangle mesh")
    warnings: list[str] = []
    body = mesh
    watertight = bool(mesh.is_watertight)
    if not watertight:
        from scipy.spatial import QhullError

        try:
            hull = convex_hull(mesh.vertices)
        except (QhullError, ValueError, IndexError):  # flat or degenerate points
            raise InputError("mass properties: the part is flat or degenerate (its convex hull has no volume); "
                             "give a closed solid, not a surface") from None
        warnings.append(f"the part mesh is not watertight: its mass properties are those of its convex hull "
                        f"(volume {float(hull.volume) * 1e6:.4g} cm^3); repair the mesh for exact values")
        body = hull
    tris = np.asarray(body.triangles, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):  # zero volume is reported below
        volume, com_b, inertia_b = polyhedron_integrals(tris)
    tol = Tolerance.for_mesh(np.asarray(body.vertices))
    if abs(volume) <= tol.area * tol.scale:
        raise InputError(f"mass properties: the part encloses no volume ({volume:.3g} m^3); "
                         "give a closed solid, not a surface or a flat mesh")
    sign = 1.0
    if volume < 0:  # inward-facing normals: the integrals change sign, the body is the same
        sign = -1.0
        warnings.append("the part mesh's normals point inwards; mass properties computed for the solid it bounds")
    volume = abs(volume)
    if mass is not None:
        density = mass / volume
    else:
        mass = density * volume
    com = np.asarray(com_b, dtype=np.float64)
    inertia = sign * density * np.asarray(inertia_b, dtype=np.float64)
    inertia = 0.5 * (inertia + inertia.T)
    return MassProperties(mass=float(mass), com=com, inertia=inertia, volume=volume, density=float(density),
                          watertight_used=watertight, warnings=tuple(warnings), material=str(material))
