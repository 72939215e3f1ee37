"""The IK family registry: one :class:`IKFamily` per ``kind:`` a robot YAML may name.

A family is one module that ends with ``FAMILY = register(IKFamily(...))``; the shipped ones are
listed once in :data:`grasplan.robot.ik.BUILTIN_FAMILIES` (importing :mod:`grasplan.robot.ik`, or any module of
it, registers them). Every family shares the numeric solver (damped least squares CLIK,
:mod:`grasplan.robot.ik.clik`); a family may add a closed-form solver that runs first for the robots it
fits (``eligible``). The robot loader looks ``kind`` up here, so an unknown family is a
ConfigError that lists the registered ones.

Model vs data: an :class:`IKFamily` is an immutable description shared by every robot and thread;
:class:`~grasplan.robot.ik.IKSolver` builds the family's closed form once per robot and thread.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ...errors import unknown_name
from ..model import Robot

class ClosedFormIK(Protocol):
    """A closed-form solver built for one robot (:attr:`IKFamily.closed_form`).

    ``ok`` is False (and ``why`` says why) when the robot, although eligible by its structure,
    fails the solver's own check against the model (e.g. the chain does not reproduce Pinocchio
    FK); the solver is then not used.
    """

    ok: bool
    why: str

    def solve(self, T_base_tool: np.ndarray) -> tuple[np.ndarray, str]:
        """Raw solutions (k, n) for ``T_base_tool`` (4, 4) in the model's root frame, unchecked
        against the joint limits, and a reason ("ok", "out_of_reach: ...") when there are none
        (k = 0)."""
        ...


def _any_robot(robot: Robot) -> str:
    return ""


@dataclass(frozen=True)
class IKFamily:
    """An IK family: the name a robot YAML's ``kind:`` gives, and how to solve its robots.

    ``closed_form(robot)`` builds the family's closed-form solver (None: CLIK only).
    ``eligible(robot)`` returns why the closed form cannot serve ``robot`` ("" when it can: joint
    count, which joint carries the tool, axis directions); an ineligible robot of the family is
    solved by CLIK alone. ``controller_base_frame``: the model frame the arm's controller expresses
    poses in (UR: ``base``), used when the robot YAML names none and the model has that frame.
    """

    name: str
    description: str
    closed_form: Callable[[Robot], ClosedFormIK] | None = None
    eligible: Callable[[Robot], str] = _any_robot
    controller_base_frame: str | None = None


#: name -> family; filled by the family modules when they are imported
FAMILIES: dict[str, IKFamily] = {}


def register(family: IKFamily) -> IKFamily:
    """Add ``family`` to :data:`FAMILIES` (idempotent for the same object); returns it."""
    if family.name in FAMILIES and FAMILIES[family.name] is not family:
        raise ValueError(f"IK family {family.name!r} is registered twice")
    FAMILIES[family.name] = family
    return family


def get_family(name: object, *, where: str = "kind") -> IKFamily:
    """The registered family ``name``; ConfigError naming ``where`` and listing the families."""
    if not isinstance(name, str) or name not in FAMILIES:
        raise unknown_name("IK family", str(name)[:80], FAMILIES, hint=where)
    return FAMILIES[name]

