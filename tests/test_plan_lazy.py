"""Rank-order, chunked evaluation of the grasp stage (``grasplan.grasps.pipeline.LazyGrasps``, ``grasplan
plan`` without ``--check-all``): whatever it ranks must be what the eager computation (every pose
collision-checked and scored) ranks at the same positions, and unchecked poses are ``not_checked``
(never called a collision)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from conftest import paper_part

K = 30
#: weights with a small physical share, so the score bound prunes (the shipped weights give the
#: physical terms 0.70 of the score: nothing is pruned there, the ranking must still agree)
PRUNING = (("center", 0.35), ("top", 0.45), ("width", 0.1), ("gravity_margin", 0.05), ("epsilon", 0.05))


def _eager_order(gr, min_distance=0.005, min_angle_deg=15.0):
    from grasplan.config.scoring import distinct_order

    ok = np.flatnonzero(np.asarray(gr.status).astype(str) == "ok")
    sc = np.asarray(gr.score, dtype=np.float64)
    order = ok[np.lexsort((ok, -sc[ok]))]
    return distinct_order(np.asarray(gr.frames.T_part_tcp), order, min_distance=min_distance,
                          min_angle_deg=min_angle_deg)



@pytest.mark.parametrize("name,weights", [
    ("example:bracket.stl", PRUNING),
    ("paper:SileanePepper.stl", PRUNING),
    ("paper:TLess20.stl", None),
    ("paper:IPAGearShaft.stl", None),  # shipped weights: the physical bound prunes (below)
])
def test_lazy_ranking_equals_eager(example_part, name, weights):
    from grasplan.grasps.pipeline import compute_grasps
    from grasplan.part.mesh import load_part
    from grasplan.config.params import GraspParams

    kind, fname = name.split(":")
    path = example_part(fname) if kind == "example" else paper_part(fname)
    part = load_part(path, units="mm" if kind == "example" else "auto")
    gp = GraspParams() if weights is None else replace(GraspParams(), score_weights=weights)
    eager = compute_grasps(part, grasps=gp)
    lazy_res = compute_grasps(part, grasps=gp, lazy=True, chunk=500)
    ev = lazy_res.lazy
    assert np.all(np.asarray(lazy_res.status).astype(str) == "not_checked")
    it = ev.ranked(0.005, 15.0)
    got = [next(it) for _ in range(K)]
    want = _eager_order(eager)[:K].tolist()
    assert got == want
    # what was checked agrees with the eager stage pose by pose; the rest is not_checked
    res = ev.result()
    st = np.asarray(res.status).astype(str)
    checked = st != "not_checked"
    assert np.count_nonzero(checked) == ev.checked > 0
    np.testing.assert_array_equal(st[checked], np.asarray(eager.status).astype(str)[checked])
    ok = st == "ok"
    np.testing.assert_allclose(np.asarray(res.score)[ok], np.asarray(eager.score)[ok], rtol=0, atol=1e-12)
    # the bound is an upper bound of every checked score
    assert np.all(ev.ub[ok] >= np.asarray(res.score)[ok])
    if weights is not None or "GearShaft" in name:
        assert ev.checked < ev.M, "the score bound pruned nothing"
    # the certified order stays the eager one as more chunks are checked
    order, n = ev.order(0.005, 15.0)
    assert order[:n].tolist() == _eager_order(eager)[:n].tolist()
    ev.check_all()
    order, n = ev.order(0.005, 15.0)
    assert n == len(order) and order.tolist() == _eager_order(eager).tolist()


def test_plan_lazy_equals_check_all(example_part):
    """The whole plan: same planned grasps and ranks with and without --check-all; unchecked poses
    are not_checked with a reason, and no not_checked pose is ranked or planned."""
    from grasplan.part.mesh import load_part
    from grasplan.config.params import GraspParams, PlanParams
    from grasplan.motion.planning import plan

    part = load_part(example_part("bracket.stl"), units="mm")
    gp = replace(GraspParams(), score_weights=PRUNING)
    pp = PlanParams(top=5, budget_s=None)
    lazy = plan(part, "ur5", grasps=gp, planning=replace(pp, check_all=False))
    full = plan(part, "ur5", grasps=gp, planning=replace(pp, check_all=True))
    assert lazy.planned_ids() == full.planned_ids() and len(lazy.planned_ids()) > 0
    st = lazy.grasps.status.astype(str)
    nc = st == "not_checked"
    assert nc.any() and "not_checked" not in set(full.grasps.status.astype(str))
    assert np.all(lazy.grasps.rank[nc] < 0)
    assert all(r.startswith("not checked: ranked below the planned grasps") for r in lazy.grasps.reason[nc])
    ranked = lazy.grasps.rank >= 0
    np.testing.assert_array_equal(lazy.grasps.rank[ranked], full.grasps.rank[ranked])
    # statuses of checked poses agree (planning outcomes of tried grasps and collisions)
    np.testing.assert_array_equal(st[~nc & (st != "not_tried")], full.grasps.status.astype(str)[~nc & (st != "not_tried")])
    doc = lazy.to_json()
    assert doc["counts"]["not_checked"] == int(nc.sum()) and doc["counts"]["checked"] == int((~nc).sum())


@pytest.mark.parametrize("name", ["example:bracket.stl", "example:gear.stl", "paper:TLess20.stl"])
def test_physical_bounds_are_upper_bounds(example_part, name):
    """The bounds the rank-order evaluation sorts by (the pad's whole area, the load straight
    down) are >= the gravity_margin and epsilon the quality step computes, pose by pose."""
    from grasplan.grasps.pipeline import compute_grasps
    from grasplan.part.mass import mass_properties
    from grasplan.part.mesh import load_part
    from grasplan.grasps.quality import physical_bounds

    kind, fname = name.split(":")
    path = example_part(fname) if kind == "example" else paper_part(fname)
    part = load_part(path, units="mm" if kind == "example" else "auto")
    gr = compute_grasps(part)
    ok = np.flatnonzero(np.asarray(gr.status).astype(str) == "ok")
    assert len(ok) and gr.quality is not None
    mp = mass_properties(part.mesh, density=gr.params.density)
    c = gr.cand.candidates
    b = physical_bounds(part.mesh, mp, gr.gripper, gr.frames.T_part_tcp[ok], gr.frames.candidate[ok], c.contacts,
                        c.normals, c.width[gr.frames.candidate[ok]], T_world_part=gr.T_world_part, mu=float(gr.cand.params.mu))
    assert np.all(b["gravity_margin"] >= gr.quality.gravity_margin * (1 - 1e-12))
    assert np.all(b["epsilon"] >= gr.quality.epsilon - 1e-12)
    # and not vacuous: the margin bound is finite and of the order of the margins
    assert np.all(np.isfinite(b["gravity_margin"])) and np.median(b["gravity_margin"] / gr.quality.gravity_margin) < 20
