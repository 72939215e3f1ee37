"""A warm Picker left running for a shift: its memory stays bounded whatever ids and poses the
scenes bring, a plan stops at its budget (a deterministic proxy: an injected clock that jumps past
the deadline inside a long stage, and counts of the work done after it), and a scene naming one
part twice in the same place is refused (exit 3 naming both ids).

Speed and RSS over thousands of requests are benchmarks/bench_soak.py's and bench_budget.py's."""
from __future__ import annotations

import gc
import json
import subprocess
import sys
import weakref
from pathlib import Path

import numpy as np
import pytest

from grasplan.cell.model import load_cell
from grasplan.errors import InputError
from grasplan.part.mesh import load_part
from grasplan.pick import Picker, PickParams
from grasplan.pick import warm
from grasplan.pick.budget import Budget, BudgetSpent
from grasplan.motion.collision_scene import CollisionScene, _SceneModel
from grasplan.piles.scene_file import Instance, Scene, load_scene
from grasplan.cell.resting import stable_pose

ROOT = Path(__file__).resolve().parents[1]
BRACKET = ROOT / "examples" / "parts" / "bracket.stl"


@pytest.fixture(scope="module")
def part():
    return load_part(BRACKET)


@pytest.fixture(scope="module")
def rest(part):
    return stable_pose(part.mesh, load_cell("bin"))


@pytest.fixture(scope="module")
def picker(part):
    pk = Picker("ur5", params=PickParams(grasps_per_instance=4))
    pk.add_part("bracket", part)
    return pk


def at(T, dx=0.0, dy=0.0, dz=0.0):
    out = np.array(T, dtype=np.float64)
    out[:3, 3] += [dx, dy, dz]
    return out


def row(rest, ids, jitter=0.0, seed=0):
    """Brackets in a row on the bin floor, 60 mm apart, each moved by up to ``jitter`` m in x, y."""
    rng = np.random.default_rng(seed)
    n = len(ids)
    poses = [at(rest, 0.06 * (k - (n - 1) / 2) + rng.uniform(-jitter, jitter), rng.uniform(-jitter, jitter))
             for k in range(n)]
    return Scene(instances=tuple(Instance(i, "bracket", T) for i, T in zip(ids, poses)), cell="bin")


# -- memory ---------------------------------------------------------------------------------------
def test_a_dropped_scene_frees_its_model_without_the_garbage_collector(part):
    """A collision scene and its variants form no reference cycle: the model (its Pinocchio
    geometry and per-pair data, megabytes in C++) is freed when the last variant is dropped, not at
    the cyclic collector's next full pass (which a long-running planner reaches rarely)."""
    from grasplan.gripper.load import load_gripper
    from grasplan.robot.description import load_robot

    scene = CollisionScene(load_robot("ur5"), load_gripper("schunk_egp_c_40"), part.mesh, np.eye(4), load_cell("bin"))
    v = scene.arranged(at(np.eye(4), 0.4, 0.0, 0.1), {})
    att = v.attached(np.eye(4))
    v.is_free(np.zeros(6))
    att.is_free(np.zeros(6))  # each variant has put its placements into the shared model
    model = weakref.ref(scene._shared)
    gc.disable()
    try:
        del scene, v, att
        assert model() is None
    finally:
        gc.enable()


def _live_models() -> int:
    # type(), not isinstance(): a dead weakref.proxy (another library's) raises on isinstance
    return sum(issubclass(type(o), _SceneModel) for o in gc.get_objects())


def test_new_ids_every_plan_keep_the_warm_state_bounded(picker, rest, monkeypatch):
    """A vision loop whose every scene has new instance ids and poses: the robot scenes hold the
    current scene's ids and at most MAX_KEPT_EXTRAS earlier ones, the kept arrangements stay within
    their entries and bytes, and no collision model is left behind (without the garbage collector)."""
    monkeypatch.setattr(warm, "MAX_SCENE_VARIANTS", 5)
    monkeypatch.setattr(warm, "MAX_SCENE_VARIANT_BYTES", 6 << 20)
    pk = Picker(picker.robot, gripper=picker.gripper, params=PickParams(grasps_per_instance=2))
    pk.add_part("bracket", picker._parts["bracket"], grasps=picker._grasps["bracket"])
    gc.collect()
    gc.disable()
    try:
        base = _live_models()
        seen = []
        for k in range(12):
            sc = row(rest, [f"r{k}_{j}" for j in range(3)], jitter=0.002, seed=k)
            res = pk.plan(sc, max_picks=1)
            assert res.picks
            st = pk._cells[res.cell]
            assert {(i.id, i.part) for i in sc.instances} <= st.extras
            assert len(st.extras) <= 3 + warm.MAX_KEPT_EXTRAS
            assert len(st.variants) <= 5 and st.variants.bytes <= warm.MAX_SCENE_VARIANT_BYTES
            seen.append(_live_models() - base)
        assert max(seen) <= 2  # the robot scene of the one part (and its successor while built), nothing piling up
    finally:
        gc.enable()


