"""Executing a planned push in the clutter world (:func:`grasplan.clutter.pushing.execute_push`),
without the planner: pushes built by the planner's own :func:`grasplan.pick.push.push_poses` for
boxes (examples/parts/box.stl, 30 x 20 x 10 mm, colliding through their convex hulls) lying in the
bin. Expected displacements come from the geometry of the poses, the outcome's numbers from MuJoCo."""
from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from grasplan.cell.model import load_cell
from grasplan.clutter.execute import APPROACH_SPEED, COLLIDE_FORCE
from grasplan.clutter.pushing import (
    COLLIDED, MOVED, NO_EFFECT, PUSH_MIN_MOVE, PUSH_OUTCOMES, PUSH_SPEED, PushOutcome, execute_push
)
from grasplan.clutter.world import ClutterWorld
from grasplan.gripper.load import load_gripper
from grasplan.part.mesh import load_part
from grasplan.part.stability import part_centre_of_mass
from grasplan.pick.push import TILTS_DEG, Candidate, PushPoses, push_poses
from grasplan.piles.scene_file import Instance
from grasplan.sim.pileworld import part_body
from grasplan.sim.simulate import CLOSE_SPEED, TORSION_LENGTH

BOX = Path(__file__).resolve().parents[1] / "examples" / "parts" / "box.stl"
#: box_a lies this far (m) from the bin's +x wall; the push moves the TCP this far (m)
GAP, DISTANCE = 0.025, 0.04
MINUS_X, PLUS_X = np.array([-1.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def cell():
    return load_cell("bin")


@pytest.fixture(scope="module")
def box():
    part = load_part(BOX)
    return part, np.asarray(part.mesh.convex_hull.vertices), np.asarray(part_centre_of_mass(part.mesh))


def _world(cell, box, gripper):
    """Two boxes lying flat in the bin, settled: ``box_a`` (body 0) GAP from the +x wall, ``box_b``
    (body 1) 75 mm from the -x wall, both on the bin's x axis; and the world's snapshot."""
    part = box[0]
    body = part_body("box", part.mesh, density=1200.0, decomposition="hull")
    bodies = [type(body)(name=n, pieces=body.pieces, mass=body.mass, hull=body.hull) for n in ("box_a", "box_b")]
    cw = ClutterWorld(cell, bodies, gripper, mu=0.3)
    Tb = np.asarray(cell.bin.T_world_bin)
    hx, (ex, _, ez) = 0.5 * cell.bin.inner[0], part.mesh.extents
    for k, x in enumerate((Tb[0, 3] + hx - GAP - 0.5 * ex, Tb[0, 3] - hx + 0.075 + 0.5 * ex)):
        T = np.eye(4)
        T[:3, 3] = [x, Tb[1, 3], Tb[2, 3] + 0.5 * ez + 1e-4]
        cw.world.place(k, T)
    assert cw.world.settle(lin=0.005, ang=0.05, hold=0.2, max_s=2.0).at_rest
    return cw, cw.world.snapshot()


@pytest.fixture(scope="module")
def jaw_world(cell, box):
    gripper = load_gripper("long_stroke_50")
    cw, snap = _world(cell, box, gripper)
    return gripper, cw, snap


def _wall_gap(cw, cell, i: int) -> float:
    """How far (m) body ``i``'s hull keeps from the bin's +x wall."""
    Tb = np.asarray(cell.bin.T_world_bin)
    return float(Tb[0, 3] + 0.5 * cell.bin.inner[0] - cw.world.hull_world(i)[:, 0].max())


def _touches(cw, T: np.ndarray, opening: float) -> list:
    """The gripper's contacts with its hand at ``T`` (jaws at ``opening``), the world not stepped."""
    import mujoco

    cw.set_hand(T)
    cw.set_jaws(opening)
    mujoco.mj_forward(cw.model, cw.data)
    out = cw.contacts()
    cw.park_hand()
    return out


def _poses(cw, box, gripper, i: int, against: str, gap: float, direction: np.ndarray, opening: float,
           tilt_deg: float | None = None) -> tuple[PushPoses, float]:
    """The planner's push poses for body ``i`` and the tilt (deg): ``tilt_deg``, or the first of the
    planner's tilts whose first pose and start touch nothing (the part included)."""
    _, hull, com = box
    c = Candidate(Instance(cw.world.bodies[i].name, "box", cw.world.pose(i)), against, gap, direction)
    for tilt in (TILTS_DEG if tilt_deg is None else (tilt_deg,)):
        pp = push_poses(c, hull, com, gripper, opening, tilt_deg=tilt)
        if tilt_deg is not None or not (_touches(cw, pp.T_above, opening) or _touches(cw, pp.T_start, opening)):
            return pp, tilt
    raise AssertionError("no tilt clears the wall and the part")


def _push(pp: PushPoses, direction: np.ndarray, distance: float, opening: float) -> SimpleNamespace:
    """A push-like record from ``pp``'s descent, moving ``distance`` along ``direction`` from its
    start and retreating by the descent's own offset."""
    T_end = pp.T_start.copy()
    T_end[:3, 3] += distance * direction
    T_retreat = T_end.copy()
    T_retreat[:3, 3] += pp.T_above[:3, 3] - pp.T_start[:3, 3]
    return SimpleNamespace(direction=direction, opening=opening, T_world_above=pp.T_above, T_world_start=pp.T_start,
                           T_world_end=T_end, T_world_retreat=T_retreat)


def _start_gap(cw, gripper, i: int, pp: PushPoses, direction: np.ndarray, opening: float) -> float:
    """How far (m) the TCP travels along ``direction`` from ``pp.T_start`` before the finger's
    leading face (the plane through the corner push_poses places: the fingers' +y face at their
    tips) reaches body ``i``'s hull at or above the fingertips (a box's back edge is parallel to the
    face, so its vertices give the first contact)."""
    finger = np.vstack([f.corners() for f in gripper.fingers(opening)])
    corner = pp.T_start[:3, :3] @ [0.0, finger[:, 1].max(), finger[:, 2].max()] + pp.T_start[:3, 3]
    y = pp.T_start[:3, 1]
    hull = cw.world.hull_world(i)
    above = hull[hull[:, 2] >= corner[2] - 1e-9]
    return float(((above - corner) @ y).min() / (direction @ y))


def _restart(cw, snap) -> None:
    cw.world.restore(snap)
    cw.park_hand()


def test_a_box_by_the_wall_is_pushed_away_from_it(jaw_world, box, cell):
    """box_a, GAP from the +x wall, pushed DISTANCE along -x with the jaws closed: the planner's
    poses need a tilt (upright, the gripper's body overlaps the wall), and the box moves along -x by
    the TCP's travel less the start gap to the finger's leading face (geometry: TIP_GAP less the
    face's lean over the box's top edge), within 1 mm (contact compliance), sideways and turned
    hardly at all; box_b, 100 mm away, does not move. The jaws stay shut the whole push."""
    gripper, cw, snap = jaw_world
    _restart(cw, snap)
    gap = _wall_gap(cw, cell, 0)
    assert gap == pytest.approx(GAP, abs=2e-4)
    opening = float(gripper.min_opening)
    pp, tilt = _poses(cw, box, gripper, 0, "bin_wall_+x", gap, MINUS_X, opening)
    upright, _ = _poses(cw, box, gripper, 0, "bin_wall_+x", gap, MINUS_X, opening, tilt_deg=0.0)
    assert tilt > 0.0 and "bin_wall_+x" in {c.other for c in _touches(cw, upright.T_start, opening)}
    expected = DISTANCE - _start_gap(cw, gripper, 0, pp, MINUS_X, opening)
    assert DISTANCE - 0.003 <= expected < DISTANCE  # TIP_GAP at most
    out = execute_push(cw, 0, _push(pp, MINUS_X, DISTANCE, opening), record=True)
    assert out.outcome == MOVED, out.reason
    assert out.along_m == pytest.approx(expected, abs=1e-3)
    assert math.sqrt(max(out.moved_m ** 2 - out.along_m ** 2, 0.0)) < 1e-3 and out.turned_deg < 2.0
    assert out.others_moved == () and out.fixed_force < COLLIDE_FORCE
    assert out.track and out.track_parts == ("box_a", "box_b")
    assert all(abs(s[2] - opening) < 1e-4 for s in out.track)  # the jaws' opening in every replay sample
    assert cw.hand_pose()[2, 3] < -1.0  # the gripper parked
    np.testing.assert_allclose(cw.pad_twist(), cw.mu * TORSION_LENGTH * 0.5 * cw.grip_force)  # pads back to nominal
    doc = out.to_json()
    assert doc["outcome"] == MOVED and doc["moved_m"] == out.moved_m and "track" not in doc
    assert doc["others_moved"] == []


def test_a_push_is_deterministic(jaw_world, box, cell):
    gripper, cw, snap = jaw_world
    opening = float(gripper.min_opening)
    outs = []
    for _ in range(2):
        _restart(cw, snap)
        pp, _ = _poses(cw, box, gripper, 0, "bin_wall_+x", _wall_gap(cw, cell, 0), MINUS_X, opening)
        outs.append(execute_push(cw, 0, _push(pp, MINUS_X, DISTANCE, opening)))
    assert outs[0].outcome == MOVED
    assert outs[0].moved_m == outs[1].moved_m and outs[0].along_m == outs[1].along_m
    assert outs[0].to_json() == outs[1].to_json()


def test_a_push_into_the_wall_collides(jaw_world, box, cell):
    """From the same start between box_a and the wall, DISTANCE towards the wall (+x): the gripper
    at the push's end would overlap the wall (the gap behind the finger is far shorter), so the run
    stops in the push phase: collided, box_a untouched."""
    gripper, cw, snap = jaw_world
    _restart(cw, snap)
    opening = float(gripper.min_opening)
    pp, _ = _poses(cw, box, gripper, 0, "bin_wall_+x", _wall_gap(cw, cell, 0), MINUS_X, opening)
    push = _push(pp, PLUS_X, DISTANCE, opening)
    assert "bin_wall_+x" in {c.other for c in _touches(cw, push.T_world_end, opening)}
    out = execute_push(cw, 0, push)
    assert out.outcome == COLLIDED and out.reason.startswith("push:"), out.reason
    assert out.moved_m < 1e-3
    # stopped in the push: after the descent, before the push's end (cosine profiles: pi d / 2 v each)
    t_descent = math.pi * float(np.linalg.norm(pp.T_start[:3, 3] - pp.T_above[:3, 3])) / (2.0 * APPROACH_SPEED)
    assert t_descent < out.sim_s < t_descent + math.pi * DISTANCE / (2.0 * PUSH_SPEED)


def test_a_gripper_starting_inside_the_wall_collides(jaw_world, box, cell):
    gripper, cw, snap = jaw_world
    _restart(cw, snap)
    opening = float(gripper.min_opening)
    pp, _ = _poses(cw, box, gripper, 0, "bin_wall_+x", _wall_gap(cw, cell, 0), MINUS_X, opening)
    push = _push(pp, MINUS_X, DISTANCE, opening)
    push.T_world_above = push.T_world_above.copy()
    push.T_world_above[0, 3] += 2.0 * GAP  # the gripper partly inside the wall (its inner face GAP behind box_a)
    assert max(c.depth for c in _touches(cw, push.T_world_above, opening) if c.other == "bin_wall_+x") > 0.001
    out = execute_push(cw, 0, push)
    assert out.outcome == COLLIDED and "first pose" in out.reason and "bin_wall_+x" in out.reason, out.reason
    assert out.sim_s == 0.0 and out.moved_m < 1e-3


def test_a_push_away_from_the_part_has_no_effect(jaw_world, box, cell):
    """box_b in the open: the planner's upright push from its +x side towards -x, flipped: the
    fingers start TIP_GAP beside it and move DISTANCE away (+x), touching nothing at its start, end
    and retreat: no effect, box_b (and box_a) where they were, no force on anything fixed."""
    gripper, cw, snap = jaw_world
    _restart(cw, snap)
    opening = float(gripper.min_opening)
    pp, tilt = _poses(cw, box, gripper, 1, "instance:box_a", 0.1, MINUS_X, opening, tilt_deg=0.0)
    push = _push(pp, PLUS_X, DISTANCE, opening)
    for T in (push.T_world_above, push.T_world_start, push.T_world_end, push.T_world_retreat):
        assert not _touches(cw, T, opening)
    assert _start_gap(cw, gripper, 1, pp, MINUS_X, opening) > 0.0  # beside the part, facing it
    out = execute_push(cw, 1, push)
    assert out.outcome == NO_EFFECT, out.reason
    assert out.moved_m < 1e-3 and out.others_moved == () and out.fixed_force == 0.0
    assert out.moved_m < PUSH_MIN_MOVE and out.outcome in PUSH_OUTCOMES


def test_a_pushed_box_pushes_its_neighbour(jaw_world, box, cell):
    """box_b placed 10 mm ahead of box_a along the push, with the jaws held 10 mm apart (both
    fingers on box_a's 20 mm face): box_a moves as alone, box_b is shoved along about the rest of
    the travel (others_moved), and the jaws keep their opening under the load."""
    gripper, cw, snap = jaw_world
    _restart(cw, snap)
    T_b = cw.world.pose(0)
    T_b[0, 3] -= float(box[0].mesh.extents[0]) + 0.01
    cw.world.place(1, T_b)
    opening = 0.01
    pp, _ = _poses(cw, box, gripper, 0, "bin_wall_+x", _wall_gap(cw, cell, 0), MINUS_X, opening)
    expected = DISTANCE - _start_gap(cw, gripper, 0, pp, MINUS_X, opening)
    out = execute_push(cw, 0, _push(pp, MINUS_X, DISTANCE, opening), record=True)
    assert out.outcome == MOVED and out.others_moved == ("box_b",), out.reason
    assert out.along_m == pytest.approx(expected, abs=1e-3)
    assert all(abs(s[2] - opening) < 2e-4 for s in out.track)
    assert cw.world.pose(1)[0, 3] < T_b[0, 3] - (expected - 0.01) + 2e-3


def test_a_linkage_grippers_push_poses_are_its_hand_poses(cell, box):
    """The Robotiq 2F-85 (its fingertips 13.5 mm beyond their full-opening place when closed): the
    planner's poses place its fingers with ``fingers(opening)``, so executed as they are they push
    box_a as the parallel gripper does (moved 13.5 mm higher they would pass over the 10 mm box)."""
    gripper = load_gripper("robotiq_2f_85")
    cw, snap = _world(cell, box, gripper)
    opening = float(gripper.min_opening)
    assert float(gripper.tcp_offset(opening)) > 0.01
    pp, _ = _poses(cw, box, gripper, 0, "bin_wall_+x", _wall_gap(cw, cell, 0), MINUS_X, opening)
    expected = DISTANCE - _start_gap(cw, gripper, 0, pp, MINUS_X, opening)
    out = execute_push(cw, 0, _push(pp, MINUS_X, DISTANCE, opening))
    assert out.outcome == MOVED and out.along_m == pytest.approx(expected, abs=1e-3), out.reason


def test_bad_input_is_refused(jaw_world, box, cell):
    gripper, cw, snap = jaw_world
    _restart(cw, snap)
    pp, _ = _poses(cw, box, gripper, 0, "bin_wall_+x", _wall_gap(cw, cell, 0), MINUS_X, 0.0)
    with pytest.raises(ValueError, match="horizontal"):
        execute_push(cw, 0, _push(pp, np.array([0.0, 0.0, 1.0]), DISTANCE, 0.0))
    with pytest.raises(ValueError, match="stroke"):
        execute_push(cw, 0, _push(pp, MINUS_X, DISTANCE, 1.0))
    with pytest.raises(ValueError, match="not in the world"):
        execute_push(cw, 5, _push(pp, MINUS_X, DISTANCE, 0.0))
    assert isinstance(PushOutcome("moved", "", 0.0, 0.0, 0.0, (), 0.0, 0.0).to_json(), dict)


def test_the_jaws_hold_their_opening_against_the_load(cell, box):
    """A 2.4 kg box of box.stl's shape in the open, pushed 40 mm along -x by the outer face of the
    leading finger (the closing axis along the push, the jaws 10 mm apart): the box's friction load
    (mu m g) presses that jaw towards closing, enough to close them by more than 2 mm in the push
    if only their damping held them (speed load / damping); held, they keep 10 mm within 0.5 mm
    (the drive's saturation: the grip force), and the box moves the travel less the 3 mm start gap."""
    gripper = load_gripper("long_stroke_50")
    part = box[0]
    body = part_body("heavy", part.mesh, density=4.0e5, decomposition="hull")
    cw = ClutterWorld(cell, [body], gripper, mu=0.3)
    Tb = np.asarray(cell.bin.T_world_bin)
    T = np.eye(4)
    T[:3, 3] = [Tb[0, 3], Tb[1, 3], Tb[2, 3] + 0.5 * float(part.mesh.extents[2]) + 1e-4]
    cw.world.place(0, T)
    cw.world.settle(lin=0.005, ang=0.05, hold=0.2, max_s=2.0)
    opening, finger = 0.01, float(np.asarray(gripper.finger.extents)[0])
    hull = cw.world.hull_world(0)
    T_start = np.eye(4)
    T_start[:3, :3] = np.diag([1.0, -1.0, -1.0])  # closing axis +x, pointing down: jaw0 (at -x) leads
    tip = float(np.asarray(gripper.finger.T_tcp_box)[2, 3]) + 0.5 * float(np.asarray(gripper.finger.extents)[2])
    T_start[:3, 3] = [hull[:, 0].max() + 0.003 + 0.5 * opening + finger, Tb[1, 3], hull[:, 2].max() - 0.005 + tip]
    T_above = T_start.copy()
    T_above[2, 3] += 0.03
    push = _push(PushPoses(T_above, T_start, T_start, T_above, DISTANCE), MINUS_X, DISTANCE, opening)
    load = 0.3 * body.mass.mass * 9.81
    damping = cw.grip_force / 2.0 / CLOSE_SPEED  # per jaw
    assert load / damping * math.pi * DISTANCE / (2.0 * PUSH_SPEED) > 0.002
    out = execute_push(cw, 0, push, record=True, settle=False)
    assert out.outcome == MOVED, out.reason
    assert out.along_m == pytest.approx(DISTANCE - 0.003, abs=1e-3)
    assert all(abs(s[2] - opening) < 5e-4 for s in out.track), min(s[2] for s in out.track)
