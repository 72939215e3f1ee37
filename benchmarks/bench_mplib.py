"""The same grasps through grasplan and MPlib, per grasp, in one run. MPlib is optional: it is never
a grasplan dependency, and without it this prints grasplan's side alone.

    .venv/bin/python benchmarks/bench_mplib.py [--parts TLess20.stl,SileanePepper.stl,IPAGearShaft.stl]
                                               [--units auto] [--time-limit 1.0] [--screw-step 0.01]

MPlib 0.2.1 needs numpy < 2 (its compiled module crashes under numpy 2), so it runs from its own
environment that also sees grasplan's packages (numpy 1.26 from that environment comes first)::

    python3 -m venv /tmp/mplibenv && /tmp/mplibenv/bin/pip install mplib==0.2.1
    echo "import site; site.addsitedir('$PWD/.venv/lib/python3.11/site-packages')" \\
        > /tmp/mplibenv/lib/python3.11/site-packages/zz_grasplan.pth
    /tmp/mplibenv/bin/python benchmarks/bench_mplib.py

Per part (paper parts from ``GRASPLAN_PAPER_PARTS``, else the example bracket in mm):

* grasplan: ``plan(part, "ur5")`` once to warm up, then REPEATS times; the median of their robot
  stages (``timing_s`` ik + approach + joint_path + lift) per planned grasp: IK (closed form), the
  approach line to the grasp, the lift, and a collision-verified joint path from q_home.
* MPlib: one ``mplib.Planner`` on the same URDF/SRDF with the same cell table (the same box), the
  part's mesh (a BVH at ``T_world_part``) and the gripper's shapes attached to the flange (fingers
  at the pre-grasp opening, as grasplan approaches). For each grasp grasplan planned:
  ``plan_pose`` q_home -> pre-grasp (the TCP backed off by ``PlanParams.backoff`` along -z; IK by
  CLIK with 20 restarts, RRTConnect, TOPP) then ``plan_screw`` to the grasp; no lift. Reached = both
  succeed; its IK and RRT are unseeded (counts and times vary from run to run). "grasplan states
  free" checks the worlds agree: grasplan's pre-grasp and grasp configurations in MPlib's world.
"""
from __future__ import annotations

import argparse
import importlib.metadata
import os
import statistics
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

PAPER = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
DEFAULT_PARTS = ("TLess20.stl", "SileanePepper.stl", "IPAGearShaft.stl")
FALLBACK = ROOT / "examples" / "parts" / "bracket.stl"
ROBOT_STAGES = ("ik", "approach", "joint_path", "lift")
TARGET_RATIO = 15.0  #: MPlib ms per grasp / grasplan ms per grasp, at least
REPEATS = 3  #: warm plans per part; grasplan's per grasp time is their median
MplibRun = tuple[list[float], list[float], int, int, int]
#: plan_screw's joint step (rad): at its default 0.1 the Jacobian steps stray ~2 mm from the straight
#: line and hit parts grasplan's approach clears; 0.01 follows it at about the same cost
SCREW_STEP = 0.01
NO_MPLIB = "MPlib not installed: the comparison needs `pip install mplib` (optional; never a grasplan dependency)"


def fail(msg: str, code: int = 2) -> NoReturn:
    print(f"bench_mplib: {msg}", file=sys.stderr)
    raise SystemExit(code)


def resolve_parts(spec: str | None, units: str) -> list[tuple[Path, str]]:
    """(path, units) per part of ``spec`` (paths or paper part names); default: the paper parts, else the bracket."""
    if spec is None:
        found = [(PAPER / n, units) for n in DEFAULT_PARTS if (PAPER / n).is_file()]
        if found:
            return found
        print(f"note: no paper parts in {PAPER} (set GRASPLAN_PAPER_PARTS); using {FALLBACK.name} in mm")
        return [(FALLBACK, "mm")]
    out = []
    for name in (s.strip() for s in spec.split(",") if s.strip()):
        p = Path(name) if Path(name).is_file() else PAPER / name
        if not p.is_file():
            fail(f"part {name!r} not found (as a path or in {PAPER}); pass existing files to --parts")
        out.append((p, units))
    return out


