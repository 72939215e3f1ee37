"""`grasplan plan`: every planned grasp re-checked by an INDEPENDENT implementation.

The checker below shares no code with grasplan.motion.collision_scene / grasplan.motion.joint_paths: Pinocchio FK on a fresh
Data, python-fcl (not coal) objects built from the URDF's collision meshes loaded with trimesh,
the gripper boxes rebuilt from the output JSON's gripper block and the issue's dimensions, a
table box, the part's BVH placed by the JSON's T_world_part, and our own 0.01 rad interpolation.
"""
from __future__ import annotations

import json
import time

import numpy as np
import pytest

STEP = 0.01
BACKOFF = 0.05
MAX_DEV = 0.002
STATUSES = {"planned", "collision_part", "collision_table", "collision_obstacle", "unreachable", "ik_collision",
            "no_path", "place_unreachable", "place_no_path", "not_tried", "not_checked"}


def test_plan_statuses_are_the_documented_ones():
    from grasplan.status import PLAN_STATUSES, Status

    assert set(PLAN_STATUSES) == STATUSES and len(PLAN_STATUSES) == len(STATUSES)
    assert {s.value for s in Status} == STATUSES | {"ok"}


# --------------------------------------------------------------------------------------------------
# independent checker
# --------------------------------------------------------------------------------------------------
from fcl_recheck import bvh as _bvh  # noqa: E402  (independent python-fcl helpers)
from fcl_recheck import dense  # noqa: E402
from fcl_recheck import fcl_tf as _fcl_tf  # noqa: E402
from fcl_recheck import RobotLinks  # noqa: E402


def _schunk_boxes(opening):
    """Issue 3's EGP-C 40 boxes in the TCP frame: (extents, centre)."""
    return [
        (np.array([0.060, 0.040, 0.095]), np.array([0.0, 0.0, -0.0795])),                      # body
        (np.array([0.008, 0.016, 0.040]), np.array([-opening / 2 - 0.004, 0.0, -0.012])),     # -x jaw
        (np.array([0.008, 0.016, 0.040]), np.array([+opening / 2 + 0.004, 0.0, -0.012])),     # +x jaw
    ]


class IndependentChecker:
    """Robot links (python-fcl BVH from the URDF meshes) + gripper boxes vs table and part."""

    def __init__(self, robot, part_mesh, T_world_part, T_flange_tcp, table_z=0.0,
                 mounted=("base_link", "shoulder_link")):
        import fcl

        self.fcl = fcl
        self.robot_links = RobotLinks(robot, T_flange_tcp, mounted)
        part_geom = _bvh(part_mesh.vertices, part_mesh.faces)
        self.part = fcl.CollisionObject(part_geom, _fcl_tf(np.asarray(T_world_part)))
        table_T = np.eye(4)
        table_T[2, 3] = table_z - 0.5
        self.table = fcl.CollisionObject(fcl.Box(20.0, 20.0, 1.0), _fcl_tf(table_T))
        self.req = fcl.CollisionRequest()

    def _hit(self, a, b):
        return self.fcl.collide(a, b, self.req, self.fcl.CollisionResult()) > 0

    def fk_tcp(self, q):
        return self.robot_links.fk_tcp(q)

    def collisions(self, q, opening):
        """List of colliding (object, obstacle) names at q with the jaws at ``opening``."""
        fcl = self.fcl
        hits = self.robot_links.hits(q, self.part, self.table, self._hit)
        T_world_tcp = self.fk_tcp(q)
        for k, (ext, c) in enumerate(_schunk_boxes(opening)):
            T = np.eye(4)
            T[:3, 3] = c
            box = fcl.CollisionObject(fcl.Box(*ext), _fcl_tf(T_world_tcp @ T))
            if self._hit(box, self.part):
                hits.append((f"gripper_box{k}", "part"))
            if self._hit(box, self.table):
                hits.append((f"gripper_box{k}", "table"))
        return hits


