"""The whole grasplan pipeline from Python: plan a part for a UR5, then write every export format.

Run:  python examples/api_example.py [PART] [-o OUT_DIR] [--top K]
(default part: examples/parts/bracket.stl, default output folder: out/api_example)

Steps:
1. ``load_part`` reads the mesh (units decided from its size: the example parts are in mm).
2. ``grasplan.plan`` runs every stage: boundary layer mesher, convexity, antipodal candidates,
   gripper poses with full-jaw collision checks, IK and collision-free joint paths for the best
   ``top`` grasps (options: ``CandidateParams``, ``GraspParams``, ``PlanParams``). It returns a
   typed ``PlanResult``.
3. ``PlanResult.write`` saves the self-contained ``grasplan.plan/1`` JSON; ``grasplan.load_result``
   reads it back (gripper, cell and robot rebuilt from the file, everything validated).
4. ``grasplan.export.write`` turns the plan into every registered format (``grasplan.export.FORMATS``):
   URScript, a timed joint trajectory, CSV, KUKA KRL, ABB RAPID, MoveIt grasps.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import grasplan
from grasplan import export

HERE = Path(__file__).resolve().parent


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("part", nargs="?", type=Path, default=HERE / "parts" / "bracket.stl", help="mesh file (STL/OBJ/PLY)")
    ap.add_argument("-o", "--out", type=Path, default=Path("out") / "api_example", help="output folder")
    ap.add_argument("--top", type=int, default=5, help="plan at most this many grasps")
    args = ap.parse_args(argv)

    part = grasplan.load_part(args.part)              # metres from here on
    result = grasplan.plan(part, "ur5", planning=grasplan.PlanParams(top=args.top, seed=0))
    counts = result.counts()
    print(f"{args.part.name}: {counts['grasps']} grasps, {counts['planned']} planned")
    if counts["planned"] == 0:
        print("no planned grasp: nothing to export", file=sys.stderr)
        return 4

    args.out.mkdir(parents=True, exist_ok=True)
    plan_path = result.write(args.out / "plan.json")
    loaded = grasplan.load_result(plan_path)           # validated, models rebuilt from the file

    best = loaded.planned_ids()[0]                     # best rank
    written = [
        export.write(loaded, "urscript", args.out / "pick.script"),                    # best grasp
        export.write(loaded, "joint-trajectory", args.out / "trajectory.json", max_accel=1.0),
        export.write(loaded, "csv", args.out / "grasps.csv"),                          # every grasp
    ]
    for name, fmt in sorted(export.load_builtin_formats().items()):
        if name not in ("urscript", "joint-trajectory", "csv"):
            written.append(export.write(loaded, name, args.out / f"pick_{name.replace('-', '_')}{fmt.extension}"))
    # the same through the result object:
    written.append(result.export("urscript", args.out / f"pick_grasp{best}.script", grasp_id=best))
    for p in [plan_path, *written]:
        print(f"wrote {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
