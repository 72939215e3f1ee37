"""Occlusion of the parts of a pile seen from a camera (:mod:`grasplan.clutter.occlusion`).

Small worlds of box-shaped parts in the ``bin`` cell (inner floor 0.30 m x 0.20 m, floor top at
z = 0.01 m, walls 0.15 m high), placed by hand (no physics: occlusion reads the world's kinematics).
The expected fractions are derived from the geometry here, and an unsettled stack of oriented
boxes is checked ray by ray against a slab ray tracer written here (no MuJoCo)."""
from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import mujoco
import numpy as np
import pytest
import trimesh

from grasplan.cell.model import BinSpec, Cell, load_cell
from grasplan.clutter.occlusion import CAMERA_HEIGHT, HIT_TOL, camera_point, occlusion, surface_points
from grasplan.clutter.world import ClutterWorld
from grasplan.errors import InputError
from grasplan.geometry.meshdata import MeshData
from grasplan.gripper.load import load_gripper
from grasplan.sim.pileworld import PartBody, PileWorld, part_body


@pytest.fixture(scope="module")
def cell() -> Cell:
    return load_cell("bin")


def _box(name: str, extents: Sequence[float] | np.ndarray) -> PartBody:
    tm = trimesh.creation.box(extents=extents)
    return part_body(name, MeshData(tm.vertices, tm.faces), density=1000.0, decomposition="hull", cache=False)


def _T(x: float, y: float, z: float, yaw_deg: float = 0.0, roll_deg: float = 0.0) -> np.ndarray:
    """A pose: rotation about world z by ``yaw_deg`` after one about x by ``roll_deg``, then (x, y, z)."""
    a, b = np.radians(yaw_deg), np.radians(roll_deg)
    Rz = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(b), -np.sin(b)], [0.0, np.sin(b), np.cos(b)]])
    T = np.eye(4)
    T[:3, :3] = Rz @ Rx
    T[:3, 3] = [x, y, z]
    return T


def _bin(cell: Cell) -> BinSpec:
    assert cell.bin is not None
    return cell.bin


def _floor(cell: Cell) -> float:
    return float(_bin(cell).T_world_bin[2, 3])


def _centre(cell: Cell) -> tuple[float, float]:
    c = np.asarray(_bin(cell).T_world_bin)[:3, 3]
    return float(c[0]), float(c[1])


# ------------------------------------------------------------------------------------------------
# the camera and the samples
# ------------------------------------------------------------------------------------------------
def test_camera_point_is_above_the_bin_floor_or_the_table(cell: Cell) -> None:
    c = np.asarray(_bin(cell).T_world_bin)[:3, 3]
    np.testing.assert_allclose(camera_point(cell), [c[0], c[1], c[2] + CAMERA_HEIGHT])
    table = load_cell("table")
    assert table.bin is None
    np.testing.assert_allclose(camera_point(table), [table.part_xy[0], table.part_xy[1], table.table_z + CAMERA_HEIGHT])


def test_surface_points_lie_on_the_part_uniformly_by_area(cell: Cell) -> None:
    ext = np.array([0.04, 0.02, 0.01])
    world = PileWorld(cell, [_box("a", ext)], mu=0.5)
    T = _T(0.4, 0.02, 0.05, yaw_deg=30.0, roll_deg=20.0)
    world.place(0, T)
    p = surface_points(world, 0, 6000, np.random.default_rng(3))
    local = (p - T[:3, 3]) @ T[:3, :3]                       # part frame
    rel = np.abs(local) / (0.5 * ext)
    assert rel.max() < 1 + 1e-5 and np.all(np.abs(rel.max(axis=1) - 1) < 1e-5)  # on the box's boundary
    face_axis = np.argmax(rel, axis=1)
    share = np.bincount(face_axis, minlength=3) / len(p)
    area = 2 * np.array([ext[1] * ext[2], ext[0] * ext[2], ext[0] * ext[1]])  # faces normal to x, y, z
    np.testing.assert_allclose(share, area / area.sum(), atol=0.025)
    top = local[face_axis == 2]  # uniform within a face: mean |x|, |y| a quarter of its sides
    np.testing.assert_allclose(np.abs(top[:, :2]).mean(axis=0), 0.25 * ext[:2], rtol=0.05)


