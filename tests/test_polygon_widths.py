"""``grasplan.geometry.polygons.equivalent_widths``: a rectangle's moments give back its sides,
under any rigid motion in its plane; an empty or vanishing patch has zero widths, without a
floating-point warning."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from grasplan.geometry.polygons import equivalent_widths, polygon_moments


def _rect(w: float, h: float, angle: float, shift: tuple[float, float]) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    P = np.array([[0, 0], [w, 0], [w, h], [0, h]], dtype=np.float64) - [w / 2, h / 2]
    return P @ np.array([[c, s], [-s, c]]) + shift


@pytest.mark.parametrize("angle, shift", [(0.0, (0.0, 0.0)), (0.7, (0.01, -0.03)), (2.5, (-0.2, 0.1))])
def test_a_rectangles_widths_come_back_under_rigid_motion(angle, shift):
    P = _rect(0.012, 0.005, angle, shift)
    mom = polygon_moments(P[None, :, 0], P[None, :, 1], np.array([4]))
    np.testing.assert_allclose(equivalent_widths(mom)[0], [0.005, 0.012], rtol=1e-9)


def test_an_empty_or_vanishing_patch_has_zero_widths_without_warnings():
    mom = np.zeros((3, 6))
    mom[1] = [1e-310, 1e-300, 1e-300, 1e-290, 1e-290, 0.0]  # subnormal area: numerically empty
    mom[2, 0] = -1.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_array_equal(equivalent_widths(mom), np.zeros((3, 2)))