def test_lru_bounds_entries_and_bytes():
    c = warm.LRU(3, 100)
    for k in range(5):
        c.put(k, str(k), 30)
    assert c.keys() == [2, 3, 4] and c.bytes == 90
    c.get(2)  # used again: the last to go
    c.put(5, "5", 60)
    assert c.keys() == [2, 5] and c.bytes == 90
    c.put(6, "too big", 101)  # larger than the byte bound: not kept
    assert 6 not in c and c.keys() == [2, 5]


def test_a_variant_is_estimated_from_its_pairs(picker, rest):
    res = picker.plan(row(rest, ["a", "b"]), max_picks=1)
    st = picker._cells[res.cell]
    base = st.scenes["bracket"]
    n_pairs = len(base.pair_rows())
    assert warm.variant_bytes(base) == warm.VARIANT_BASE_BYTES + warm.VARIANT_PAIR_BYTES * n_pairs
    assert st.variants.bytes == warm.variant_bytes(base) * len(st.variants)


def test_scene_parts_beyond_the_bound_are_dropped(tmp_path, rest, picker, monkeypatch):
    """Parts that scene files name with a mesh are kept up to MAX_SCENE_PARTS beyond the current
    scene's (least recently used dropped); parts given to add_part stay."""
    import shutil

    monkeypatch.setattr("grasplan.pick.picker.MAX_SCENE_PARTS", 1)
    pk = Picker(picker.robot, gripper=picker.gripper)
    pk.add_part("bracket", picker._parts["bracket"], grasps=picker._grasps["bracket"])
    for k in range(3):
        shutil.copy(BRACKET, tmp_path / f"b{k}.stl")
        doc = {"schema": "grasplan.scene/1", "cell": "bin", "parts": {f"p{k}": {"mesh": f"b{k}.stl"}},
               "instances": [{"id": "a", "part": f"p{k}", "T": at(rest, 0.0).tolist()}]}
        path = tmp_path / f"s{k}.json"
        path.write_text(json.dumps(doc))
        pk._ensure_parts(load_scene(path))
    assert sorted(pk.parts()) == ["bracket", "p1", "p2"]


# -- the budget -----------------------------------------------------------------------------------
class JumpClock:
    """A clock that stands still until :meth:`jump` moves it far past any budget."""

    def __init__(self):
        self.t = 1000.0
        self.reads = 0

    def __call__(self) -> float:
        self.reads += 1
        return self.t

    def jump(self) -> None:
        self.t += 1e6


def test_the_budget_stops_inside_an_instance(picker, rest, monkeypatch):
    """Past the budget during a grasp's motion planning, no further grasp of that instance (nor any
    other instance) is planned: the plan returns with both not_tried."""
    import grasplan.pick.picker as pm
    from grasplan.pick.codes import Reason
    from grasplan.motion.grasp_motion import Outcome

    clock = JumpClock()
    calls = []

    def motion(*a, **k):  # every grasp fails after a long search: more grasps would be tried
        calls.append(1)
        clock.jump()
        return Outcome(Reason.NO_TRANSIT, "RRTConnect found no path (mocked)")

    monkeypatch.setattr(pm, "plan_pick_motion", motion)
    pk = Picker(picker.robot, gripper=picker.gripper, params=PickParams(budget_s=5.0, grasps_per_instance=12),
                clock=clock)
    pk.add_part("bracket", picker._parts["bracket"], grasps=picker._grasps["bracket"])
    res = pk.plan(row(rest, ["a", "b"]))
    assert len(calls) == 1
    assert not res.picks and [r.status for r in res.instances] == ["not_tried", "not_tried"]
    assert all("budget" in r.reason for r in res.instances)
    pk.params = PickParams(budget_s=None, grasps_per_instance=12)  # the same without a budget: every grasp
    calls.clear()
    pk.plan(row(rest, ["a", "b"]))
    assert len(calls) >= 12


