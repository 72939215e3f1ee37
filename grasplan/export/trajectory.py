"""Timed joint trajectory (ROS ``trajectory_msgs/JointTrajectory`` layout) of a planned grasp.

:func:`joint_trajectory` times the verified path from q_home to q_grasp (a pick-and-place
sequence: each piece between gripper events, :func:`sequence_trajectory`) with TOPP-RA along a
dense spline (:func:`time_parameterize`), within the URDF velocity limits and an acceleration
limit, and re-checks the timed motion before it is returned: a trajectory that fails a check is
never written.

JSON: ``{"schema": "grasplan.joint_trajectory/1", "joint_names", "grasp_id", "points": [{"positions",
"velocities", "accelerations", "time_from_start": {"sec", "nanosec"}}], "grasplan": {limits and
checks}}``; ``joint_names`` and ``points`` map one to one onto the ROS message.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, cast

import numpy as np

from ..errors import InputError, PlanningError
from ..results.export_registry import DEFAULT_MAX_ACCEL, ExportFormat, ExportOptions, register

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from .program import MotionProgram
    from ..motion.collision_scene import CollisionScene
    from ..results.joint_motion import Motion
    from ..results.plan_result import GraspView, PlanResult
    from ..robot.model import Robot

SCHEMA = "grasplan.joint_trajectory/1"
KNOT_STEP = 0.005      #: rad, spline knot spacing (max joint motion between knots)
SAMPLE_STEP = 0.01     #: rad, max joint motion between output points
MARGIN = 0.98          #: TOPP-RA runs with the limits times this, the check uses the full limits
CHECK_STEP = 0.01      #: rad, collision check interpolation step


class PathChecker(Protocol):
    """What the trajectory checks read of a collision scene (a :class:`~grasplan.motion.collision_scene.CollisionScene`)."""

    def path_free(self, qs: np.ndarray, opening: float, *, step: float) -> bool: ...


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


@dataclass(frozen=True)
class TimedPath:
    """A rest-to-rest timed path: times ``t`` (m,), positions ``q``, velocities ``qd`` and
    accelerations ``qdd`` (m, n); the spline's ``knots`` (K, n); TOPP-RA's path speeds ``sd`` at its
    grid points; ``duration`` s; ``waypoint_samples`` the sample at each waypoint of the path."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    knots: np.ndarray
    sd: np.ndarray
    duration: float
    waypoint_samples: np.ndarray