def check_planned_grasp(chk: IndependentChecker, robot, g: dict, doc: dict):
    q_home = np.asarray(doc["robot"]["q_home"])
    full = np.asarray(g["path"], dtype=np.float64)
    gi = next((s["end"] for s in g.get("segments", []) if s["label"] == "approach"), len(full) - 1)
    path = full[:gi + 1]  # home -> grasp; the lift and place are re-checked in tests/test_pick_place.py
    qg, qp, k = np.asarray(g["q_grasp"]), np.asarray(g["q_pregrasp"]), g["pregrasp_index"]
    assert path.ndim == 2 and path.shape[1] == len(q_home)
    np.testing.assert_allclose(path[0], q_home, atol=1e-12)
    np.testing.assert_allclose(path[k], qp, atol=1e-12)
    np.testing.assert_allclose(path[-1], qg, atol=1e-12)
    assert 0 < k < len(path) - 1
    # joint limits (URDF, via Pinocchio's model)
    lo, hi = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    d = dense(path)
    assert np.all(d >= lo - 1e-9) and np.all(d <= hi + 1e-9)
    # the grasp pose
    T_world_part = np.asarray(doc["part"]["T_world_part"])
    T_world_tcp = T_world_part @ np.asarray(g["T_part_tcp"])
    np.testing.assert_allclose(chk.fk_tcp(qg), T_world_tcp, atol=1e-4)
    T_pre = T_world_tcp.copy()
    T_pre[:3, 3] -= BACKOFF * T_world_tcp[:3, 2]
    np.testing.assert_allclose(chk.fk_tcp(qp), T_pre, atol=1e-4)
    # the straight approach: every 0.01 rad point and every segment midpoint within 2 mm of the line
    app = dense(path[k:])
    mids = 0.5 * (path[k:-1] + path[k + 1:])
    a, b = T_pre[:3, 3], T_world_tcp[:3, 3]
    u = (b - a) / np.linalg.norm(b - a)
    for q in np.concatenate([app, mids]):
        p = chk.fk_tcp(q)[:3, 3] - a
        t = np.clip(p @ u, 0.0, BACKOFF)
        assert np.linalg.norm(p - t * u) <= MAX_DEV, f"grasp {g['id']}: approach {np.linalg.norm(p - t * u)} m off the line"
    # collisions along the whole path, jaws at the pre-grasp opening
    max_opening = float(doc["gripper"]["max_opening"])
    opening = min(max_opening, float(g["width"]) + 0.010)
    for q in d:
        hits = chk.collisions(q, opening)
        assert not hits, f"grasp {g['id']}: collision {hits} at q={q.tolist()}"


def _near(T: np.ndarray, i: int, js: np.ndarray, max_dist: float, max_angle: float) -> np.ndarray:
    """(len(js),) bool: TCP j within max_dist (m) of TCP i AND rotated at most max_angle (rad) from it."""
    d = np.linalg.norm(T[js, :3, 3] - T[i, :3, 3], axis=1)
    cos = (np.einsum("ij,nij->n", T[i, :3, :3], T[js, :3, :3]) - 1.0) / 2.0
    return (d <= max_dist) & (np.arccos(np.clip(cos, -1.0, 1.0)) <= max_angle)


