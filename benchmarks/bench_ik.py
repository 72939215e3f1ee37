"""IK and collision-check speed: `python benchmarks/bench_ik.py` prints medians per call, the
ratio of the UR5 closed-form median to its target and the process's peak RSS.

Targets (issue 4): IK < 1 ms per solve on the UR5's closed-form path.
"""
from __future__ import annotations

import resource
import time
from pathlib import Path

import numpy as np

from grasplan.cell.model import load_cell
from grasplan.gripper.load import load_gripper
from grasplan.robot.ik.solve import solve_ik
from grasplan.part.mesh import load_part
from grasplan.robot.description import load_robot
from grasplan.motion.collision_scene import CollisionScene
from grasplan.cell.resting import stable_pose

ROOT = Path(__file__).resolve().parents[1]
TARGET_IK_MS = 1.0  #: UR5 closed-form solve, median ms


def _ik_rows(name, method, n, **kw):
    r = load_robot(name)
    rng = np.random.default_rng(0)
    Q = rng.uniform(r.lower, r.upper, size=(n, r.nq))
    Ts = [r.fk(q) for q in Q]
    solve_ik(r, Ts[0], method=method, **kw)  # warm up (solver construction)
    times, ok = [], 0
    for T in Ts:
        t = time.perf_counter()
        res = solve_ik(r, T, method=method, **kw)
        times.append(time.perf_counter() - t)
        ok += res.ok
    extra = ",".join(f"{k}={v}" for k, v in kw.items())
    return (f"{name} {method}" + (f" ({extra})" if extra else ""), n, 100.0 * ok / n, 1e3 * float(np.median(times)))


def main() -> None:
    rows = [_ik_rows("ur5", "analytic", 2000),
            _ik_rows("ur5", "clik", 200, max_solutions=1),
            _ik_rows("ur5", "clik", 50),
            _ik_rows("panda", "clik", 200, max_solutions=1),
            _ik_rows("panda", "clik", 50),
            # issue 23: the UR family's one closed form on the other arms, the xArm7 by CLIK
            _ik_rows("ur3", "analytic", 1000),
            _ik_rows("ur10", "analytic", 1000),
            _ik_rows("xarm7", "clik", 200, max_solutions=1)]
    print(f"{'IK':42s} {'n':>6s} {'success %':>10s} {'median ms':>10s}")
    for label, n, succ, med in rows:
        print(f"{label:42s} {n:6d} {succ:10.1f} {med:10.3f}")
    med = rows[0][3]
    print(f"UR5 closed-form target < {TARGET_IK_MS:g} ms: {'PASS' if med < TARGET_IK_MS else 'FAIL'} "
          f"({med:.3f} ms, {med / TARGET_IK_MS:.2f} x target)")

    part = load_part(ROOT / "examples" / "parts" / "bracket.stl", units="mm")
    cell, gripper = load_cell(), load_gripper()
    T_wp = stable_pose(part.mesh, cell)
    print(f"\n{'collision check (bracket, table, gripper)':42s} {'free %':>10s} {'free ms':>10s} {'any ms':>10s}")
    for name in ("ur5", "panda", "ur10", "xarm7"):
        r = load_robot(name)
        t = time.perf_counter()
        scene = CollisionScene(r, gripper, part.mesh, T_wp, cell)
        t_build = time.perf_counter() - t
        rng = np.random.default_rng(1)
        Q = rng.uniform(r.lower, r.upper, size=(3000, r.nq))
        t_any, free = [], []
        for q in Q:
            t = time.perf_counter()
            f = scene.is_free(q, 0.03)
            t_any.append(time.perf_counter() - t)
            free.append(f)
        free = np.array(free)
        t_free = np.array(t_any)[free]
        print(f"{name + f' (scene built in {1e3 * t_build:.1f} ms)':42s} {100 * free.mean():10.1f} "
              f"{1e3 * np.median(t_free):10.3f} {1e3 * np.median(t_any):10.3f}")
    print(f"\npeak RSS: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()