def _spline_knots(path: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(knots, kidx)``: ``path`` densified so that no joint moves more than :data:`KNOT_STEP`
    between knots (at least 4 knots, for a not-a-knot spline), and the knot of each waypoint."""
    from ..geometry.interpolation import interpolate_path

    knots, kidx = interpolate_path(path, step=KNOT_STEP, return_index=True)
    if len(knots) < 2:
        raise InputError("the path has no motion (all waypoints equal)")
    # the spline needs >= 4 knots for not-a-knot; a very short path gets a few extra
    if len(knots) < 4:
        knots, kidx = interpolate_path(path, step=float(np.max(np.abs(knots[-1] - knots[0]))) / 4.0,
                                       return_index=True)
    return knots, kidx


def _sample_times(traj: Any, q_grid: np.ndarray, t_grid: np.ndarray) -> np.ndarray:
    """Output times: TOPP-RA's grid times, subdivided until no joint moves more than
    :data:`SAMPLE_STEP` between consecutive samples of ``traj``."""
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
    return t


def time_parameterize(path: np.ndarray, vmax: np.ndarray, amax: np.ndarray) -> TimedPath:
    """TOPP-RA along the dense spline through ``path`` (k, n); rest to rest.

    The path (piecewise linear in joint space) is densified at :data:`KNOT_STEP`; a cubic spline
    through these knots, parameterised by joint-space arc length, is the geometric path (near a
    corner of the polyline it deviates from it by a small fraction of the knot step; the corners'
    high curvature makes TOPP-RA slow the arm down there instead of cutting across). TOPP-RA
    (constant-acceleration parameterisation: positions lie exactly on the spline) runs with the
    limits times :data:`MARGIN`, on the knots and the midpoints between them. The output samples
    are the grid points, subdivided (:func:`_sample_times`). Raises PlanningError on failure.
    """
    import toppra
    import toppra.algorithm as algo
    import toppra.constraint as constraint

    knots, kidx = _spline_knots(path)
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
    t = _sample_times(traj, spline(grid), t_grid)
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
    return TimedPath(t=t, q=q, qd=qd, qdd=qdd, knots=knots, sd=sd, duration=float(t[-1]),
                     waypoint_samples=np.minimum(wp, len(t) - 1))


def _limits(robot: Robot, max_accel: ArrayLike, velocity_scale: float
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(vmax, amax, lower, upper)`` (n,) each: the robot's velocity limits times ``velocity_scale``,
    ``max_accel`` for every joint (one value or n), the joint limits."""
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


def build_scene(plan: PlanResult) -> CollisionScene:
    """A CollisionScene of the plan's own robot, gripper, part (sha256-checked) and cell."""
    from ..motion.collision_scene import CollisionScene

    robot = cast("Robot", plan.robot)  # exports refuse a result without a robot
    return CollisionScene(robot, plan.gripper, plan.mesh(), plan.T_world_part, plan.cell)


def _duration(ti: float) -> dict[str, int]:
    """``time_from_start`` of a point at ``ti`` s: whole seconds and nanoseconds."""
    sec = int(math.floor(ti))
    ns = int(round((ti - sec) * 1e9))
    if ns >= 1_000_000_000:
        sec, ns = sec + 1, ns - 1_000_000_000
    return {"sec": sec, "nanosec": ns}


def _points(gid: int, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> list[dict[str, Any]]:
    """The ROS points of a timed motion; PlanningError when two share a time after rounding to nanoseconds."""
    points = [{"positions": qi.tolist(), "velocities": vi.tolist(), "accelerations": ai.tolist(),
               "time_from_start": _duration(ti)} for ti, qi, vi, ai in zip(t, q, qd, qdd)]
    ns_all = [p["time_from_start"]["sec"] * 1_000_000_000 + p["time_from_start"]["nanosec"] for p in points]
    if any(b <= a_ for a_, b in zip(ns_all, ns_all[1:])):
        raise PlanningError(f"grasp {gid}: two points share a time_from_start after rounding to nanoseconds")
    return points


def _summary(plan: PlanResult, vmax: np.ndarray, amax: np.ndarray, duration: float, v_ratio: float, a_ratio: float,
             step: float, deviation: float, opening: float) -> dict[str, Any]:
    """The first entries of the document's ``grasplan`` block: robot, part, limits and what the checks measured."""
    return {
        "robot": cast("Robot", plan.robot).name,
        "part_sha256": plan.part.sha256,
        "part_scale_to_m": plan.part.scale_to_m,
        "duration_s": duration,
        "velocity_limit": vmax.tolist(),
        "acceleration_limit": amax.tolist(),
        "max_velocity_ratio": v_ratio,
        "max_acceleration_ratio": a_ratio,
        "max_step_rad": step,
        "max_deviation_rad": deviation,
        "pregrasp_opening": opening,
    }


def _check_collisions(gid: int, scene: PathChecker, q: np.ndarray, opening: float, deviation: float) -> None:
    """PlanningError when the timed positions ``q``, interpolated at :data:`CHECK_STEP`, collide with
    the jaws at ``opening`` (naming the first contact when the scene can)."""
    if scene.path_free(q, opening, step=CHECK_STEP):
        return
    detail = ""
    first = getattr(scene, "first_collision", None)
    if first is not None:
        for qq in densify(q, CHECK_STEP):
            hit = first(qq, opening)
            if hit:
                detail = f" (first contact: {hit})"
                break
    raise PlanningError(f"grasp {gid}: the timed trajectory collides when interpolated at {CHECK_STEP} rad"
                        f"{detail}; it deviates up to {deviation:.4f} rad from the planned path. "
                        "Export another grasp with --grasp, or re-plan.")


def joint_trajectory(plan: PlanResult, *, grasp_id: int | None = None, max_accel: ArrayLike = DEFAULT_MAX_ACCEL,
                     velocity_scale: float = 1.0, scene: PathChecker | None = None) -> dict[str, Any]:
    """The ``grasplan.joint_trajectory/1`` document for ``grasp_id`` (default: the best planned
    grasp) of a :class:`~grasplan.results.plan_result.PlanResult`.

    The path is timed by :func:`time_parameterize` with the URDF velocity limits times
    ``velocity_scale`` and ``max_accel`` (rad/s^2), at rest at both ends. Verification, fatal when it
    fails: times strictly increasing; start and end at rest at ``q_home`` / ``q_grasp``; every point
    within the joint limits; velocities within the limits at every point and as finite differences
    between points (:func:`_check_timed`); and the sampled positions, interpolated linearly at
    :data:`CHECK_STEP`, collision-free with the jaws at the pre-grasp opening.
    ``scene``: object with ``path_free(qs, opening, *, step)`` (default: :func:`build_scene`).
    Raises PlanningError when the timed trajectory fails a check (never writes an unchecked one).
    """
    g = plan.select(grasp_id)
    robot = cast("Robot", plan.robot)   # select() refuses a result without a robot
    m = cast("Motion", g.motion)        # select() returns a planned grasp: it has its motion
    vmax, amax, lower, upper = _limits(robot, max_accel, velocity_scale)
    path = np.asarray(m.path, dtype=np.float64)
    if np.any(path < lower - 1e-9) or np.any(path > upper + 1e-9):
        raise InputError(f"grasp {g.id}: the planned path leaves the joint limits of {robot.name!r}")
    from .program import is_sequence

    if is_sequence(m):
        return sequence_trajectory(plan, g, vmax=vmax, amax=amax, lower=lower, upper=upper, scene=scene)
    res = time_parameterize(path, vmax, amax)
    t, q, qd, qdd = res.t, res.q, res.qd, res.qdd
    step, v_ratio, v_fd_ratio = _check_timed(g.id, t, q, qd, vmax, lower, upper, path[0], m.q_grasp,
                                             "q_home to q_grasp")
    a_ratio = float(np.max(np.abs(qdd) / amax))
    deviation = float(np.max(point_to_polyline_distance(q, path)))
    opening = float(plan.gripper.pregrasp_opening(g.width))
    _check_collisions(g.id, build_scene(plan) if scene is None else scene, q, opening, deviation)
    points = _points(g.id, t, q, qd, qdd)
    return {
        "schema": SCHEMA,
        "joint_names": list(robot.joint_names),
        "grasp_id": int(g.id),
        "points": points,
        "grasplan": {
            **_summary(plan, vmax, amax, res.duration, max(v_ratio, v_fd_ratio), a_ratio, step, deviation, opening),
            "collision_checked_step_rad": CHECK_STEP,
            "method": "cubic spline through the path densified at 0.005 rad; TOPP-RA (constant-acceleration "
                      "parameterisation), rest to rest",
        },
    }


def _check_timed(gid: int, t: np.ndarray, q: np.ndarray, qd: np.ndarray, vmax: np.ndarray, lower: np.ndarray,
                 upper: np.ndarray, q_start: np.ndarray, q_end: np.ndarray, what: str) -> tuple[float, float, float]:
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


def segment_scenes(plan: PlanResult, mp: MotionProgram, scene: PathChecker) -> list[tuple[PathChecker, float, str]]:
    """For each segment of a sequence (:class:`~grasplan.export.program.MotionProgram`): the scene
    and jaw opening its samples are checked with, and a label of the check. Before the close: the
    plan's scene, jaws at the pre-grasp opening; while attached: ``scene.attached(T_tcp_part)``,
    jaws at the close width; after the open: ``scene.with_part_at(T_world_part_place)``, jaws at
    the open width."""
    g = plan.select(mp.grasp_id)
    m = g.motion
    close = next((e for e in mp.events if e.action == "close"), None)
    opened = next((e for e in mp.events if e.action == "open"), None)
    out: list[tuple[PathChecker, float, str]] = []
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


@dataclass(frozen=True)
class _Pieces:
    """The timed pieces of a sequence, joined: ``t``, ``q``, ``qd``, ``qdd`` over all points; ``rows``
    {path row: its point (a row between two pieces: the arrival)}; per piece the largest ``steps``,
    velocity ratios ``v_ratios``, ``a_ratios`` and ``deviations`` from the path."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    rows: dict[int, int]
    steps: list[float]
    v_ratios: list[float]
    a_ratios: list[float]
    deviations: list[float]


def _timed_pieces(gid: int, path: np.ndarray, cuts: list[int], vmax: np.ndarray, amax: np.ndarray,
                  lower: np.ndarray, upper: np.ndarray) -> _Pieces:
    """One rest-to-rest :func:`time_parameterize` piece between consecutive ``cuts`` (path rows),
    each checked (:func:`_check_timed`); the pieces are joined with a :data:`GRIPPER_DWELL_S` pause
    between them (the first point of a piece repeats the previous end)."""
    ts, qs, qds, qdds = [], [], [], []
    rows: dict[int, int] = {}
    t0 = 0.0
    steps: list[float] = []
    v_ratios: list[float] = []
    deviations: list[float] = []
    a_ratios: list[float] = []
    n_points = 0
    for a, b in zip(cuts[:-1], cuts[1:]):
        piece = path[a:b + 1]
        res = time_parameterize(piece, vmax, amax)
        t, q, qd, qdd = res.t, res.q, res.qd, res.qdd
        step, v1, v2 = _check_timed(gid, t, q, qd, vmax, lower, upper, piece[0], piece[-1],
                                    f"path row {a} to row {b}")
        steps.append(step)
        v_ratios.append(max(v1, v2))
        a_ratios.append(float(np.max(np.abs(qdd) / amax)))
        deviations.append(float(np.max(point_to_polyline_distance(q, piece))))
        if n_points:  # the event's dwell: the piece's first point (= the previous end) repeated later
            t0 += GRIPPER_DWELL_S
        for r, w in zip(range(a, b + 1), res.waypoint_samples):
            if r not in rows or r == a:  # a boundary row: the first of its two points (the arrival)
                rows.setdefault(r, n_points + int(w))
        ts.append(t + t0)
        qs.append(q)
        qds.append(qd)
        qdds.append(qdd)
        t0 += float(t[-1])
        n_points += len(t)
    return _Pieces(np.concatenate(ts), np.concatenate(qs), np.concatenate(qds), np.concatenate(qdds), rows,
                   steps, v_ratios, a_ratios, deviations)


def _segment_points(mp: MotionProgram, rows: dict[int, int]) -> list[tuple[int, int]]:
    """``(first, last)`` point of each segment of ``mp``: a segment starting at a gripper event starts
    after the dwell (the repeated point)."""
    out = []
    for seg in mp.segments:
        lo, hi = rows[seg.start], rows[seg.end]
        if seg.start in [e.index for e in mp.events]:  # start after the dwell (same position)
            lo += 1
        out.append((lo, hi))
    return out


def _check_segments(gid: int, plan: PlanResult, mp: MotionProgram, scene: PathChecker, q: np.ndarray,
                    spans: list[tuple[int, int]], deviation: float) -> list[dict[str, Any]]:
    """Each segment's points re-checked for collisions with its own scene (:func:`segment_scenes`);
    PlanningError at the first that collides. Returns what was checked, per segment."""
    checked = []
    for seg, (lo, hi), (sc, opening, what) in zip(mp.segments, spans, segment_scenes(plan, mp, scene)):
        if not sc.path_free(q[lo:hi + 1], opening, step=CHECK_STEP):
            raise PlanningError(f"grasp {gid}: the timed trajectory collides in the {seg.label} segment "
                                f"({what}) when interpolated at {CHECK_STEP} rad; it deviates up to {deviation:.4f} "
                                "rad from the planned path. Export another grasp with --grasp, or re-plan.")
        checked.append({"segment": seg.label, "opening": float(opening), "scene": what})
    return checked


def sequence_trajectory(plan: PlanResult, g: GraspView, *, vmax: np.ndarray, amax: np.ndarray, lower: np.ndarray,
                        upper: np.ndarray, scene: PathChecker | None = None) -> dict[str, Any]:
    """The joint trajectory of a pick(-and-place) sequence: one rest-to-rest TOPP-RA piece between
    gripper events (the robot stops at each event and stands still for :data:`GRIPPER_DWELL_S`:
    the point is repeated), every segment re-checked for collisions with its own scene (see
    :func:`segment_scenes`). Adds ``segments`` (point ranges) and ``gripper`` (point and time of
    each event) to the document."""
    from .program import SEGMENT_TEXT, motion_program

    mp = motion_program(plan, g.id)
    path = np.asarray(cast("Motion", g.motion).path, dtype=np.float64)
    k = len(path)
    cuts = sorted({0, k - 1} | {e.index for e in mp.events if 0 < e.index < k - 1})
    pc = _timed_pieces(g.id, path, cuts, vmax, amax, lower, upper)
    t, q, rows = pc.t, pc.q, pc.rows
    if np.any(np.diff(t) <= 0):
        raise PlanningError(f"grasp {g.id}: the timed trajectory fails its checks: times not strictly increasing")
    for r in range(k):  # every waypoint is a point of the trajectory
        if np.max(np.abs(q[rows[r]] - path[r])) > 1e-9:
            raise PlanningError(f"grasp {g.id}: the timed trajectory misses path row {r}")
    spans = _segment_points(mp, rows)
    checked = _check_segments(g.id, plan, mp, build_scene(plan) if scene is None else scene, q, spans,
                              max(pc.deviations))
    points = _points(g.id, t, q, pc.qd, pc.qdd)
    seg_doc = [{"label": seg.label, "start": lo, "end": hi, "path_start": seg.start, "path_end": seg.end,
                "linear": seg.linear, "attached": seg.attached, "description": SEGMENT_TEXT[seg.label]}
               for seg, (lo, hi) in zip(mp.segments, spans)]
    grip_doc = [{"action": e.action, "width": e.width, "path_index": e.index, "point": rows[e.index],
                 "time_from_start": points[rows[e.index]]["time_from_start"], "dwell_s": GRIPPER_DWELL_S}
                for e in mp.events]
    return {
        "schema": SCHEMA,
        "joint_names": list(cast("Robot", plan.robot).joint_names),
        "grasp_id": int(g.id),
        "points": points,
        "segments": seg_doc,
        "gripper": grip_doc,
        "grasplan": {
            **_summary(plan, vmax, amax, float(t[-1]), max(pc.v_ratios), max(pc.a_ratios), max(pc.steps),
                       max(pc.deviations), mp.pregrasp_opening),
            "gripper_dwell_s": GRIPPER_DWELL_S,
            "collision_checked_step_rad": CHECK_STEP,
            "collision_checks": checked,
            "method": "per piece between gripper events: cubic spline through the path densified at 0.005 rad; "
                      "TOPP-RA (constant-acceleration parameterisation), rest to rest; the robot stands still "
                      f"{GRIPPER_DWELL_S} s at each gripper event (the point is repeated)",
        },
    }


def _render(plan: PlanResult, opts: ExportOptions) -> dict[str, str]:
    """The ``joint-trajectory`` export: the document as JSON."""
    from ..io import to_json_text

    doc = joint_trajectory(plan, grasp_id=opts.grasp_id, max_accel=opts.max_accel, velocity_scale=opts.velocity_scale)
    return {".json": to_json_text(doc, indent=1) + "\n"}


register(ExportFormat(name="joint-trajectory", extension=".json", render=_render,
                      description="ROS JointTrajectory (JSON), TOPP-RA timed within the limits, re-checked for collisions."))