def check_distinct_ranking(ranked: list[dict], plan_params: dict) -> None:
    """The ranking (issue 9): by score (ties by id), except that a near-duplicate of a better grasp
    (TCP within distinct_distance and distinct_angle_deg) moves behind every distinct grasp.

    Checked from the document alone: the ranking is a prefix of pairwise-distinct grasps followed by
    near-duplicates, each part in score order (ties by id), and every duplicate is near a better
    grasp of the prefix."""
    n = len(ranked)
    if n < 2:
        return
    dist = float(plan_params["distinct_distance"])
    ang = np.radians(float(plan_params["distinct_angle_deg"]))
    T = np.array([g["T_part_tcp"] for g in ranked], dtype=np.float64)
    score = np.array([g["score"] for g in ranked], dtype=np.float64)
    ids = np.array([g["id"] for g in ranked])
    split = n   # the first grasp (clearly) near a better one starts the duplicates
    if dist > 0:
        for k in range(1, n):
            if _near(T, k, np.arange(k), dist * (1 - 1e-6), ang - 1e-6).any():
                split = k
                break
    for part in (np.arange(split), np.arange(split, n)):
        s, i = score[part], ids[part]
        better_or_tie = (s[:-1] > s[1:]) | ((s[:-1] == s[1:]) & (i[:-1] < i[1:]))
        assert np.all(better_or_tie), "ranking is not by score (ties by id) within the distinct / duplicate parts"
    for k in range(split, n):
        prefix = np.arange(split)
        near = _near(T, k, prefix, dist * (1 + 1e-6), ang + 1e-6)
        assert near.any(), f"grasp {ids[k]} ranks behind the distinct grasps but is near none of them"
        assert np.max(score[prefix[near]]) >= score[k], f"grasp {ids[k]} is a duplicate of only worse grasps"
    for k in range(1, split):  # the distinct prefix is pairwise distinct (with a margin for JSON rounding)
        assert not _near(T, k, np.arange(k), dist * (1 - 1e-6), ang - 1e-6).any()


def check_scores(doc: dict, mesh) -> None:
    """The documented score (docs/quality.md), recomputed from the file: the weights
    params.score_weights (from the packaged configs/scoring.yaml) over center = 1 - min(1, |TCP -
    centre of mass| / (half the bounding-box diagonal)), top = max(0, -z_tcp . z_world),
    width = (max_opening - width) / max_opening and the normalised gravity_margin / epsilon of each
    grasp's quality object."""
    assert doc["plan_params"]["score_weights"] is None  # the plan uses the grasp stage's score
    weights = dict(doc["params"]["score_weights"])
    refs = dict(doc["params"]["score_refs"])
    from plan_docs import kept_grasps

    ranked = [g for g in kept_grasps(doc) if g["rank"] is not None]  # a compact plan's untried columns too
    assert ranked
    T = np.array([g["T_part_tcp"] for g in ranked])
    w = np.array([g["width"] for g in ranked])
    T_world_part = np.asarray(doc["part"]["T_world_part"])
    assert mesh.is_watertight
    com = np.asarray(mesh.center_mass)
    np.testing.assert_allclose(doc["part"]["com"], com, atol=1e-9)
    r = 0.5 * np.linalg.norm(mesh.bounds[1] - mesh.bounds[0])
    mo = float(doc["gripper"]["max_opening"])
    gm = np.array([g["quality"]["gravity_margin"] for g in ranked])
    eps = np.array([g["quality"]["epsilon"] for g in ranked])
    terms = {"center": 1.0 - np.minimum(1.0, np.linalg.norm(T[:, :3, 3] - com, axis=1) / r),
             "top": np.maximum(0.0, -(T[:, :3, 2] @ T_world_part[:3, :3].T)[:, 2]),
             "width": (mo - w) / mo,
             "gravity_margin": np.clip(0.5 + 0.5 * np.log(gm) / np.log(refs["gravity_margin_ref"]), 0.0, 1.0),
             "epsilon": np.clip(eps / refs["epsilon_ref"], 0.0, 1.0)}
    expected = sum(v * terms[k] for k, v in weights.items()) / sum(weights.values())
    np.testing.assert_allclose([g["score"] for g in ranked], expected, atol=1e-7)


