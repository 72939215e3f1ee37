"""Inverse kinematics of a robot's tool frame: the IK families' closed forms, then Pinocchio CLIK.

:func:`solve_ik` is the entry point (its docstring gives the order of the solvers and the checks).
Results never raise for an unreachable target: :class:`IKResult` holds zero solutions and a
``reason``. Solutions are deduplicated and sorted by the distance (Euclidean norm of the joint
difference) to the reference configuration ``q_ref`` (default: ``robot.q_home``).

Adding a family: a module that builds its closed form (a :class:`~grasplan.robot.ik.registry.ClosedFormIK`)
and ends with ``FAMILY = register(IKFamily(...))``, plus its entry in :data:`BUILTIN_FAMILIES`.
"""
from __future__ import annotations

import math
import threading
import weakref
from dataclasses import dataclass
from typing import Literal

import numpy as np
import pinocchio as pin

from ...errors import InputError
from ..model import Robot
from ...geometry.transforms import check_transform, inv_rigid
from . import clik, ur
from .clik import CLIK
from .registry import FAMILIES, ClosedFormIK, IKFamily, get_family
from .solution_kernels import select_solutions
from .solution_kernels import wrap_rows as wrap_many  # :func:`wrap_to_limits` of every row

#: the shipped IK families (importing their modules registered them)
BUILTIN_FAMILIES: tuple[IKFamily, ...] = (clik.FAMILY, ur.FAMILY)

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
    out, ok = wrap_many(np.asarray(q, dtype=np.float64)[None], lower, upper, q_ref)
    return out[0] if ok[0] else None


#: two solutions closer than this in every joint (rad) are one
DEDUP_TOL = 1e-5


def _dedup_sort(sols: list[np.ndarray], q_ref: np.ndarray, n: int, tol: float = DEDUP_TOL) -> np.ndarray:
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
# solver object and entry point
# --------------------------------------------------------------------------------------------
class IKSolver:
    """IK for one robot; owns its scratch ``pin.Data`` (not thread-safe: one per thread).

    ``analytic``: the closed form of the robot's IK family, built for this solver (None when the
    family has none or the robot does not fit it: ``no_closed_form`` says why); ``clik``: the
    numeric solver with its own ``pin.Data``.
    """

    def __init__(self, robot: Robot):
        self.robot = robot
        self.data = robot.model.createData()
        self.T_base_world = inv_rigid(robot.T_world_base)
        family = get_family(robot.kind, where=f"robot {robot.name!r}")
        if family.closed_form is None:
            with_one = ", ".join(sorted(n for n, f in FAMILIES.items() if f.closed_form is not None))
            self.no_closed_form = f"IK family {family.name!r} has no closed form (families with one: {with_one})"
        else:
            self.no_closed_form = family.eligible(robot)
        self.analytic: ClosedFormIK | None = (
            family.closed_form(robot) if family.closed_form is not None and not self.no_closed_form else None)
        if self.analytic is not None and not self.analytic.ok:
            self.no_closed_form = self.analytic.why
        self.clik = CLIK(robot)

    def _reached(self, qs: np.ndarray) -> np.ndarray:
        """Pinocchio's tool poses (k, 4, 4) in the base frame at each of ``qs`` (k, nq)."""
        m, d, fid = self.robot.model, self.data, self.robot.tool_frame_id
        T = np.empty((len(qs), 4, 4))
        for k, q in enumerate(qs):
            pin.forwardKinematics(m, d, q)
            T[k] = pin.updateFramePlacement(m, d, fid).homogeneous
        return T

    def seeds(self, q_ref: np.ndarray, n_random: int, seed: int) -> np.ndarray:
        r = self.robot
        rng = np.random.default_rng(seed)
        rand = rng.uniform(r.lower, r.upper, size=(n_random, r.nq))
        return np.vstack([q_ref, r.q_home, rand])

    def solve(self, T_world_tool: np.ndarray, *, seeds: np.ndarray | None = None, n_random_seeds: int = 10,
              seed: int = 0, q_ref: np.ndarray | None = None, method: Literal["auto", "analytic", "clik"] = "auto",
              max_solutions: int | None = None, pos_tol: float = 1e-6, rot_tol: float = 1e-6
              ) -> IKResult:
        r = self.robot
        T_world_tool = check_transform(T_world_tool, "T_world_tool")
        q_ref = r.q_home.copy() if q_ref is None else r.check_q(q_ref, where="q_ref")
        if method not in ("auto", "analytic", "clik"):
            raise InputError(f"method: expected 'auto', 'analytic' or 'clik', got {method!r}")
        T_base_tool = self.T_base_world @ T_world_tool
        sols: list[np.ndarray] = []
        reason = ""
        used: list[str] = []
        closed = self.analytic if self.analytic is not None and self.analytic.ok else None
        if method == "analytic" and closed is None:
            raise InputError(f"method='analytic' is not available for robot {r.name!r}: {self.no_closed_form}")
        if closed is not None and method in ("auto", "analytic"):
            used.append("analytic")
            raw, reason = closed.solve(T_base_tool)
            if len(raw):
                W, in_limits = wrap_many(raw, r.lower, r.upper, q_ref)
                W = W[in_limits]
                # every one checked by Pinocchio's FK; nearest q_ref first, one within the dedup
                # tolerance of one kept dropped, at most max_solutions
                kept = select_solutions(W, self._reached(W), T_base_tool, q_ref, pos_tol, rot_tol, DEDUP_TOL,
                                        len(W) if max_solutions is None else max_solutions).tolist()
                sols = [W[i] for i in kept]
                if not sols:
                    reason = (f"joint_limits: all {len(raw)} closed-form solutions are outside the limits"
                              if not in_limits.any() else "no_convergence: closed-form solutions failed the FK check")
            # CLIK only when the closed form found a candidate that failed (numerical edge cases)
            if sols or not len(raw) or method == "analytic":
                out = np.array(sols).reshape(-1, r.nq)
                return IKResult(out, "ok" if len(out) else reason, "analytic")
        used.append("clik")
        oMdes = pin.SE3(T_base_tool[:3, :3].copy(), T_base_tool[:3, 3].copy())
        S = self.seeds(q_ref, n_random_seeds, seed) if seeds is None else np.atleast_2d(
            np.asarray(seeds, dtype=float))
        if S.ndim != 2 or S.shape[1] != r.nq:
            raise InputError(f"seeds: expected shape (k, {r.nq}), got {S.shape}")
        for q0 in S:
            q_sol = self.clik.solve_one(oMdes, q0, pos_tol, rot_tol)
            if q_sol is not None:
                sols.append(q_sol)
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


