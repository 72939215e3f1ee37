"""A run's setup at the edge: the input files a command reads and the one output rule that keeps
an output from replacing any of them (:mod:`.outputs`).

Every name below is imported from its module on first use (:mod:`grasplan._lazy`).
"""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "check_outputs": ".outputs", "config_input": ".outputs", "config_files": ".outputs",
    "robot_files": ".outputs", "scene_files": ".outputs", "picks_files": ".outputs",
    "result_files": ".outputs", "file_input": ".outputs",
})