def test_the_budget_stops_the_scene_checks(picker, rest, monkeypatch):
    """Past the budget during the interpenetration estimate, no further pair is estimated, nothing is
    planned and the warnings say how many pairs were left."""
    import grasplan.piles.checks as pc

    clock = JumpClock()
    pairs = []
    real = pc._depth_into

    def depth(*a, **k):
        pairs.append(1)
        clock.jump()
        return real(*a, **k)

    monkeypatch.setattr(pc, "_depth_into", depth)
    pk = Picker(picker.robot, gripper=picker.gripper, params=PickParams(budget_s=5.0), clock=clock)
    pk.add_part("bracket", picker._parts["bracket"], grasps=picker._grasps["bracket"])
    # three brackets pushed 6 mm into each other in a row: three pairs to estimate
    sc = Scene(instances=tuple(Instance(i, "bracket", at(rest, 0.006 * k)) for k, i in enumerate("abc")), cell="bin")
    res = pk.plan(sc)
    assert len(pairs) == 2  # the two directions of the first pair
    assert [r.status for r in res.instances] == ["not_tried"] * 3
    assert any("not checked for interpenetration" in w and w.startswith("scene checks stopped") for w in res.warnings)


def test_the_budget_stops_a_depth_measurement(part):
    """pair_depth looks at the budget while it measures: a clock past it ends a long measurement."""
    from grasplan.cell.shapes import bvh
    from grasplan.geometry.meshdata import convex_hull
    from grasplan.pick.depth import PartDepth, pair_depth

    m = part.mesh
    pd = PartDepth.build(m, bvh(m.vertices, m.faces), np.asarray(convex_hull(np.asarray(m.vertices)).vertices))
    T_b = at(np.eye(4), 0.004)
    exact = pair_depth(pd, np.eye(4), pd, T_b)
    assert exact > 0.002
    clock = JumpClock()
    b = Budget(1.0, clock)
    clock.jump()
    with pytest.raises(BudgetSpent):
        pair_depth(pd, np.eye(4), pd, T_b, budget=b)
    assert pair_depth(pd, np.eye(4), pd, T_b, budget=Budget(None, clock)) == exact


def test_the_budget_caps_each_path_query():
    from types import SimpleNamespace

    from grasplan.motion.grasp_motion import MotionContext

    clock = JumpClock()
    ctx = SimpleNamespace(params=PickParams(time_limit_per_query=0.2, path_attempts=2), budget=Budget(0.1, clock))
    assert MotionContext.rrt_time(ctx) == pytest.approx(0.05)  # both attempts within the 0.1 s left
    ctx.budget = Budget(10.0, clock)
    assert MotionContext.rrt_time(ctx) == 0.2
    ctx.budget = Budget(None, clock)
    assert MotionContext.rrt_time(ctx) == 0.2
    ctx.budget = Budget(0.0, lambda: 0.0)
    with pytest.raises(BudgetSpent):
        MotionContext.rrt_time(ctx)


def test_the_budget_stops_building_the_robot_scenes(picker, rest):
    """A budget spent before the robot scenes are built: none is replaced half-way."""
    from grasplan.pick.warm import build_scenes

    st = picker._cells[picker.plan(row(rest, ["a"]), max_picks=0).cell]
    before = dict(st.scenes), st.extras
    clock = JumpClock()
    b = Budget(1.0, clock)
    clock.jump()
    with pytest.raises(BudgetSpent):
        build_scenes(st, picker.robot, picker.gripper, {"bracket": picker._parts["bracket"].mesh},
                     row(rest, ["new_a", "new_b"]), None, b)
    assert (dict(st.scenes), st.extras) == before


# -- one part twice -------------------------------------------------------------------------------
def test_the_same_part_twice_in_one_place_is_refused(picker, rest):
    sc = Scene(instances=(Instance("a", "bracket", rest), Instance("b", "bracket", at(rest, 0.1)),
                          Instance("c", "bracket", at(rest, 0.0003, -0.0002))), cell="bin")
    with pytest.raises(InputError, match=r"instances 'a' \(bracket\) and 'c' \(bracket\) lie in the same place"):
        picker.plan(sc)


def test_pick_cli_refuses_a_duplicate_with_exit_3(tmp_path, rest):
    doc = {"schema": "grasplan.scene/1", "cell": "bin", "parts": {"bracket": {"mesh": str(BRACKET)}},
           "instances": [{"id": i, "part": "bracket", "T": rest.tolist()} for i in ("first", "second")]}
    (tmp_path / "s.json").write_text(json.dumps(doc))
    r = subprocess.run([sys.executable, "-c", "from grasplan.cli import main; main()", "pick", str(tmp_path / "s.json"),
                        "-o", str(tmp_path / "p.json")], capture_output=True, text=True, timeout=600)
    assert r.returncode == 3, r.stderr
    assert "'first'" in r.stderr and "'second'" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "p.json").exists()