def solve_ik(robot: Robot, T_world_tool: np.ndarray, *, seeds: np.ndarray | None = None,
             n_random_seeds: int = 10, seed: int = 0, q_ref: np.ndarray | None = None, method: Literal["auto", "analytic", "clik"] = "auto",
             max_solutions: int | None = None, pos_tol: float = 1e-6, rot_tol: float = 1e-6
             ) -> IKResult:
    """IK of the tool frame (``robot.tool_frame``) for ``T_world_tool`` (4, 4).

    The robot YAML's ``kind:`` names an IK family (:mod:`grasplan.robot.ik.registry`); when that
    family has a closed form that fits the robot (``ur``: :mod:`grasplan.robot.ik.ur`, all eight
    branches), it runs first: every one of its solutions is checked by Pinocchio FK (position <=
    ``pos_tol`` = 1e-6 m, orientation <= ``rot_tol`` = 1e-6 rad) and wrapped into the joint limits
    (each joint shifted by multiples of 2 pi towards the reference configuration). Other robots
    (``generic``), and targets where the closed form yields candidates but none verified, use damped
    least squares CLIK (:mod:`grasplan.robot.ik.clik`) from several deterministic seeds (q_ref,
    q_home, then seeded random configurations within the limits), with the joint limits enforced at
    every step.

    seeds: optional (k, n) CLIK start configurations (default: q_ref, q_home and
        ``n_random_seeds`` uniform random ones drawn with ``seed``).
    q_ref: reference (n,) for 2 pi wrapping and sorting (default ``robot.q_home``).
    method: "auto" (the family's closed form where it fits, CLIK otherwise or as fallback),
        "analytic" (closed form only; InputError when the robot has none), "clik".
    Returns an :class:`IKResult`; zero solutions with a reason when unreachable (never raises for
    an unreachable target; raises InputError for a malformed matrix). Deterministic.
    """
    return get_solver(robot).solve(T_world_tool, seeds=seeds, n_random_seeds=n_random_seeds,
                                   seed=seed, q_ref=q_ref, method=method,
                                   max_solutions=max_solutions, pos_tol=pos_tol, rot_tol=rot_tol)
