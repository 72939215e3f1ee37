"""Inverse kinematics: a closed-form UR solver (all eight branches) and Pinocchio CLIK.

:func:`solve_ik` is the entry point. For ``kind: ur`` robots the closed-form solver runs first;
every one of its solutions is checked by Pinocchio FK (position <= ``pos_tol`` = 1e-6 m,
orientation <= ``rot_tol`` = 1e-6 rad) and wrapped into the joint limits (each joint shifted by
multiples of 2 pi towards the reference configuration). Generic robots (and UR targets where the
closed form yields nothing verified although the wrist centre is within reach) use damped least
squares CLIK from several deterministic seeds (q_ref, q_home, then seeded random configurations
within the limits), with the joint limits enforced at every step.

Results never raise for an unreachable target: :class:`IKResult` holds zero solutions and a
``reason``. Solutions are deduplicated and sorted by the distance (Euclidean norm of the joint
difference) to the reference configuration ``q_ref`` (default: ``robot.q_home``).

UR frame conventions (derived from the Pinocchio model, proven by tests): the closed form uses the
classic UR DH chain whose frame 0 is the URDF frame ``base`` (``base_link`` rotated 180 deg about
z) and whose frame 6 is a flange frame on the wrist-3 axis; the joint angles are identical to the
URDF's (no offsets). The DH lengths d1, a2, a3, d4, d5, d6 are read from the model's joint
placements; the constant transform from DH frame 6 to the robot's tool frame is measured once at
q = 0, and the whole chain is verified against Pinocchio FK on random configurations when the
solver is built (if that check fails, the closed form is disabled and CLIK is used).
"""
from __future__ import annotations

import math
import threading
import weakref
from dataclasses import dataclass
from typing import Literal

import numpy as np
import pinocchio as pin

from .errors import InputError
from .robot import Robot
from .transforms import check_transform, inv_rigid, pose_error

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class IKResult:
    """IK solutions for one target.

    q: (k, n) float64, sorted by distance to the reference configuration (k may be 0).
    reason: "ok" or why there is no solution ("out_of_reach: ...", "joint_limits: ...",
        "no_convergence: ...").
    method: "analytic", "clik" or "analytic+clik".
    """

    q: np.ndarray
    reason: str
    method: str = ""

    @property
    def ok(self) -> bool:
        return len(self.q) > 0

    @property
    def best(self) -> np.ndarray | None:
        """The solution closest to the reference configuration, or None."""
        return self.q[0] if len(self.q) else None

    def __len__(self) -> int:
        return len(self.q)


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------
def wrap_to_limits(q: np.ndarray, lower: np.ndarray, upper: np.ndarray, q_ref: np.ndarray
                   ) -> np.ndarray | None:
    """Shift each joint by multiples of 2 pi to the value within [lower, upper] closest to q_ref.

    q: (n,) -> (n,) or None when some joint has no 2 pi-equivalent within its limits.
    """
    k = np.round((q_ref - q) / TWO_PI)
    out = q + k * TWO_PI
    # the closest may be outside the limits: try the neighbours
    for j in np.nonzero((out < lower - 1e-12) | (out > upper + 1e-12))[0]:
        cands = out[j] + TWO_PI * np.array([-2, -1, 1, 2])
        cands = cands[(cands >= lower[j] - 1e-12) & (cands <= upper[j] + 1e-12)]
        if len(cands) == 0:
            return None
        out[j] = cands[np.argmin(np.abs(cands - q_ref[j]))]
    return np.clip(out, lower, upper)


def _dedup_sort(sols: list[np.ndarray], q_ref: np.ndarray, n: int, tol: float = 1e-5) -> np.ndarray:
    if not sols:
        return np.zeros((0, n))
    S = np.array(sols)
    order = np.argsort(np.linalg.norm(S - q_ref, axis=1), kind="stable")
    keep: list[np.ndarray] = []
    for i in order:
        if all(np.max(np.abs(S[i] - k)) > tol for k in keep):
            keep.append(S[i])
    return np.array(keep)


