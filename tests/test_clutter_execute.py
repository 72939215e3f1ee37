"""Executing a pick in the clutter world (issue 21), without the planner: grasps from
``compute_grasps`` posed on a part dropped alone into the bin; a round with a tiny planner.

The checks read the world through MuJoCo's own state (body positions, contacts), not through the
executor's verdict, and a miss must fail with a reason."""
from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from grasplan.cell.model import load_cell
from grasplan.clutter.execute import (
    CLEAR_MARGIN, COLLIDED, DROPPED, LIFT_MIN, MISSED, OUTCOMES, PROTOCOL, PUSHED, SLIPPED, SUCCESS, TURN_MAX_DEG,
    TURNED, execute_pick, judge
)
from grasplan.clutter.perception import parse_pose_noise, perturb
from grasplan.clutter.rounds import run_round
from grasplan.clutter.world import ClutterWorld, pad_arc
from grasplan.sim.drop import DropParams, PileItem, drop_pile
from grasplan.errors import InputError
from grasplan.grasps.pipeline import compute_grasps
from grasplan.gripper.load import load_gripper
from grasplan.part.mesh import load_part
from grasplan.piles.scene_file import Scene
from grasplan.geometry.transforms import pose_error

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "parts"
APPROACH, LIFT = 0.08, 0.10


@pytest.fixture(scope="module")
def cell():
    return load_cell("bin")


@pytest.fixture(scope="module")
def gripper():
    return load_gripper("long_stroke_50")


def _pick(T_world_tcp: np.ndarray, width: float, gripper, instance: str = "box_0", part: str = "box"):
    """A pick-like record: straight approach along the TCP z, lift straight up."""
    pre = T_world_tcp.copy()
    pre[:3, 3] -= APPROACH * T_world_tcp[:3, 2]
    lifted = T_world_tcp.copy()
    lifted[2, 3] += LIFT
    return SimpleNamespace(instance=instance, part=part, T_world_pregrasp=pre, T_world_tcp=T_world_tcp,
                           T_world_lifted=lifted, opening=float(gripper.pregrasp_opening(width)), width=float(width))


def _top_down(part, gripper, cell, T_world_part, n=1):
    """The best-scored collision-free grasps (against the part and the bin) whose approach points down."""
    g = compute_grasps(part, gripper=gripper, cell=cell, T_world_part=T_world_part)
    ok = np.flatnonzero(g.status == "ok")
    ok = ok[g.T_world_tcp[ok][:, 2, 2] < -0.7]
    rows = ok[np.argsort(-g.score[ok], kind="stable")][:n]
    assert len(rows), "no downward grasp on the part"
    return [(g.T_world_tcp[r], float(g.width[r])) for r in rows]


@pytest.fixture(scope="module")
def lone_box(cell, gripper):
    part = load_part(EXAMPLES / "box.stl")
    holder = {}

    def make(bodies):
        holder["cw"] = ClutterWorld(cell, bodies, gripper, mu=0.3)
        return holder["cw"].world

    res = drop_pile(cell, [PileItem("box", part, 1)],
                    params=DropParams(seed=1, decomposition="hull", material="plastic"), make_world=make)
    return part, holder["cw"], res.scene.instances[0].T_world_part


def test_gripper_is_where_it_is_driven(lone_box, gripper):
    """The hand's MuJoCo frame is the TCP frame: the jaws' inner faces sit +-opening/2 along its x."""
    import mujoco

    _, cw, _ = lone_box
    T = np.eye(4)
    T[:3, 3] = [0.45, 0.0, 0.4]
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    cw.set_hand(T)
    cw.set_jaws(0.03)
    mujoco.mj_forward(cw.model, cw.data)
    np.testing.assert_allclose(cw.hand_pose(), T, atol=1e-12)
    assert cw.opening() == pytest.approx(0.03)
    for k, sign in ((0, -1.0), (1, 1.0)):
        gid = mujoco.mj_name2id(cw.model, mujoco.mjtObj.mjOBJ_GEOM, f"#jaw{k}")
        centre = cw.data.geom_xpos[gid]
        half_thick = 0.5 * float(np.asarray(gripper.finger.extents)[0])
        x_tcp = (T[:3, :3].T @ (centre - T[:3, 3]))[0]
        assert x_tcp == pytest.approx(sign * (0.015 + half_thick), abs=1e-9)
    cw.park_hand()


