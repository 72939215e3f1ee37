"""Benchmarks of the planning stage: RRTConnect per query and the whole ``plan`` per part.

    python benchmarks/bench_plan.py [--parts TLess20.stl,SileanePepper.stl,...] [--queries 30]

1. RRTConnect: the UR5 in the table cell with TLess20 (or the example bracket) at its stable pose;
   goals are collision-free IK solutions of random reachable TCP poses above the table (pointing
   down) and random collision-free configurations (joints within +-pi, flange above 0.1 m); ``plan_joint_path(q_home -> goal)`` per query (verification included). Reported for all
   queries and for those whose straight segment is blocked (where RRTConnect really runs).
2. ``grasplan.plan(part, "ur5", planning=PlanParams(top=20, seed=0))`` per part (paper parts when
   present, else the examples), with the triangle count, the planned count, the ratio of the total
   to the 10 s target (< 10 s for a 5k-triangle part) and the process's peak RSS.
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
PAPER = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
TARGET_PLAN_S = 10.0  #: plan() of a 5k-triangle part, s


def _table(rows, header):
    from grasplan.cli.common import table

    return table(rows, header)


def bench_rrt(n_queries: int, seed: int = 0):
    from grasplan.cell import load_cell, stable_pose
    from grasplan.gripper import load_gripper
    from grasplan.ik import solve_ik
    from grasplan.mesh import load_part
    from grasplan.paths import plan_joint_path
    from grasplan.robot import load_robot
    from grasplan.scene import CollisionScene

    part_path = PAPER / "TLess20.stl"
    if not part_path.exists():
        part_path = ROOT / "examples" / "parts" / "bracket.stl"
    part = load_part(part_path)
    robot, gripper, cell = load_robot("ur5"), load_gripper(), load_cell()
    T_world_part = stable_pose(part.mesh, cell)
    scene = CollisionScene(robot, gripper, part.mesh, T_world_part, cell)
    rng = np.random.default_rng(seed)
    T_tcp_flange = np.linalg.inv(gripper.T_flange_tcp)
    goals = []
    tries = 0
    while len(goals) < n_queries and tries < 50 * n_queries:
        tries += 1
        T = np.eye(4)
        T[:3, 3] = [rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6), rng.uniform(0.05, 0.5)]
        if np.linalg.norm(T[:2, 3]) < 0.25:
            continue
        a = rng.uniform(0, 2 * np.pi)
        # TCP z pointing down, x rotated by a
        T[:3, :3] = np.array([[np.cos(a), np.sin(a), 0], [np.sin(a), -np.cos(a), 0], [0, 0, -1]])
        sols = solve_ik(robot, T @ T_tcp_flange).q
        if len(sols) and scene.is_free(sols[0], 0.03):
            goals.append(sols[0])
    # plus random free configurations (joint 2/3 within +-pi): many straight segments from home
    # to these cross the table or the robot itself, which is where RRTConnect really works
    tries = 0
    n_pose_goals = len(goals)
    while len(goals) < n_pose_goals + n_queries and tries < 100 * n_queries:
        tries += 1
        q = rng.uniform(np.maximum(robot.lower, -np.pi), np.minimum(robot.upper, np.pi))
        if scene.is_free(q, 0.03) and robot.fk(q)[2, 3] > 0.1:
            goals.append(q)
    times, times_blocked, fails = [], [], 0
    for k, q in enumerate(goals):
        blocked = not scene.path_free(np.stack([robot.q_home, q]), 0.03)
        t = time.perf_counter()
        p = plan_joint_path(scene, robot.q_home, q, opening=0.03, seed=k, time_limit=1.0)
        dt = time.perf_counter() - t
        if p is None:
            fails += 1
            continue
        times.append(dt)
        if blocked:
            times_blocked.append(dt)
    rows = [("all queries", len(times), 1e3 * statistics.median(times) if times else float("nan")),
            ("straight segment blocked", len(times_blocked),
             1e3 * statistics.median(times_blocked) if times_blocked else float("nan"))]
    print(f"RRTConnect q_home -> random free goal (UR5, {part_path.name} on the table, verified at 0.01 rad); "
          f"{len(goals)} queries, failures: {fails}")
    print(_table(rows, ("queries", "n", "median ms")))
    print(f"peak RSS: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")
    return rows


def bench_plan(parts: list[Path]):
    from grasplan.mesh import load_part
    from grasplan.params import PlanParams
    from grasplan.planning import plan

    params = PlanParams(top=20, seed=0)
    rows = []
    for path in parts:
        t = time.perf_counter()
        part = load_part(path)
        res = plan(part, robot="ur5", planning=params)
        dt = time.perf_counter() - t
        c = res.counts()
        # the grasp stage: candidates (its sub-stages blm, convexity, antipodal are inside it), the
        # stable pose, TCP frames and the collision filter
        g = res.grasp_result.timing_s
        grasp_s = sum(float(g.get(k, 0.0)) for k in ("candidates", "stable_pose", "frames", "collision"))
        rss_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KiB
        rows.append((path.name, part.triangles, c["planned"], c["grasps"], grasp_s,
                     float(res.timing_s["plan"]), dt, dt / TARGET_PLAN_S, rss_mib))
        print(f"  {path.name}: {dt:.1f} s", file=sys.stderr)
    print(f"grasplan.plan(part, 'ur5', planning=PlanParams(top={params.top}, seed={params.seed})); "
          f"target total < {TARGET_PLAN_S:g} s (5k triangles); peak RSS is the process's high-water mark so far")
    print(_table(rows, ("part", "triangles", "planned", "grasp poses", "grasp stage s", "planning s", "total s",
                        "total / target", "peak RSS MiB")))
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--parts", default="TLess20.stl,SileanePepper.stl,IPAGearShaft.stl",
                    help="comma-separated paper parts (falls back to examples/parts when absent)")
    ap.add_argument("--queries", type=int, default=30)
    args = ap.parse_args()
    bench_rrt(args.queries)
    parts = [PAPER / p for p in args.parts.split(",") if (PAPER / p).exists()]
    if not parts:
        parts = sorted((ROOT / "examples" / "parts").glob("*.stl"))
    bench_plan(parts)


if __name__ == "__main__":
    main()