# --------------------------------------------------------------------------------------------
# closed-form UR solver
# --------------------------------------------------------------------------------------------
def _dh(theta, d, a, alpha) -> np.ndarray:
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, a * ct],
                     [st, ct * ca, -ct * sa, a * st],
                     [0.0, sa, ca, d],
                     [0.0, 0.0, 0.0, 1.0]])


_ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)


class URAnalytic:
    """Closed-form IK of a UR arm (6R, three parallel axes, spherical-ish wrist offsets).

    Built from the Pinocchio model: DH lengths from the joint placements, ``T_base_dh0`` =
    180 deg about z (the URDF ``base`` frame), ``T_dh6_tool`` measured at q = 0. ``ok`` is False
    (with ``why``) when the model does not match the UR structure.
    """

    def __init__(self, robot: Robot):
        self.robot = robot
        m = robot.model
        self.ok = False
        self.why = ""
        if m.nq != 6:
            self.why = f"{m.nq} joints, not 6"
            return
        jp = [m.jointPlacements[i].translation for i in range(1, 7)]
        self.d1 = float(jp[0][2])
        shoulder_offset = float(jp[1][1])
        self.a2 = -float(jp[2][2])
        elbow_offset = float(jp[2][1])
        self.a3 = -float(jp[3][2])
        self.d4 = shoulder_offset + elbow_offset + float(jp[4][1])
        self.d5 = float(jp[5][2])
        # d6: offset of the tool frame along the wrist-3 axis (the joint's local y for UR URDFs)
        T_j6_tool = m.frames[robot.tool_frame_id].placement
        if robot.tool_joint_id != 6:
            self.why = "the tool frame does not move with joint 6"
            return
        axis6 = np.asarray(m.joints[6].shortname() == "JointModelRY" and [0, 1, 0] or [0, 0, 0], float)
        if not np.any(axis6):
            self.why = f"wrist 3 axis is not y ({m.joints[6].shortname()})"
            return
        self.d6 = float(T_j6_tool.translation @ axis6)
        self.T_urdf_dh0 = np.diag([-1.0, -1.0, 1.0, 1.0])  # base_link -> DH frame 0 ("base")
        # DH frame 6 -> tool frame, measured at q = 0
        data = m.createData()
        q0 = np.zeros(6)
        pin.forwardKinematics(m, data, q0)
        T_tool0 = pin.updateFramePlacement(m, data, robot.tool_frame_id).homogeneous
        self.T_dh6_tool = inv_rigid(self.fk_dh(q0)) @ inv_rigid(self.T_urdf_dh0) @ T_tool0
        self.T_tool_dh6 = inv_rigid(self.T_dh6_tool)
        # prove the chain against Pinocchio on random configurations
        rng = np.random.default_rng(12345)
        for q in rng.uniform(-math.pi, math.pi, size=(20, 6)):
            pin.forwardKinematics(m, data, q)
            T_pin = pin.updateFramePlacement(m, data, robot.tool_frame_id).homogeneous
            T_me = self.T_urdf_dh0 @ self.fk_dh(q) @ self.T_dh6_tool
            dp, dr = pose_error(T_pin, T_me)
            if dp > 1e-9 or dr > 1e-9:
                self.why = f"DH chain derived from the model disagrees with Pinocchio FK ({dp:.2e} m)"
                return
        self.ok = True

    def fk_dh(self, q) -> np.ndarray:
        d = (self.d1, 0.0, 0.0, self.d4, self.d5, self.d6)
        a = (0.0, self.a2, self.a3, 0.0, 0.0, 0.0)
        T = np.eye(4)
        for i in range(6):
            T = T @ _dh(q[i], d[i], a[i], _ALPHA[i])
        return T

    def solve(self, T_base_tool: np.ndarray) -> tuple[list[np.ndarray], str]:
        """Up to eight raw solutions (angles in (-pi, pi]) for T_base_tool (the robot's model
        frame, i.e. base_link) and a reason when there are none."""
        T = inv_rigid(self.T_urdf_dh0) @ T_base_tool @ self.T_tool_dh6  # DH0 -> DH6
        d1, a2, a3, d4, d5, d6 = self.d1, self.a2, self.a3, self.d4, self.d5, self.d6
        R, p = T[:3, :3], T[:3, 3]
        p05 = p - d6 * R[:, 2]
        r = math.hypot(p05[0], p05[1])
        if r < abs(d4) - 1e-12:
            return [], "out_of_reach: wrist centre inside the shoulder cylinder (|p05_xy| < d4)"
        phi = math.atan2(p05[1], p05[0])
        s = max(-1.0, min(1.0, d4 / r)) if r > 0 else 0.0
        th1s = (phi + math.asin(s), phi + math.pi - math.asin(s))
        sols: list[np.ndarray] = []
        reason = "out_of_reach: target beyond the arm's reach"
        for th1 in th1s:
            s1, c1 = math.sin(th1), math.cos(th1)
            a6 = R.T @ np.array([s1, -c1, 0.0])  # common axis of joints 2-4, in frame 6
            c5 = max(-1.0, min(1.0, a6[2]))
            for sign5 in (1.0, -1.0):
                th5 = sign5 * math.acos(c5)
                s5 = math.sin(th5)
                if abs(s5) < 1e-10:
                    th6 = 0.0  # wrist singularity: theta6 is free; theta4 absorbs it
                else:
                    th6 = math.atan2(-a6[1] / s5, a6[0] / s5)
                T01 = _dh(th1, d1, 0.0, _ALPHA[0])
                T45 = _dh(th5, d5, 0.0, _ALPHA[4])
                T56 = _dh(th6, d6, 0.0, _ALPHA[5])
                T14 = inv_rigid(T01) @ T @ inv_rigid(T45 @ T56)
                x, y = T14[0, 3], T14[1, 3]
                c3 = (x * x + y * y - a2 * a2 - a3 * a3) / (2.0 * a2 * a3)
                if c3 > 1.0 + 1e-9 or c3 < -1.0 - 1e-9:
                    continue
                c3 = max(-1.0, min(1.0, c3))
                for sign3 in (1.0, -1.0):
                    th3 = sign3 * math.acos(c3)
                    th2 = math.atan2(y, x) - math.atan2(a3 * math.sin(th3), a2 + a3 * math.cos(th3))
                    th234 = math.atan2(T14[1, 0], T14[0, 0])
                    th4 = th234 - th2 - th3
                    q = np.array([th1, th2, th3, th4, th5, th6])
                    sols.append((q + math.pi) % TWO_PI - math.pi)
        return sols, ("ok" if sols else reason)


