"""The lift's resting-contact window is ``lift_contact`` of TCP travel, not the first line waypoint
(:func:`grasplan.motion.lift_check.lift_collision` with ``resting``): a part still touching the table
3 mm up is a lift collision when 2 mm are allowed, although the first waypoint lies 4 mm up."""
from __future__ import annotations

import numpy as np

from grasplan.motion.lift_check import lift_collision, lift_travel, touch_waypoints


class _TableScene:
    """A stand-in collision scene: joint 0 is the TCP travel x 10 (m); the carried part touches
    the table while the travel is within ``touch`` (m)."""

    def __init__(self, touch: tuple[float, float]):
        self.touch = touch
        self.checked: list[float] = []

    def _travel(self, q: np.ndarray) -> float:
        return float(q[0]) / 10.0

    def resting(self, qs: np.ndarray, window: float = 0.002) -> np.ndarray:
        """Per configuration: within ``window`` of travel (``lift_collision``'s ``resting``)."""
        return np.asarray(qs)[:, 0] / 10.0 <= window + 1e-9

    def is_free(self, q: np.ndarray, width: float) -> bool:
        self.checked.append(self._travel(q))
        return not (self.touch[0] <= self._travel(q) <= self.touch[1])

    def colliding_pairs(self, q: np.ndarray, width: float) -> list[tuple[str, str, str]]:
        return [] if self.is_free(q, width) else [("part", "table", "attached")]


def _lift(n: int = 6) -> np.ndarray:
    path = np.zeros((n, 6))
    path[:, 0] = 0.04 * np.arange(n)  # waypoints 4 mm of travel apart
    return path


def test_contact_beyond_lift_contact_before_the_first_waypoint_is_a_collision():
    sc = _TableScene((0.0025, 0.0035))  # touches the table 2.5-3.5 mm up
    pairs = lift_collision(sc, _lift(), 0.02, 1, None, None, None, sc.resting)
    assert pairs == [("part", "table", "attached")]
    # without the window, the whole first waypoint interval (4 mm) could rest: the old behaviour
    assert lift_collision(_TableScene((0.0025, 0.0035)), _lift(), 0.02, 1) is None


def test_resting_within_lift_contact_is_allowed():
    sc = _TableScene((0.0, 0.0015))  # leaves the table 1.5 mm up
    assert lift_collision(sc, _lift(), 0.02, 1, None, None, None, sc.resting) is None
    assert any(0.0015 < t < 0.004 for t in sc.checked)  # configurations between grasp and waypoint 1 were checked


def test_a_waypoint_at_lift_contact_itself_may_rest():
    """With the lift's 2 mm waypoints one lies at lift_contact (2 mm) exactly: it is inside the
    window (a part whose estimated pose sinks it 3 mm into the floor still touches it there and is
    clear 4 mm up), and the next one is the first that may not rest."""
    travel = lift_travel(0.1)  # 2 mm apart
    np.testing.assert_allclose(np.diff(travel), 0.002)
    assert touch_waypoints(0.002, travel) == 2 and touch_waypoints(0.003, travel) == 2
    assert touch_waypoints(0.0019, travel) == 1 and touch_waypoints(0.0, travel) == 0
    assert touch_waypoints(0.002, 0.004 * np.arange(26)) == 1  # the approach's 4 mm spacing: the first is beyond
    odd = lift_travel(0.0045)  # 1.5 mm apart: the waypoint at 3 mm is within a 3 mm window
    assert len(odd) == 4 and touch_waypoints(0.003, odd) == 3
    path = np.zeros((6, 6))
    path[:, 0] = 10 * travel[:6]  # the stand-in's joint 0 is travel x 10
    window = touch_waypoints(0.002, travel)

    resting = _TableScene((0.0, 0.0)).resting
    assert lift_collision(_TableScene((0.0, 0.002)), path, 0.02, window, None, None, None, resting) is None
    assert lift_collision(_TableScene((0.0, 0.0031)), path, 0.02, window, None, None, None, resting) == [
        ("part", "table", "attached")]
    # the first waypoint beyond the window checked as a resting one would have let this through
    assert lift_collision(_TableScene((0.0, 0.002)), path, 0.02, window - 1, None, None, None, resting) == [
        ("part", "table", "attached")]
