"""The simulated holding force of grasps: the grip force at which the lift and shake of
:func:`grasplan.sim.simulate.simulate_grasps` starts to hold each one, found by bisection in log
space around a predicted force (the quality's ``hold_force_N``). What the prediction is
calibrated against (``benchmarks/quality.py --calibrate``, tests/test_calibration.py)."""
from __future__ import annotations

import numpy as np

from ..geometry.meshdata import TriangleMesh
from ..gripper.model import Gripper
from ..part.mass import MassProperties
from .simulate import simulate_grasps

#: the bisection's bracket, either way of the predicted force (x) and its steps: resolution
#: exp(log(RANGE) / 2^(STEPS - 1)), 4.4 %
RANGE, STEPS = 16.0, 7


def simulated_hold_force(part_mesh: TriangleMesh, gripper: Gripper, T_world_part: np.ndarray,
                         T_part_tcp: np.ndarray, width: np.ndarray, predicted: np.ndarray, *,
                         mass_props: MassProperties, table_z: float = 0.0, mu: float = 0.3,
                         contact_area: np.ndarray | None = None, decomposition: str = "coacd",
                         range_factor: float = RANGE, steps: int = STEPS) -> tuple[np.ndarray, np.ndarray]:
    """(k,) the grip force (N) at which each of the k grasps starts to hold in the simulation,
    bisected in log space within ``range_factor``x either way of ``predicted`` (k,) N; and (k,)
    bool: the bisection ended at an end of that bracket (the simulated force lies beyond it:
    censored). ``steps`` simulations per grasp, one grasp per simulation (each its own force)."""
    predicted = np.asarray(predicted, dtype=np.float64)
    if predicted.shape != (len(T_part_tcp),) or not (np.isfinite(predicted) & (predicted > 0)).all():
        raise ValueError("predicted: one positive finite force (N) per grasp")
    lo0, hi0 = np.log(predicted / range_factor), np.log(predicted * range_factor)
    lo, hi = lo0.copy(), hi0.copy()
    area = None if contact_area is None else np.asarray(contact_area)
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        held = np.array([simulate_grasps(part_mesh, gripper, T_world_part, T_part_tcp[i:i + 1], width[i:i + 1],
                                         table_z=table_z, mass_props=mass_props, mu=mu,
                                         grip_force=float(np.exp(mid[i])), decomposition=decomposition,
                                         contact_area=None if area is None else area[i:i + 1]).success[0]
                         for i in range(len(T_part_tcp))], dtype=bool)
        hi, lo = np.where(held, mid, hi), np.where(held, lo, mid)
    step = (hi0 - lo0) / 2 ** steps
    censored = (lo <= lo0 + 1.01 * step) | (hi >= hi0 - 1.01 * step)
    return np.exp(0.5 * (lo + hi)), censored