def test_lone_part_is_picked(lone_box, gripper, cell):
    part, cw, T_part = lone_box
    snap = cw.world.snapshot()
    (T, w), = _top_down(part, gripper, cell, T_part)
    z0 = cw.data.xipos[cw.world.body_ids[0]][2]
    out = execute_pick(cw, 0, _pick(T, w, gripper), settle=False)
    assert out.outcome == SUCCESS, out.reason
    assert out.lift >= LIFT_MIN and out.held_at_close
    assert not cw.world.present[0]  # a picked part leaves the world
    # MuJoCo's own record: the jaws closed on the box (opening about its width), nothing was pushed
    assert out.opening == pytest.approx(w, abs=2e-3)
    assert out.pushed < 1e-3 and out.fixed_force == 0.0
    assert out.lift == pytest.approx(LIFT, abs=5e-3)
    cw.world.restore(snap)
    cw.park_hand()
    assert cw.data.xipos[cw.world.body_ids[0]][2] == pytest.approx(z0)


def test_a_tilted_lift_is_followed(lone_box, gripper, cell):
    """A pick whose lift is tilted 45 deg (a planner's lift away from a neighbour): the hand follows the
    pick's own straight line to T_world_lifted (MuJoCo's hand frame in every replay sample) and the box
    comes up with it, displaced sideways as planned (towards the bin's middle: clear of its walls)."""
    part, cw, T_part = lone_box
    snap = cw.world.snapshot()
    (T, w), = _top_down(part, gripper, cell, T_part)
    pick = _pick(T, w, gripper)
    side = np.asarray(cell.bin.T_world_bin)[:2, 3] - T[:2, 3]
    u = np.append(np.sqrt(0.5) * side / np.linalg.norm(side), np.sqrt(0.5))
    pick.T_world_lifted = T.copy()
    pick.T_world_lifted[:3, 3] += LIFT * u
    x0 = cw.data.xipos[cw.world.body_ids[0]].copy()
    out = execute_pick(cw, 0, pick, settle=False, record=True)
    assert out.outcome == SUCCESS, out.reason
    hand = np.array([h[:3, 3] for _, h, _, _ in out.track])
    k0 = int(np.flatnonzero(np.linalg.norm(hand - T[:3, 3], axis=1) < 1e-6)[0])  # at the grasp: close, lift, hold
    off = hand[k0:] - T[:3, 3]
    assert len(off) > 20
    along = off @ u
    assert np.max(np.linalg.norm(off - along[:, None] * u, axis=1)) < 2e-4  # on the planned line
    assert np.max(along) == pytest.approx(LIFT, abs=1e-4)
    box = out.track[-1][3][0][:3, 3]  # the box's pose at the end of the hold: moved with the hand
    np.testing.assert_allclose(box[:2] - x0[:2], LIFT * u[:2], atol=3e-3)
    assert out.lift == pytest.approx(LIFT * np.sqrt(0.5), abs=5e-3)
    cw.world.restore(snap)
    cw.park_hand()


def test_miss_fails_with_a_reason(lone_box, gripper, cell):
    """The same grasp 40 mm to the side closes on air; straight into the floor is a collision."""
    part, cw, T_part = lone_box
    snap = cw.world.snapshot()
    (T, w), = _top_down(part, gripper, cell, T_part)
    aside = T.copy()
    aside[:3, 3] += 0.04 * T[:3, 1]
    out = execute_pick(cw, 0, _pick(aside, w, gripper), settle=False)
    assert out.outcome == MISSED and "without holding" in out.reason
    assert cw.world.present[0] and out.lift < 1e-3
    cw.world.restore(snap)
    cw.park_hand()
    low = T.copy()
    low[:3, 3] += 0.03 * T[:3, 2]  # 30 mm deeper: the fingertips go into the bin floor
    out = execute_pick(cw, 0, _pick(low, w, gripper), settle=False)
    assert out.outcome == COLLIDED and "bin_floor" in out.reason and out.fixed_force > 50.0
    cw.world.restore(snap)
    cw.park_hand()


