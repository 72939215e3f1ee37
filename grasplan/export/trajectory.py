"""Timed joint trajectory (ROS ``trajectory_msgs/JointTrajectory`` layout) from q_home to q_grasp.

Method (the timed motion must stay on the verified path, so no spline through sparse waypoints):

1. The planned path (``q_home`` -> ``q_pregrasp`` -> ``q_grasp``, piecewise linear in joint space)
   is densified so that no joint moves more than ``KNOT_STEP`` (0.005 rad) between knots.
2. A cubic spline through these dense knots, parameterised by joint-space arc length, is the
   geometric path. Near a corner of the polyline it deviates from it by a small fraction of the knot
   step (measured and reported as ``max_deviation_rad``); the corners' high curvature makes TOPP-RA
   slow the arm down there instead of cutting across.
3. TOPP-RA (``toppra``, constant-acceleration parameterisation: positions lie exactly on the
   spline) with the URDF velocity limits times ``velocity_scale`` and ``max_accel``, both with a
   2 % safety margin, at rest at both ends.
4. The output points are the TOPP-RA grid points, subdivided until no joint moves more than
   ``SAMPLE_STEP`` (0.01 rad) between consecutive points.
5. Verification, fatal when it fails: times strictly increasing; start and end at rest at
   ``q_home`` / ``q_grasp``; every point within the joint limits; velocities within the limits at
   every point and as finite differences between points; and the sampled positions, interpolated
   linearly at 0.01 rad, collision-free with the jaws at the pre-grasp opening
   (``CollisionScene.path_free``).

JSON: ``{"schema": "grasplan.joint_trajectory/1", "joint_names", "grasp_id", "points": [{"positions",
"velocities", "accelerations", "time_from_start": {"sec", "nanosec"}}], "grasplan": {limits and
checks}}``; ``joint_names`` and ``points`` map one to one onto the ROS message.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import InputError, PlanningError
from ..results.export_registry import DEFAULT_MAX_ACCEL, ExportFormat, register

SCHEMA = "grasplan.joint_trajectory/1"
KNOT_STEP = 0.005      #: rad, spline knot spacing (max joint motion between knots)
SAMPLE_STEP = 0.01     #: rad, max joint motion between output points
MARGIN = 0.98          #: TOPP-RA runs with the limits times this, the check uses the full limits
CHECK_STEP = 0.01      #: rad, collision check interpolation step


def densify(path: np.ndarray, step: float) -> np.ndarray:
    """The planner's densifier (:func:`grasplan.geometry.interpolation.interpolate_path`)."""
    from ..geometry.interpolation import interpolate_path

    return interpolate_path(path, step=step)


