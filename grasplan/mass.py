"""Mass properties of a part: uniform density, centre of mass and inertia from its closed mesh.

A watertight mesh is integrated as it is (divergence theorem over its triangles,
:func:`polyhedron_integrals`); a mesh
that is not watertight has no defined volume, so its convex hull is used instead and a warning
says so (the hull over-estimates the volume of a concave part and moves the centre of mass).

Units: kg, m, kg/m^3, kg m^2. The inertia is about the centre of mass, in the part frame's axes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .errors import InputError
from .meshdata import MeshData, convex_hull
from .tolerance import Tolerance

if TYPE_CHECKING:
    import trimesh

#: default density, kg/m^3 (steel)
DEFAULT_DENSITY = 7850.0


def polyhedron_integrals(triangles: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """``(volume, centre of mass (3,), inertia (3, 3) about it)`` at unit density of the solid
    bounded by ``triangles (n, 3, 3)`` (outward winding; signed: inward gives negative volume and
    inertia), by the divergence theorem: D. Eberly, "Polyhedral mass properties (revisited)",
    2002 (the formulation of ``trimesh.triangles.mass_properties``, whose operations this repeats)."""
    t = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    t0, t1, t2 = t[:, 0, :], t[:, 1, :], t[:, 2, :]
    d = t[:, 1:, :] - t[:, :2, :]
    crosses = np.cross(d[:, 0], d[:, 1])
    f1 = t0 + t1 + t2
    f2 = t0 ** 2 + t1 ** 2 + t0 * t1 + t2 * f1
    f3 = t0 ** 3 + t0 ** 2 * t1 + t0 * t1 ** 2 + t1 ** 3 + t2 * f2
    g0 = f2 + (t0 + f1) * t0
    g1 = f2 + (t1 + f1) * t1
    g2 = f2 + (t2 + f1) * t2
    integral = np.zeros((10, len(f1)))
    integral[0] = crosses[:, 0] * f1[:, 0]
    integral[1:4] = (crosses * f2).T
    integral[4:7] = (crosses * f3).T
    for i in range(3):
        j = (i + 1) % 3
        integral[i + 7] = crosses[:, i] * (t0[:, j] * g0[:, i] + t1[:, j] * g1[:, i] + t2[:, j] * g2[:, i])
    s = integral.sum(axis=1) / np.array([6, 24, 24, 24, 60, 60, 60, 120, 120, 120], dtype=np.float64)
    volume = float(s[0])
    with np.errstate(invalid="ignore", divide="ignore"):
        com = s[1:4] / volume
    inertia = np.zeros((3, 3))
    inertia[0, 0] = s[5] + s[6] - volume * (com[[1, 2]] ** 2).sum()
    inertia[1, 1] = s[4] + s[6] - volume * (com[[0, 2]] ** 2).sum()
    inertia[2, 2] = s[4] + s[5] - volume * (com[[0, 1]] ** 2).sum()
    inertia[0, 1] = inertia[1, 0] = -(s[7] - volume * np.prod(com[[0, 1]]))
    inertia[1, 2] = inertia[2, 1] = -(s[8] - volume * np.prod(com[[1, 2]]))
    inertia[0, 2] = inertia[2, 0] = -(s[9] - volume * np.prod(com[[0, 2]]))
    return volume, com, inertia


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
    """

    mass: float
    com: np.ndarray
    inertia: np.ndarray
    volume: float
    density: float
    watertight_used: bool
    warnings: tuple[str, ...] = ()

    def record(self) -> dict:
        """The few numbers a grasps/plan file records under ``part``: ``mass_kg``, ``com`` (m, part
        frame), ``density`` (kg/m^3) and ``mass_from`` ("mesh" or "convex_hull")."""
        return {"mass_kg": float(self.mass), "com": [float(x) for x in self.com], "density": float(self.density),
                "mass_from": "mesh" if self.watertight_used else "convex_hull"}

    def to_json(self) -> dict:
        return {"mass": float(self.mass), "com": self.com.tolist(), "inertia": self.inertia.tolist(),
                "volume": float(self.volume), "density": float(self.density),
                "watertight_used": bool(self.watertight_used)}


def _positive(value, name: str, fix: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a number, got {value!r} ({fix})") from None
    if not math.isfinite(v) or v <= 0:
        raise InputError(f"{name}: must be a finite number > 0, got {value!r} ({fix})")
    return v


def mass_properties(mesh: MeshData | trimesh.Trimesh, *, density: float = DEFAULT_DENSITY,
                    mass: float | None = None) -> MassProperties:
    """Mass, centre of mass and inertia of ``mesh`` (part frame, metres) at uniform density.

    Parameters
    ----------
    mesh : MeshData or trimesh.Trimesh
        The part, metres. Not watertight: its convex hull is used, with a warning.
    density : float
        kg/m^3 (default 7850, steel). Ignored when ``mass`` is given.
    mass : float, optional
        kg; sets the density to ``mass / volume``.

    Raises
    ------
    InputError
        Non-positive density or mass, or a body without volume (flat or degenerate mesh).
    """
    density = _positive(density, "density", "give kg/m^3, e.g. 7850 for steel, 2700 for aluminium")
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
            body = convex_hull(mesh.vertices)
        except (QhullError, ValueError, IndexError):  # flat or degenerate points
            raise InputError("mass properties: the part is flat or degenerate (its convex hull has no volume); "
                             "give a closed solid, not a surface") from None
        warnings.append(f"the part mesh is not watertight: its mass properties are those of its convex hull "
                        f"(volume {float(body.volume) * 1e6:.4g} cm^3); repair the mesh for exact values")
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
                          watertight_used=watertight, warnings=tuple(warnings))