def test_pose_noise_is_exact_and_seeded():
    rng = np.random.default_rng(5)
    T = np.eye(4)
    T[:3, 3] = [0.4, 0.1, 0.05]
    com = np.array([0.01, -0.02, 0.005])
    Tn = perturb(T, com, 0.002, 2.0, rng)
    c0 = T[:3, :3] @ com + T[:3, 3]
    c1 = Tn[:3, :3] @ com + Tn[:3, 3]
    assert np.linalg.norm(c1 - c0) == pytest.approx(0.002)  # moved 2 mm (centre of mass) ...
    assert np.degrees(pose_error(T, Tn)[1]) == pytest.approx(2.0)  # ... and turned 2 deg
    np.testing.assert_array_equal(Tn, perturb(T, com, 0.002, 2.0, np.random.default_rng(5)))
    assert parse_pose_noise("2mm,2deg") == pytest.approx((0.002, 2.0))
    for bad in ("2mm", "2mm,", "x,2deg", "1m,2deg", "2mm,90deg"):
        with pytest.raises(InputError, match="--pose-noise"):
            parse_pose_noise(bad)


def _tiny_round(cell, gripper, seen=None):
    """Two boxes, a planner that takes the highest part's best downward grasp."""
    part = load_part(EXAMPLES / "box.stl")

    def plan(scene: Scene):
        if seen is not None:
            seen.append(scene.ids)
        inst = max(scene.instances, key=lambda i: i.T_world_part[2, 3])
        (T, w), = _top_down(part, gripper, cell, inst.T_world_part)
        return SimpleNamespace(picks=(_pick(T, w, gripper, inst.id),), instances=())

    return run_round(cell, [PileItem("box", part, 2)], gripper, plan,
                     drop=DropParams(seed=3, decomposition="hull", material="plastic"),
                     record=True)


def test_round_with_a_tiny_planner(cell, gripper):
    """The round clears the bin on its first two attempts, and the planner sees one part fewer
    each time; the same round again gives the same bits."""
    seen: list[list[str]] = []
    rr = _tiny_round(cell, gripper, seen)
    assert rr.ended == "empty", [a.reason for a in rr.attempts]
    assert [a.outcome for a in rr.attempts] == [SUCCESS, SUCCESS]
    assert [len(s) for s in seen] == [2, 1] and set(seen[0]) == {"box_0", "box_1"}
    assert seen[1][0] != rr.attempts[0].instance
    assert len(rr.replay) == 2 and rr.replay[0]["track"]
    again = _tiny_round(cell, gripper)
    assert [a.instance for a in again.attempts] == [a.instance for a in rr.attempts]
    for a, b in zip(rr.attempts, again.attempts):
        assert a.execution.lift == b.execution.lift and a.execution.opening == b.execution.opening
    np.testing.assert_array_equal(rr.replay[1]["track"][-1][1], again.replay[1]["track"][-1][1])


@pytest.mark.parametrize("gripper_name", ["robotiq_2f_85", "onrobot_rg2", "onrobot_rg6"])
def test_linkage_pads_ride_their_arc(cell, gripper_name):
    """A linkage gripper (the pads move on an arc, the TCP with the opening): while the jaws close
    under the motors, MuJoCo's pad is where the gripper model puts it at the opening MuJoCo reports
    (grasplan.gripper.linkage: along x and along the approach axis). The 2F-85's pad path is a
    quartic in the opening; the RG2's and RG6's are not (followed nearly to the circle's side) and
    ride a joint of their own, the arc length (grasplan.clutter.world.PadArc)."""
    import mujoco

    g = load_gripper(gripper_name)
    assert pad_arc(g).chained == gripper_name.startswith("onrobot")
    part = load_part(EXAMPLES / "box.stl")
    holder = {}

    def make(bodies):
        holder["cw"] = ClutterWorld(cell, bodies, g, mu=0.3)
        return holder["cw"].world

    drop_pile(cell, [PileItem("box", part, 1)], params=DropParams(seed=1, decomposition="hull", material="plastic"),
              make_world=make)
    cw = holder["cw"]
    T = np.eye(4)
    T[:3, 3] = [0.45, 0.0, 0.4]  # in the air above the bin
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    cw.set_hand(T)
    cw.set_jaws(g.max_opening)
    cw.squeeze(cw.grip_force)
    pad = mujoco.mj_name2id(cw.model, mujoco.mjtObj.mjOBJ_GEOM, "#jaw1")
    # closing at full speed the soft joint equalities lag: 0.1 mm, and the RG2's pad, whose path is
    # 3.2 times steeper than 45 deg near full opening, up to 0.34 mm along the approach axis
    moving = 4e-4 if gripper_name.startswith("onrobot") else 2e-4
    seen = []
    for _ in range(60):  # 0.3 s at 5 ms
        cw.set_hand(T)
        cw.step(0.005)
        o = cw.opening()
        want = T @ g.fingers(o)[1].T_tcp_box
        np.testing.assert_allclose(cw.data.geom_xpos[pad], want[:3, 3], atol=moving)
        seen.append(o)
    assert seen[0] - seen[-1] > 0.01  # the jaws did close (by more than 10 mm)
    z_travel = g.tcp_offset(seen[-1]) - g.tcp_offset(seen[0])
    assert abs(z_travel) > 1e-3  # and the pads moved along the approach axis, as the model says
    for opening in (g.max_opening, 0.5 * g.max_opening):  # at rest the pad lies on the model's path
        cw.set_jaws(opening)
        for _ in range(40):
            cw.set_hand(T)
            cw.step(0.005)
        want = T @ g.fingers(cw.opening())[1].T_tcp_box
        np.testing.assert_allclose(cw.opening(), opening, atol=1e-4)  # motors off: it stays put
        np.testing.assert_allclose(cw.data.geom_xpos[pad], want[:3, 3], atol=5e-5)


