"""Pick-and-place (issue 12 item 5): lift with the part in the jaws, transfer, descend, release,
retreat; every planned path re-checked by an INDEPENDENT python-fcl checker.

The checker below shares no code with grasplan.motion.collision_scene / grasplan.motion.joint_paths / grasplan.motion.pickplace:
Pinocchio FK on a fresh Data, python-fcl (not coal) objects built from the URDF's collision
meshes loaded with trimesh, the gripper shapes rebuilt as fcl boxes/meshes, the part as an fcl
BVH placed statically before the close event, riding on FK(TCP) @ T_tcp_part between the close and
open events (its lowest vertex against the table plane computed exactly) and statically at the
place after the open event, and our own 0.01 rad interpolation. The shared re-check
tests/fcl_recheck.py (URDF read independently, self-collision, obstacles) checks the same paths a
second time (:func:`shared_recheck`).
"""
from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

STEP = 0.01
PLACE_DY = 0.3  # m: the place is the resting pose moved this far along world y
#: scoring without the quality terms keeps these tests independent of grasplan.grasps.quality's speed
FAST_WEIGHTS = (("center", 0.1), ("top", 0.15), ("width", 0.05))


from fcl_recheck import bvh as _bvh  # noqa: E402  (independent python-fcl helpers)
from fcl_recheck import dense  # noqa: E402
from fcl_recheck import fcl_tf as _fcl_tf  # noqa: E402
from fcl_recheck import RobotLinks  # noqa: E402


def _shape_objects(shape):
    """(fcl geometry, T_tcp_geom) of a gripper shape (box: extents + T_tcp_box; mesh: vertices/faces)."""
    import fcl

    if hasattr(shape, "extents"):
        return fcl.Box(*np.asarray(shape.extents, dtype=np.float64)), np.asarray(shape.T_tcp_box, dtype=np.float64)
    return _bvh(shape.vertices, shape.faces), np.eye(4)


class PickPlaceChecker:
    """Robot links + gripper vs table and the part, the part static / attached / placed."""

    def __init__(self, robot, gripper, part_mesh, table_z=0.0, mounted=("base_link", "shoulder_link")):
        import fcl

        self.fcl = fcl
        self.gripper = gripper
        self.robot_links = RobotLinks(robot, gripper.T_flange_tcp, mounted)
        self.part_V = np.asarray(part_mesh.vertices, dtype=np.float64)
        self.part = fcl.CollisionObject(_bvh(part_mesh.vertices, part_mesh.faces), fcl.Transform())
        self.table_z = float(table_z)
        T = np.eye(4)
        T[2, 3] = table_z - 0.5
        self.table = fcl.CollisionObject(fcl.Box(20.0, 20.0, 1.0), _fcl_tf(T))
        self.body = [_shape_objects(s) for s in gripper.body]

    def _hit(self, a, b):
        return self.fcl.collide(a, b, self.fcl.CollisionRequest(), self.fcl.CollisionResult()) > 0

    def fk_tcp(self, q):
        return self.robot_links.fk_tcp(q)

    def part_lowest_z(self, T_world_part):
        return float((self.part_V @ T_world_part[2, :3] + T_world_part[2, 3]).min())

    def collisions(self, q, opening, T_world_part, attached: bool):
        """Colliding (body, body) pairs at ``q``; the part at ``T_world_part``; ``attached``: the part is
        in the jaws (only the jaws may touch it; it is checked against the table exactly)."""
        fcl = self.fcl
        self.part.setTransform(_fcl_tf(T_world_part))
        hits = self.robot_links.hits(q, self.part, self.table, self._hit)
        T_tcp = self.fk_tcp(q)
        shapes = [("body", g, T) for g, T in self.body]
        if not attached:
            shapes += [(f"finger{k}", *_shape_objects(s)) for k, s in enumerate(self.gripper.fingers(opening))]
        else:  # the jaws may touch the part, not the table
            shapes_f = [(f"finger{k}", *_shape_objects(s)) for k, s in enumerate(self.gripper.fingers(opening))]
            for name, g, T in shapes_f:
                if self._hit(fcl.CollisionObject(g, _fcl_tf(T_tcp @ T)), self.table):
                    hits.append((f"gripper:{name}", "table"))
        for name, g, T in shapes:
            obj = fcl.CollisionObject(g, _fcl_tf(T_tcp @ T))
            if self._hit(obj, self.part):
                hits.append((f"gripper:{name}", "part"))
            if self._hit(obj, self.table):
                hits.append((f"gripper:{name}", "table"))
        if attached and self.part_lowest_z(T_world_part) < self.table_z - 1e-4:
            hits.append(("part", "table"))
        return hits