def check_plan_doc(doc: dict, top: int):
    from plan_docs import REJECTED, kept_grasps, status_counts

    assert doc["schema"] == "grasplan.plan/1"
    r = doc["robot"]
    assert set(r) >= {"name", "joint_names", "T_world_base", "q_home"}
    grasps = kept_grasps(doc)
    ids = [g["id"] for g in grasps]
    if doc.get("keep", "all") == "all":
        assert ids == list(range(len(grasps)))
    else:  # compact: the colliding poses are counted, every other pose is listed once
        assert ids == sorted(set(ids)) and not any(g["status"] in REJECTED for g in doc["grasps"])
        assert len(ids) + sum(sum(doc["rejected"][s]) for s in REJECTED) == doc["counts"]["poses"]
    for g in grasps:
        assert g["status"] in STATUSES
        assert isinstance(g["reason"], str) and g["reason"]
    counts = status_counts(doc, STATUSES)
    for s in STATUSES:
        assert doc["counts"][s] == counts[s]
    assert counts["planned"] <= top
    ranked = sorted((g for g in grasps if g["rank"] is not None), key=lambda g: g["rank"])
    assert [g["rank"] for g in ranked] == list(range(len(ranked)))
    scores = [g["score"] for g in ranked]
    assert all(0.0 <= s <= 1.0 for s in scores)
    check_distinct_ranking(ranked, doc["plan_params"])
    # the rejected grasps of the grasp stage are never ranked; ranked ones were ok there
    for g in grasps:
        if g["status"] in ("collision_part", "collision_table"):
            assert g["rank"] is None and "path" not in g
        else:
            assert g["rank"] is not None
    # nothing ranked after the last tried grasp was tried: not_tried is a suffix of the ranking
    tried = [g["status"] != "not_tried" for g in ranked]
    if False in tried:
        assert not any(tried[tried.index(False):])
    for g in grasps:
        assert ("path" in g) == (g["status"] == "planned")


# --------------------------------------------------------------------------------------------------
# paper parts: one plan per part, shared by the tests
# --------------------------------------------------------------------------------------------------
PAPER = ["TLess20.stl", "SileanePepper.stl", "IPAGearShaft.stl"]
TOP = 5


@pytest.fixture(scope="module", params=PAPER)
def paper_plan(request):
    from conftest import paper_part

    from grasplan.part.mesh import load_part
    from grasplan.config.params import PlanParams
    from grasplan.motion.planning import plan

    path = paper_part(request.param)
    t = time.perf_counter()
    part = load_part(path)
    result = plan(part, robot="ur5", planning=PlanParams(top=TOP, seed=0))
    elapsed = time.perf_counter() - t
    # the full to_json() of every grasp pose is large: check the planned grasps as written
    # (PlanResult.planned(): the JSON entries) plus the header blocks; the whole document is checked
    # on the example part in the CLI test
    doc = {"robot": result.robot.to_json(), "part": result.part.to_json(),
           "gripper": {"max_opening": float(result.gripper.max_opening),
                       "T_flange_tcp": np.asarray(result.gripper.T_flange_tcp).tolist()},
           "grasps": result.planned()}
    # the JSON entries are the result's arrays
    for e in doc["grasps"]:
        row = result.grasps.index_of(e["id"])
        np.testing.assert_allclose(e["T_part_tcp"], result.grasps.T_part_tcp[row], atol=1e-9)
        assert e["width"] == pytest.approx(float(result.grasps.width[row]), abs=1e-9)
    return request.param, part, result, doc, elapsed


@pytest.mark.slow
@pytest.mark.paper
def test_paper_parts_planned_and_independently_verified(paper_plan):
    from grasplan.robot.description import load_robot

    name, part, result, doc, elapsed = paper_plan
    c = result.counts()
    assert set(c) == STATUSES | {"grasps"}
    counted = 0 if result.rejected is None else int(result.rejected.counts.sum())  # the poses that hit the part
    assert sum(c[s] for s in STATUSES) == c["grasps"] == len(result.grasps) + counted
    assert c["planned"] <= TOP
    planned = [g for g in doc["grasps"] if g["status"] == "planned"]
    assert len(planned) >= 5, f"{name}: only {len(planned)} planned; counts {result.counts()}"
    assert elapsed < 120.0, f"{name}: plan took {elapsed:.1f} s"
    robot = load_robot("ur5")
    chk = IndependentChecker(robot, part.mesh, doc["part"]["T_world_part"], doc["gripper"]["T_flange_tcp"])
    for g in planned:
        check_planned_grasp(chk, robot, g, doc)