# --------------------------------------------------------------------------------------------
# CLIK
# --------------------------------------------------------------------------------------------
class CLIK:
    """Damped least squares CLIK on the tool frame; owns its ``pin.Data``."""

    def __init__(self, robot: Robot, *, max_iter: int = 200, damping: float = 1e-6, step: float = 1.0):
        self.robot = robot
        self.data = robot.model.createData()
        self.max_iter = max_iter
        self.damping = damping
        self.step = step

    def solve_one(self, oMdes: pin.SE3, q0: np.ndarray, pos_tol: float, rot_tol: float
                  ) -> np.ndarray | None:
        m, d, fid = self.robot.model, self.data, self.robot.tool_frame_id
        lo, hi = self.robot.lower, self.robot.upper
        q = np.clip(q0.astype(float), lo, hi)
        eye6 = np.eye(6)
        for _ in range(self.max_iter):
            pin.forwardKinematics(m, d, q)
            oMf = pin.updateFramePlacement(m, d, fid)
            iMd = oMf.actInv(oMdes)
            err = pin.log6(iMd).vector
            if np.linalg.norm(err[:3]) < 0.1 * pos_tol and np.linalg.norm(err[3:]) < 0.1 * rot_tol:
                return q
            J = pin.computeFrameJacobian(m, d, q, fid, pin.ReferenceFrame.LOCAL)
            J = -pin.Jlog6(iMd.inverse()) @ J
            lam = self.damping + 1e-3 * float(err @ err)  # more damping far from the target
            v = -J.T @ np.linalg.solve(J @ J.T + lam * eye6, err)
            q = np.clip(q + self.step * v, lo, hi)
        pin.forwardKinematics(m, d, q)
        oMf = pin.updateFramePlacement(m, d, fid)
        dp, dr = pose_error(oMf.homogeneous, oMdes.homogeneous)
        return q if (dp <= pos_tol and dr <= rot_tol) else None

    def fk(self, q) -> np.ndarray:
        """T_world_tool (4, 4) with this solver's own data."""
        m, d = self.robot.model, self.data
        pin.framesForwardKinematics(m, d, np.asarray(q, dtype=np.float64))
        return self.robot.T_world_base @ d.oMf[self.robot.tool_frame_id].homogeneous

    def track(self, T_world_tool: np.ndarray, q_seed: np.ndarray, *, iters: int = 20, pos_tol: float = 1e-6,
              rot_tol: float = 1e-5, damping: float = 1e-6) -> np.ndarray | None:
        """Newton / damped least squares from ``q_seed`` without joint clipping, for following a
        Cartesian path in small steps (the caller checks limits and jumps); q (n,) or None."""
        m, d, fid = self.robot.model, self.data, self.robot.tool_frame_id
        target = pin.SE3(inv_rigid(self.robot.T_world_base) @ np.asarray(T_world_tool, dtype=np.float64))
        q = np.array(q_seed, dtype=np.float64)
        eye6 = np.eye(6)
        for _ in range(iters):
            pin.framesForwardKinematics(m, d, q)
            err = pin.log6(d.oMf[fid].actInv(target)).vector  # in the tool (LOCAL) frame
            if np.linalg.norm(err[:3]) < pos_tol and np.linalg.norm(err[3:]) < rot_tol:
                return q
            J = pin.computeFrameJacobian(m, d, q, fid, pin.LOCAL)
            q = pin.integrate(m, q, J.T @ np.linalg.solve(J @ J.T + damping * eye6, err))
        return None