def check_pick_place(chk: PickPlaceChecker, result, gid: int, *, placed: bool, max_dev: float):
    """Segments, events, the straight lift and an fcl re-check of the whole path at 0.01 rad (grasp
    ``gid``)."""
    m, i = result.motions[gid], result.grasps.index_of(gid)
    cell = result.cell
    segs = m.segment_list()
    labels = [s[0] for s in segs]
    assert labels == (["transit", "approach", "lift", "transfer", "descend", "retreat"] if placed
                      else ["transit", "approach", "lift"])
    assert segs[0][1] == 0 and segs[-1][2] == len(m.path) - 1
    assert all(a[2] == b[1] and a[1] < a[2] for a, b in itertools.pairwise(segs))
    seg = {lab: (a, b) for lab, a, b in segs}
    # events at the segment boundaries, with the documented widths
    close, opened = m.event("close"), m.event("open")
    assert close.index == seg["approach"][1] == seg["lift"][0]
    assert close.width == pytest.approx(float(result.grasps.width[i]))
    opening = float(result.gripper.pregrasp_opening(result.grasps.width[i]))
    if placed:
        assert opened.index == seg["descend"][1] == seg["retreat"][0]
        assert opened.width == pytest.approx(opening)
        assert [e.action for e in m.gripper] == ["close", "open"]
    else:
        assert opened is None and [e.action for e in m.gripper] == ["close"]
    np.testing.assert_allclose(m.path[close.index], m.q_grasp, atol=1e-12)
    np.testing.assert_allclose(m.path[m.pregrasp_index], m.q_pregrasp, atol=1e-12)
    # the grasp and the attached part
    T_world_tcp = result.T_world_part @ result.grasps.T_part_tcp[i]
    np.testing.assert_allclose(chk.fk_tcp(m.q_grasp), T_world_tcp, atol=1e-4)
    np.testing.assert_allclose(T_world_tcp @ m.T_tcp_part, result.T_world_part, atol=1e-9)
    # the lift: straight along the retreat direction, retreat_distance long, orientation kept
    u = np.asarray(cell.retreat_direction, dtype=np.float64)
    u /= np.linalg.norm(u)
    a0, a1 = seg["lift"]
    lift = m.path[a0:a1 + 1]
    probes = np.concatenate([dense(lift), 0.5 * (lift[:-1] + lift[1:])])
    p0 = T_world_tcp[:3, 3]
    for q in probes:
        T = chk.fk_tcp(q)
        d = T[:3, 3] - p0
        t = float(np.clip(d @ u, 0.0, cell.retreat_distance))
        assert np.linalg.norm(d - t * u) <= max_dev + 1e-9, "lift leaves the straight line"
        assert np.allclose(T[:3, :3], T_world_tcp[:3, :3], atol=1e-3)
    T_end = chk.fk_tcp(lift[-1])
    np.testing.assert_allclose(T_end[:3, 3], p0 + cell.retreat_distance * u, atol=1e-5)
    if placed:
        T_place = np.asarray(m.T_world_part_place)
        np.testing.assert_allclose(chk.fk_tcp(m.path[opened.index]) @ m.T_tcp_part, T_place, atol=1e-4)
        # descend straight down onto the place (the reverse of a lift there)
        d0, d1 = seg["descend"]
        T_pl = chk.fk_tcp(m.path[d1])
        np.testing.assert_allclose(chk.fk_tcp(m.path[d0])[:3, 3], T_pl[:3, 3] + cell.retreat_distance * u, atol=1e-5)
    # collisions along the whole path at 0.01 rad: static part / attached (only the jaws touch it) / placed
    c_idx, o_idx = m.attached_range()
    k_rows = np.arange(len(m.path))
    for r0, r1 in itertools.pairwise(k_rows):
        attached = c_idx <= r0 and r1 <= o_idx
        for q in dense(m.path[r0:r1 + 1])[(0 if r0 == 0 else 1):]:
            if attached:
                T_part, op = chk.fk_tcp(q) @ m.T_tcp_part, float(result.grasps.width[i])
            elif r1 <= c_idx:
                T_part, op = result.T_world_part, opening
            else:
                T_part, op = np.asarray(m.T_world_part_place), opening
            hits = chk.collisions(q, op, T_part, attached)
            assert not hits, f"grasp {i}: {hits} between rows {r0} and {r1} (attached={attached})"