def mplib_status() -> str | None:
    """None when mplib can run here, else why not (without importing a build that crashes under numpy 2)."""
    try:
        version = importlib.metadata.version("mplib")
    except importlib.metadata.PackageNotFoundError:
        return NO_MPLIB
    if version.startswith("0.") and int(np.__version__.split(".")[0]) >= 2:
        return (f"MPlib {version} is installed but needs numpy < 2 (this environment has numpy {np.__version__}); "
                f"run this script from a separate environment (see its docstring)")
    try:
        import mplib  # noqa: F401
    except ImportError as exc:
        return f"{NO_MPLIB} ({exc})"
    return None


def run_grasplan(path: Path, units: str) -> tuple[Any, list[int], float]:
    """The plan, its planned ids and the median over REPEATS plans of the robot stages per planned grasp, ms."""
    from grasplan import load_part, plan
    from grasplan.config.params import PAPER_GRIPPER

    part = load_part(path, units=units)
    plan(part, "ur5", gripper=PAPER_GRIPPER)  # the first plan in a process loads kernels and reads (or computes) the database
    runs = [plan(part, "ur5", gripper=PAPER_GRIPPER) for _ in range(REPEATS)]
    ids = runs[-1].planned_ids()
    robot_s = statistics.median(sum(float(r.timing_s.get(k, 0.0)) for k in ROBOT_STAGES) for r in runs)
    return runs[-1], ids, 1e3 * robot_s / max(1, len(ids))


def minimal_srdf(urdf: Path, out: Path) -> Path:
    """An SRDF disabling the collisions of each joint's parent and child links."""
    root = ET.parse(urdf).getroot()
    links = [(j.find("parent"), j.find("child")) for j in root.iter("joint")]
    pairs = "".join(f'  <disable_collisions link1="{p.get("link")}" link2="{c.get("link")}"/>\n'
                    for p, c in links if p is not None and c is not None)
    out.write_text(f'<?xml version="1.0"?>\n<robot name="{root.get("name", "robot")}">\n{pairs}</robot>\n')
    return out


def mesh_bvh(vertices: np.ndarray, faces: np.ndarray) -> Any:
    """An FCL triangle mesh (BVH) of ``vertices`` (V, 3) m and ``faces`` (F, 3)."""
    from mplib.collision_detection import fcl

    bvh = fcl.BVHModel()
    bvh.begin_model()
    bvh.add_sub_model(vertices=np.asarray(vertices, dtype=np.float64), faces=np.asarray(faces, dtype=np.int32))
    bvh.end_model()
    return bvh


def shape_geometry(shape: Any) -> Any:
    """A gripper shape as an FCL triangle mesh in the TCP frame. Triangles, not ``fcl.Box``: FCL's
    box-vs-mesh test (GJK) reports contact at up to ~0.6 mm clearance, its mesh-vs-mesh test is exact."""
    import trimesh
    from grasplan.gripper.model import Box

    if isinstance(shape, Box):
        shape = trimesh.creation.box(extents=np.asarray(shape.extents, dtype=np.float64), transform=shape.T_tcp_box)
    return mesh_bvh(shape.vertices, shape.faces)


