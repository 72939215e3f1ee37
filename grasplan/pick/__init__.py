"""Picking from a pile: :class:`Picker` plans picks of many part instances at poses
from vision against the bin, the neighbours and a point cloud; :class:`PickResult` is its typed
result (``grasplan.picks/1``) with each instance's :class:`PickStatus` and :class:`Reason` code,
:func:`load_picks` reads a picks file back. See docs/pick.md. The names load on first use (the
planner brings numba, coal, Pinocchio and SciPy; ``grasplan pick --help`` needs none of them)."""
from __future__ import annotations

from .._lazy import lazy_exports

__all__ = ["Picker", "PickParams", "Pick", "PickResult", "InstanceReport", "PickStatus", "Reason"]
__getattr__, __dir__ = lazy_exports(globals(), {
    "PickStatus": ".codes", "Reason": ".codes", "PickParams": ".params", "Picker": ".picker",
    "InstanceReport": ".result", "Pick": ".result", "PickResult": ".result"})