def shared_recheck(result):
    """The shared python-fcl re-check (tests/fcl_recheck.py: URDF geometry read independently,
    self-collision, obstacles) of every planned path: nothing collides at 0.01 rad."""
    import fcl_recheck

    reports = fcl_recheck.recheck_result(result, step=STEP)
    assert reports and all(r.configs > 0 for r in reports.values())
    bad = {i: r.problems for i, r in reports.items() if r.problems}
    assert not bad, bad


def _place_of(T_world_part, dy=PLACE_DY):
    T = np.array(T_world_part, dtype=np.float64)
    T[1, 3] += dy
    return T


def _robot():
    from grasplan.robot.description import load_robot

    return load_robot("ur5")


# --------------------------------------------------------------------------------------------------
# fast: the bracket
# --------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def bracket_plans():
    from conftest import EXAMPLE_PARTS

    from grasplan.part.mesh import load_part
    from grasplan.config.params import PlanParams
    from grasplan.motion.planning import plan

    part = load_part(EXAMPLE_PARTS / "bracket.stl", units="mm")
    prm = PlanParams(top=2, seed=0, score_weights=FAST_WEIGHTS)
    lift_only = plan(part, "ur5", planning=prm)
    placed = plan(part, "ur5", planning=prm, place=_place_of(lift_only.T_world_part))
    return part, lift_only, placed


def test_bracket_lift_always_planned_and_rechecked(bracket_plans):
    part, res, _ = bracket_plans
    ids = res.planned_ids()
    assert len(ids) == 2
    robot = _robot()
    chk = PickPlaceChecker(robot, res.gripper, part.mesh, table_z=res.cell.table_z)
    for i in ids:
        check_pick_place(chk, res, i, placed=False, max_dev=res.params.planning.max_dev)
        assert res.motions[i].T_world_part_place is None
    shared_recheck(res)


def test_bracket_pick_and_place_rechecked_and_round_trips(bracket_plans, tmp_path):
    from grasplan.results.reader import load_result

    part, _, res = bracket_plans
    ids = res.planned_ids()
    assert len(ids) == 2
    robot = _robot()
    chk = PickPlaceChecker(robot, res.gripper, part.mesh, table_z=res.cell.table_z)
    for i in ids:
        check_pick_place(chk, res, i, placed=True, max_dev=res.params.planning.max_dev)
    shared_recheck(res)
    # JSON round trip: the file carries the segments, events, the place and the part in the jaws
    path = res.write(tmp_path / "pp.json")
    doc = json.loads(path.read_text())
    g = next(x for x in doc["grasps"] if x["id"] == ids[0])
    assert [s["label"] for s in g["segments"]][-1] == "retreat"
    assert [e["action"] for e in g["gripper"]] == ["close", "open"]
    back = load_result(path)
    for i in ids:
        a, b = res.motions[i], back.motions[i]
        np.testing.assert_allclose(a.path, b.path, atol=1e-9)
        assert a.segment_list() == b.segment_list() and a.gripper == b.gripper
        np.testing.assert_allclose(a.T_world_part_place, b.T_world_part_place, atol=1e-12)
        np.testing.assert_allclose(a.T_tcp_part, b.T_tcp_part, atol=1e-12)
    np.testing.assert_allclose(back.cell.place, res.cell.place)