class MplibCell:
    """One MPlib planner for a plan's robot, table, part and gripper."""

    def __init__(self, res: Any, tmp: Path) -> None:
        import mplib
        from mplib.collision_detection import fcl
        from grasplan.cell.shapes import TABLE_SIZE, table_pose
        from grasplan.robot.files import package_share_dir

        robot, self.gripper = res.robot, res.gripper
        # a copy of the URDF beside links to its packages, package:// dropped: MPlib reads mesh paths
        # relative to the URDF's folder (and would write its own copy next to the original)
        text, share = Path(robot.urdf_path).read_text(), package_share_dir()
        for pkg in {s.split("/", 1)[0] for s in text.split("package://")[1:]} & {p.name for p in share.iterdir()}:
            (tmp / pkg).symlink_to(share / pkg)
        urdf = tmp / Path(robot.urdf_path).name
        urdf.write_text(text.replace("package://", ""))
        srdf = Path(robot.srdf_path) if robot.srdf_path else minimal_srdf(urdf, tmp / "robot.srdf")
        self.planner = mplib.Planner(urdf=str(urdf), srdf=str(srdf), move_group=robot.tool_frame)
        self.planner.set_base_pose(mplib.Pose(np.asarray(robot.T_world_base, dtype=np.float64)))
        self.world, self.art = self.planner.planning_world, self.planner.robot.get_name()
        self.q_home = np.asarray(robot.q_home, dtype=np.float64)
        self.world.add_object(fcl.FCLObject("table", mplib.Pose(table_pose(res.cell.table_z)),
                                            [fcl.CollisionObject(fcl.Box(*TABLE_SIZE))], [mplib.Pose()]))
        mesh = res.mesh()
        self.world.add_object(fcl.FCLObject("part", mplib.Pose(np.asarray(res.T_world_part, dtype=np.float64)),
                                            [fcl.CollisionObject(mesh_bvh(mesh.vertices, mesh.faces))],
                                            [mplib.Pose()]))
        # as grasplan's scene: links on the same or adjacent joints never collide (MPlib reads only the
        # SRDF's pairs), the links moving with the flange touch the gripper, the mounted links the table
        links = self.planner.pinocchio_model.get_link_names()
        self.tool, pm = links.index(robot.tool_frame), robot.model
        joint = {ln: pm.frames[pm.getFrameId(ln)].parentJoint for ln in links if pm.existFrame(ln)}
        self.touch = [ln for ln, j in joint.items() if j == joint[robot.tool_frame]]
        self.acm = self.world.get_allowed_collision_matrix()
        for a, ja in joint.items():
            for b, jb in joint.items():
                if a < b and (ja == jb or pm.parents[ja] == jb or pm.parents[jb] == ja):
                    self.acm.set_entry(a, b, True)
        self.acm.set_entry("table", list(robot.mounted_links), True)
        self.names: list[str] = []
        for k, shape in enumerate(self.gripper.body):
            self._attach(f"gripper_body_{k}", shape)

    def _attach(self, name: str, shape: Any) -> None:
        import mplib

        self.world.attach_object(name, shape_geometry(shape), self.art, self.tool,
                                 mplib.Pose(np.asarray(self.gripper.T_flange_tcp, dtype=np.float64)), self.touch)
        if name not in self.names:
            self.names.append(name)
        self.acm.set_entry(self.names, self.names, True)  # the gripper's own shapes overlap

    def set_fingers(self, width: float) -> None:
        for name, shape in zip(("finger_left", "finger_right"),
                               self.gripper.fingers(float(self.gripper.pregrasp_opening(width)))):
            self._attach(name, shape)

    def is_free(self, q: np.ndarray) -> bool:
        return not self.planner.check_for_collision(self.world.check_collision, np.asarray(q, dtype=np.float64))

    def grasp(self, T_world_tcp: np.ndarray, width: float, backoff: float, time_limit: float,
              screw_step: float) -> tuple[bool, bool, float, float]:
        """(pre-grasp reached, grasp reached, seconds to the pre-grasp, seconds of the screw)."""
        import mplib
        from grasplan.geometry.transforms import translation

        T_tcp_flange = np.linalg.inv(self.gripper.T_flange_tcp_at(width))
        T_pre = T_world_tcp @ translation(0.0, 0.0, -backoff) @ T_tcp_flange
        t0 = time.perf_counter()
        r1 = self.planner.plan_pose(mplib.Pose(T_pre), self.q_home, planning_time=time_limit)
        t1 = time.perf_counter()
        ok1 = r1["status"] == "Success"
        q_pre = np.asarray(r1["position"][-1], dtype=np.float64) if ok1 else None
        r2 = self.planner.plan_screw(mplib.Pose(T_world_tcp @ T_tcp_flange), q_pre, qpos_step=screw_step) if ok1 else {}
        return ok1, r2.get("status") == "Success", t1 - t0, time.perf_counter() - t1


