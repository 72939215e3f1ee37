"""The compiled oriented-box broad phase (grasplan/motion/pathboxes.py) in front of coal: a configuration
it leaves no pair at must be free for coal (on random configurations of a pile scene for two robots, with
the part static and held in the jaws, every pair and a lift's reduced pair set), it must clear a
good share of the free ones (else it is useless and a broken kernel returning nothing would pass),
its box test must agree with coal's distance between two boxes, and ``path_free`` with it must
decide random paths as checking every interpolated configuration with coal does."""
from __future__ import annotations

from pathlib import Path

import coal
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from grasplan.cell.model import load_cell
from grasplan.cell.shapes import bvh
from grasplan.gripper.load import load_gripper
from grasplan.geometry.interpolation import interpolate_path
from grasplan.part.mesh import load_part
from grasplan.motion.pathboxes import SLACK, obb_apart, scene_open
from grasplan.motion.lift_check import lift_precheck_drop
from grasplan.robot.description import load_robot
from grasplan.motion.collision_scene import CollisionScene, ExtraBody

BRACKET = Path(__file__).resolve().parents[1] / "examples" / "parts" / "bracket.stl"


def _pile_scene(robot_name: str) -> CollisionScene:
    part = load_part(BRACKET)
    geom = bvh(part.mesh.vertices, part.mesh.faces)
    extras = [ExtraBody(f"instance:{k}", geom, "instance") for k in range(3)]
    scene = CollisionScene(load_robot(robot_name), load_gripper("schunk_egp_c_40"), part.mesh, np.eye(4),
                           load_cell("bin"), extras=extras)
    T = np.eye(4)
    T[:3, 3] = [0.45, 0.0, 0.03]
    poses = {}
    for k in range(3):
        Tk = np.eye(4)
        Tk[:3, :3] = Rotation.from_euler("z", 40 * k, degrees=True).as_matrix()
        Tk[:3, 3] = [0.42 + 0.04 * k, 0.05 * (k - 1), 0.03]
        poses[f"instance:{k}"] = Tk
    return scene.arranged(T, poses)


def _configs(robot, rng, n):
    """Uniform in the joint limits (many collide: table, self) and near the bin (the arm bent down
    over it: near misses)."""
    lo, hi = np.maximum(robot.lower, -2 * np.pi), np.minimum(robot.upper, 2 * np.pi)
    uni = rng.uniform(lo, hi, (n, robot.nq))
    home = np.asarray(robot.q_home, dtype=np.float64)
    near = home + rng.normal(0.0, 0.6, (n, robot.nq))
    return np.clip(np.vstack([uni, near]), robot.lower, robot.upper)


@pytest.mark.parametrize("robot_name", ["ur5", "panda"])
def test_cleared_configurations_are_free_for_coal(robot_name):
    scene = _pile_scene(robot_name)
    rng = np.random.default_rng(7)
    qs = _configs(scene.robot, rng, 400)
    variants = [(scene, 0.03, None)]
    att = scene.attached(np.eye(4))  # the part at the TCP
    variants.append((att, 0.02, None))
    variants.append((att, 0.02, np.flatnonzero(att._active & lift_precheck_drop(att))))  # the lift's reduced set
    for sc, opening, off in variants:
        if off is not None:
            sc.switch_pairs(off, False)
        try:
            sc.set_opening(opening)
            starts, _ = scene_open(sc, qs)
            clear = starts[1:] == starts[:-1]  # no pair left to coal
            free = np.array([sc.is_free_exhaustive(q, opening) for q in qs])
        finally:
            if off is not None:
                sc.switch_pairs(off, True)
        assert not np.any(clear & ~free), np.flatnonzero(clear & ~free)[:5]  # never clears a collision
        assert free.sum() > 40 and (~free).sum() > 40  # both kinds met
        assert clear[free].mean() > 0.3, clear[free].mean()  # and clears a good share of the free ones


