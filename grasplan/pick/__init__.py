"""Picking from a pile: :class:`Picker` plans picks of many part instances at poses
from vision against the bin, the neighbours and a point cloud; :class:`PickResult` is its typed
result (``grasplan.picks/1``) with each instance's :class:`PickStatus` and :class:`Reason` code,
:func:`load_picks` reads a picks file back. See docs/pick.md."""
from __future__ import annotations

from .codes import PickStatus, Reason
from .params import PickParams
from .picker import Picker
from .result import InstanceReport, Pick, PickResult

__all__ = ["Picker", "PickParams", "Pick", "PickResult", "InstanceReport", "PickStatus", "Reason"]