def run_mplib(res: Any, ids: list[int], time_limit: float, screw_step: float) -> MplibRun:
    """Per grasp seconds to the pre-grasp and of the screw; pre-grasps and grasps reached; grasplan's states free."""
    pose, screw, pre, ok, free = [], [], 0, 0, 0
    with tempfile.TemporaryDirectory() as tmp:
        cell = MplibCell(res, Path(tmp))
        if not cell.is_free(cell.q_home):
            print("  warning: q_home collides in MPlib's world", file=sys.stderr)
        for gid in ids:
            g = res.grasp(gid)
            cell.set_fingers(g.width)
            free += sum(cell.is_free(q) for q in (g.motion.q_pregrasp, g.motion.q_grasp))
            ok1, ok2, t_pose, t_screw = cell.grasp(np.asarray(g.T_world_tcp, dtype=np.float64), g.width,
                                                   res.retreat_distance, time_limit, screw_step)
            pose.append(t_pose)
            screw.append(t_screw)
            pre, ok = pre + ok1, ok + ok2
    return pose, screw, pre, ok, free


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--parts", help="comma-separated part files or names in the paper folder")
    ap.add_argument("--units", default="auto", help="units of the part files (auto, m, mm, ...)")
    ap.add_argument("--time-limit", type=float, default=None,
                    help="MPlib RRTConnect seconds per query (default: grasplan's time_limit_per_query)")
    ap.add_argument("--screw-step", type=float, default=SCREW_STEP,
                    help=f"plan_screw qpos_step, rad (default {SCREW_STEP:g}; MPlib's own 0.1 strays from the line)")
    args = ap.parse_args(argv)
    parts, why_not = resolve_parts(args.parts, args.units), mplib_status()
    from grasplan import GrasplanError
    from grasplan.cli.common import table

    rows: list[tuple[object, ...]] = []
    ratios, g_ms, m_ms = [], [], []
    for path, units in parts:
        try:
            res, ids, per_g = run_grasplan(path, units)
        except GrasplanError as exc:
            fail(f"{path.name}: {exc}", exc.exit_code)
        print(f"  {path.name}: grasplan {len(ids)} planned, {per_g:.2f} ms/grasp", file=sys.stderr)
        if not ids:
            continue
        g_ms.append(per_g)
        if why_not is not None:
            rows.append((path.name, len(ids), per_g))
            continue
        limit = args.time_limit if args.time_limit is not None else float(res.params.planning.time_limit_per_query)
        try:
            pose, screw, pre, ok, free = run_mplib(res, ids, limit, args.screw_step)
        except (ValueError, RuntimeError) as exc:
            fail(f"{path.name}: MPlib failed: {exc}", 3)
        total, n = [a + b for a, b in zip(pose, screw)], len(ids)
        m_ms.append(mean_ms := 1e3 * statistics.fmean(total))
        ratios.append(ratio := mean_ms / per_g)
        rows.append((path.name, n, per_g, mean_ms, 1e3 * statistics.median(total), 1e3 * statistics.fmean(screw),
                     f"{pre}/{n}", f"{ok}/{n}", f"{free}/{2 * n}", ratio, "met" if ratio >= TARGET_RATIO else "MISSED"))
    if not rows:
        fail("no part gave planned grasps to compare", 3)
    print("\ngrasps = grasplan's planned grasps (all reached); grasplan ms/grasp = plan(part, 'ur5') robot stages "
          f"(ik + approach + joint_path + lift, median of {REPEATS} warm plans) per planned grasp: closed-form IK, "
          "approach line, lift, verified joint path from q_home")
    if why_not is not None:
        print(table(rows, ("part", "grasps", "grasplan ms/grasp")))
        print(f"median grasplan ms/grasp: {statistics.median(g_ms):.2f}\n{why_not}")
        return 0
    print(f"MPlib {importlib.metadata.version('mplib')}, same grasps, table, part mesh and gripper shapes: plan_pose "
          f"q_home -> pre-grasp (CLIK x20 restarts + RRTConnect + TOPP) then plan_screw to the grasp (step "
          f"{args.screw_step:g} rad, + TOPP), no lift; ms/grasp = mean (and median) wall per grasp, screw = its "
          f"part; pre-grasp / reached = n of N; grasplan states free = its pre-grasp and grasp configurations free "
          f"in MPlib's world; ratio = MPlib mean / grasplan (target >= {TARGET_RATIO:g}x)")
    print(table(rows, ("part", "grasps", "grasplan ms/grasp", "MPlib ms/grasp", "MPlib median", "screw ms",
                       "MPlib pre-grasp", "MPlib reached", "grasplan states free", "ratio", "target")))
    print(f"medians over parts: grasplan {statistics.median(g_ms):.2f} ms/grasp, MPlib {statistics.median(m_ms):.1f} "
          f"ms/grasp, ratio {statistics.median(ratios):.1f}x")
    if os.getloadavg()[0] > (os.cpu_count() or 1):
        print(f"note: load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; times are inflated")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