def test_box_test_agrees_with_coal():
    rng = np.random.default_rng(0)
    K = 4000
    Ra = Rotation.random(K, random_state=1).as_matrix()
    Rb = Rotation.random(K, random_state=2).as_matrix()
    Rb[:500] = Ra[:500]  # parallel edges
    Rb[500:1000] = Ra[500:1000] @ Rotation.from_euler("z", rng.uniform(0, 3, (500, 1))).as_matrix()
    ha, hb = rng.uniform(0.01, 0.3, (K, 3)), rng.uniform(0.01, 0.3, (K, 3))
    ca, cb = rng.uniform(-0.5, 0.5, (K, 3)), rng.uniform(-0.5, 0.5, (K, 3))
    req = coal.DistanceRequest()
    n_apart = 0
    for k in range(K):
        res = coal.DistanceResult()
        d = coal.distance(coal.Box(*(2 * ha[k])), coal.Transform3s(Ra[k], ca[k]), coal.Box(*(2 * hb[k])),
                          coal.Transform3s(Rb[k], cb[k]), req, res)
        apart = obb_apart(Ra[k], ca[k], ha[k], Rb[k], cb[k], hb[k], SLACK)
        if d <= SLACK:
            assert not apart, (k, d)
        elif d > 1e-6:  # the separating-axis test is exact for two boxes
            assert apart, (k, d)
        n_apart += apart
    assert 300 < n_apart < K - 300


def test_path_free_decides_as_coal_at_every_step():
    scene = _pile_scene("ur5")
    robot = scene.robot
    rng = np.random.default_rng(3)
    home = np.asarray(robot.q_home, dtype=np.float64)
    n_free = n_hit = 0
    for _ in range(30):
        qs = np.clip(home + rng.normal(0.0, 0.5, (3, robot.nq)), robot.lower, robot.upper)
        qs[0] = home
        want = all(scene.is_free_exhaustive(q, 0.03) for q in interpolate_path(qs))
        assert scene.path_free(qs, 0.03) == want
        n_free += want
        n_hit += not want
    assert n_free > 3 and n_hit > 3


@pytest.mark.parametrize("robot_name", ["ur5", "panda"])
def test_open_pairs_hold_every_colliding_pair(robot_name):
    """``scene_open`` lists, per configuration, the pairs whose boxes overlap: every pair coal finds
    colliding (all pairs, no broad phase) is among them, so ``is_free`` (coal on those pairs alone)
    decides as checking every pair does, with the part static, held, and the lift's reduced set."""
    scene = _pile_scene(robot_name)
    rng = np.random.default_rng(11)
    qs = _configs(scene.robot, rng, 150)
    att = scene.attached(np.eye(4))
    n_hit = n_open = 0
    for sc, opening, off in [(scene, 0.03, None), (att, 0.02, None),
                             (att, 0.02, np.flatnonzero(att._active & lift_precheck_drop(att)))]:
        if off is not None:
            sc.switch_pairs(off, False)
        try:
            sc.set_opening(opening)
            starts, pair_ids = scene_open(sc, qs)
            for k, q in enumerate(qs):
                hit = set(sc._hits(q, opening, False))  # every colliding active pair
                listed = set(pair_ids[starts[k]:starts[k + 1]].tolist())
                assert hit <= listed, (k, hit - listed)
                assert sc.is_free(q, opening) == (not hit) == sc.is_free_exhaustive(q, opening)
                n_hit += bool(hit)
                n_open += len(listed)
        finally:
            if off is not None:
                sc.switch_pairs(off, True)
    assert n_hit > 30 and n_open < 0.5 * len(qs) * 3 * len(scene.pair_rows())  # both kinds met; a real filter


