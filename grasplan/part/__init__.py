"""The part: its mesh file read and repaired in metres (:class:`Part`), its mass properties and
the poses it rests in.

Every name below is imported from its module on first use (:mod:`grasplan._lazy`).
"""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "Part": ".mesh", "load_part": ".mesh", "part_from_arrays": ".mesh", "part_from_trimesh": ".mesh",
    "read_mesh": ".meshfile", "ReadLimits": ".meshfile",
    "MassProperties": ".mass", "mass_properties": ".mass",
    "stable_poses": ".stability", "part_centre_of_mass": ".stability",
})