@pytest.mark.slow
@pytest.mark.paper
def test_independent_checker_can_fail(paper_plan):
    """The checker is not vacuous: it flags the arm driven through the table and the part."""
    from grasplan.robot.description import load_robot

    name, part, result, doc, _ = paper_plan
    robot = load_robot("ur5")
    chk = IndependentChecker(robot, part.mesh, doc["part"]["T_world_part"], doc["gripper"]["T_flange_tcp"])
    g = next(g for g in doc["grasps"] if g["status"] == "planned")
    q = np.asarray(g["q_grasp"], dtype=np.float64)
    opening = min(float(doc["gripper"]["max_opening"]), float(g["width"]) + 0.010)
    assert chk.collisions(q, opening) == []
    # jaws closed to zero at the grasp: the fingers are inside the part
    assert any(o == "part" for _, o in chk.collisions(q, 0.0))
    # push the TCP 0.1 m further along its approach: into the part / table
    T = chk.fk_tcp(q)
    deeper = T.copy()
    deeper[:3, 3] += 0.1 * T[:3, 2]
    from grasplan.robot.ik.solve import solve_ik

    sols = solve_ik(robot, deeper @ np.linalg.inv(np.asarray(doc["gripper"]["T_flange_tcp"]))).q
    if len(sols):
        assert chk.collisions(sols[0], opening)


# --------------------------------------------------------------------------------------------------
# CLI on an example part (fast)
# --------------------------------------------------------------------------------------------------
def _run(args):
    from click.testing import CliRunner

    from grasplan.cli import main

    return CliRunner().invoke(main, args)