@pytest.mark.parametrize("path", sorted((Path(__file__).resolve().parents[1] / "configs" / "grippers").glob("*.yaml")),
                         ids=lambda p: p.stem)
def test_every_shipped_gripper_has_a_clutter_world(cell, path):
    """grasplan clutter --gripper NAME works for every gripper shipped: its world builds (the RG2's
    and RG6's once failed with an internal error, their pad paths no quartic in the opening) and its
    jaws open to the full stroke."""
    import mujoco

    g = load_gripper(str(path))
    cw = ClutterWorld(cell, [], g, mu=0.5)
    cw.set_jaws(g.max_opening)
    mujoco.mj_forward(cw.model, cw.data)
    assert abs(cw.opening() - g.max_opening) < 1e-9
    assert (pad_arc(g) is not None) == bool(g.moving_tcp)


def test_a_pad_path_no_quartic_fits_is_refused_naming_the_gripper():
    """A linkage whose pads' path has a kink (neither a quartic in the opening nor in the arc length):
    InputError naming the gripper and the grippers that work, not an internal error."""
    kinked = SimpleNamespace(name="kinked", moving_tcp=True, max_opening=0.1,
                             tcp_offset=lambda o: np.where(np.asarray(o) > 0.05, 0.02, 0.0) + 0.1 * np.asarray(o))
    with pytest.raises(InputError, match=r"gripper kinked: .*neither a quartic.*onrobot_rg2"):
        pad_arc(kinked)
    assert pad_arc(load_gripper("long_stroke_50")) is None


def test_a_lift_into_a_wall_is_a_collision(lone_box, gripper, cell):
    """A lift tilted 45 deg towards the nearest bin wall drives the gripper's housing into it: the
    kinematic hand is pushed back off its path within a control period (MuJoCo's hand frame), a
    collision (the arm's protective stop), not a slip."""
    part, cw, T_part = lone_box
    snap = cw.world.snapshot()
    (T, w), = _top_down(part, gripper, cell, T_part)
    pick = _pick(T, w, gripper)
    c = np.asarray(cell.bin.T_world_bin)[:2, 3]
    half = 0.5 * np.asarray(cell.bin.inner)
    gaps = np.concatenate([c + half - T[:2, 3], T[:2, 3] - (c - half)])  # to the +x, +y, -x, -y walls
    k = int(np.argmin(gaps))
    u = np.zeros(3)
    u[k % 2] = 1.0 if k < 2 else -1.0
    u = np.sqrt(0.5) * (u + np.array([0.0, 0.0, 1.0]))
    assert gaps[k] < LIFT * np.sqrt(0.5) + 0.5 * 0.06  # the 71 mm sideways take the 60 mm housing to that wall
    pick.T_world_lifted = T.copy()
    pick.T_world_lifted[:3, 3] += LIFT * u
    out = execute_pick(cw, 0, pick, settle=False)
    assert out.outcome == COLLIDED and "lift" in out.reason and "off its path" in out.reason, out.reason
    cw.world.restore(snap)
    cw.park_hand()


