"""A run's setup at the edge: the robot, gripper and cell resolved and loaded once, with the files
they were read from (:mod:`.resolved`), and the one output rule that keeps an output from
replacing any input (:mod:`.outputs`).

Every name below is imported from its module on first use (:mod:`grasplan._lazy`).
"""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "Setup": ".resolved", "Source": ".resolved", "build_setup": ".resolved", "load_description": ".resolved",
    "check_outputs": ".outputs", "config_input": ".outputs", "config_files": ".outputs",
    "robot_files": ".outputs", "scene_files": ".outputs", "picks_files": ".outputs",
    "result_files": ".outputs", "file_input": ".outputs",
})
