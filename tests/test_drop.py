"""``grasplan scene drop`` (issue 21): piles made in MuJoCo, checked independently of MuJoCo.

The checks re-derive everything from the scene's poses and the part meshes: containment in the
bin from the cell's numbers, resting and interpenetration with python-fcl distances and a
winding-number inside test written here (no MuJoCo, no CoACD, no coal).
"""
from __future__ import annotations

import itertools
import math
from pathlib import Path

import fcl
import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

from grasplan.cell.model import load_cell
from grasplan.cli import main
from grasplan.errors import InputError
from grasplan.sim.drop import DropParams, PileError, PileItem, SettleError, drop_pile, outside_bin
from grasplan.part.mesh import load_part
from grasplan.sim.pileworld import PileWorld, part_body
from grasplan.piles.scene_file import load_scene, part_name
from grasplan.piles.scene_write import write_scene

#: settled parts: inside the bin within this (m); resting: within this of the floor or a neighbour (m);
#: interpenetration at most this (m)
INSIDE_TOL, REST_TOL, PENETRATION_TOL = 1e-3, 3e-3, 2e-3
EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "parts"
EXAMPLE_PILE = (("box.stl", 2), ("bracket.stl", 2), ("gear.stl", 1))
PAPER_PILE = ("TLess20.stl", "TLess22.stl", "SileanePepper.stl", "IPARingScrew.stl", "SileaneGear.stl")


def _items(paths_counts) -> list[PileItem]:
    items: list[PileItem] = []
    for path, n in paths_counts:
        items.append(PileItem(part_name(path), load_part(path), n))
    return items


def _example_items():
    return _items([(EXAMPLES / p, n) for p, n in EXAMPLE_PILE])


@pytest.fixture(scope="module")
def cell():
    return load_cell("bin")


@pytest.fixture(scope="module")
def example_pile(cell):
    items = _example_items()
    return items, drop_pile(cell, items, params=DropParams(seed=0))


# ------------------------------------------------------------------------------------------------
# independent checks (no MuJoCo)
# ------------------------------------------------------------------------------------------------
def _world_meshes(items, scene) -> dict[str, trimesh.Trimesh]:
    parts = {it.name: it.part for it in items}
    out = {}
    for inst in scene.instances:
        p = parts[inst.part]
        m = trimesh.Trimesh(np.asarray(p.vertices), np.asarray(p.faces), process=False)
        m.apply_transform(inst.T_world_part)
        out[inst.id] = m
    return out


def _fcl(m: trimesh.Trimesh) -> fcl.CollisionObject:
    bvh = fcl.BVHModel()
    bvh.beginModel(len(m.vertices), len(m.faces))
    bvh.addSubModel(np.asarray(m.vertices), np.asarray(m.faces))
    bvh.endModel()
    return fcl.CollisionObject(bvh, fcl.Transform())


