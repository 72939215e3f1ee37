"""grasplan.piles.checks: the interpenetration depth skips probe points that cannot matter (outside
the other mesh's box, within tol of its surface) without changing a warning: against the same
estimate over every probe point, for pairs of parts pushed into each other by 0 to 8 mm."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from grasplan.piles import checks as pc
from grasplan.cell.shapes import bvh
from grasplan.part.mesh import load_part
from grasplan.geometry.transforms import rpy_matrix

PARTS = Path(__file__).resolve().parents[1] / "examples" / "parts"


@pytest.mark.parametrize("name", ["bracket", "gear"])
def test_skipped_probes_change_no_warning(name):
    mesh = load_part(PARTS / f"{name}.stl").mesh
    prep, b_bvh = pc._prepared(mesh), bvh(mesh.vertices, mesh.faces)
    extent = float(np.ptp(mesh.vertices, axis=0).max())
    rng = np.random.default_rng(3)
    tol = 0.002
    deeper = 0
    for k in range(24):
        Ta, Tb = np.eye(4), np.eye(4)
        Ta[:3, :3] = rpy_matrix(*rng.uniform(-np.pi, np.pi, 3))
        Tb[:3, :3] = rpy_matrix(*rng.uniform(-np.pi, np.pi, 3))
        Tb[:3, 3] = rng.normal(size=3) / np.sqrt(3) * (extent * rng.uniform(0.4, 1.0))
        wa = mesh.vertices @ Ta[:3, :3].T + Ta[:3, 3]
        wb = mesh.vertices @ Tb[:3, :3].T + Tb[:3, 3]
        lo, hi = np.maximum(wa.min(0), wb.min(0)), np.minimum(wa.max(0), wb.max(0))
        if np.any(lo > hi):
            continue
        every = pc._depth_into(prep, Ta, mesh, prep, b_bvh, Tb, lo, hi, floor=0.0)  # none skipped but outside b's box
        fast = pc._depth_into(prep, Ta, mesh, prep, b_bvh, Tb, lo, hi, floor=tol)
        if every > tol:
            deeper += 1
            assert fast == every, (k, fast, every)
        else:
            assert fast <= tol, (k, fast, every)
    assert deeper >= 3  # the cases include real interpenetration


def test_obstacles_whose_box_is_not_met_are_skipped_without_changing_an_error():
    """check_cell skips an obstacle whose bounding box the instance's does not meet: the same
    error (or none) as the depth into every obstacle, for boxes, cylinders and spheres turned at
    random and parts placed at random around them."""
    from types import SimpleNamespace

    from grasplan.cell.model import Obstacle
    from grasplan.errors import InputError
    from grasplan.piles.scene_file import Instance

    mesh = load_part(PARTS / "gear.stl").mesh
    rng = np.random.default_rng(5)

    def pose(scale: float) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = rpy_matrix(*rng.uniform(-np.pi, np.pi, 3))
        T[:3, 3] = rng.uniform(-scale, scale, 3)
        return T
    obstacles = [Obstacle("b", "box", pose(0.05), size=(0.04, 0.02, 0.03)),
                 Obstacle("c", "cylinder", pose(0.05), radius=0.012, length=0.05),
                 Obstacle("s", "sphere", pose(0.05), radius=0.015)]
    cell = SimpleNamespace(table_z=-1.0, obstacles=obstacles)
    tol = 0.002
    outcomes = set()
    for k in range(200):
        inst = Instance(id=f"i{k}", part="gear", T_world_part=pose(0.09))
        pts = mesh.vertices @ inst.T_world_part[:3, :3].T + inst.T_world_part[:3, 3]
        deep = next((o.name for o in obstacles if pc._inside_depth(o, pts) > tol), None)  # every obstacle
        try:
            pc.check_cell([inst], {"gear": mesh}, cell, tol=tol)
            got = None
        except InputError as exc:
            got = str(exc).split("inside obstacle ")[1].split(";")[0]
        assert got == deep, (k, got, deep)
        outcomes.add(got)
    assert outcomes == {None, "b", "c", "s"}  # every kind hit, and misses
