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
from .registry import DEFAULT_MAX_ACCEL, ExportFormat, register

SCHEMA = "grasplan.joint_trajectory/1"
KNOT_STEP = 0.005      #: rad, spline knot spacing (max joint motion between knots)
SAMPLE_STEP = 0.01     #: rad, max joint motion between output points
MARGIN = 0.98          #: TOPP-RA runs with the limits times this, the check uses the full limits
CHECK_STEP = 0.01      #: rad, collision check interpolation step


def densify(path: np.ndarray, step: float) -> np.ndarray:
    """The planner's densifier (:func:`grasplan.paths.interpolate_path`)."""
    from ..paths import interpolate_path

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

    knots = densify(path, KNOT_STEP)
    if len(knots) < 2:
        raise InputError("the path has no motion (all waypoints equal)")
    # the spline needs >= 4 knots for not-a-knot; a very short path gets a few extra
    if len(knots) < 4:
        knots = densify(path, float(np.max(np.abs(knots[-1] - knots[0]))) / 4.0)
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
    return {"t": t, "q": q, "qd": qd, "qdd": qdd, "knots": knots, "sd": sd, "duration": float(t[-1])}


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
    from ..scene import CollisionScene

    return CollisionScene(plan.robot, plan.gripper, plan.mesh(), plan.T_world_part, plan.cell)


def joint_trajectory(plan, *, grasp_id: int | None = None, max_accel=DEFAULT_MAX_ACCEL,
                     velocity_scale: float = 1.0, scene=None) -> dict:
    """The ``grasplan.joint_trajectory/1`` document for ``grasp_id`` (default: the best planned
    grasp) of a :class:`~grasplan.result.PlanResult`.

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
    res = time_parameterize(path, vmax, amax)
    t, q, qd, qdd = res["t"], res["q"], res["qd"], res["qdd"]
    # ---- checks (fatal) ----
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
    if np.max(np.abs(q[0] - path[0])) > 1e-9 or np.max(np.abs(q[-1] - m.q_grasp)) > 1e-9:
        problems.append("does not run from q_home to q_grasp")
    if problems:
        raise PlanningError(f"grasp {g.id}: the timed trajectory fails its checks: {'; '.join(problems)}")
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


def _render(plan, opts) -> dict[str, str]:
    from ..io import to_json_text

    doc = joint_trajectory(plan, grasp_id=opts.grasp_id, max_accel=opts.max_accel, velocity_scale=opts.velocity_scale)
    return {".json": to_json_text(doc, indent=1) + "\n"}


register(ExportFormat(name="joint-trajectory", extension=".json", render=_render,
                      description="ROS JointTrajectory (JSON), TOPP-RA timed within the limits, re-checked for collisions."))