def _winding(points: np.ndarray, tris: np.ndarray, chunk: int = 4_000_000) -> np.ndarray:
    """Generalised winding number of each point w.r.t. a closed triangle mesh (1 inside, 0 outside):
    the solid angles of the triangles (Van Oosterom and Strackee 1983) over 4 pi."""
    out = np.zeros(len(points))
    step = max(1, chunk // max(1, len(tris)))
    for s in range(0, len(points), step):
        a = tris[None, :, 0, :] - points[s:s + step, None, :]
        b = tris[None, :, 1, :] - points[s:s + step, None, :]
        c = tris[None, :, 2, :] - points[s:s + step, None, :]
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum("pfi,pfi->pf", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("pfi,pfi->pf", a, b) * lc + np.einsum("pfi,pfi->pf", b, c) * la
               + np.einsum("pfi,pfi->pf", c, a) * lb)
        out[s:s + step] = 2.0 * np.arctan2(det, den).sum(axis=1) / (4 * math.pi)
    return out


def _penetration(a: trimesh.Trimesh, b: trimesh.Trimesh, n: int = 3000, floor: float = 1e-4,
                 margin: float = 5e-3) -> float:
    """How deep (m) surface points of ``a`` lie inside ``b``: the largest distance to ``b``'s surface
    (python-fcl) of a point that ``b``'s winding number puts inside; 0 when none is deeper than
    ``floor``. The points: ``a``'s vertices and ``n`` seeded surface samples within ``margin`` of
    where the two surfaces cross (python-fcl's triangle contacts) and inside ``b``'s convex hull
    (scipy), tested deepest first: the first inside one is the answer. Surfaces that do not cross:
    0, or inf when ``a`` lies wholly inside ``b``."""
    from scipy.spatial import ConvexHull

    obj_a, obj_b = _fcl(a), _fcl(b)
    res = fcl.CollisionResult()
    if not fcl.collide(obj_a, obj_b, fcl.CollisionRequest(num_max_contacts=1_000_000, enable_contact=True), res):
        return 0.0 if _winding(a.vertices[:1], b.triangles)[0] < 0.5 else math.inf
    cross = np.array([c.pos for c in res.contacts])
    pts = np.concatenate([a.vertices, trimesh.sample.sample_surface(a, n, seed=0)[0]])
    pts = pts[np.all((pts >= cross.min(axis=0) - margin) & (pts <= cross.max(axis=0) + margin), axis=1)]
    eq = ConvexHull(b.vertices).equations
    pts = pts[np.all(pts @ eq[:, :3].T + eq[:, 3] <= 0.0, axis=1)]
    d = np.array([fcl.distance(fcl.CollisionObject(fcl.Sphere(1e-9), fcl.Transform(p)), obj_b,
                               fcl.DistanceRequest()) for p in pts])
    keep = np.flatnonzero(d > floor)
    keep = keep[np.argsort(-d[keep], kind="stable")]
    for s in range(0, len(keep), 64):
        rows = keep[s:s + 64]
        inside = rows[_winding(pts[rows], b.triangles) > 0.5]
        if len(inside):
            return float(d[inside[0]])
    return 0.0


def check_pile(cell, items, scene) -> dict:
    """Assert the pile's promises on every instance; returns the measured numbers."""
    meshes = _world_meshes(items, scene)
    b = cell.bin
    T_bin = np.asarray(b.T_world_bin)
    floor = float(T_bin[2, 3])
    objs = {k: _fcl(m) for k, m in meshes.items()}
    worst_pen, rests = 0.0, {}
    for k, m in meshes.items():
        q = (m.vertices - T_bin[:3, 3]) @ T_bin[:3, :3]
        assert np.abs(q[:, 0]).max() <= b.inner[0] / 2 + INSIDE_TOL, f"{k} beyond the x walls"
        assert np.abs(q[:, 1]).max() <= b.inner[1] / 2 + INSIDE_TOL, f"{k} beyond the y walls"
        assert q[:, 2].min() >= -INSIDE_TOL, f"{k} below the floor's top: {q[:, 2].min()}"
        assert q[:, 2].max() <= b.height + INSIDE_TOL, f"{k} above the walls"
        gap_floor = float(m.vertices[:, 2].min() - floor)
        gap_part = min((fcl.distance(objs[k], objs[j], fcl.DistanceRequest()) for j in meshes if j != k),
                       default=math.inf)
        rests[k] = min(gap_floor, max(gap_part, 0.0))
        assert rests[k] <= REST_TOL, f"{k} floats: {gap_floor * 1e3:.2f} mm above the floor, " \
                                     f"{gap_part * 1e3:.2f} mm from the nearest part"
    for (i, a), (j, c) in itertools.combinations(meshes.items(), 2):
        if np.all(a.bounds[0] <= c.bounds[1]) and np.all(c.bounds[0] <= a.bounds[1]):
            d = max(_penetration(a, c), _penetration(c, a))
            assert d <= PENETRATION_TOL, f"{i} and {j} interpenetrate by {d * 1e3:.2f} mm"
            worst_pen = max(worst_pen, d)
    return {"penetration": worst_pen, "rest": max(rests.values())}


# ------------------------------------------------------------------------------------------------
# the checks check
# ------------------------------------------------------------------------------------------------
def test_independent_checks_catch_floating_penetrating_and_outside_parts(cell, example_pile):
    """The checkers themselves fail on a pile made wrong: a part lifted 40 mm, one moved into
    another, one pushed through the wall (else a pass would mean nothing)."""
    items, res = example_pile
    scene = res.scene
    first = scene.instances[0]
    up = first.T_world_part.copy()
    up[2, 3] += 0.04
    with pytest.raises(AssertionError, match="floats"):
        check_pile(cell, items, scene.with_poses({first.id: up}))
    out = first.T_world_part.copy()
    out[0, 3] = cell.bin.T_world_bin[0, 3] + cell.bin.inner[0] / 2
    with pytest.raises(AssertionError, match="beyond the x walls"):
        check_pile(cell, items, scene.with_poses({first.id: out}))
    box = trimesh.creation.box((0.03, 0.02, 0.01))
    cube = trimesh.creation.box((0.006, 0.006, 0.006))
    cube.apply_translation([0.0, 0.0, 0.005])  # its lower half, 3 mm, inside the box's top
    assert _penetration(cube, box) == pytest.approx(0.003, abs=1e-6)
    cube.apply_translation([0.0, 0.0, 0.0031])
    assert _penetration(cube, box) == 0.0
    assert _penetration(trimesh.creation.box((0.004, 0.004, 0.004)), box) == math.inf  # wholly inside


def test_winding_number_inside_outside():
    box = trimesh.creation.box((0.02, 0.02, 0.02))
    w = _winding(np.array([[0.0, 0, 0], [0.005, 0.009, -0.009], [0.011, 0, 0], [0.0, 0.3, 0]]), box.triangles)
    np.testing.assert_allclose(w, [1, 1, 0, 0], atol=1e-9)


# ------------------------------------------------------------------------------------------------
# drops of the example parts
# ------------------------------------------------------------------------------------------------
def test_example_pile_is_settled_inside_the_bin_resting_and_not_interpenetrating(cell, example_pile):
    items, res = example_pile
    scene = res.scene
    assert [i.id for i in scene.instances] and sorted(i.id for i in scene.instances) == [
        "box_0", "box_1", "bracket_0", "bracket_1", "gear_0"]
    assert scene.cell == "bin" and [p.name for p in scene.parts] == ["box", "bracket", "gear"]
    assert all(p.units == "mm" for p in scene.parts)
    assert all(Path(p.mesh).name == f"{p.name}.stl" for p in scene.parts)
    check_pile(cell, items, scene)
    assert len(res.drops) == 5 and all(0 < d.settle_s < 10 for d in res.drops)
    assert {r["sha256"] for r in res.parts.values()} == {it.part.sha256 for it in items}
    # released above the pile: every release pose lies above the floor by at least the gap
    for d, it in zip(res.drops, scene.instances):
        assert d.id == it.id


def test_drop_is_deterministic_for_a_seed_and_differs_for_another(cell, example_pile):
    items, res = example_pile
    again = drop_pile(cell, _example_items(), params=DropParams(seed=0))
    assert [i.id for i in again.scene.instances] == [i.id for i in res.scene.instances]
    for a, b in zip(res.scene.instances, again.scene.instances):
        assert np.array_equal(a.T_world_part, b.T_world_part), a.id
    other = drop_pile(cell, _example_items(), params=DropParams(seed=1))
    T0 = {i.id: i.T_world_part for i in res.scene.instances}
    moved = [np.abs(i.T_world_part[:3, 3] - T0[i.id][:3, 3]).max() for i in other.scene.instances]
    assert max(moved) > 0.01
    check_pile(cell, items, other.scene)


def test_written_scene_reads_back_equal(tmp_path, cell, example_pile):
    _, res = example_pile
    for name in ("pile.yaml", "sub/pile.json"):
        out = tmp_path / name
        written = write_scene(out, res.scene, header=["made by a test"])
        back = load_scene(out)
        assert back.cell == res.scene.cell and back.ids == res.scene.ids
        assert all(a == b for a, b in zip(back.instances, res.scene.instances))  # exact poses
        for p, q in zip(back.parts, res.scene.parts):
            assert (p.name, p.units) == (q.name, q.units)
            assert back.resolve(p.mesh).resolve() == Path(q.mesh).resolve()
        assert [p.mesh for p in back.parts] == [p.mesh for p in written.parts]
    # a folder sharing more than the root with the meshes gets relative paths
    near = EXAMPLES.parent / "_drop_test_tmp"
    try:
        w = write_scene(near / "s.yaml", res.scene)
        assert all(p.mesh == f"../parts/{p.name}.stl" for p in w.parts)
        assert load_scene(near / "s.yaml").resolve(w.parts[0].mesh).resolve() == (EXAMPLES / "box.stl").resolve()
    finally:
        for f in near.glob("*"):
            f.unlink()
        if near.exists():
            near.rmdir()


def test_part_frame_is_the_mesh_frame_not_the_inertial_frame(cell):
    """MuJoCo's geom centres (each convex piece's centroid) sit where the pose read by the world
    puts the part's pieces: the pose is the mesh frame's, not the centre of mass frame's."""
    from grasplan.geometry.meshdata import convex_hull

    part = load_part(EXAMPLES / "bracket.stl")
    body = part_body("b", part.mesh, density=1200.0)
    assert np.linalg.norm(body.mass.com) > 0.005  # the mesh origin is far from the centre of mass
    world = PileWorld(cell, [body], mu=0.3)
    T = np.eye(4)
    T[:3, :3] = trimesh.transformations.rotation_matrix(0.7, [1, 2, 3])[:3, :3]
    T[:3, 3] = [0.45, 0.0, 0.08]
    world.place(0, T)
    np.testing.assert_allclose(world.pose(0), T, atol=1e-12)
    world.settle(lin=0.005, ang=0.05, hold=0.2, max_s=5.0)
    T1 = world.pose(0)
    geoms = np.flatnonzero(world.model.geom_bodyid == world.model.body("b").id)
    centres = np.array([convex_hull(p).center_mass for p in body.pieces])
    np.testing.assert_allclose(world.data.geom_xpos[geoms], centres @ T1[:3, :3].T + T1[:3, 3], atol=1e-9)
    hull = body.hull @ T1[:3, :3].T + T1[:3, 3]
    assert abs(hull[:, 2].min() - cell.bin.T_world_bin[2, 3]) < 2e-4  # resting on the floor
    world.park(0)
    assert world.pose(0)[2, 3] < -1.0 and not world.present[0]


def test_outside_bin_measures_the_worst_side(cell):
    c = np.asarray(cell.bin.T_world_bin)[:3, 3]
    pts = c + np.array([[0.0, 0.0, 0.0], [0.152, 0.0, 0.05]])
    by, where = outside_bin(cell, pts)
    assert by == pytest.approx(0.002) and "x" in where
    by, where = outside_bin(cell, c + np.array([[0.0, 0.0, -0.003], [0.0, 0.0, 0.16]]))
    assert by == pytest.approx(0.01) and where == "above the walls"
    assert outside_bin(cell, c + np.array([[0.0, 0.0, 0.01]]))[1] == ""


def test_a_pile_that_does_not_fit_is_refused_before_simulating(cell):
    gear = load_part(EXAMPLES / "gear.stl")
    with pytest.raises(PileError, match=r"convex hulls take .* of the bin's inner volume"):
        drop_pile(cell, [PileItem("gear", gear, 500)])
    huge = load_part(EXAMPLES / "box.stl", units="cm")  # 300 x 200 x 100 mm
    with pytest.raises(PileError, match=r"does not fit in the bin \(300 x 200 mm inside, walls 150 mm high\)"):
        drop_pile(cell, [PileItem("box", huge, 1)])
    with pytest.raises(InputError, match="has no bin"):
        drop_pile(load_cell("table"), [PileItem("gear", gear, 1)])


SMALL_BIN = ("name: small_bin\nbin: {inner: [%g, %g], wall: 0.005, height: 0.02, "
             "T: {xyz: [0.45, 0.0, 0.005]}}\n")


def test_a_failed_drop_is_undone_and_tried_again(tmp_path):
    """In a 60 x 50 mm bin with 20 mm walls a 30 x 20 x 10 mm box may come to rest on its end (30 mm
    high, over the rim): that drop is undone and tried again; the pile is still deterministic."""
    small = tmp_path / "small_bin.yaml"
    small.write_text(SMALL_BIN % (0.06, 0.05))
    cell = load_cell(small)
    items = [PileItem("box", load_part(EXAMPLES / "box.stl"), 2)]
    a = drop_pile(cell, items, params=DropParams(seed=0))
    assert max(d.attempts for d in a.drops) > 1  # (seed 0 does retry: the test would be void otherwise)
    check_pile(cell, items, a.scene)
    b = drop_pile(cell, items, params=DropParams(seed=0))
    assert all(x == y for x, y in zip(a.scene.instances, b.scene.instances))


def test_a_pile_overflowing_a_small_bin_is_refused_after_settling(tmp_path):
    """3 boxes (30 x 20 x 10 mm) in a 50 x 40 mm bin with 20 mm walls: at most two fit lying flat."""
    small = tmp_path / "small_bin.yaml"
    small.write_text(SMALL_BIN % (0.05, 0.04))
    with pytest.raises(PileError, match=r"from 5 random poses, the last left box_\d [\d.]+ mm (above|beyond) the walls"):
        drop_pile(load_cell(small), [PileItem("box", load_part(EXAMPLES / "box.stl"), 3)])


def test_a_pile_that_does_not_come_to_rest_is_an_error(cell, monkeypatch):
    import grasplan.sim.drop as drop

    monkeypatch.setattr(drop, "MAX_SETTLE_S", 0.05)
    with pytest.raises(SettleError, match=r"did not come to rest within 0.05 s: dropping box_0 .* left box_0 moving at"):
        drop_pile(cell, [PileItem("box", load_part(EXAMPLES / "box.stl"), 1)])


def test_part_names():
    assert part_name("x/TLess20.stl") == "TLess20"
    assert part_name("a b(1).STL") == "a_b_1_"
    assert part_name("-x.stl") == "_-x"


# ------------------------------------------------------------------------------------------------
# the command
# ------------------------------------------------------------------------------------------------
def _cli(*args):
    return CliRunner().invoke(main, ["scene", "drop", *map(str, args)])


def test_cli_writes_the_scene(tmp_path):
    out = tmp_path / "pile.yaml"
    r = _cli("--part", f"{EXAMPLES / 'box.stl'}:2", "--part", f"{EXAMPLES / 'gear.stl'}:1", "--seed", 3, "-o", out)
    assert r.exit_code == 0, r.output
    assert "drop 3/3" in r.stderr and "wrote" in r.stdout
    scene = load_scene(out)
    assert sorted(scene.ids) == ["box_0", "box_1", "gear_0"]
    text = out.read_text()
    assert load_part(EXAMPLES / "box.stl").sha256 in text and "seed 3" in text.splitlines()[0]
    same = drop_pile(load_cell("bin"), _items([(EXAMPLES / "box.stl", 2), (EXAMPLES / "gear.stl", 1)]),
                     params=DropParams(seed=3))
    assert all(a == b for a, b in zip(scene.instances, same.scene.instances))
    again = tmp_path / "again.yaml"
    r = _cli("--part", f"{EXAMPLES / 'box.stl'}:2", "--part", f"{EXAMPLES / 'gear.stl'}:1", "--seed", 3, "-o", again)
    assert r.exit_code == 0 and again.read_bytes() == text.encode()


@pytest.mark.parametrize("args, match", [
    (("--part", "{box}"), "expected PATH:COUNT"),
    (("--part", "{box}:two"), "not a whole number"),
    (("--part", "{box}:0"), "count must be 1"),
    (("--part", "missing.stl:2"), "missing.stl"),
    (("--part", "{box}:1", "--cell", "nosuchcell"), "unknown cell 'nosuchcell'"),
    (("--part", "{box}:1", "--cell", "table"), "has no bin"),
    (("--part", "{gear}:500"), "does not fit the bin"),
    (("--part", "{box}:1", "--units", "cm"), "does not fit in the bin"),
    (("--part", "{box}:1", "--part", "{box}:2"), "given twice"),
    (("--part", "{box}:1", "--part", "{other_box}:2"), "both give part name 'box'"),
    (("--part", "{box}:1", "--density", "-3"), "density"),
])
def test_cli_refuses_bad_input_with_exit_3_and_writes_nothing(tmp_path, args, match):
    out = tmp_path / "pile.yaml"
    other = tmp_path.parent / f"{tmp_path.name}-other" / "box.stl"  # outside tmp_path: nothing written there
    other.parent.mkdir(exist_ok=True)
    other.write_bytes((EXAMPLES / "gear.stl").read_bytes())
    args = [a.format(box=EXAMPLES / "box.stl", gear=EXAMPLES / "gear.stl", other_box=other) for a in args]
    r = _cli(*args, "-o", out)
    assert r.exit_code == 3, r.output
    assert match in r.stderr and "Traceback" not in r.output
    assert not out.exists() and not list(tmp_path.iterdir())


def test_cli_refuses_other_suffixes(tmp_path):
    r = _cli("--part", f"{EXAMPLES / 'box.stl'}:1", "-o", tmp_path / "pile.txt")
    assert r.exit_code == 3 and "*.yaml, *.yml or *.json" in r.stderr


# ------------------------------------------------------------------------------------------------
# the paper parts
# ------------------------------------------------------------------------------------------------
@pytest.mark.paper
@pytest.mark.slow
def test_mixed_paper_pile(paper, cell):
    items = _items([(paper(n), 1) for n in PAPER_PILE])
    res = drop_pile(cell, items, params=DropParams(seed=0))
    assert len(res.scene.instances) == 5
    measured = check_pile(cell, items, res.scene)
    assert measured["penetration"] <= PENETRATION_TOL


DROP_OPTIONS = [p for p in __import__("grasplan.cli.scene", fromlist=["drop"]).drop.params
                if p.name != "output" and not getattr(p, "is_flag", False)]


@pytest.mark.parametrize("opt", DROP_OPTIONS, ids=[o.opts[0] for o in DROP_OPTIONS])
def test_cli_bad_option_values_exit_2_or_3_naming_the_problem(opt, tmp_path):
    """As tests/test_cli_options.py does for every top-level command (it does not walk groups)."""
    import re

    leaks = re.compile(r"Traceback|KeyError|IndexError|ValueError|TypeError|AttributeError|internal error")
    for value in ("0", "-1", "nan", "inf", "1e308", "-1e308", "x!", "", "1e-300", "9" * 400):
        args = ["--part", f"{tmp_path / 'missing_input.stl'}:1", opt.opts[0], value, "-o", tmp_path / "out.yaml"]
        r = _cli(*args)
        assert r.exit_code in (2, 3), (args, r.exit_code, r.output[-500:])
        assert not leaks.search(r.output), (args, r.output[-800:])
        assert any(o in r.output for o in opt.opts) or opt.name in r.output or "missing_input" in r.output, (
            args, r.output[-500:])
        assert not list(tmp_path.glob("out*")), args


def test_the_cells_other_obstacles_are_in_the_world(tmp_path):
    """A post (cylinder) and a block (mesh file) standing in the bin: a box dropped on each rests on it."""
    import shutil

    shutil.copy(EXAMPLES / "box.stl", tmp_path / "block.stl")  # 30 x 20 x 10 mm; its bounds place it on the floor
    block = load_part(tmp_path / "block.stl").mesh
    lo, hi = block.bounds
    (tmp_path / "c.yaml").write_text(
        "name: c\nbin: {inner: [0.30, 0.20], wall: 0.01, height: 0.15, T: {xyz: [0.45, 0.0, 0.01]}}\n"
        "obstacles:\n"
        "  - {name: post, cylinder: {radius: 0.02, length: 0.05}, T: {xyz: [0.40, 0.0, 0.035]}}\n"
        f"  - {{name: block, mesh: {{path: block.stl, scale: 0.001}}, T: {{xyz: [0.52, 0.0, {0.01 - lo[2]:.6f}]}}}}\n")
    cell = load_cell(tmp_path / "c.yaml")
    box = part_body("box", load_part(EXAMPLES / "box.stl").mesh, density=1200.0)
    other = part_body("box2", load_part(EXAMPLES / "box.stl").mesh, density=1200.0)
    world = PileWorld(cell, [box, other], mu=0.3)
    for i, (x, top) in enumerate([(0.40, 0.06), (0.52, 0.01 + hi[2] - lo[2])]):
        T = np.eye(4)
        T[:3, 3] = [x, 0.0, top + 0.01 - box.hull[:, 2].min()]
        world.place(i, T)
    s = world.settle(lin=0.005, ang=0.05, hold=0.2, max_s=5.0)
    assert s.at_rest
    assert world.hull_world(0)[:, 2].min() == pytest.approx(0.06, abs=5e-4)  # on the post's top
    assert world.hull_world(1)[:, 2].min() == pytest.approx(0.01 + hi[2] - lo[2], abs=5e-4)  # on the block