def test_checker_can_fail(bracket_plans):
    """The re-check sees a part carried through the table, and a part left in the jaws' way."""
    part, _, res = bracket_plans
    gid = res.planned_ids()[0]
    m, i = res.motions[gid], res.grasps.index_of(gid)
    robot = _robot()
    chk = PickPlaceChecker(robot, res.gripper, part.mesh, table_z=res.cell.table_z)
    sunk = chk.fk_tcp(m.q_grasp) @ m.T_tcp_part
    sunk[2, 3] -= 0.01
    assert ("part", "table") in chk.collisions(m.q_grasp, float(res.grasps.width[i]), sunk, True)
    # the static part where the jaws close (not attached): the fingers at width 0 are inside it
    assert chk.collisions(m.q_grasp, 0.0, res.T_world_part, False)


@pytest.mark.parametrize("bad, match", [
    (lambda g: g["segments"].__setitem__(2, {**g["segments"][2], "label": "jump"}), "label"),
    (lambda g: g["segments"].__setitem__(2, {**g["segments"][2], "label": "transfer"}), "segment labels"),
    (lambda g: g.__setitem__("segments", g["segments"][:-1]), "segment labels"),
    (lambda g: g["segments"][-1].__setitem__("end", g["segments"][-1]["end"] - 1), "last segment ends"),
    (lambda g: g["segments"][2].__setitem__("start", g["segments"][2]["start"] + 1), "consecutive"),
    (lambda g: g["gripper"][1].__setitem__("index", g["gripper"][1]["index"] - 1), "segment boundaries"),
    (lambda g: g["gripper"][0].__setitem__("action", "squeeze"), "action"),
    (lambda g: g.pop("T_world_part_place"), "T_world_part_place"),
    (lambda g: g["T_world_part_place"][1].__setitem__(3, g["T_world_part_place"][1][3] + 0.05), "place"),
    (lambda g: g["T_tcp_part"][0].__setitem__(3, g["T_tcp_part"][0][3] + 0.05), "T_tcp_part"),
])
def test_loader_rejects_tampered_sequences(bracket_plans, bad, match):
    from grasplan.errors import InputError
    from grasplan.results.reader import result_from_document

    _, _, res = bracket_plans
    doc = json.loads(json.dumps(res.to_json()))
    gid = res.planned_ids()[0]
    result_from_document(doc)  # the untouched document loads
    bad(next(g for g in doc["grasps"] if g["id"] == gid))
    with pytest.raises(InputError, match=match):
        result_from_document(doc)


def test_old_motion_without_segments_is_transit_plus_approach():
    from grasplan.results.joint_motion import Motion

    p = np.zeros((5, 6))
    p[:, 0] = np.arange(5)
    m = Motion(q_grasp=p[-1], q_pregrasp=p[2], path=p, pregrasp_index=2)
    assert m.segment_list() == [("transit", 0, 2), ("approach", 2, 4)]
    assert m.grasp_index == 4 and m.attached_range() == (4, 4)
    j = m.to_json()
    assert j["segments"][1] == {"label": "approach", "start": 2, "end": 4} and j["gripper"] == []


# --------------------------------------------------------------------------------------------------
# CLI: bad and unreachable places, a lift that cannot be done
# --------------------------------------------------------------------------------------------------
def _run(args):
    from click.testing import CliRunner

    from grasplan.cli import main

    return CliRunner().invoke(main, args)


def test_cli_place_in_table_exit_3_nothing_written(tmp_path, example_part):
    out = tmp_path / "plan.json"
    r = _run(["plan", str(example_part("bracket.stl")), "--units", "mm", "--robot", "ur5", "--top", "1",
              "--place", "0.45,0.3,-0.02,0,0,0", "-o", str(out)])
    assert r.exit_code == 3, r.output
    assert "place" in r.output and "table" in r.output and "mm" in r.output
    assert not out.exists()


def test_cli_place_in_obstacle_exit_3(tmp_path, example_part):
    cell = tmp_path / "blocked.yaml"
    cell.write_text("name: blocked\nobstacles:\n"
                    "  - {name: block, box: {size: [0.10, 0.10, 0.10]}, T: {xyz: [0.45, 0.3, 0.05]}}\n"
                    "place: {T: {xyz: [0.45, 0.3, 0.02], rpy_deg: [0, 0, 0]}}\n")
    out = tmp_path / "plan.json"
    r = _run(["plan", str(example_part("bracket.stl")), "--units", "mm", "--robot", "ur5", "--top", "1",
              "--cell", str(cell), "-o", str(out)])
    assert r.exit_code == 3, r.output
    assert "place" in r.output and "block" in r.output
    assert not out.exists()


