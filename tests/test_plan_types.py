"""The typed hand-offs of planning: the run's option sets (RunParams), one resting pose's plan or
error (PosePlan), and the progress events a plan reports (GraspStageDone, GraspTried)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from grasplan.config.params import CandidateParams, GraspParams, PlanParams, RunParams
from grasplan.errors import InputError
from grasplan.results.pose_plans import PosePlan, write_pose_plans


# -- RunParams -----------------------------------------------------------------------------------------
def test_run_params_pop_their_options_and_leave_the_rest():
    kwargs = {"top": 3, "spacing": 0.004, "roll_step_deg": 30.0, "place": None, "output": "x.json", "units": "mm"}
    run = RunParams.from_options(kwargs)
    assert kwargs == {"output": "x.json", "units": "mm"}
    assert run.planning == PlanParams(top=3) and run.candidates == CandidateParams(spacing=0.004)
    assert run.grasps == GraspParams(roll_step_deg=30.0)


def test_run_params_build_only_the_sets_asked_for():
    kwargs = {"spacing": 0.004, "top": 3}
    run = RunParams.from_options(kwargs, (CandidateParams,))
    assert run.candidates.spacing == 0.004 and run.planning == PlanParams() and kwargs == {"top": 3}
    with pytest.raises(InputError, match=r"--top \(top\)"):
        RunParams.from_options({"top": 0})
    with pytest.raises(dataclasses.FrozenInstanceError):
        run.candidates = CandidateParams()  # type: ignore[misc]


# -- PosePlan ------------------------------------------------------------------------------------------
def test_pose_plan_holds_a_result_or_an_error():
    with pytest.raises(ValueError, match="exactly one"):
        PosePlan(0, 0.5)
    p = PosePlan(1, 0.25, error="the part is inside an obstacle")
    assert p.result is None and p.error.startswith("the part")


def test_pose_plans_that_all_failed_write_nothing_and_say_why(tmp_path):
    runs = [PosePlan(0, 0.6, error="part inside the wall"), PosePlan(2, 0.1, error="base inside the box")]
    done = write_pose_plans(runs, tmp_path / "out.json", min_probability=0.02)
    assert done.result is None and done.chosen is None and done.planned == 0
    assert not list(tmp_path.iterdir())
    assert [r[0] for r in done.table_rows()] == [0, 2] and done.table_rows()[1][-1] == "base inside the box"
    msg = str(done.error("plate.stl"))
    assert "pose 0: part inside the wall" in msg and "pose 2: base inside the box" in msg


def test_plan_poses_gives_each_pose_its_result_or_its_error(example_part):
    from grasplan.motion.planning import plan_poses, stable_pose_indices
    from grasplan.part.mesh import load_part

    part = load_part(example_part("gear.stl"), units="mm")
    planning = PlanParams(top=1)
    runs = plan_poses(part, "ur5", planning=planning)
    assert [(r.index, r.probability) for r in runs] == stable_pose_indices(part.mesh)
    assert len(runs) >= 2 and all(r.error is None and r.result is not None for r in runs)
    assert all(r.result.params.grasps.pose_index == r.index for r in runs)
    # a place in the table fails every pose's checks before planning: each gets the message
    T_in_table = np.eye(4)
    T_in_table[:3, 3] = (0.45, 0.3, -0.02)
    failed = plan_poses(part, "ur5", planning=planning, place=T_in_table)
    assert [r.index for r in failed] == [r.index for r in runs]
    assert all(r.result is None and "place" in r.error for r in failed)
    with pytest.raises(InputError, match="--part-pose"):
        plan_poses(part, "ur5", T_world_part=np.eye(4))


# -- progress events -----------------------------------------------------------------------------------
def test_plan_reports_the_grasp_stage_then_every_tried_grasp(example_part):
    from grasplan.motion.planning import GraspDatabaseNote, GraspStageDone, GraspTried, plan

    events: list = []
    res = plan(example_part("bracket.stl"), "ur5", units="mm", planning=PlanParams(top=2), progress=events.append)
    events = [e for e in events if not isinstance(e, GraspDatabaseNote)]  # only when the database is computed
    assert isinstance(events[0], GraspStageDone) and all(isinstance(e, GraspTried) for e in events[1:])
    counts = res.counts()
    assert events[0].counts["ok"] == counts["grasps"] - sum(
        counts[s] for s in ("collision_part", "collision_table", "collision_obstacle"))
    tried = events[1:]
    assert [e.tried for e in tried] == list(range(1, len(tried) + 1))
    assert tried[-1].planned == counts["planned"] == 2
    assert all(e.top == 2 and e.candidates == events[0].counts["ok"] for e in tried)
    status = res.grasps.status.astype(str)
    assert [status[res.grasps.index_of(e.grasp_id)] for e in tried] == [e.status.value for e in tried]
    assert sum(e.status.value == "planned" for e in tried) == 2