def test_ranges_list_what_each_configuration_needs():
    """Along continuous paths (the pile close by, many configurations colliding), the kernel's
    ranges (pairs whose boxes, grown by the range's joint motion, lie apart skipped for the whole
    range) list per configuration a subset of the pairs a call with that configuration alone
    lists, never dropping a pair coal finds colliding, with the part static and held."""
    from grasplan.motion import pathboxes

    scene = _pile_scene("ur5")
    robot = scene.robot
    rng = np.random.default_rng(5)
    home = np.asarray(robot.q_home, dtype=np.float64)
    att = scene.attached(np.eye(4))
    n_open = n_cfg = n_hit = 0
    for sc, opening in ((scene, 0.03), (att, 0.02)):
        sc.set_opening(opening)
        for _ in range(6):
            qs = interpolate_path(np.clip(home + rng.normal(0.0, 0.6, (3, robot.nq)), robot.lower, robot.upper))
            assert len(qs) > 50
            starts, ids = scene_open(sc, qs)
            (head, tol, tail), rows, _ = pathboxes._prepared(sc)
            active = np.flatnonzero(sc._active)
            s2, f2, _ = pathboxes._open_pairs(qs, *head, rows[active], tol, *tail)
            np.testing.assert_array_equal(s2, starts)
            np.testing.assert_array_equal(active[f2], ids)
            for k in range(len(qs)):
                s1, i1 = scene_open(sc, qs[k:k + 1])
                listed = set(ids[starts[k]:starts[k + 1]].tolist())
                assert listed <= set(i1.tolist()), k
                hit = set(sc._hits(qs[k], opening, False))
                assert hit <= listed, (k, hit - listed)
                n_hit += bool(hit)
            n_open += int(np.sum(starts[1:] > starts[:-1]))
            n_cfg += len(qs)
    assert 0 < n_open < n_cfg  # configurations with pairs open and without both met
    assert n_hit > 0