def test_cli_plan_bracket_independently_verified(tmp_path, example_part):
    from grasplan.part.mesh import load_part
    from grasplan.robot.description import load_robot

    out = tmp_path / "plan.json"
    # distinct-ranking thresholds away from the roll step (15 deg) and round lengths: see
    # test_distinct_ranking_at_the_roll_step for the default 15 deg
    r = _run(["plan", str(example_part("bracket.stl")), "--units", "mm", "--robot", "ur5", "--top", "3",
              "--distinct-distance", "4.7mm", "--distinct-angle", "20", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "planned" in r.output and "seconds" in r.output
    doc = json.loads(out.read_text())
    assert doc["plan_params"]["distinct_distance"] == pytest.approx(0.0047)
    assert doc["plan_params"]["distinct_angle_deg"] == 20.0
    check_plan_doc(doc, 3)
    planned = [g for g in doc["grasps"] if g["status"] == "planned"]
    assert len(planned) == 3
    part = load_part(example_part("bracket.stl"), units="mm")
    check_scores(doc, part.mesh)
    robot = load_robot("ur5")
    chk = IndependentChecker(robot, part.mesh, doc["part"]["T_world_part"], doc["gripper"]["T_flange_tcp"])
    for g in planned:
        check_planned_grasp(chk, robot, g, doc)
    # deterministic: the same run again gives the same paths
    out2 = tmp_path / "plan2.json"
    r = _run(["plan", str(example_part("bracket.stl")), "--units", "mm", "--top", "3",
              "--distinct-distance", "4.7mm", "--distinct-angle", "20", "-o", str(out2)])
    assert r.exit_code == 0, r.output
    doc2 = json.loads(out2.read_text())
    assert [g.get("path") for g in doc2["grasps"]] == [g.get("path") for g in doc["grasps"]]


def test_plan_params_are_validated_and_old_keywords_are_gone(example_part):
    import grasplan
    from grasplan.errors import InputError
    from grasplan.config.params import PlanParams

    with pytest.raises(InputError, match=r"--top \(top\): must be >= 1.*got 0"):
        PlanParams(top=0)
    with pytest.raises(InputError, match=r"--time-limit \(time_limit_per_query\).*got -1"):
        PlanParams(time_limit_per_query=-1.0)
    with pytest.raises(InputError, match=r"score_weights: unknown term\(s\) \['nope'\]"):
        PlanParams(score_weights=(("nope", 1.0),))
    with pytest.raises(TypeError):
        grasplan.plan(example_part("box.stl"), "ur5", top=3)


def test_cli_unknown_robot_exit_3_nothing_written(tmp_path, example_part):
    out = tmp_path / "plan.json"
    r = _run(["plan", str(example_part("bracket.stl")), "--units", "mm", "--robot", "ur6", "-o", str(out)])
    assert r.exit_code == 3
    assert "ur5" in r.output and "panda" in r.output
    assert not out.exists()


def test_cli_out_of_reach_exit_4_file_explains(tmp_path, example_part):
    """The part 5 m away: nothing reachable; exit 4, the file says why for every grasp."""
    out = tmp_path / "plan.json"
    r = _run(["plan", str(example_part("box.stl")), "--units", "mm", "--top", "3", "--part-pose", "5,0,0.01,0,0,0",
              "-o", str(out)])
    assert r.exit_code == 4, r.output
    doc = json.loads(out.read_text())
    st = [g["status"] for g in doc["grasps"]]
    assert "planned" not in st
    tried = [g for g in doc["grasps"] if g["status"] not in ("not_tried", "collision_part", "collision_table")]
    assert tried and all(g["status"] == "unreachable" for g in tried)


def test_distinct_ranking_at_the_roll_step(example_part):
    """Two rolls of one candidate exactly --distinct-angle (15 deg) apart, same TCP origin, are
    'within' the angle: the second must rank behind a distinct grasp. With the defaults the bracket's
    three best 'distinct' grasps are one contact pair rolled -15, 0, +15 deg."""
    from grasplan.grasps.pipeline import compute_grasps
    from grasplan.part.mesh import load_part
    from grasplan.config.params import GraspParams, PlanParams
    from grasplan.grasps.ranking import distinct_order

    gr = compute_grasps(load_part(example_part("bracket.stl"), units="mm"), grasps=GraspParams(roll_step_deg=15.0))
    T, cand, roll = gr.frames.T_part_tcp, gr.frames.candidate, gr.frames.roll
    same = np.flatnonzero(cand == cand[0])
    a, b = same[0], same[1]
    assert np.degrees(roll[b] - roll[a]) == pytest.approx(15.0) and np.allclose(T[a][:3, 3], T[b][:3, 3])
    far = int(np.argmax(np.linalg.norm(T[:, :3, 3] - T[a][:3, 3], axis=1)))
    order, n = distinct_order(T, np.array([a, b, far]), min_distance=PlanParams().distinct_distance,
                              min_angle_deg=PlanParams().distinct_angle_deg)
    assert order.tolist() == [a, far, b] and n == 2


def test_a_grasp_colliding_where_the_tcp_pose_alone_decides_fails_every_solution(example_part, monkeypatch):
    """A grasp whose first IK solution collides at the grasp on a pair the TCP pose alone places
    (the flange's link or the gripper against the table) is not tried with its other solutions:
    the plan is the one trying every solution (statuses, reasons naming all of them, motions), and
    the shortcut was taken."""
    import grasplan.motion.grasp_motion as gm
    from grasplan.motion.planning import plan
    from grasplan.part.mesh import load_part

    taken = []
    orig = gm._placed_by_tcp

    def record(*args):
        taken.append(orig(*args))
        return taken[-1]

    part = load_part(example_part("bracket.stl"), units="mm")
    monkeypatch.setattr(gm, "_placed_by_tcp", record)
    fast = plan(part, "ur5")
    monkeypatch.setattr(gm, "_placed_by_tcp", lambda *args: False)
    slow = plan(part, "ur5")
    assert sum(taken) >= 2
    np.testing.assert_array_equal(fast.grasps.status.astype(str), slow.grasps.status.astype(str))
    np.testing.assert_array_equal(fast.grasps.reason.astype(str), slow.grasps.reason.astype(str))
    assert fast.planned_ids() == slow.planned_ids()
    for gid, m in fast.motions.items():
        np.testing.assert_array_equal(m.path, slow.motions[gid].path)
    assert any("8 collide at the grasp" in r for r in fast.grasps.reason.astype(str))