# --------------------------------------------------------------------------------------------
# solver object and entry point
# --------------------------------------------------------------------------------------------
class IKSolver:
    """IK for one robot; owns its scratch ``pin.Data`` (not thread-safe: one per thread)."""

    def __init__(self, robot: Robot):
        self.robot = robot
        self.data = robot.model.createData()
        self.analytic = URAnalytic(robot) if robot.kind == "ur" else None
        self.clik = CLIK(robot)

    def _verify(self, q: np.ndarray, T_base_tool: np.ndarray, pos_tol: float, rot_tol: float) -> bool:
        m, d = self.robot.model, self.data
        pin.forwardKinematics(m, d, q)
        T = pin.updateFramePlacement(m, d, self.robot.tool_frame_id).homogeneous
        dp, dr = pose_error(T, T_base_tool)
        return dp <= pos_tol and dr <= rot_tol

    def seeds(self, q_ref: np.ndarray, n_random: int, seed: int) -> np.ndarray:
        r = self.robot
        rng = np.random.default_rng(seed)
        rand = rng.uniform(r.lower, r.upper, size=(n_random, r.nq))
        return np.vstack([q_ref, r.q_home, rand])

    def solve(self, T_world_tool, *, seeds=None, n_random_seeds: int = 10, seed: int = 0,
              q_ref=None, method: Literal["auto", "analytic", "clik"] = "auto",
              max_solutions: int | None = None, pos_tol: float = 1e-6, rot_tol: float = 1e-6
              ) -> IKResult:
        r = self.robot
        T_world_tool = check_transform(T_world_tool, "T_world_tool")
        q_ref = r.q_home.copy() if q_ref is None else r.check_q(q_ref, where="q_ref")
        if method not in ("auto", "analytic", "clik"):
            raise InputError(f"method: expected 'auto', 'analytic' or 'clik', got {method!r}")
        T_base_tool = inv_rigid(r.T_world_base) @ T_world_tool
        sols: list[np.ndarray] = []
        reason = ""
        used = []
        use_analytic = method in ("auto", "analytic") and self.analytic is not None and self.analytic.ok
        if method == "analytic" and not use_analytic:
            why = self.analytic.why if self.analytic is not None else f"robot kind {r.kind!r} is not 'ur'"
            raise InputError(f"method='analytic' is not available for robot {r.name!r}: {why}")
        if use_analytic:
            used.append("analytic")
            raw, reason = self.analytic.solve(T_base_tool)
            n_lim = 0
            for q in raw:
                qw = wrap_to_limits(q, r.lower, r.upper, q_ref)
                if qw is None:
                    n_lim += 1
                    continue
                if self._verify(qw, T_base_tool, pos_tol, rot_tol):
                    sols.append(qw)
            if raw and not sols:
                reason = (f"joint_limits: all {len(raw)} closed-form solutions are outside the limits"
                          if n_lim == len(raw) else "no_convergence: closed-form solutions failed the FK check")
            # CLIK only when the closed form found a candidate that failed (numerical edge cases)
            if sols or not raw or method == "analytic":
                out = _dedup_sort(sols, q_ref, r.nq)
                if max_solutions is not None:
                    out = out[:max_solutions]
                return IKResult(out, "ok" if len(out) else reason, "analytic")
        used.append("clik")
        oMdes = pin.SE3(T_base_tool[:3, :3].copy(), T_base_tool[:3, 3].copy())
        S = self.seeds(q_ref, n_random_seeds, seed) if seeds is None else np.atleast_2d(
            np.asarray(seeds, dtype=float))
        if S.ndim != 2 or S.shape[1] != r.nq:
            raise InputError(f"seeds: expected shape (k, {r.nq}), got {S.shape}")
        for q0 in S:
            q = self.clik.solve_one(oMdes, q0, pos_tol, rot_tol)
            if q is not None:
                sols.append(q)
                if max_solutions is not None and len(_dedup_sort(sols, q_ref, r.nq)) >= max_solutions:
                    break
        out = _dedup_sort(sols, q_ref, r.nq)
        if max_solutions is not None:
            out = out[:max_solutions]
        if len(out):
            reason = "ok"
        elif not reason:
            reason = f"no_convergence: CLIK failed from all {len(S)} seeds (unreachable or at the joint limits)"
        return IKResult(out, reason, "+".join(used))


