"""The whole grasplan pipeline from Python: plan a part for a UR5, then write every export format.

Run:  python examples/api_example.py [PART] [-o OUT_DIR] [--top K]
(default part: examples/parts/bracket.stl, default output folder: out/api_example)

Steps:
1. ``load_part`` reads the mesh (units decided from its size: the example parts are in mm).
2. ``grasplan.planning.plan`` runs every stage: boundary layer mesher, convexity, antipodal candidates,
   gripper poses with full-jaw collision checks, IK and collision-free joint paths for the best
   ``top`` grasps. It returns a ``PlanResult``.
3. ``PlanResult.write`` saves the ``grasplan.plan/1`` JSON; ``grasplan.schemas.validate`` checks it.
4. ``grasplan.export.write`` turns the plan into a URScript program, a timed, collision-checked
   joint trajectory (ROS JointTrajectory layout) and a CSV of every grasp.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from grasplan import export
from grasplan.mesh import load_part
from grasplan.planning import plan
from grasplan.schemas import validate

HERE = Path(__file__).resolve().parent


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("part", nargs="?", type=Path, default=HERE / "parts" / "bracket.stl", help="mesh file (STL/OBJ/PLY)")
    ap.add_argument("-o", "--out", type=Path, default=Path("out") / "api_example", help="output folder")
    ap.add_argument("--top", type=int, default=5, help="plan at most this many grasps")
    args = ap.parse_args(argv)

    part = load_part(args.part)                       # metres from here on
    result = plan(part, robot="ur5", top=args.top, seed=0)
    counts = result.counts()
    print(f"{args.part.name}: {counts['grasps']} grasps, {counts['planned']} planned")
    if counts["planned"] == 0:
        print("no planned grasp: nothing to export", file=sys.stderr)
        return 4

    args.out.mkdir(parents=True, exist_ok=True)
    plan_path = result.write(args.out / "plan.json")
    doc = result.to_json()
    validate(doc)                                     # the JSON Schema shipped in grasplan/schemas

    best = export.planned_ids(doc)[0]                 # highest score
    written = [
        export.write(doc, "urscript", args.out / "pick.script"),                       # best grasp
        export.write(doc, "joint-trajectory", args.out / "trajectory.json", max_accel=1.0),
        export.write(doc, "csv", args.out / "grasps.csv"),                             # every grasp
    ]
    # the same through the result object:
    written.append(result.export("urscript", args.out / f"pick_grasp{best}.script", grasp_id=best))
    for p in [plan_path, *written]:
        print(f"wrote {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