def test_cli_unreachable_place_exit_4_every_grasp_place_unreachable(tmp_path, example_part):
    out = tmp_path / "plan.json"
    r = _run(["plan", str(example_part("bracket.stl")), "--units", "mm", "--robot", "ur5", "--top", "2",
              "--budget", "60", "--place", "3,0,0.2,0,0,0", "-o", str(out)])
    assert r.exit_code == 4, r.output
    assert "place_unreachable" in r.output and "--place" in r.output
    doc = json.loads(out.read_text())
    tried = [g for g in doc["grasps"] if g["status"] not in ("not_tried", "collision_part", "collision_table",
                                                             "collision_obstacle")]
    # every grasp that got through the pick could not be placed, and says why
    placing = [g for g in tried if g["status"] not in ("unreachable", "ik_collision", "no_path")]
    assert len(placing) >= 2 and all(g["status"] == "place_unreachable" for g in placing)
    assert all(g["reason"].startswith("place: no IK") and "reach" in g["reason"] for g in placing)
    assert not [g for g in tried if g["status"] != "place_unreachable" and g["reason"].startswith("place")]


def test_lift_into_the_table_is_refused_with_a_lift_reason(tmp_path):
    """retreat straight down: every lift drives the part into the table -> not planned, reason 'lift:'."""
    from conftest import EXAMPLE_PARTS

    from grasplan.cell.model import cell_from_dict
    from grasplan.part.mesh import load_part
    from grasplan.config.params import PlanParams
    from grasplan.motion.planning import plan

    cell = cell_from_dict({"retreat": {"direction": [0, 0, -1], "distance": 0.05}}, name="down")
    part = load_part(EXAMPLE_PARTS / "bracket.stl", units="mm")
    res = plan(part, "ur5", cell=cell, planning=PlanParams(top=2, seed=0, score_weights=FAST_WEIGHTS, budget_s=5))
    st = res.grasps.status.astype(str)
    tried = np.flatnonzero(~np.isin(st, ["not_tried", "collision_part", "collision_table", "collision_obstacle"]))
    assert len(tried) and not np.any(st == "planned")
    lift = [i for i in tried if str(res.grasps.reason[i]).startswith("lift:")]
    assert lift, [res.grasps.reason[i] for i in tried]
    assert all(st[i] in ("ik_collision", "no_path") for i in lift)
    assert any("table" in str(res.grasps.reason[i]) for i in lift)


# --------------------------------------------------------------------------------------------------
# the acceptance: SileanePepper from the table to a place 0.3 m away
# --------------------------------------------------------------------------------------------------
@pytest.mark.paper
def test_pepper_pick_and_place_part_touches_only_the_jaws(paper):
    from grasplan.part.mesh import load_part
    from grasplan.config.params import PlanParams
    from grasplan.motion.planning import plan

    part = load_part(paper("SileanePepper.stl"))
    prm = PlanParams(top=2, seed=0, score_weights=FAST_WEIGHTS)
    from grasplan.cell.model import load_cell
    from grasplan.cell.resting import stable_pose

    T_rest = stable_pose(part.mesh, load_cell("table"))
    res = plan(part, "ur5", planning=prm, place=_place_of(T_rest))
    ids = res.planned_ids()
    assert ids, res.counts()
    robot = _robot()
    chk = PickPlaceChecker(robot, res.gripper, part.mesh, table_z=res.cell.table_z)
    for i in ids:
        check_pick_place(chk, res, i, placed=True, max_dev=res.params.planning.max_dev)
    shared_recheck(res)
    m = res.motions[ids[0]]
    moved = chk.fk_tcp(m.path[m.event("open").index]) @ m.T_tcp_part
    assert np.linalg.norm(moved[:3, 3] - res.T_world_part[:3, 3]) == pytest.approx(PLACE_DY, abs=1e-4)