_tls = threading.local()


def get_solver(robot: Robot) -> IKSolver:
    """The calling thread's cached :class:`IKSolver` for ``robot``."""
    cache = getattr(_tls, "cache", None)
    if cache is None:
        cache = _tls.cache = weakref.WeakKeyDictionary()
    s = cache.get(robot)
    if s is None:
        s = cache[robot] = IKSolver(robot)
    return s


def solve_ik(robot: Robot, T_world_tool, *, seeds=None, n_random_seeds: int = 10, seed: int = 0,
             q_ref=None, method: Literal["auto", "analytic", "clik"] = "auto",
             max_solutions: int | None = None, pos_tol: float = 1e-6, rot_tol: float = 1e-6
             ) -> IKResult:
    """IK of the tool frame (``robot.tool_frame``) for ``T_world_tool`` (4, 4).

    seeds: optional (k, n) CLIK start configurations (default: q_ref, q_home and
        ``n_random_seeds`` uniform random ones drawn with ``seed``).
    q_ref: reference (n,) for 2 pi wrapping and sorting (default ``robot.q_home``).
    method: "auto" (closed form for UR arms, CLIK otherwise or as fallback), "analytic", "clik".
    Returns an :class:`IKResult`; zero solutions with a reason when unreachable (never raises for
    an unreachable target; raises InputError for a malformed matrix). Deterministic.
    """
    return get_solver(robot).solve(T_world_tool, seeds=seeds, n_random_seeds=n_random_seeds,
                                   seed=seed, q_ref=q_ref, method=method,
                                   max_solutions=max_solutions, pos_tol=pos_tol, rot_tol=rot_tol)
