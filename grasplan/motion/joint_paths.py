"""Joint-space paths (OMPL RRTConnect) and straight-line TCP approaches.

Two functions, both pure given their inputs (a robot model, a collision scene or a validity
callable, start/goal), both deterministic for a given ``seed``: :func:`plan_joint_path` (a
collision-free joint path between two configurations, verified independently) and
:func:`approach_path_reason` (joint waypoints moving the TCP on a straight line, with
:func:`approach_path` returning only the path).

Conventions: joint vectors are ``(n,)`` float64 radians; paths are ``(k, n)`` arrays whose first row
is the start and whose last row is the goal. Transforms are 4x4 ``T_<parent>_<child>`` matrices.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..robot.ik.lines import closed_form_line, ur_closed_form
from ..robot.ik.solve import get_solver
from ..geometry.interpolation import STEP, interpolate_path
from ..robot.model import Robot
from .collision_scene import CollisionScene
from ..geometry.transforms import check_transform

Validity = Callable[[np.ndarray], bool]
#: a path checker: ``(path (k, n), step) -> bool``
PathCheck = Callable[[np.ndarray, float], bool]


# --------------------------------------------------------------------------------------------------
# independent path checking (densified by grasplan.geometry.interpolation.interpolate_path)
# --------------------------------------------------------------------------------------------------
def path_free_fn(validity: Validity, path: np.ndarray, *, step: float = STEP) -> bool:
    """``True`` when ``validity(q)`` holds at every point of ``interpolate_path(path, step=step)``."""
    return all(bool(validity(q)) for q in interpolate_path(path, step=step))


def _validity_and_checker(scene_or_validity: CollisionScene | Validity, opening: float | None
                          ) -> tuple[Validity, PathCheck]:
    """(state validity q -> bool, path checker (k, n) -> bool) for a scene or a plain callable."""
    if not isinstance(scene_or_validity, CollisionScene):
        fn = scene_or_validity
        return fn, (lambda path, step: path_free_fn(fn, path, step=step))
    scene = scene_or_validity
    if opening is None:
        raise ValueError("opening (jaw opening, m) is required when planning against a CollisionScene")
    o = opening
    return (lambda q: scene.is_free(q, o)), (lambda path, step: scene.path_free(path, o, step=step))


# --------------------------------------------------------------------------------------------------
# OMPL RRTConnect
# --------------------------------------------------------------------------------------------------
def _ompl() -> tuple[Any, Any, Any]:
    """OMPL's ``base``, ``geometric`` and ``util`` modules, its planner chatter (Info:) off."""
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    if ou.getLogLevel().value < ou.LogLevel.LOG_WARN.value:
        ou.setLogLevel(ou.LogLevel.LOG_WARN)  # planner chatter (Info:) off; warnings stay
    return ob, og, ou


def _seed_ompl(ou: Any, seed: int) -> None:
    """Seed OMPL's seed generator: every RNG created afterwards (planner, samplers) is deterministic.

    OMPL logs an error when the seed is changed after the first RNG exists (it still reseeds the
    generator, which is what we want per query), so its log is muted for this one call.
    """
    level = ou.getLogLevel()
    ou.setLogLevel(ou.LogLevel.LOG_NONE)
    try:
        ou.RNG.setSeed(int(seed) % (2**31 - 1) + 1)  # 0 would mean "random"
    finally:
        ou.setLogLevel(level)


