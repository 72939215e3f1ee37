"""grasplan pick with a gripper whose TCP moves with the opening (parallel_linkage: Robotiq 2F-85):
the grasp TCP is moved to the frame the gripper's shapes are given in (as grasplan plan does), and
every pick is re-checked by python-fcl and by forward kinematics at the grasp width."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from pick_recheck import recheck_pick  # noqa: E402

from grasplan.cell.model import load_cell  # noqa: E402
from grasplan.part.mesh import load_part  # noqa: E402
from grasplan.pick import Picker, PickParams  # noqa: E402
from grasplan.piles.scene_file import Instance, Scene  # noqa: E402
from grasplan.cell.resting import stable_pose  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BRACKET = ROOT / "examples" / "parts" / "bracket.stl"


@pytest.fixture(scope="module")
def setup():
    part = load_part(BRACKET)
    pk = Picker("ur5", gripper="robotiq_2f_85", params=PickParams(grasps_per_instance=8))
    pk.add_part("bracket", part)
    return pk, part, stable_pose(part.mesh, load_cell("bin"))


def test_linkage_gripper_picks_with_the_tcp_at_the_grasp_width(setup):
    pk, part, rest = setup
    assert pk.gripper.moving_tcp
    b = np.array(rest)
    b[0, 3] += 0.09
    sc = Scene(instances=(Instance("a", "bracket", rest), Instance("b", "bracket", b)), cell="bin")
    res = pk.plan(sc)
    assert res.picks, [r.reason for r in res.instances]
    for p in res.picks:
        # FK at the grasp puts the TCP between the contacts: T_flange_tcp_at(width), not T_flange_tcp
        T_fk = pk.robot.fk(p.motion.q_grasp) @ pk.gripper.T_flange_tcp_at(p.width)
        np.testing.assert_allclose(T_fk, p.T_world_tcp, atol=2e-4)
        off = float(pk.gripper.tcp_offset(p.width))
        assert abs(off) > 1e-3  # the linkage really moves the TCP at this width (the test can fail)
        T_fixed = pk.robot.fk(p.motion.q_grasp) @ pk.gripper.T_flange_tcp
        assert np.linalg.norm(T_fixed[:3, 3] - p.T_world_tcp[:3, 3]) > 0.5 * abs(off)
        rep = recheck_pick(pk.robot, pk.gripper, res.cell, p, sc.instances, {"bracket": part.mesh},
                           lift_contact=res.params.lift_contact, lift_depth=res.params.lift_depth)
        assert rep.ok, (p.instance, rep.problems)
    # the picks file round-trips: its reader re-checks every motion by FK at the grasp width
    import json

    from grasplan.pick.reader import result_from_picks

    back = result_from_picks(json.loads(json.dumps(res.to_json())))
    np.testing.assert_allclose(back.picks[0].T_world_tcp, res.picks[0].T_world_tcp, atol=1e-9)
