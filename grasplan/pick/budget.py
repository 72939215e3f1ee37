"""The wall-clock budget of one :meth:`grasplan.Picker.plan` call (``PickParams.budget_s``,
``grasplan pick --budget``, the service's share of its time limit).

A :class:`Budget` is a deadline on the picker's clock (``time.perf_counter`` unless the Picker was
given another one: tests pass a fake clock to check that planning stops once it is past). The
planner asks :meth:`Budget.check` between every stage that can take long (each robot scene built,
each pair of the scene checks' interpenetration estimate, each chunk of grasps, each lift
direction and each contact depth of the lift checks, each IK solution of a grasp's motion, every
few hundred points of a depth measurement) and :meth:`Budget.left` caps the time of each OMPL
query, so that a plan stops within a small part of a second of its budget; the instance being
planned then is ``not_tried`` like those not reached.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable


class BudgetSpent(Exception):
    """Raised inside planning when the budget is spent; :meth:`grasplan.Picker.plan` catches it."""


class Budget:
    """A deadline ``seconds`` (None: none) after now on ``clock`` (seconds, monotonic)."""

    def __init__(self, seconds: float | None, clock: Callable[[], float] = time.perf_counter):
        self.clock = clock
        self.start = clock()
        self.end = None if seconds is None else self.start + float(seconds)

    def spent(self) -> bool:
        """Whether the deadline has passed."""
        return self.end is not None and self.clock() > self.end

    def check(self) -> None:
        """Raise :class:`BudgetSpent` once the deadline has passed."""
        if self.end is not None and self.clock() > self.end:
            raise BudgetSpent

    def left(self) -> float:
        """Seconds left (``inf`` without a deadline, 0 once past it)."""
        return math.inf if self.end is None else max(self.end - self.clock(), 0.0)

    def cap(self, seconds: float) -> float:
        """``seconds`` capped at the time left; :class:`BudgetSpent` when none is left."""
        left = self.left()
        if left <= 0.0:
            raise BudgetSpent
        return min(float(seconds), left)


#: a budget that never runs out (the default of the helpers that take one)
UNLIMITED = Budget(None)
