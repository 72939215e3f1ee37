"""The predicted holding force (``hold_force_N`` = grip_force / gravity_margin) against the
simulation on small convex parts (their hull is exact, so the simulation's collision shape is the
part): the grip force at which MuJoCo's lift and shake starts to hold each grasp
(:func:`grasplan.sim.hold_force.simulated_hold_force`, bisected around the prediction).

On the example box and a bar lying flat, the simulated force orders the grasps as the prediction
does and lies within a few per cent of it. On a standing cylinder gripped on its side the
prediction is conservative (the simulation holds at 0.3-1x it): the shake twists the part about
the closing axis with its centre of mass hanging below, so the simulated part swings and gravity
brings it back, a slip the margin (the load at which slip starts) counts and the simulation's
final-pose rule does not (docs/quality.md). No part needs more than the prediction allows. The full
calibration over the paper parts is ``benchmarks/quality.py --calibrate``."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.stats import spearmanr

from grasplan.config.params import GraspParams
from grasplan.grasps.pipeline import compute_grasps
from grasplan.part.mesh import load_part, part_from_trimesh
from grasplan.sim.hold_force import simulated_hold_force
from grasplan.sim.simulate import simulate_grasps

BOX = Path(__file__).resolve().parents[1] / "examples" / "parts" / "box.stl"
STEEL = 7850.0
SPREAD = 5  #: grasps per part, spread evenly over the range of their predicted holding force
#: the parts whose twist gravity loads (the prediction is tight there) and the one it does not
TIGHT, ALL = ("box", "bar"), ("box", "bar", "cylinder")


def _part(name: str):
    if name == "box":
        return load_part(BOX)  # 10 x 20 x 30 mm
    if name == "bar":  # 100 x 24 x 16 mm lying flat, 0.30 kg in steel: grasps off its centre twist it
        return part_from_trimesh(trimesh.creation.box(extents=(0.1, 0.024, 0.016)), units="m", path="bar")
    return part_from_trimesh(trimesh.creation.cylinder(radius=0.018, height=0.06, sections=24), units="m",
                             path="cylinder")  # curved contacts, 0.48 kg in steel


@pytest.fixture(scope="module", params=ALL)
def calibration(request):
    part = _part(request.param)
    gr = compute_grasps(part, gripper="long_stroke_50", grasps=GraspParams(density=STEEL, roll_step_deg=60))
    ok = np.flatnonzero(np.asarray(gr.status).astype(str) == "ok")
    q, mp = gr.quality, gr.mass_props
    assert q is not None and mp is not None and len(ok) >= SPREAD
    force = float(gr.gripper.grip_force) / q.gravity_margin
    by_force = np.argsort(force, kind="stable")
    pick = by_force[np.unique(np.linspace(0, len(ok) - 1, SPREAD).round().astype(int))]
    rows = ok[pick]
    T, width = gr.frames.T_part_tcp[rows], gr.cand.candidates.width[gr.frames.candidate[rows]]
    sim, censored = simulated_hold_force(part.mesh, gr.gripper, gr.T_world_part, T, width, force[pick],
                                         mass_props=mp, table_z=gr.cell.table_z, contact_area=q.contact_area[pick],
                                         decomposition="hull", steps=5)
    nominal = simulate_grasps(part.mesh, gr.gripper, gr.T_world_part, T, width, table_z=gr.cell.table_z,
                              mass_props=mp, contact_area=q.contact_area[pick], decomposition="hull").success
    return request.param, float(gr.gripper.grip_force), q.gravity_margin[pick], force[pick], sim, censored, nominal


def test_the_simulated_holding_force_orders_the_grasps_as_predicted(calibration):
    name, _, _, predicted, sim, censored, _ = calibration
    assert not censored.any(), f"{name}: simulated holding force beyond 16x the prediction"
    assert np.ptp(predicted) > 0.2 * predicted.max(), f"{name}: the grasps should span a range of forces"
    if name not in TIGHT:
        pytest.skip(f"{name}: the simulated part swings back under gravity (module docstring)")
    rho = spearmanr(predicted, sim).statistic
    assert rho >= 0.9, f"{name}: Spearman {rho:.2f}; predicted {np.round(predicted, 1)}, simulated {np.round(sim, 1)}"


def test_no_grasp_needs_more_than_the_predicted_force(calibration):
    """The simulation holds every grasp at no more than 1.2x its predicted force; where gravity
    loads the twist, from 0.8x (the bisection's 13 % step and MuJoCo's soft contacts)."""
    name, _, _, predicted, sim, _, _ = calibration
    ratio = sim / predicted
    assert (ratio < 1.2).all(), f"{name}: simulated / predicted {np.round(ratio, 2)}"
    if name in TIGHT:
        assert (ratio > 0.8).all(), f"{name}: simulated / predicted {np.round(ratio, 2)}"


def test_predicted_hold_agrees_with_the_simulation_at_the_grippers_force(calibration):
    """Held at the gripper's force where the bisection says so (beyond its last bracket, +-10 %)."""
    name, grip_force, margin, _, sim, _, nominal = calibration
    clear = np.abs(np.log(sim / grip_force)) > np.log(1.1)
    assert np.array_equal(nominal[clear], (sim <= grip_force)[clear]), \
        f"{name}: simulated {np.round(sim, 1)} N vs {grip_force} N, held {nominal}"
    if name in TIGHT:
        assert np.array_equal(nominal, margin >= 1.0), f"{name}: margins {np.round(margin, 2)}, held {nominal}"
    else:  # conservative: nothing predicted to hold slips
        assert nominal[margin >= 1.0].all(), f"{name}: margins {np.round(margin, 2)}, held {nominal}"