@pytest.mark.parametrize("gripper_name", ["long_stroke_50", "robotiq_2f_85"])
def test_twist_slips_at_the_pad_patch_torsion(cell, tmp_path, gripper_name):
    """Issue 22 in the clutter world: a 120 x 30 x 30 mm block in the middle of the bin picked from
    above 40 mm off its centre of mass, so its weight twists it about the closing axis. Analytic
    holding limit (the soft-finger ellipse of each pad patch, as grasplan.sim.simulate: the torque m g d
    shared by the pads' capacities ``c sqrt(N^2 - (m g / (2 mu))^2)``, c = mu (2/3) sqrt(area / pi),
    N = F / 2): the grip force F* = 2 sqrt((m g d / 2c)^2 + (m g / 2 mu)^2). At 0.8 F* the block turns
    in the jaws (about 40 deg), at 1.2 F* it comes up square (MuJoCo's poses); the old per-contact-point
    torsion held it within 4 deg down to 0.6 F*. Parallel jaws and a linkage gripper's pads on their arc."""
    import trimesh

    from grasplan.grasps.patches import contact_patches
    from grasplan.sim.pileworld import part_body
    from grasplan.grasps.wrench import torsion_length

    g = load_gripper(gripper_name)
    path = tmp_path / "block.stl"
    trimesh.creation.box((0.12, 0.03, 0.03)).export(path)
    part = load_part(path, units="m")
    mu, d = 0.3, 0.04
    body = part_body("block", part.mesh, density=2700.0, decomposition="hull")
    T_wp = np.array(cell.bin.T_world_bin, dtype=np.float64)  # lying flat in the middle of the bin floor
    T_wp[:3, 3] += T_wp[:3, 2] * (0.015 + 1e-4)
    T_pt = np.eye(4)  # from above, closing across the block (part y), 40 mm along it
    T_pt[:3, :3] = np.diag([1.0, -1.0, -1.0])[:, [1, 0, 2]]
    T_pt[:3, 1] = np.cross(T_pt[:3, 2], T_pt[:3, 0])
    T_pt[:3, 3] = [d, 0.0, 0.008]  # 8 mm above the middle: a 2F-85's fingertips clear the floor
    C = np.array([T_pt[:3, 3] - 0.015 * T_pt[:3, 0], T_pt[:3, 3] + 0.015 * T_pt[:3, 0]])
    area = contact_patches(part.mesh, g, T_pt[None], C[None])[0][0]
    assert np.all(area > 1e-4)  # a flat pad on a flat face
    torsion = mu * torsion_length(area)
    mg = body.mass.mass * 9.81
    f_star = 2.0 * math.sqrt((mg * d / (2.0 * torsion.mean())) ** 2 + (mg / (2.0 * mu)) ** 2)
    assert 10.0 < f_star < 100.0
    turned = {}
    for factor in (0.8, 1.2):
        cw = ClutterWorld(cell, [body], g, mu=mu, grip_force=factor * f_star)
        cw.world.place(0, T_wp)
        out = execute_pick(cw, 0, _pick(T_wp @ T_pt, 0.03, g), jaw_torsion=torsion, record=True, settle=False)
        assert out.held_at_close, out.reason
        assert np.all(cw.pad_twist() > 0)
        k = [k for k, s in enumerate(out.track) if s[2] < 0.031][0]  # the jaws closed on the block
        R0, R1 = out.track[k][3][0][:3, :3], out.track[-1][3][0][:3, :3]
        turned[factor] = math.degrees(math.acos(np.clip((np.trace(R0.T @ R1) - 1.0) / 2.0, -1.0, 1.0)))
    assert turned[1.2] < 2.0 < 10.0 < turned[0.8], turned


# ------------------------------------------------------------------------------------------------
# the stricter success rule: clearance height, turn in the jaws, the pads' patch from the contact
# ------------------------------------------------------------------------------------------------
def _hand_top(out) -> float:
    """The hand's height at the end of the hold (the last replay sample)."""
    return float(out.track[-1][1][2, 3])