def test_one_pass_for_a_lift_keeps_every_pair_coal_finds_with_some_pairs_off():
    """The lift check's one box pass (``lift_check._open_rows``): the configurations of one group,
    the pairs that group switches off dropped, list every pair coal finds colliding with those
    pairs off, and none of them."""
    from grasplan.motion.lift_check import _open_rows

    scene = _pile_scene("ur5")
    robot = scene.robot
    att = scene.attached(np.eye(4))
    att.set_opening(0.02)
    rng = np.random.default_rng(9)
    home = np.asarray(robot.q_home, dtype=np.float64)
    n_hit = n_dropped = 0
    for _ in range(4):
        qs = interpolate_path(np.clip(home + rng.normal(0.0, 0.6, (3, robot.nq)), robot.lower, robot.upper))
        open_all = scene_open(att, qs)
        rows = np.sort(rng.choice(len(qs), size=len(qs) // 3, replace=False))
        listed_all = np.unique(open_all[1])
        off = rng.choice(listed_all, size=max(1, len(listed_all) // 2), replace=False) if len(listed_all) else None
        starts, ids = _open_rows(open_all, rows, off)
        assert len(starts) == len(rows) + 1 and starts[-1] == len(ids)
        if off is not None:
            assert not np.isin(ids, off).any()
            att.switch_pairs(off, False)
        try:
            for j, k in enumerate(rows.tolist()):
                hit = set(att._hits(qs[k], 0.02, False))
                listed = set(ids[starts[j]:starts[j + 1]].tolist())
                assert hit <= listed, (k, hit - listed)
                n_hit += bool(hit)
                n_dropped += len(set(open_all[1][open_all[0][k]:open_all[0][k + 1]].tolist()) - listed)
        finally:
            if off is not None:
                att.switch_pairs(off, True)
    assert n_hit > 0 and n_dropped > 0


@pytest.fixture(scope="module")
def gear_plan():
    """The example gear planned with the UR5 on the table, and its collision scene."""
    from grasplan.motion.planning import plan

    part = load_part(BRACKET.with_name("gear.stl"))  # the jaws reach between its teeth: inside its box
    res = plan(part, "ur5", gripper="long_stroke_50")
    assert res.robot is not None
    return res, CollisionScene(res.robot, res.gripper, part.mesh, res.T_world_part, res.cell)


def test_ranges_place_the_boxes_at_few_configurations_of_planned_transits(gear_plan):
    """On the gear's planned transits (home to pre-grasp, densified at 0.01 rad), the ranges put
    most pairs apart for whole stretches: the chain's boxes are placed at under a third as many
    configurations (ranges counted) as the transit has, and the listing is the single
    configurations' (none open: the transits are free)."""
    from grasplan.motion import pathboxes

    res, scene = gear_plan
    n_cfg = n_placed = 0
    for gid, m in res.motions.items():
        a, b = m.segment("transit")
        qs = interpolate_path(np.asarray(m.path[a:b + 1], dtype=np.float64))
        width = float(res.grasps.width[np.flatnonzero(res.grasps.ids == gid)[0]])
        scene.set_opening(float(res.gripper.pregrasp_opening(width)))
        scene._apply()
        (head, tol, tail), rows, _ = pathboxes._prepared(scene)
        active = np.flatnonzero(scene._active)
        starts, flat, placed = pathboxes._open_pairs(qs, *head, rows[active], tol, *tail)
        single = [len(scene_open(scene, qs[k:k + 1])[1]) for k in range(0, len(qs), 7)]
        assert not flat.size and not any(single)
        n_cfg += len(qs)
        n_placed += placed
    assert n_cfg > 500 and n_placed < n_cfg / 3, (n_placed, n_cfg)


def test_part_triangles_clear_jaws_beside_the_part(gear_plan):
    """Near the part (the example gear's planned grasps and their approaches, each configuration jittered
    by up to a few millimetres at the jaws), the pairs with the part whose boxes overlap are tested
    against the part's triangles (``PartBoxes``): every pair coal finds colliding is still listed,
    the listing is a subset of the boxes-alone listing, and the triangles clear a share of the
    jaw-part pairs the boxes alone leave to coal."""
    from grasplan.motion import pathboxes

    res, scene = gear_plan
    rng = np.random.default_rng(3)
    runs = []
    for gid, m in res.motions.items():
        a, b = m.segment("approach") or (0, 0)
        app = interpolate_path(np.asarray(m.path[a:b + 1], dtype=np.float64))
        width = float(res.grasps.width[np.flatnonzero(res.grasps.ids == gid)[0]])
        runs.append((app + rng.normal(0.0, 0.004, app.shape), float(res.gripper.pregrasp_opening(width))))
    assert runs
    part_pairs = {k for k, (a, b, kind, _, _) in enumerate(scene.pair_rows()) if "part" in (a, b)}
    n_hit = n_cleared = 0
    for qs, opening in runs:
        scene.set_opening(opening)
        starts, ids = scene_open(scene, qs)
        saved = pathboxes._BOXES.pop(scene._shared)
        try:  # the same scene with the boxes alone
            pathboxes._BOXES[scene._shared] = pathboxes.PathBoxes(scene._shared.model, scene._shared.gm,
                                                                  scene._shared.pairs)
            scene.__dict__.pop("_boxes_sel", None)
            starts0, ids0 = scene_open(scene, qs)
        finally:
            pathboxes._BOXES[scene._shared] = saved
            scene.__dict__.pop("_boxes_sel", None)
        for k, q in enumerate(qs):
            listed = set(ids[starts[k]:starts[k + 1]].tolist())
            alone = set(ids0[starts0[k]:starts0[k + 1]].tolist())
            hit = set(scene._hits(q, opening, False))
            assert hit <= listed <= alone, (k, hit - listed, listed - alone)
            n_hit += bool(hit & part_pairs)
            n_cleared += len((alone - listed) & part_pairs)
    assert n_hit > 0 and n_cleared > 20, (n_hit, n_cleared)  # near contact both ways; the triangles clear some


@pytest.mark.parametrize("robot_name", ["ur5", "panda"])
def test_growth_bounds_how_far_every_box_corner_moves(robot_name):
    """The range bound (``_growth``) against Pinocchio: for random middle configurations and joint
    ranges, every corner of every box moves at most its bound in the world, and relative to each
    of its chain's joints at most the bound of the joints below that joint."""
    import pinocchio as pin

    from grasplan.motion import pathboxes

    scene = _pile_scene(robot_name)
    att = scene.attached(np.eye(4))
    rng = np.random.default_rng(17)
    n_checked = 0
    for sc in (scene, att):
        sc.set_opening(0.03)
        (head, _, _), _, _ = pathboxes._prepared(sc)
        parent, R0, t0, kind, axis, iq, gjoint, R_loc, c_loc, half, reach = head
        boxes = pathboxes._BOXES[sc._shared]
        used = boxes.selected[0].tolist()
        m, gm = sc.model, sc.geom_model
        d, gd = m.createData(), pin.GeometryData(gm)
        signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
        J, G = len(parent), len(gjoint)
        for _ in range(60):
            q_mid = rng.uniform(np.maximum(sc.robot.lower, -3), np.minimum(sc.robot.upper, 3))
            delta = rng.uniform(0.0, 0.4, m.nq) * (rng.random(m.nq) < 0.8)
            q = q_mid + rng.choice([-1.0, 1.0], m.nq) * delta  # a corner of the range: the farthest
            oR, ot = np.zeros((J, 3, 3)), np.zeros((J, 3))
            R, c, hw = np.zeros((1, G, 3, 3)), np.zeros((1, G, 3)), np.zeros((1, G, 3))
            pathboxes._chain(q_mid[None], 0, parent, R0, t0, kind, axis, iq, oR, ot)
            cum, loose = np.zeros((G, J)), np.zeros(J)
            for g in range(G):
                if gjoint[g]:
                    pathboxes._place(g, gjoint[g], 0, oR, ot, R_loc, c_loc, half, R, c, hw)
                    pathboxes._growth(g, gjoint[g], parent, axis, iq, reach, delta, oR, ot, c[0, g], half[g], loose,
                                      cum)
            corners = []
            for qq in (q_mid, q):
                pin.forwardKinematics(m, d, qq)
                pin.updateGeometryPlacements(m, d, gm, gd, qq)
                corners.append(([[gd.oMg[k].act(boxes.center[k] + s * boxes.half[k]) for s in signs] for k in used],
                                [d.oMi[j].copy() for j in range(J)]))
            (mid_pts, mid_oMi), (q_pts, q_oMi) = corners
            for g, (pa, pb) in enumerate(zip(mid_pts, q_pts)):
                if not gjoint[g]:
                    continue
                j = int(gjoint[g])
                while True:  # j = the joint's frame the motion is measured in (0: the world)
                    bound = cum[g, gjoint[g]] - cum[g, j]
                    moved = max(np.linalg.norm(q_oMi[j].actInv(b) - mid_oMi[j].actInv(a)) for a, b in zip(pa, pb))
                    assert moved <= bound + 1e-9, (g, j, moved, bound)
                    n_checked += 1
                    if j == 0:
                        break
                    j = int(parent[j])
    assert n_checked > 1000


def test_a_nan_configuration_is_never_cleared_by_a_range(gear_plan):
    """A configuration with a NaN joint inside a path the ranges would clear: it is listed as it is
    alone (every pair its NaN boxes cannot put apart goes to coal), not cleared with its range."""
    res, scene = gear_plan
    m = next(iter(res.motions.values()))
    a, b = m.segment("transit")
    qs = interpolate_path(np.asarray(m.path[a:b + 1], dtype=np.float64))
    scene.set_opening(0.03)
    k = len(qs) // 3
    qs[k, 2] = np.nan
    starts, ids = scene_open(scene, qs)
    s1, i1 = scene_open(scene, qs[k:k + 1])
    assert len(i1) > 0
    assert sorted(ids[starts[k]:starts[k + 1]].tolist()) == sorted(i1.tolist())