def test_coplanar_faces_do_not_go_through_the_winding_number(part, rest, monkeypatch):
    """Two brackets resting on the floor, one moved 2.5 mm along it: the faces in one plane put
    hundreds of surface samples exactly on the other part's surface, which the ray test cannot
    decide. The depth treats those as outside (they are at most rounding deep): the same depth as
    deciding every one with the generalised winding number, with almost none of them sent there."""
    import coal

    import grasplan.piles.checks as pc
    from grasplan.cell.shapes import bvh
    from grasplan.geometry.meshdata import convex_hull
    from grasplan.pick.depth import PartDepth, pair_depth

    m = part.mesh
    pd = PartDepth.build(m, bvh(m.vertices, m.faces), np.asarray(convex_hull(np.asarray(m.vertices)).vertices))
    T_b = at(rest, 0.0025)
    wound = []
    real = pc.points_inside

    def counted(mesh, pts):
        wound.append(len(pts))
        return real(mesh, pts)

    monkeypatch.setattr(pc, "points_inside", counted)
    monkeypatch.setattr("grasplan.geometry.containment.points_inside", counted)  # through points_inside_tree
    depth = pair_depth(pd, rest, pd, T_b)
    # the reference: every sample of either part inside the other by the exact test, its exact distance
    ref = 0.0
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    for Ta, Tb in ((rest, T_b), (T_b, rest)):
        local = (pd.samples @ Ta[:3, :3].T + Ta[:3, 3] - Tb[:3, 3]) @ Tb[:3, :3]
        for p in local[real(m, local)]:
            res.clear()
            ref = max(ref, coal.distance(coal.Sphere(1e-12), coal.Transform3s(np.eye(3), p), pd.bvh,
                                         coal.Transform3s(), req, res))
    assert depth == pytest.approx(ref, abs=2e-9) and depth > 0.002
    assert sum(wound) <= 20, wound


def _box_mesh(tmp_path, name, extents):
    import trimesh

    path = tmp_path / f"{name}.stl"
    trimesh.creation.box(extents=extents).export(path)
    return load_part(path, units="m").mesh


def test_a_thin_part_flat_on_its_twin_is_no_duplicate(tmp_path):
    """A plate 1.5 mm thick lying flat on its twin: every hull vertex is within 1.5 mm (less than
    the 2 mm tolerance) of the other's, but that is its thickness: two parts, not one seen twice.
    The same plate moved 0.3 mm is refused."""
    from grasplan.piles.checks import check_coincident

    plate = _box_mesh(tmp_path, "plate", (0.03, 0.02, 0.0015))
    T = np.eye(4)
    check_coincident([Instance("a", "plate", T), Instance("b", "plate", at(T, dz=0.0015))], {"plate": plate}, tol=0.002)
    with pytest.raises(InputError, match=r"'a' \(plate\) and 'b' \(plate\) lie in the same place"):
        check_coincident([Instance("a", "plate", T), Instance("b", "plate", at(T, 0.0003))], {"plate": plate},
                         tol=0.002)


def test_instances_deep_inside_each_other_are_refused(tmp_path):
    """Two 40 mm cubes 15 mm into each other: no pose estimate is that wrong (more than 10 mm, five
    times the tolerance): refused naming both; 4 mm into each other: a warning, planned as given."""
    from grasplan.piles.checks import check_instances, deep_limit

    cube = _box_mesh(tmp_path, "cube", (0.04, 0.04, 0.04))
    cell = load_cell("bin")
    T = at(np.eye(4), 0.45, 0.0, 0.031)
    assert deep_limit(0.002) == pytest.approx(0.010)
    with pytest.raises(InputError, match=r"'a' \(cube\) and 'b' \(cube\) interpenetrate by at least 1[45]\.\d mm"):
        check_instances([Instance("a", "cube", T), Instance("b", "cube", at(T, 0.025))], {"cube": cube}, cell,
                        tol=0.002)
    (w,) = check_instances([Instance("a", "cube", T), Instance("b", "cube", at(T, 0.036))], {"cube": cube}, cell,
                           tol=0.002)
    assert "'a' and 'b' interpenetrate" in w