def test_a_short_lift_is_extracted_to_the_clearance_height(lone_box, gripper, cell):
    """A pick whose planned lift (20 mm) leaves the box deep in the bin, with the bin's rim as the
    clearance height: after the lift the hand goes straight up by the height still missing to
    rim + CLEAR_MARGIN, the box held rigidly between the jaws comes up with it, its lowest point ends
    at rim + CLEAR_MARGIN (the hand's rise above the grasp is that height less where the box's lowest
    point started). Without a clearance height the same 20 mm lift is under LIFT_MIN: slipped."""
    part, cw, T_part = lone_box
    snap = cw.world.snapshot()
    (T, w), = _top_down(part, gripper, cell, T_part)
    pick = _pick(T, w, gripper)
    pick.T_world_lifted = T.copy()
    pick.T_world_lifted[2, 3] += 0.02
    rim = float(np.asarray(cell.bin.T_world_bin)[2, 3] + cell.bin.height)
    low0 = float(cw.world.hull_world(0)[:, 2].min())
    assert low0 + 0.02 < rim  # the planned lift alone does not clear the rim
    out = execute_pick(cw, 0, pick, settle=False, record=True, clear_z=rim)
    assert out.outcome == SUCCESS and "extracted" in out.reason, out.reason
    assert out.low_z is not None
    assert out.low_z >= rim and out.low_z == pytest.approx(rim + CLEAR_MARGIN, abs=1e-3)
    assert _hand_top(out) - T[2, 3] == pytest.approx(rim + CLEAR_MARGIN - low0, abs=1e-3)
    assert out.to_json()["low_z_m"] == out.low_z and out.patch == "planned"
    cw.world.restore(snap)
    cw.park_hand()
    out = execute_pick(cw, 0, pick, settle=False, record=True)
    assert out.outcome == SLIPPED and "rose only" in out.reason, out.reason
    assert _hand_top(out) == pytest.approx(T[2, 3] + 0.02, abs=1e-6)  # no extraction without clear_z
    cw.world.restore(snap)
    cw.park_hand()


def test_a_part_not_held_is_not_extracted(lone_box, gripper, cell):
    """The jaws close beside the box (40 mm aside): nothing between them, so no extraction (the hand
    stops at the planned lift) and the box stays below the clearance height: missed, not success."""
    part, cw, T_part = lone_box
    snap = cw.world.snapshot()
    (T, w), = _top_down(part, gripper, cell, T_part)
    aside = T.copy()
    aside[:3, 3] += 0.04 * T[:3, 1]
    pick = _pick(aside, w, gripper)
    rim = float(np.asarray(cell.bin.T_world_bin)[2, 3] + cell.bin.height)
    out = execute_pick(cw, 0, pick, settle=False, record=True, clear_z=rim)
    assert out.outcome == MISSED and out.low_z is not None and out.low_z < rim, out.reason
    assert _hand_top(out) == pytest.approx(pick.T_world_lifted[2, 3], abs=1e-6)
    cw.world.restore(snap)
    cw.park_hand()


def _bar(cell, tmp_path, gripper, mu=0.3):
    """A 120 x 30 x 30 mm aluminium bar lying flat in the middle of the bin floor, alone in its world."""
    import trimesh

    from grasplan.sim.pileworld import part_body

    path = tmp_path / "bar.stl"
    trimesh.creation.box((0.12, 0.03, 0.03)).export(path)
    part = load_part(path, units="m")
    body = part_body("bar", part.mesh, density=2700.0, decomposition="hull")
    cw = ClutterWorld(cell, [body], gripper, mu=mu)
    T_wp = np.array(cell.bin.T_world_bin, dtype=np.float64)
    T_wp[:3, 3] += T_wp[:3, 2] * (0.015 + 1e-4)
    cw.world.place(0, T_wp)
    return part, body, cw, T_wp