def point_to_polyline_distance(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Euclidean joint-space distance (m,) of each point (m, n) to the polyline (k, n)."""
    a, b = poly[:-1], poly[1:]
    ab = b - a
    L2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
    out = np.empty(len(points))
    for s in range(0, len(points), 256):
        p = points[s:s + 256]
        t = np.clip(np.einsum("mij,ij->mi", p[:, None, :] - a[None], ab) / L2, 0.0, 1.0)
        c = a[None] + t[..., None] * ab[None]
        out[s:s + 256] = np.min(np.linalg.norm(p[:, None, :] - c, axis=2), axis=1)
    return out


def time_parameterize(path: np.ndarray, vmax: np.ndarray, amax: np.ndarray) -> dict[str, np.ndarray]:
    """TOPP-RA along the dense spline through ``path`` (k, n); rest to rest.

    Returns ``{"t": (m,), "q": (m, n), "qd": (m, n), "qdd": (m, n), "knots": (K, n)}`` with no
    joint moving more than :data:`SAMPLE_STEP` between samples. Raises PlanningError on failure.
    """
    import toppra
    import toppra.algorithm as algo
    import toppra.constraint as constraint

    from ..geometry.interpolation import interpolate_path

    knots, kidx = interpolate_path(path, step=KNOT_STEP, return_index=True)
    if len(knots) < 2:
        raise InputError("the path has no motion (all waypoints equal)")
    # the spline needs >= 4 knots for not-a-knot; a very short path gets a few extra
    if len(knots) < 4:
        knots, kidx = interpolate_path(path, step=float(np.max(np.abs(knots[-1] - knots[0]))) / 4.0,
                                       return_index=True)
    ss = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(knots, axis=0), axis=1))])
    spline = toppra.SplineInterpolator(ss, knots)
    # grid: every knot and the midpoints between knots
    grid = np.sort(np.concatenate([ss, 0.5 * (ss[1:] + ss[:-1])]))
    cons = [constraint.JointVelocityConstraint(MARGIN * vmax),
            constraint.JointAccelerationConstraint(MARGIN * amax)]
    instance = algo.TOPPRA(cons, spline, gridpoints=grid, solver_wrapper="seidel",
                           parametrizer="ParametrizeConstAccel")
    traj = instance.compute_trajectory(0.0, 0.0)
    if traj is None:
        raise PlanningError("TOPP-RA could not time-parameterise the path within the velocity/acceleration limits")
    sd = np.asarray(instance.problem_data.sd_vec, dtype=np.float64)
    t_grid = np.asarray(traj._ts, dtype=np.float64)
    if not np.all(np.isfinite(t_grid)) or np.any(np.diff(t_grid) <= 0):
        raise PlanningError("TOPP-RA returned non-increasing times (the path speed reached zero inside the path)")

    # samples: grid times, subdivided where a joint would move more than SAMPLE_STEP
    q_grid = spline(grid)
    dq = np.max(np.abs(np.diff(q_grid, axis=0)), axis=1)
    sub = np.maximum(1, np.ceil(dq / (0.9 * SAMPLE_STEP)).astype(int))
    seg = np.repeat(np.arange(len(dq)), sub)
    frac = np.concatenate([np.arange(p) / p for p in sub])
    t = np.concatenate([t_grid[seg] + frac * np.diff(t_grid)[seg], t_grid[-1:]])
    for _ in range(6):
        q = traj(t)
        step = np.max(np.abs(np.diff(q, axis=0)), axis=1)
        bad = np.flatnonzero(step > SAMPLE_STEP)
        if len(bad) == 0:
            break
        t = np.sort(np.concatenate([t, 0.5 * (t[bad] + t[bad + 1])]))
    q = traj(t)
    qd = traj(t, 1)
    qdd = traj(t, 2)
    # exact rest and exact end points (TOPP-RA gives sd = 0 at both ends)
    qd[0] = 0.0
    qd[-1] = 0.0
    q[0] = knots[0]
    q[-1] = knots[-1]
    # the sample at each waypoint of ``path``: knot j is grid point 2j, and every grid time is a sample
    wp = np.searchsorted(t, t_grid[2 * np.asarray(kidx)])
    return {"t": t, "q": q, "qd": qd, "qdd": qdd, "knots": knots, "sd": sd, "duration": float(t[-1]),
            "waypoint_samples": np.minimum(wp, len(t) - 1)}


def _limits(robot, max_accel, velocity_scale) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    n = robot.nq
    if not (0.0 < velocity_scale <= 1.0):
        raise InputError(f"velocity_scale must be in (0, 1], got {velocity_scale!r}")
    amax = np.broadcast_to(np.asarray(max_accel, dtype=np.float64), (n,)).copy() if np.ndim(max_accel) == 0 \
        else np.asarray(max_accel, dtype=np.float64)
    if amax.shape != (n,) or not np.all(np.isfinite(amax)) or np.any(amax <= 0):
        raise InputError(f"max_accel must be > 0 rad/s^2 (one value or {n}), got {max_accel!r}")
    vlim = np.asarray(robot.velocity_limit, dtype=np.float64)
    if vlim.shape != (n,) or np.any(vlim <= 0):
        raise InputError(f"robot {robot.name!r}: velocity limits {vlim} unusable")
    return vlim * velocity_scale, amax, np.asarray(robot.lower, dtype=np.float64), np.asarray(robot.upper, dtype=np.float64)


def build_scene(plan):
    """A CollisionScene of the plan's own robot, gripper, part (sha256-checked) and cell."""
    from ..motion.collision_scene import CollisionScene

    return CollisionScene(plan.robot, plan.gripper, plan.mesh(), plan.T_world_part, plan.cell)


def joint_trajectory(plan, *, grasp_id: int | None = None, max_accel=DEFAULT_MAX_ACCEL,
                     velocity_scale: float = 1.0, scene=None) -> dict:
    """The ``grasplan.joint_trajectory/1`` document for ``grasp_id`` (default: the best planned
    grasp) of a :class:`~grasplan.results.plan_result.PlanResult`.

    ``scene``: object with ``path_free(qs, opening, *, step)`` (default: :func:`build_scene`).
    Raises PlanningError when the timed trajectory fails a check (never writes an unchecked one).
    """
    g = plan.select(grasp_id)
    robot = plan.robot
    m = g.motion
    vmax, amax, lower, upper = _limits(robot, max_accel, velocity_scale)
    path = np.asarray(m.path, dtype=np.float64)
    if np.any(path < lower - 1e-9) or np.any(path > upper + 1e-9):
        raise InputError(f"grasp {g.id}: the planned path leaves the joint limits of {robot.name!r}")
    from .program import is_sequence

    if is_sequence(m):
        return sequence_trajectory(plan, g, vmax=vmax, amax=amax, lower=lower, upper=upper, scene=scene)
    res = time_parameterize(path, vmax, amax)
    t, q, qd, qdd = res["t"], res["q"], res["qd"], res["qdd"]
    # ---- checks (fatal) ----
    step, v_ratio, v_fd_ratio = _check_timed(g.id, t, q, qd, vmax, lower, upper, path[0], m.q_grasp,
                                             "q_home to q_grasp")
    a_ratio = float(np.max(np.abs(qdd) / amax))
    deviation = float(np.max(point_to_polyline_distance(q, path)))
    opening = float(plan.gripper.pregrasp_opening(g.width))
    if scene is None:
        scene = build_scene(plan)
    if not scene.path_free(q, opening, step=CHECK_STEP):
        detail = ""
        first = getattr(scene, "first_collision", None)
        if first is not None:
            for qq in densify(q, CHECK_STEP):
                hit = first(qq, opening)
                if hit:
                    detail = f" (first contact: {hit})"
                    break
        raise PlanningError(f"grasp {g.id}: the timed trajectory collides when interpolated at {CHECK_STEP} rad"
                            f"{detail}; it deviates up to {deviation:.4f} rad from the planned path. "
                            "Export another grasp with --grasp, or re-plan.")

    points = []
    for ti, qi, vi, ai in zip(t, q, qd, qdd):
        sec = int(math.floor(ti))
        ns = int(round((ti - sec) * 1e9))
        if ns >= 1_000_000_000:
            sec, ns = sec + 1, ns - 1_000_000_000
        points.append({"positions": qi.tolist(), "velocities": vi.tolist(), "accelerations": ai.tolist(),
                       "time_from_start": {"sec": sec, "nanosec": ns}})
    ns_all = [p["time_from_start"]["sec"] * 1_000_000_000 + p["time_from_start"]["nanosec"] for p in points]
    if any(b <= a_ for a_, b in zip(ns_all, ns_all[1:])):
        raise PlanningError(f"grasp {g.id}: two points share a time_from_start after rounding to nanoseconds")

    return {
        "schema": SCHEMA,
        "joint_names": list(robot.joint_names),
        "grasp_id": int(g.id),
        "points": points,
        "grasplan": {
            "robot": robot.name,
            "part_sha256": plan.part.sha256,
            "part_scale_to_m": plan.part.scale_to_m,
            "duration_s": res["duration"],
            "velocity_limit": vmax.tolist(),
            "acceleration_limit": amax.tolist(),
            "max_velocity_ratio": max(v_ratio, v_fd_ratio),
            "max_acceleration_ratio": a_ratio,
            "max_step_rad": step,
            "max_deviation_rad": deviation,
            "pregrasp_opening": opening,
            "collision_checked_step_rad": CHECK_STEP,
            "method": "cubic spline through the path densified at 0.005 rad; TOPP-RA (constant-acceleration "
                      "parameterisation), rest to rest",
        },
    }


def _check_timed(gid, t, q, qd, vmax, lower, upper, q_start, q_end, what: str) -> tuple[float, float, float]:
    """The fatal checks of a timed piece: times increasing, steps <= SAMPLE_STEP, velocities
    (analytic and finite differences) within the limits, joint limits, start and end points.
    Returns ``(max step, velocity ratio, finite-difference velocity ratio)``."""
    dt = np.diff(t)
    problems = []
    if np.any(dt <= 0):
        problems.append("times not strictly increasing")
    step = float(np.max(np.abs(np.diff(q, axis=0))))
    if step > SAMPLE_STEP + 1e-12:
        problems.append(f"points {step:.4f} rad apart (> {SAMPLE_STEP})")
    v_ratio = float(np.max(np.abs(qd) / vmax))
    v_fd_ratio = float(np.max(np.abs(np.diff(q, axis=0)) / dt[:, None] / vmax))
    if v_ratio > 1.0 + 1e-9 or v_fd_ratio > 1.0 + 1e-9:
        problems.append(f"velocity {max(v_ratio, v_fd_ratio):.3f} x the limit")
    if np.any(q < lower - 1e-9) or np.any(q > upper + 1e-9):
        problems.append("joint limits exceeded")
    if np.max(np.abs(q[0] - q_start)) > 1e-9 or np.max(np.abs(q[-1] - q_end)) > 1e-9:
        problems.append(f"does not run from {what}")
    if problems:
        raise PlanningError(f"grasp {gid}: the timed trajectory fails its checks: {'; '.join(problems)}")
    return step, v_ratio, v_fd_ratio


#: s, the robot stands still at a gripper event for this long (the trajectory repeats the point)
GRIPPER_DWELL_S = 0.5


def _duration(ti: float) -> dict:
    sec = int(math.floor(ti))
    ns = int(round((ti - sec) * 1e9))
    if ns >= 1_000_000_000:
        sec, ns = sec + 1, ns - 1_000_000_000
    return {"sec": sec, "nanosec": ns}


def segment_scenes(plan, mp, scene):
    """For each segment of a sequence (:class:`~grasplan.export.program.MotionProgram`): the scene
    and jaw opening its samples are checked with, and a label of the check. Before the close: the
    plan's scene, jaws at the pre-grasp opening; while attached: ``scene.attached(T_tcp_part)``,
    jaws at the close width; after the open: ``scene.with_part_at(T_world_part_place)``, jaws at
    the open width."""
    g = plan.select(mp.grasp_id)
    m = g.motion
    close = next((e for e in mp.events if e.action == "close"), None)
    opened = next((e for e in mp.events if e.action == "open"), None)
    out = []
    for seg in mp.segments:
        if close is None or seg.end <= close.index:
            out.append((scene, mp.pregrasp_opening, "part static at its pick pose, jaws at the pre-grasp opening"))
            continue
        if opened is None or seg.end <= opened.index:
            attached = getattr(scene, "attached", None)
            T_tcp_part = getattr(m, "T_tcp_part", None)
            if attached is None or T_tcp_part is None:
                raise InputError(f"grasp {g.id}: the {seg.label} segment carries the part, but the collision scene "
                                 "cannot attach it (update grasplan) or the plan lacks T_tcp_part (plan again)")
            out.append((attached(np.asarray(T_tcp_part, dtype=np.float64)), close.width,
                        "part in the jaws"))
            continue
        placed = getattr(scene, "with_part_at", None)
        T_place = getattr(m, "T_world_part_place", None)
        if placed is None or T_place is None:
            raise InputError(f"grasp {g.id}: the {seg.label} segment follows the release, but the collision scene "
                             "cannot move the part (update grasplan) or the plan lacks T_world_part_place")
        out.append((placed(np.asarray(T_place, dtype=np.float64)), opened.width, "part released at the place"))
    return out


def sequence_trajectory(plan, g, *, vmax, amax, lower, upper, scene=None) -> dict:
    """The joint trajectory of a pick(-and-place) sequence: one rest-to-rest TOPP-RA piece between
    gripper events (the robot stops at each event and stands still for :data:`GRIPPER_DWELL_S`:
    the point is repeated), every segment re-checked for collisions with its own scene (see
    :func:`segment_scenes`). Adds ``segments`` (point ranges) and ``gripper`` (point and time of
    each event) to the document."""
    from .program import SEGMENT_TEXT, motion_program

    mp = motion_program(plan, g.id)
    m = g.motion
    path = np.asarray(m.path, dtype=np.float64)
    k = len(path)
    cuts = sorted({0, k - 1} | {e.index for e in mp.events if 0 < e.index < k - 1})
    ts, qs, qds, qdds = [], [], [], []
    rows: dict[int, int] = {}
    t0, steps, v_ratios, deviations, a_ratios = 0.0, [], [], [], []
    n_points = 0
    for a, b in zip(cuts[:-1], cuts[1:]):
        piece = path[a:b + 1]
        res = time_parameterize(piece, vmax, amax)
        t, q, qd, qdd = res["t"], res["q"], res["qd"], res["qdd"]
        step, v1, v2 = _check_timed(g.id, t, q, qd, vmax, lower, upper, piece[0], piece[-1],
                                    f"path row {a} to row {b}")
        steps.append(step)
        v_ratios.append(max(v1, v2))
        a_ratios.append(float(np.max(np.abs(qdd) / amax)))
        deviations.append(float(np.max(point_to_polyline_distance(q, piece))))
        if n_points:  # the event's dwell: the piece's first point (= the previous end) repeated later
            t0 += GRIPPER_DWELL_S
        wp = res["waypoint_samples"]
        for r, w in zip(range(a, b + 1), wp):
            if r not in rows or r == a:  # a boundary row: the first of its two points (the arrival)
                rows.setdefault(r, n_points + int(w))
        ts.append(t + t0)
        qs.append(q)
        qds.append(qd)
        qdds.append(qdd)
        t0 += float(t[-1])
        n_points += len(t)
    t = np.concatenate(ts)
    q = np.concatenate(qs)
    qd = np.concatenate(qds)
    qdd = np.concatenate(qdds)
    if np.any(np.diff(t) <= 0):
        raise PlanningError(f"grasp {g.id}: the timed trajectory fails its checks: times not strictly increasing")
    for r in range(k):  # every waypoint is a point of the trajectory
        if np.max(np.abs(q[rows[r]] - path[r])) > 1e-9:
            raise PlanningError(f"grasp {g.id}: the timed trajectory misses path row {r}")
    if scene is None:
        scene = build_scene(plan)
    checked = []
    for seg, (sc, opening, what) in zip(mp.segments, segment_scenes(plan, mp, scene)):
        lo, hi = rows[seg.start], rows[seg.end]
        if seg.start in [e.index for e in mp.events]:  # start after the dwell (same position)
            lo += 1
        if not sc.path_free(q[lo:hi + 1], opening, step=CHECK_STEP):
            raise PlanningError(f"grasp {g.id}: the timed trajectory collides in the {seg.label} segment ({what}) "
                                f"when interpolated at {CHECK_STEP} rad; it deviates up to {max(deviations):.4f} rad "
                                "from the planned path. Export another grasp with --grasp, or re-plan.")
        checked.append({"segment": seg.label, "opening": float(opening), "scene": what})
    points = [{"positions": qi.tolist(), "velocities": vi.tolist(), "accelerations": ai.tolist(),
               "time_from_start": _duration(ti)} for ti, qi, vi, ai in zip(t, q, qd, qdd)]
    ns_all = [p["time_from_start"]["sec"] * 1_000_000_000 + p["time_from_start"]["nanosec"] for p in points]
    if any(b <= a_ for a_, b in zip(ns_all, ns_all[1:])):
        raise PlanningError(f"grasp {g.id}: two points share a time_from_start after rounding to nanoseconds")
    seg_doc = []
    for seg in mp.segments:
        lo, hi = rows[seg.start], rows[seg.end]
        if seg.start in [e.index for e in mp.events]:
            lo += 1
        seg_doc.append({"label": seg.label, "start": lo, "end": hi, "path_start": seg.start, "path_end": seg.end,
                        "linear": seg.linear, "attached": seg.attached, "description": SEGMENT_TEXT[seg.label]})
    grip_doc = [{"action": e.action, "width": e.width, "path_index": e.index, "point": rows[e.index],
                 "time_from_start": points[rows[e.index]]["time_from_start"], "dwell_s": GRIPPER_DWELL_S}
                for e in mp.events]
    return {
        "schema": SCHEMA,
        "joint_names": list(plan.robot.joint_names),
        "grasp_id": int(g.id),
        "points": points,
        "segments": seg_doc,
        "gripper": grip_doc,
        "grasplan": {
            "robot": plan.robot.name,
            "part_sha256": plan.part.sha256,
            "part_scale_to_m": plan.part.scale_to_m,
            "duration_s": float(t[-1]),
            "velocity_limit": vmax.tolist(),
            "acceleration_limit": amax.tolist(),
            "max_velocity_ratio": max(v_ratios),
            "max_acceleration_ratio": max(a_ratios),
            "max_step_rad": max(steps),
            "max_deviation_rad": max(deviations),
            "pregrasp_opening": mp.pregrasp_opening,
            "gripper_dwell_s": GRIPPER_DWELL_S,
            "collision_checked_step_rad": CHECK_STEP,
            "collision_checks": checked,
            "method": "per piece between gripper events: cubic spline through the path densified at 0.005 rad; "
                      "TOPP-RA (constant-acceleration parameterisation), rest to rest; the robot stands still "
                      f"{GRIPPER_DWELL_S} s at each gripper event (the point is repeated)",
        },
    }


def _render(plan, opts) -> dict[str, str]:
    from ..io import to_json_text

    doc = joint_trajectory(plan, grasp_id=opts.grasp_id, max_accel=opts.max_accel, velocity_scale=opts.velocity_scale)
    return {".json": to_json_text(doc, indent=1) + "\n"}


register(ExportFormat(name="joint-trajectory", extension=".json", render=_render,
                      description="ROS JointTrajectory (JSON), TOPP-RA timed within the limits, re-checked for collisions."))