# ------------------------------------------------------------------------------------------------
# derived cases
# ------------------------------------------------------------------------------------------------
def test_a_lone_part_in_the_middle_is_seen(cell: Cell) -> None:
    world = PileWorld(cell, [_box("a", [0.03, 0.02, 0.01])], mu=0.5)
    x, y = _centre(cell)
    world.place(0, _T(x, y, _floor(cell) + 0.005, yaw_deg=20.0))
    occ = occlusion(world, camera_point(cell))
    assert occ.shape == (1,) and occ.dtype == np.float64
    assert occ[0] < 0.02


def test_a_part_under_a_plate_is_hidden_and_the_plate_is_seen(cell: Cell) -> None:
    world = PileWorld(cell, [_box("small", [0.02, 0.02, 0.01]), _box("plate", [0.06, 0.06, 0.004])], mu=0.5)
    x, y = _centre(cell)
    z = _floor(cell)
    world.place(0, _T(x, y, z + 0.005))
    world.place(1, _T(x, y, z + 0.010 + 0.002))  # resting on the small box, reaching 20 mm past it
    occ = occlusion(world, camera_point(cell))
    assert occ[0] > 0.95 and occ[1] < 0.02, occ


@pytest.mark.parametrize("covered", [0.5, 0.75])
def test_a_half_covered_part_is_hidden_by_its_covered_share(cell: Cell, covered: float) -> None:
    """A plate lies on the part, its edge across the part's length at ``covered`` of it. Seen from
    straight above the part's centre, every surface point on the plate's side of that edge is
    behind the plate (up to a sliver next to the edge, the rays' slant over the plate's height,
    < 2 % of the part) and no other: the expected fraction is that side's share of the surface,
    top and bottom, the two long sides in part and the end face under the plate."""
    L, W, H = 0.04, 0.02, 0.01
    world = PileWorld(cell, [_box("part", [L, W, H]), _box("plate", [0.08, 0.06, 0.004])], mu=0.5)
    x, y = _centre(cell)
    z = _floor(cell)
    world.place(0, _T(x, y, z + 0.5 * H))
    edge = x - 0.5 * L + covered * L  # the plate covers x < edge
    world.place(1, _T(edge - 0.04, y, z + H + 0.002))
    total = 2 * (L * W + L * H + W * H)
    expected = (covered * 2 * (L * W + L * H) + W * H) / total
    occ = occlusion(world, camera_point(cell), rays=1024)
    assert abs(occ[0] - expected) < 0.08, (occ[0], expected)  # 1024 rays: sampling sd <= 0.016
    assert occ[1] < 0.02


def test_a_bin_wall_hides_a_part_from_a_low_camera_outside_the_bin(cell: Cell) -> None:
    x, y = _centre(cell)
    z = _floor(cell)
    inner_x = x + 0.5 * _bin(cell).inner[0]            # the +x wall's inner face
    outer_x = inner_x + _bin(cell).wall
    world = PileWorld(cell, [_box("a", [0.03, 0.02, 0.01])], mu=0.5)
    world.place(0, _T(inner_x - 0.015, y, z + 0.005))  # against the +x wall
    low = np.array([outer_x + 0.15, y, z + 0.5 * _bin(cell).height])  # outside, below the wall's top
    # every ray from there to the part crosses the wall's outer face within the wall's extent
    hull = world.hull_world(0)
    s = (outer_x - low[0]) / (hull[:, 0] - low[0])
    cross = low + s[:, None] * (hull - low)
    assert np.all(cross[:, 2] > z) and np.all(cross[:, 2] < z + _bin(cell).height)
    assert np.all(np.abs(cross[:, 1] - y) < 0.5 * _bin(cell).inner[1] + _bin(cell).wall)
    assert occlusion(world, low)[0] > 0.9
    assert occlusion(world, camera_point(cell))[0] < 0.05
    wall = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_GEOM, "bin_wall_+x")
    world.model.geom_rgba[wall, 3] = 0.0  # drawn invisible: out of the camera's scene
    assert occlusion(world, low)[0] < 0.05


