"""``lift_carry`` (docs/pick.md, the lift): a part whose every lift pushes into a neighbour lying on
it is picked when that neighbour is free to rise (the lift raises it: it is not dragged through),
the pick names it (``lift_carries``), and it is refused when something holds the neighbour down.
Every pick re-checked independently (tests/pick_recheck.py: python-fcl, trimesh depths), the
neighbour's freedom to rise included."""
from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from pick_recheck import recheck_pick, rises_freely  # noqa: E402

from grasplan.cell.model import load_cell  # noqa: E402
from grasplan.part.mesh import load_part  # noqa: E402
from grasplan.pick import Picker, PickParams  # noqa: E402
from grasplan.pick.reader import load_picks  # noqa: E402
from grasplan.piles.scene_file import Instance, Scene  # noqa: E402
from grasplan.cell.resting import stable_pose  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BOX = ROOT / "examples" / "parts" / "box.stl"
NOISE = 0.0002  # each box 0.2 mm into the one under it (pose estimates)


def _extent(mesh, T):
    w = np.asarray(mesh.vertices) @ T[:3, :3].T + T[:3, 3]
    return w.min(axis=0), w.max(axis=0)


def _placed(mesh, T_rest, turn_deg: float, lo_xy, z0: float) -> np.ndarray:
    """``T_rest`` turned about world z and moved so that the part's box starts at ``lo_xy`` and its
    bottom is at ``z0``."""
    c, s = np.cos(np.radians(turn_deg)), np.sin(np.radians(turn_deg))
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T = T @ T_rest
    lo, _ = _extent(mesh, T)
    T[:3, 3] += np.array([lo_xy[0], lo_xy[1], z0]) - lo
    return T


@pytest.fixture(scope="module")
def pile():
    """Box a (30 x 20 x 10 mm) flat on the bin floor; box b turned 90 deg lying across a's +x end
    (on a's top from 12 mm before its end, overhanging it by 8 mm: its centre of mass over a), so
    every lift of a, straight or tilted, pushes into b; c, a third box, lies on b's far end."""
    box = load_part(BOX)
    rest = stable_pose(box.mesh, load_cell("bin"))
    lo, hi = _extent(box.mesh, rest)
    a = rest
    b = _placed(box.mesh, rest, 90.0, (hi[0] - 0.012, -0.015), hi[2] - NOISE)
    lo_b, hi_b = _extent(box.mesh, b)
    c = _placed(box.mesh, rest, 0.0, (lo_b[0] + 0.002, -0.010), hi_b[2] - NOISE)
    return box, a, b, c


def _picker(box, **kw):
    pk = Picker("ur5", gripper="long_stroke_50", params=PickParams(grasps_per_instance=8, **kw))
    pk.add_part("box", box)
    return pk


def test_a_neighbour_lying_on_the_part_is_raised_by_its_lift(pile, tmp_path):
    box, a, b, _ = pile
    sc = Scene(instances=(Instance("a", "box", a), Instance("b", "box", b)), cell="bin")
    # without lift_carry a is blocked by b: every lift drags it into b
    strict = _picker(box, lift_carry=False).plan(sc).report("a")
    assert strict.status == "blocked" and strict.blocked_by == ("b",), strict
    pk = _picker(box)
    res = pk.plan(sc)
    assert [q.instance for q in res.picks] == ["b", "a"]  # the part on top first
    rep = res.report("a")
    assert rep.status == "picked" and "the lift raises b lying on it" in rep.reason, rep
    pick = res.pick("a")
    assert pick.carries == ("b",) and res.pick("b").carries == ()
    lift = pick.T_world_lifted[:3, 3] - pick.T_world_tcp[:3, 3]
    np.testing.assert_allclose(lift / np.linalg.norm(lift), [0, 0, 1], atol=1e-9)  # the straight lift, raising b
    # independently: b is free to rise (python-fcl), and a touches nothing else along the lift
    meshes = {"box": box.mesh}
    rc = recheck_pick(pk.robot, pk.gripper, res.cell, pick, sc.instances, meshes,
                      lift_contact=res.params.lift_contact, lift_depth=res.params.lift_depth,
                      rest_cap=res.params.overlap_tol)
    assert rc.ok, rc.problems
    # the same pick without b named as raised fails the re-check: the lift does push into b
    rc_no = recheck_pick(pk.robot, pk.gripper, res.cell, replace(pick, carries=()), sc.instances, meshes,
                         lift_contact=res.params.lift_contact, lift_depth=res.params.lift_depth,
                         rest_cap=res.params.overlap_tol)
    assert not rc_no.ok and "instance_b" in rc_no.problems[0], rc_no.problems
    # the picks file names it and reads back
    out = res.write(tmp_path / "picks.json")
    doc = json.loads(out.read_text())
    assert [p["lift_carries"] for p in doc["picks"]] == [[], ["b"]]
    back = load_picks(out)
    assert back.pick("a").carries == ("b",)
    # a file naming an instance that is not another one of the scene is refused, naming the field
    from grasplan.errors import InputError

    for bad in (["zz"], ["a"]):
        doc["picks"][1]["lift_carries"] = bad
        (tmp_path / "bad.json").write_text(json.dumps(doc))
        with pytest.raises(InputError, match=r"picks\[1\]: lift_carries names"):
            load_picks(tmp_path / "bad.json")
    # a robot program and the viewer of that pick
    from click.testing import CliRunner

    from grasplan.cli import main

    for args in (["export", str(out), "--format", "urscript", "--instance", "a", "-o", str(tmp_path / "a.script")],
                 ["view", str(out), "--instance", "a", "-o", str(tmp_path / "a.html")]):
        r = CliRunner().invoke(main, args)
        assert r.exit_code == 0, r.output
    assert "movel" in (tmp_path / "a.script").read_text()


def test_a_neighbour_held_down_is_not_raised(pile):
    box, a, b, c = pile
    sc = Scene(instances=(Instance("a", "box", a), Instance("b", "box", b), Instance("c", "box", c)), cell="bin")
    meshes = {"box": box.mesh}
    cell = load_cell("bin")
    up = np.asarray(cell.retreat_direction, dtype=np.float64)
    kw = dict(up=up, dist=cell.retreat_distance, lift_contact=0.002, lift_depth=0.001, rest_cap=0.002)
    # the independent check agrees: c holds b down, nothing holds c
    assert "c" in rises_freely(sc.instances[1], sc.instances, meshes, **kw)
    assert rises_freely(sc.instances[2], sc.instances, meshes, **kw) == ""
    res = _picker(box).plan(sc)
    rep = res.report("a")
    assert rep.status == "blocked" and "b" in rep.blocked_by, rep
    assert "raising what lies on it or not" in rep.reason, rep.reason
    assert all("a" not in q.carries for q in res.picks)
