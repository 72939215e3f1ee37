"""grasplan: verified parallel-jaw grasps from a part's CAD mesh.

Pipeline (one module per stage): :mod:`grasplan.mesh` -> :mod:`grasplan.blm` ->
:mod:`grasplan.convexity` -> :mod:`grasplan.antipodal` -> :mod:`grasplan.frames` ->
:mod:`grasplan.collision` -> :mod:`grasplan.ik` -> :mod:`grasplan.paths` -> :mod:`grasplan.export`.
"""
from .errors import GrasplanError, InputError, MeshError, ConfigError
from .mesh import Part, load_part

__version__ = "0.1.0"
__all__ = ["GrasplanError", "InputError", "MeshError", "ConfigError", "Part", "load_part", "__version__"]