def _bar_grasp(d: float, h: float = 0.008) -> np.ndarray:
    """T_part_tcp from above, closing across the bar (part y), ``d`` along it and ``h`` above its middle."""
    T = np.eye(4)
    T[:3, :3] = [[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]  # x = -y_part, y = -x_part, z down
    T[:3, 3] = [d, 0.0, h]
    return T


def test_a_bar_swinging_in_the_jaws_is_turned(cell, tmp_path):
    """A bar picked 40 mm off its centre of mass (8 mm above its middle) with pads whose twist
    capacity is half the gravity moment m g d: the bar turns about the closing axis until the moment,
    m g (d cos a - h sin a), is at most the capacity, i.e. at least to the angle a_min where
    cos a - (h / d) sin a = 1/2 (about 50 deg); from rest it overshoots, never stops short. It is
    still held (the grip's friction carries its weight) and its centre of mass rose far more than
    LIFT_MIN: turned, not success. The same pads from ``patch_torsion`` over a planned torsion that
    would hold it: turned too. Four times the moment as the capacity, or the grasp over the centre
    of mass (no moment): success, turned about 0 deg."""
    g = load_gripper("long_stroke_50")
    d, h, lift = 0.04, 0.008, 0.15
    part, body, cw, T_wp = _bar(cell, tmp_path, g)
    snap = cw.world.snapshot()
    mg = body.mass.mass * 9.81
    N = 0.5 * cw.grip_force  # each pad's normal force; each carries half the weight in friction
    per_pad = math.sqrt(N ** 2 - (mg / (2.0 * cw.mu)) ** 2)

    def torsion(capacity: float) -> np.ndarray:  # both pads' torsion lengths giving this total capacity
        return np.full(2, capacity / (2.0 * per_pad))

    a = np.radians(np.linspace(0.0, 90.0, 9001))
    a_min = math.degrees(a[np.argmax(np.cos(a) - (h / d) * np.sin(a) <= 0.5)])
    assert 40.0 < a_min < 60.0

    def run(grasp_d, **kw):
        pick = _pick(T_wp @ _bar_grasp(grasp_d, h), 0.03, g)
        pick.T_world_lifted[2, 3] += lift - LIFT  # the bar (100 mm from the axis at most) hangs clear
        out = execute_pick(cw, 0, pick, settle=False, **kw)
        cw.world.restore(snap)
        cw.park_hand()
        return out

    low, high = torsion(0.5 * mg * d), torsion(4.0 * mg * d)
    out = run(d, jaw_torsion=low)
    assert out.outcome == TURNED and out.held_at_close, out.reason
    assert out.turned_in_jaws_deg >= a_min - 2.0 and out.lift > LIFT_MIN
    assert out.to_json()["turned_in_jaws_deg"] == out.turned_in_jaws_deg
    out = run(d, jaw_torsion=high, patch_torsion=lambda T, C: low)
    assert out.outcome == TURNED and out.patch == "contact" and out.turned_in_jaws_deg >= a_min - 2.0, out.reason
    out = run(d, jaw_torsion=high)
    assert out.outcome == SUCCESS and out.turned_in_jaws_deg < 2.0, out.reason
    out = run(0.0, jaw_torsion=low)
    assert out.outcome == SUCCESS and out.turned_in_jaws_deg < 2.0, out.reason


def _pad_centroid(gripper, T_part_hand: np.ndarray, opening: float, jaw: int) -> np.ndarray:
    """Where a flat pad pressing evenly on the bar's side face pushes (part frame): the centre of
    the overlap of the finger's inner face (the finger box at ``opening``) with the face."""
    finger = gripper.fingers(opening)[jaw]
    Tb, e = np.asarray(finger.T_tcp_box), 0.5 * np.asarray(finger.extents)
    # the inner face is the box's -x side for both jaws (the -x jaw's box is the +x jaw's turned about z)
    corners = np.array([[-e[0], sy * e[1], sz * e[2], 1.0] for sy in (-1, 1) for sz in (-1, 1)])
    P = (T_part_hand @ Tb @ corners.T).T[:, :3]
    lo = np.maximum(P.min(axis=0), [-0.06, -0.015, -0.015])
    hi = np.minimum(P.max(axis=0), [0.06, 0.015, 0.015])
    assert np.all(hi[[0, 2]] > lo[[0, 2]])  # the pad overlaps the face
    return 0.5 * (lo + hi)


@pytest.mark.parametrize("gripper_name", ["long_stroke_50", "robotiq_2f_85"])
def test_patch_torsion_sees_the_grasp_actually_made(cell, tmp_path, gripper_name):
    """patch_torsion is called once, after the close, with the grasp the jaws made in the bar's
    frame: T_part_tcp (the hand frame moved back by inv(T_tcp_gripper(width)): a linkage's TCP
    12.9 mm off the hand at 30 mm) within 1 mm / 1 deg of the planned one, and each jaw's contact
    point on its side of the bar (jaw0 at -x of the TCP, jaw1 at +x: part y = +-15 mm) at the centre
    of its pad's overlap with the face. Its lengths then rule the pads' hinges (after the pick, at
    rest: the nominal capacity, lengths x half the grip force)."""
    g = load_gripper(gripper_name)
    part, body, cw, T_wp = _bar(cell, tmp_path, g)
    T_pt = _bar_grasp(0.0, 0.008)
    seen = []
    values = np.array([1.1e-3, 0.9e-3])

    def patch(T, C):
        seen.append((np.array(T), np.array(C)))
        return values

    out = execute_pick(cw, 0, _pick(T_wp @ T_pt, 0.03, g), jaw_torsion=np.full(2, 2e-3), patch_torsion=patch,
                       settle=False)
    assert out.outcome == SUCCESS and out.patch == "contact" and out.to_json()["patch"] == "contact", out.reason
    assert len(seen) == 1
    T, C = seen[0]
    pos_err, ang_err = pose_error(T_pt, T)
    assert pos_err < 1e-3 and math.degrees(ang_err) < 1.0, (pos_err, math.degrees(ang_err))
    assert C.shape == (2, 3)
    np.testing.assert_allclose(C[:, 1], [0.015, -0.015], atol=5e-4)  # jaw0 at TCP -x = part +y
    T_part_hand = T_pt @ np.asarray(g.T_tcp_gripper(0.03))
    for jaw in (0, 1):
        np.testing.assert_allclose(C[jaw], _pad_centroid(g, T_part_hand, 0.03, jaw), atol=2e-3)
    np.testing.assert_allclose(cw.pad_twist(), values * 0.5 * cw.grip_force, rtol=1e-12)


def test_patch_torsion_refused_keeps_the_planned_torsion(lone_box, gripper, cell):
    """patch_torsion raising ValueError, or giving a non-finite length: the torsion given stays (the
    pads' capacity after the pick: jaw_torsion x half the grip force), Outcome.patch "planned"; a
    pick whose jaws close beside the part never calls it."""
    part, cw, T_part = lone_box
    snap = cw.world.snapshot()
    (T, w), = _top_down(part, gripper, cell, T_part)
    planned = np.array([1.5e-3, 1.2e-3])

    def refuse(T, C):
        raise ValueError("no patch here")

    for patch in (refuse, lambda T, C: np.array([np.nan, 1e-3])):
        out = execute_pick(cw, 0, _pick(T, w, gripper), jaw_torsion=planned, patch_torsion=patch, settle=False)
        assert out.outcome == SUCCESS and out.patch == "planned", out.reason
        np.testing.assert_allclose(cw.pad_twist(), planned * 0.5 * cw.grip_force, rtol=1e-12)
        cw.world.restore(snap)
        cw.park_hand()
    calls = []

    def record(T, C):
        calls.append(1)
        return planned

    aside = T.copy()
    aside[:3, 3] += 0.04 * T[:3, 1]
    out = execute_pick(cw, 0, _pick(aside, w, gripper), patch_torsion=record, settle=False)
    assert out.outcome == MISSED and calls == [] and out.patch == "planned"
    cw.world.restore(snap)
    cw.park_hand()


@pytest.mark.parametrize("measured, expected", [
    # held at the end and high: success unless turned more than TURN_MAX_DEG in the jaws
    (dict(held_at_close=True, held_after_lift=True, held_at_end=True, high=True, turned_in_jaws_deg=3.0), SUCCESS),
    (dict(held_at_close=True, held_after_lift=True, held_at_end=True, high=True, turned_in_jaws_deg=15.0), SUCCESS),
    (dict(held_at_close=True, held_after_lift=True, held_at_end=True, high=True, turned_in_jaws_deg=15.5), TURNED),
    # held at the top, lost in the hold
    (dict(held_at_close=True, held_after_lift=True, held_at_end=False, high=False, turned_in_jaws_deg=0.0), DROPPED),
    (dict(held_at_close=True, held_after_lift=True, held_at_end=False, high=True, turned_in_jaws_deg=40.0), DROPPED),
    # held when closed: lost in the lift, or held but never high enough
    (dict(held_at_close=True, held_after_lift=False, held_at_end=False, high=False, turned_in_jaws_deg=0.0), SLIPPED),
    (dict(held_at_close=True, held_after_lift=True, held_at_end=True, high=False, turned_in_jaws_deg=0.0), SLIPPED),
    # never held: pushed (moved or turned before the close) or missed
    (dict(held_at_close=False, held_after_lift=False, held_at_end=False, high=False, turned_in_jaws_deg=0.0,
          pushed=0.006), PUSHED),
    (dict(held_at_close=False, held_after_lift=False, held_at_end=False, high=False, turned_in_jaws_deg=0.0,
          turned_deg=11.0), PUSHED),
    (dict(held_at_close=False, held_after_lift=False, held_at_end=False, high=False, turned_in_jaws_deg=0.0), MISSED),
])
def test_judge_decides_in_order(measured, expected):
    kw = dict(pushed=0.0, turned_deg=0.0) | measured
    assert judge(**kw) == expected
    assert expected in OUTCOMES


def test_protocol_records_the_new_limits():
    assert PROTOCOL["turn_max_deg"] == TURN_MAX_DEG == 15.0 and PROTOCOL["clear_margin"] == CLEAR_MARGIN == 0.01
    assert OUTCOMES.index(TURNED) < OUTCOMES.index(DROPPED) < OUTCOMES.index(SLIPPED)