# ------------------------------------------------------------------------------------------------
# parked bodies, seeds, independence, the gripper
# ------------------------------------------------------------------------------------------------
def _half_covered(cell: Cell) -> PileWorld:
    world = PileWorld(cell, [_box("part", [0.04, 0.02, 0.01]), _box("plate", [0.08, 0.06, 0.004]),
                             _box("far", [0.02, 0.02, 0.02]), _box("away", [0.02, 0.02, 0.02])], mu=0.5)
    x, y = _centre(cell)
    z = _floor(cell)
    world.place(0, _T(x, y, z + 0.005))
    world.place(1, _T(x - 0.04, y, z + 0.012))
    world.place(2, _T(x + 0.1, y + 0.06, z + 0.01))
    return world


def test_parked_bodies_are_nan_and_the_same_seed_gives_the_same_array(cell: Cell) -> None:
    world = _half_covered(cell)
    cam = camera_point(cell)
    occ = occlusion(world, cam, seed=5)
    assert np.isnan(occ[3]) and np.all(np.isfinite(occ[:3]))
    np.testing.assert_array_equal(occlusion(world, cam, seed=5), occ)
    other = occlusion(world, cam, seed=6)
    assert other[0] != occ[0]  # a partly hidden part: other samples, another estimate
    world.park(1)
    assert np.isnan(occlusion(world, cam)[1])


def test_a_bodys_occlusion_does_not_depend_on_bodies_out_of_its_view(cell: Cell) -> None:
    """A half-covered part's estimate (one that other samples would change) is the same bits
    whether a body listed before it, in a corner out of its view, is present or parked."""
    world = PileWorld(cell, [_box("corner", [0.02, 0.02, 0.02]), _box("part", [0.04, 0.02, 0.01]),
                             _box("plate", [0.08, 0.06, 0.004])], mu=0.5)
    x, y = _centre(cell)
    z = _floor(cell)
    world.place(1, _T(x, y, z + 0.005))
    world.place(2, _T(x - 0.04, y, z + 0.012))
    cam = camera_point(cell)
    alone = occlusion(world, cam, seed=2)
    assert occlusion(world, cam, seed=3)[1] != alone[1]
    world.place(0, _T(x - 0.1, y - 0.06, z + 0.01))
    with_corner = occlusion(world, cam, seed=2)
    assert with_corner[0] == 0.0
    np.testing.assert_array_equal(with_corner[1:], alone[1:])


def test_the_gripper_is_not_an_occluder(cell: Cell) -> None:
    """The clutter world's gripper (a body neither part nor static) right above a part: rays pass
    through it. It does stand in the way (the ray to the part's centre meets it first)."""
    gripper = load_gripper("schunk_egp_c_40")
    cw = ClutterWorld(cell, [_box("a", [0.03, 0.02, 0.01])], gripper, mu=0.5)
    x, y = _centre(cell)
    cw.world.place(0, _T(x, y, _floor(cell) + 0.005))
    cam = camera_point(cell)
    seen = occlusion(cw.world, cam)
    cw.set_hand(_T(x, y, _floor(cell) + 0.25))
    mujoco.mj_forward(cw.model, cw.data)
    gid = np.empty(1, dtype=np.int32)
    down = cw.world.pose(0)[:3, 3] - cam
    mujoco.mj_ray(cw.model, cw.data, cam, down / np.linalg.norm(down), None, True, -1, gid)
    assert gid[0] >= 0 and cw.model.geom_bodyid[gid[0]] not in (0, cw.world.body_ids[0])
    np.testing.assert_array_equal(occlusion(cw.world, cam), seen)
    assert seen[0] < 0.02


def test_bad_arguments_are_input_errors(cell: Cell) -> None:
    world = PileWorld(cell, [_box("a", [0.03, 0.02, 0.01])], mu=0.5)
    with pytest.raises(InputError):
        occlusion(world, [0.0, 0.0])
    with pytest.raises(InputError):
        occlusion(world, [0.0, np.nan, 1.0])
    with pytest.raises(InputError):
        occlusion(world, camera_point(cell), rays=0)
    assert np.isnan(occlusion(world, camera_point(cell))).all()  # nothing present