def _checked_query(scene_or_validity: CollisionScene | Validity, q_start: np.ndarray, q_goal: np.ndarray,
                   lower: np.ndarray | None, upper: np.ndarray | None, time_limit: float, step: float,
                   attempts: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(q_start, q_goal, lower, upper)`` as (n,) float64, the limits defaulting to the scene robot's;
    ValueError for inconsistent shapes, limits or budgets."""
    q_start = np.asarray(q_start, dtype=np.float64).reshape(-1)
    q_goal = np.asarray(q_goal, dtype=np.float64).reshape(-1)
    n = len(q_start)
    if q_goal.shape != (n,):
        raise ValueError(f"q_start and q_goal must have the same shape (n,), got {q_start.shape} and {q_goal.shape}")
    if lower is None or upper is None:
        if not isinstance(scene_or_validity, CollisionScene):
            raise ValueError("lower and upper joint limits are required with a plain validity callable")
        robot = scene_or_validity.robot
        lower = robot.lower if lower is None else lower
        upper = robot.upper if upper is None else upper
    lower = np.asarray(lower, dtype=np.float64).reshape(-1)
    upper = np.asarray(upper, dtype=np.float64).reshape(-1)
    if lower.shape != (n,) or upper.shape != (n,):
        raise ValueError(f"lower/upper must have shape ({n},), got {lower.shape} and {upper.shape}")
    if not np.all(upper > lower):
        raise ValueError("every upper joint limit must exceed its lower limit")
    if not (time_limit > 0 and step > 0 and attempts >= 1):
        raise ValueError("time_limit and step must be > 0 and attempts >= 1")
    return q_start, q_goal, lower, upper


def _rrt_connect(ob: Any, og: Any, valid: Validity, q_start: np.ndarray, q_goal: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                 *, resolution: float, time_limit: float, simplify: bool) -> np.ndarray | None:
    """One RRTConnect query in the box ``[lower, upper]``, motions checked at ``resolution`` rad
    (Euclidean), shortcut-simplified when ``simplify``; the path (exact end points) or None. ``ob``,
    ``og``: OMPL's ``base`` and ``geometric`` modules."""
    n = len(q_start)
    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    bounds.low = lower.tolist()
    bounds.high = upper.tolist()
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)
    buf = np.empty(n)

    def is_valid(state: Any, _buf: np.ndarray = buf) -> bool:
        for i in range(n):
            _buf[i] = state[i]
        return bool(valid(_buf))

    si.setStateValidityChecker(is_valid)
    # the resolution is a fraction of the space's extent (Euclidean)
    si.setStateValidityCheckingResolution(min(1.0, resolution / space.getMaximumExtent()))
    si.setup()
    ss = og.SimpleSetup(si)
    start, goal = si.allocState(), si.allocState()
    for i in range(n):
        start[i] = float(q_start[i])
        goal[i] = float(q_goal[i])
    ss.setStartAndGoalStates(start, goal)
    ss.setPlanner(og.RRTConnect(si))
    status = ss.solve(float(time_limit))
    if not (status and ss.haveExactSolutionPath()):
        return None
    path_g = ss.getSolutionPath()
    if simplify:
        ps = og.PathSimplifier(si)
        ps.reduceVertices(path_g)
        ps.collapseCloseVertices(path_g)
    states = path_g.getStates()
    path = np.array([[s[i] for i in range(n)] for s in states], dtype=np.float64)
    # exact endpoints (OMPL copies them, but make it bitwise)
    path[0], path[-1] = q_start, q_goal
    return path


def plan_joint_path(
    scene_or_validity: CollisionScene | Validity,
    q_start: np.ndarray,
    q_goal: np.ndarray,
    *,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
    opening: float | None = None,
    seed: int = 0,
    time_limit: float = 2.0,
    step: float = STEP,
    simplify: bool = True,
    attempts: int = 3,
) -> np.ndarray | None:
    """A collision-free joint path ``q_start -> q_goal`` (RRTConnect + simplify), or ``None``.

    RRTConnect (OMPL 2.x) in joint space, then shortcut-simplified (``PathSimplifier.reduceVertices``
    + ``collapseCloseVertices``: a bounded number of random shortcut attempts, not a wall-clock
    budget, so the result does not depend on the machine's speed; ``simplifyMax`` shortens more but
    costs 5-10x the planning time). Motions are checked by OMPL's discrete motion validator with a
    resolution of ``step`` rad (Euclidean in joint space), and the final path is re-verified
    independently by interpolating every segment linearly in ``ceil(max_j |dq_j| / step)`` equal
    sub-steps and checking every sub-step (``CollisionScene.path_free`` for a scene). A path that
    fails the re-check is not returned: the query is retried with another seed and a finer OMPL
    resolution.

    Parameters
    ----------
    scene_or_validity
        A ``CollisionScene`` (``is_free(q, opening)``, ``path_free(qs, opening, step=)``) or a plain
        callable ``validity(q (n,)) -> bool``.
    q_start, q_goal : (n,) float64, rad
        Both must be valid and inside ``[lower, upper]``, else ``None`` is returned.
    lower, upper : (n,) float64, rad
        Joint limits (the sampling bounds). Default: ``scene.robot.lower/upper`` for a scene.
    opening : float, m
        Jaw opening the scene checks the gripper with (required for a scene).
    seed : int
        Seeds OMPL's RNG: the same inputs and seed give the same path.
    time_limit : float, s
        Budget of each RRTConnect attempt (the planner's own termination condition).
    step : float, rad
        Motion-check resolution; the returned path is verified by linear interpolation at ``<= step``
        rad per joint.
    simplify : bool
        Shortcut the raw RRTConnect path (``reduceVertices`` + ``collapseCloseVertices``).
    attempts : int
        Attempts (seed, seed+1, ...; each with a finer OMPL resolution) before giving up.

    Returns
    -------
    (k, n) float64 with ``k >= 2``, first row ``q_start``, last row ``q_goal``; or ``None`` when no
    verified path was found within ``attempts`` x ``time_limit``.
    """
    q_start, q_goal, lower, upper = _checked_query(scene_or_validity, q_start, q_goal, lower, upper, time_limit,
                                                   step, attempts)
    valid, path_ok = _validity_and_checker(scene_or_validity, opening)
    for q in (q_start, q_goal):
        if np.any(q < lower) or np.any(q > upper) or not valid(q):
            return None
    # trivial case: the straight segment is already free
    direct = np.stack([q_start, q_goal])
    if path_ok(direct, step):
        return direct

    ob, og, ou = _ompl()
    for attempt in range(attempts):
        _seed_ompl(ou, seed * 7919 + attempt)
        # halve the resolution on each retry (a path failing the re-check was checked too coarsely)
        path = _rrt_connect(ob, og, valid, q_start, q_goal, lower, upper, resolution=step / (2.0**attempt),
                            time_limit=time_limit, simplify=simplify)
        if path is not None and path_ok(path, step):
            return path
    return None


