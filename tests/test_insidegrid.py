"""The voxel grid of grasplan/geometry/insidegrid.py checked against independent tests: every point it calls
inside or outside is so by the generalised winding number (no ray casting), and every inside
point's depth bound is at most its exact distance to the surface (trimesh's closest point on each
triangle), on the example parts, on curved primitives at several tessellations and with the part
moved and turned (the grid lives in the part's frame)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from grasplan.geometry.containment import RayGrid, points_inside, points_inside_tree
from grasplan.geometry.insidegrid import InsideGrid, inside_grid
from grasplan.part.mesh import load_part, part_from_arrays, part_from_trimesh

BRACKET = Path(__file__).resolve().parents[1] / "examples" / "parts" / "bracket.stl"


def _exact_distance(mesh, pts: np.ndarray) -> np.ndarray:
    tri = np.asarray(mesh.vertices)[np.asarray(mesh.faces)]
    out = np.empty(len(pts))
    for c in range(0, len(pts), 32):
        p = pts[c:c + 32]
        cp = trimesh.triangles.closest_point(np.repeat(tri[None], len(p), axis=0).reshape(-1, 3, 3),
                                             np.repeat(p, len(tri), axis=0))
        out[c:c + 32] = np.linalg.norm(cp - np.repeat(p, len(tri), axis=0), axis=1).reshape(len(p), len(tri)).min(axis=1)
    return out


def _check(mesh, grid: InsideGrid, pts: np.ndarray, n_dist: int = 300) -> tuple[float, float]:
    """Asserts the grid's promises at ``pts``; returns (share decided, share inside)."""
    state, deep = grid.lookup(pts)
    wind = points_inside(mesh, pts)
    assert not np.any((state == 1) & ~wind), "a point the grid calls inside is outside"
    assert not np.any((state == -1) & wind), "a point the grid calls outside is inside"
    assert np.all(deep[state != 1] == 0.0)
    ins = np.flatnonzero(state == 1)[:n_dist]
    if len(ins):
        d = _exact_distance(mesh, pts[ins])
        assert np.all(deep[ins] <= d + 1e-12), float(np.max(deep[ins] - d))
    # the grid with the exact test behind it is the exact test
    ray = RayGrid(mesh.vertices, mesh.faces)
    assert np.array_equal(grid.inside(ray, mesh, pts), points_inside_tree(ray, mesh, pts))
    return float(np.mean(state != 0)), float(np.mean(wind))


def _points(mesh, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(mesh.vertices).min(axis=0), np.asarray(mesh.vertices).max(axis=0)
    pad = 0.1 * (hi - lo)
    return rng.uniform(lo - pad, hi + pad, (n, 3))


@pytest.mark.parametrize("name", ["gear.stl", "box.stl", "bracket.stl"])
def test_grid_verdicts_hold_on_the_example_parts(example_part, name):
    mesh = load_part(example_part(name)).mesh
    grid = inside_grid(mesh)
    assert inside_grid(mesh) is grid  # built once per mesh
    decided, share_in = _check(mesh, grid, _points(mesh, 3000, 0))
    assert 0.05 < share_in < 0.95  # inside and outside points were both tested
    assert decided > 0.5  # the grid decides most points by itself
    assert np.any(grid.depth_lo > 0.0)


@settings(max_examples=8, deadline=None)
@given(kind=st.sampled_from(["cylinder", "cone", "sphere", "torus"]), sections=st.integers(6, 40),
       seed=st.integers(0, 1000))
def test_grid_verdicts_hold_on_curved_primitives_at_any_tessellation(kind, sections, seed):
    if kind == "cylinder":
        tm = trimesh.creation.cylinder(radius=0.02, height=0.05, sections=sections)
    elif kind == "cone":
        tm = trimesh.creation.cone(radius=0.02, height=0.04, sections=sections)
    elif kind == "sphere":
        tm = trimesh.creation.uv_sphere(radius=0.02, count=(max(sections // 2, 4), sections))
    else:
        tm = trimesh.creation.torus(major_radius=0.025, minor_radius=0.008, major_sections=sections,
                                    minor_sections=max(sections // 2, 6))
    mesh = part_from_trimesh(tm).mesh
    _check(mesh, InsideGrid.build(mesh), _points(mesh, 1500, seed), n_dist=150)


@settings(max_examples=5, deadline=None)
@given(rot=st.tuples(*[st.floats(-np.pi, np.pi)] * 3), shift=st.tuples(*[st.floats(-0.5, 0.5)] * 3))
def test_grid_verdicts_hold_for_a_moved_part(rot, shift):
    """The bracket moved and turned (its mesh, not the query): the grid built for it still keeps
    every promise (nothing in the grid depends on the mesh's placement or axes)."""
    m0 = load_part(BRACKET).mesh
    T = trimesh.transformations.euler_matrix(*rot)
    mesh = part_from_arrays(np.asarray(m0.vertices) @ T[:3, :3].T + np.asarray(shift), m0.faces).mesh
    _check(mesh, InsideGrid.build(mesh), _points(mesh, 1500, 1), n_dist=100)


def test_grid_size_is_bounded_for_a_large_part():
    mesh = part_from_trimesh(trimesh.creation.box(extents=(1.0, 0.6, 0.4))).mesh
    grid = InsideGrid.build(mesh, max_voxels=200_000)
    assert grid.state.size <= 200_000
    pts = _points(mesh, 2000, 2)
    decided, _ = _check(mesh, grid, pts)
    assert decided > 0.3  # a coarse grid (18 mm voxels) still decides a good share
    # far beyond the grid: outside, decided without a test
    state, deep = grid.lookup(np.array([[5.0, 5.0, 5.0], [-3.0, 0.0, 0.0]]))
    assert np.all(state == -1) and np.all(deep == 0.0)