# ------------------------------------------------------------------------------------------------
# a stack of oriented boxes against an independent ray tracer
# ------------------------------------------------------------------------------------------------
#: (extents, x, y offset from the bin centre, yaw_deg, roll_deg): stacked in this order, 1 mm apart
STACK = (((0.05, 0.03, 0.012), 0.0, 0.0, 10.0, 0.0),
         ((0.04, 0.02, 0.010), 0.012, 0.008, 55.0, 0.0),
         ((0.03, 0.03, 0.020), -0.02, -0.004, -20.0, 0.0),
         ((0.06, 0.012, 0.010), 0.004, 0.01, 80.0, 35.0),
         ((0.025, 0.02, 0.008), 0.11, 0.06, 0.0, 0.0))


def _stack(cell: Cell) -> tuple[PileWorld, list[tuple[np.ndarray, np.ndarray]]]:
    """The five boxes of :data:`STACK` (the last one alone near a corner), each box's pose and half
    extents. Boxes of the stack lie 1 mm above the one below (by their vertical extents)."""
    world = PileWorld(cell, [_box(f"b{k}", e) for k, (e, *_) in enumerate(STACK)], mu=0.5)
    x0, y0 = _centre(cell)
    bottom = _floor(cell)
    boxes = []
    for k, (e, dx, dy, yaw, roll) in enumerate(STACK):
        half = 0.5 * np.asarray(e)
        R = _T(0, 0, 0, yaw, roll)[:3, :3]
        half_z = float(np.abs(R[2]) @ half)  # the box's vertical half extent
        if k == len(STACK) - 1:
            bottom = _floor(cell)
        T = _T(x0 + dx, y0 + dy, bottom + half_z, yaw, roll)
        world.place(k, T)
        boxes.append((T, half))
        bottom += 2 * half_z + 0.001
    return world, boxes


def _ray_box(cam: np.ndarray, dirs: np.ndarray, T: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Distance (m) along each unit ray from ``cam`` to the box (pose ``T``, half extents), inf if
    it misses: the slab method."""
    o = (cam - T[:3, 3]) @ T[:3, :3]
    d = dirs @ T[:3, :3]
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-half - o) / d, (half - o) / d
    lo = np.nanmax(np.minimum(t1, t2), axis=1)
    hi = np.nanmin(np.maximum(t1, t2), axis=1)
    t = np.where(lo >= 0, lo, hi)
    return np.where((hi >= lo) & (t >= 0), t, np.inf)


@pytest.mark.parametrize("where", ["above", "oblique"])
def test_a_stack_matches_an_independent_ray_tracer(cell: Cell, where: str) -> None:
    world, boxes = _stack(cell)
    x0, y0 = _centre(cell)
    cam = camera_point(cell) if where == "above" else np.array([x0 - 0.25, y0 - 0.2, _floor(cell) + 0.3])
    statics = [(o.T_world_obstacle, 0.5 * np.asarray(o.size)) for o in _bin(cell).obstacles()]
    rays = 512
    occ = occlusion(world, cam, rays=rays, seed=1)
    ref = np.empty(len(boxes))
    for i, (T, half) in enumerate(boxes):
        p = surface_points(world, i, rays, np.random.default_rng((1, i)))
        reach = np.linalg.norm(p - cam, axis=1)
        dirs = (p - cam) / reach[:, None]
        own = _ray_box(cam, dirs, T, half)
        others = [_ray_box(cam, dirs, Tb, hb) for j, (Tb, hb) in enumerate(boxes) if j != i]
        others += [_ray_box(cam, dirs, np.asarray(Tb), hb) for Tb, hb in statics]
        first_other = np.min(others, axis=0)
        ref[i] = np.mean((first_other <= reach + HIT_TOL) & (first_other < own))
    assert np.all(np.abs(occ - ref) <= 2.0 / rays), (occ, ref)  # grazing rays: float32 mesh vertices
    assert np.ptp(ref) > 0.3 and np.any(ref == 0)  # the stack hides some boxes and not others


def test_five_parts_take_well_under_50_ms(cell: Cell) -> None:
    world, _ = _stack(cell)
    cam = camera_point(cell)
    occlusion(world, cam)
    best = min(_timed(lambda: occlusion(world, cam)) for _ in range(5))
    assert best < 0.05, best


def _timed(f: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    f()
    return time.perf_counter() - t0