# --------------------------------------------------------------------------------------------------
# straight-line TCP approach
# --------------------------------------------------------------------------------------------------
def _dist_to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances of points ``p`` (m, 3) to the segment a-b."""
    ab = b - a
    L2 = float(ab @ ab)
    t = np.clip(((p - a) @ ab) / L2, 0.0, 1.0) if L2 > 0 else np.zeros(len(p))
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def approach_path(robot: Robot, scene: CollisionScene | None, T_world_tcp_pre: np.ndarray,
                  T_world_tcp_grasp: np.ndarray, q_pre: np.ndarray, *, opening: float, max_dev: float = 0.002,
                  T_flange_tcp: np.ndarray | None = None, sample: float = 0.001, max_joint_step: float = 0.1,
                  step: float = STEP) -> np.ndarray | None:
    """Joint waypoints moving the TCP on the straight line ``T_world_tcp_pre -> T_world_tcp_grasp``.

    See :func:`approach_path_reason` (same arguments) for the details; this returns only the path
    (``None`` when it fails).
    """
    return approach_path_reason(robot, scene, T_world_tcp_pre, T_world_tcp_grasp, q_pre, opening=opening,
                                max_dev=max_dev, T_flange_tcp=T_flange_tcp, sample=sample,
                                max_joint_step=max_joint_step, step=step)[0]


def _track_line(solver: Any, robot: Robot, q: np.ndarray, T_pre: np.ndarray, b: np.ndarray, m: int,
                T_tcp_flange: np.ndarray, max_joint_step: float) -> tuple[np.ndarray | None, str]:
    """``(path, "ok")`` of ``m`` IK steps from ``q`` moving the TCP from ``T_pre`` to position ``b``
    (orientation kept), each seeded with the previous joint vector; or ``(None, reason)``: ``"ik"``,
    ``"limits"`` or ``"jump"`` (a joint moving more than ``max_joint_step``)."""
    lower = np.asarray(robot.lower, dtype=np.float64)
    upper = np.asarray(robot.upper, dtype=np.float64)
    a, R = T_pre[:3, 3], T_pre[:3, :3]
    qs = [q]
    for i in range(1, m + 1):
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = a + (b - a) * (i / m)
        q_new = solver.track(T @ T_tcp_flange, q)
        if q_new is None:
            return None, "ik"
        if np.any(q_new < lower) or np.any(q_new > upper):
            return None, "limits"
        if np.max(np.abs(q_new - q)) > max_joint_step:
            return None, "jump"
        qs.append(q_new)
        q = q_new
    return np.array(qs), "ok"


def approach_path_reason(
    robot: Robot,
    scene: CollisionScene | None,
    T_world_tcp_pre: np.ndarray,
    T_world_tcp_grasp: np.ndarray,
    q_pre: np.ndarray,
    *,
    opening: float,
    max_dev: float = 0.002,
    T_flange_tcp: np.ndarray | None = None,
    sample: float = 0.001,
    max_joint_step: float = 0.1,
    step: float = STEP,
) -> tuple[np.ndarray | None, str]:
    """Joint waypoints moving the TCP on the straight line ``T_world_tcp_pre -> T_world_tcp_grasp``.

    The two TCP poses must share their orientation (the pre-grasp is the grasp backed off along its
    own -z). TCP poses are sampled every ``sample`` metres. A UR arm solves each exactly on the
    branch ``q_pre`` is on (:func:`grasplan.robot.ik.lines.closed_form_line`, compiled); other arms
    by a damped least-squares IK seeded with the previous joint vector (continuity: no branch
    switch, :func:`_track_line`). The function is symmetric: it follows the line from the first
    pose to the second, starting at ``q_pre`` (which must reach the first pose), so it can also
    trace grasp -> pre-grasp.

    Parameters
    ----------
    robot : grasplan.robot.description.Robot
        ``model``, ``tool_frame_id``, ``q_home``, ``lower``, ``upper``, ``fk(q)``.
    scene : CollisionScene or None
        Checks the approach (``path_free(qs, opening, step=step)``), jaws at ``opening`` (m, the
        pre-grasp opening); ``None`` skips collisions.
    T_world_tcp_pre, T_world_tcp_grasp : (4, 4)
        Start and end TCP poses; ``q_pre`` (n,) reaches the start (``FK(q_pre) @ T_flange_tcp``).
    max_dev : float, m
        Largest TCP distance from the line, checked at every waypoint and the midpoint of each pair
        of consecutive waypoints (the linear joint interpolation a controller executes).
    T_flange_tcp : (4, 4)
        Tool-flange -> TCP; default ``scene.gripper.T_flange_tcp``.
    sample : float, m
        TCP spacing of the waypoints along the line.
    max_joint_step : float, rad
        Largest per-joint change between consecutive waypoints (a larger one is a branch jump).

    Returns
    -------
    (path, reason): path (k, n) float64, first row ``q_pre``, last row a joint vector reaching
    ``T_world_tcp_grasp``, reason ``"ok"``; or ``None`` and the reason: ``"start"`` (q_pre does not
    reach the first pose), ``"ik"`` (IK lost on the line), ``"limits"``, ``"jump"``, ``"deviation"``
    (kinematic failures) or ``"collision"``.
    """
    T_pre = check_transform(T_world_tcp_pre, "T_world_tcp_pre", error=ValueError)
    T_gr = check_transform(T_world_tcp_grasp, "T_world_tcp_grasp", error=ValueError)
    if T_flange_tcp is None:
        if scene is None:
            raise ValueError("T_flange_tcp (4, 4) is required without a scene (default: scene.gripper.T_flange_tcp)")
        T_flange_tcp = scene.gripper.T_flange_tcp
    T_flange_tcp = np.asarray(T_flange_tcp, dtype=np.float64)
    closed = ur_closed_form(robot)
    if closed is not None:  # a UR arm: every waypoint exactly, in one compiled pass (pick's lines too)
        path, reason = closed_form_line(closed, robot, T_pre, T_gr, np.asarray(q_pre, dtype=np.float64),
                                        max_dev=max_dev, T_flange_tcp=T_flange_tcp, sample=sample,
                                        max_joint_step=max_joint_step)
    else:
        path, reason = _clik_line(robot, T_pre, T_gr, q_pre, max_dev=max_dev, T_flange_tcp=T_flange_tcp,
                                  sample=sample, max_joint_step=max_joint_step)
    if path is None:
        return None, reason
    if scene is not None and not scene.path_free(path, opening, step=step):
        return None, "collision"
    return path, "ok"


def _clik_line(robot: Robot, T_pre: np.ndarray, T_gr: np.ndarray, q_pre: np.ndarray, *, max_dev: float,
               T_flange_tcp: np.ndarray, sample: float, max_joint_step: float) -> tuple[np.ndarray | None, str]:
    """The straight line of :func:`approach_path_reason` by the damped least-squares tracker (arms
    without a closed form), collisions not checked."""
    T_tcp_flange = np.linalg.inv(T_flange_tcp)
    solver = get_solver(robot).clik  # this thread's own Pinocchio data
    q = np.asarray(q_pre, dtype=np.float64).copy()

    a, b = T_pre[:3, 3], T_gr[:3, 3]
    length = float(np.linalg.norm(b - a))
    m = max(1, int(np.ceil(length / sample - 1e-12)))
    # start pose must match q_pre
    tcp0 = solver.fk(q) @ T_flange_tcp
    if np.linalg.norm(tcp0[:3, 3] - a) > max_dev * 0.5:
        return None, "start"
    path, reason = _track_line(solver, robot, q, T_pre, b, m, T_tcp_flange, max_joint_step)
    if path is None:
        return None, reason
    # deviation of the executed (joint-linear) motion: waypoints and midpoints
    probes = np.concatenate([path, 0.5 * (path[:-1] + path[1:])], axis=0)
    tcp = np.array([(solver.fk(p) @ T_flange_tcp)[:3, 3] for p in probes])
    if np.max(_dist_to_segment(tcp, a, b)) > max_dev:
        return None, "deviation"
    return path, "ok"
