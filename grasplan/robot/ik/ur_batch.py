"""The UR closed form and its forward kinematics, compiled (:mod:`grasplan.compiled`): one pose or a stack of them.

:class:`grasplan.robot.ik.ur.URAnalytic` builds a :data:`Chain` (DH parameters and the constant frames
around them) and calls these kernels: :func:`solve_one` (all eight branches at one pose, what IK
needs), :func:`branch_many` (one branch, shoulder choice, wrist sign and elbow sign, at every
pose of a stack), :func:`line` (a whole straight TCP line on the start's branch, with its start
and deviation checks: :mod:`grasplan.robot.ik.lines`) and :func:`fk_many`.
The arithmetic is the classic UR closed form (Hawkins, "Analytic inverse kinematics for the
Universal Robots UR-5/UR-10 arms", 2013) on the chain ``T_urdf_dh0 @ A1 ... A6 @ T_dh6_tool``;
the chain is proven against Pinocchio when the closed form is built, and every IK solution is
checked by Pinocchio FK before it is returned (:mod:`grasplan.robot.ik`).

Compiled because NumPy's per-call overhead on small matrices cost ~0.3 ms per line and ~0.15 ms
per IK pose; here a few microseconds, and a whole line is one call.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ...compiled.jit import kernel

TWO_PI = 2.0 * math.pi
#: DH twist angles of the UR chain (rad)
ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
#: the eight branches in the closed form's order: (shoulder th1 choice, wrist sign, elbow sign)
BRANCHES = tuple((i1, s5, s3) for i1 in (0, 1) for s5 in (1.0, -1.0) for s3 in (1.0, -1.0))
_EYE4 = np.eye(4)
_I1 = np.array([b[0] for b in BRANCHES], dtype=np.int64)
_S5 = np.array([b[1] for b in BRANCHES], dtype=np.float64)
_S3 = np.array([b[2] for b in BRANCHES], dtype=np.float64)


class Chain(NamedTuple):
    """A UR arm for the kernels: ``dh`` (6, 3) d, a, alpha per joint; base_link -> DH frame 0 and
    back; DH frame 6 -> tool and back (each (4, 4), C-contiguous float64)."""

    dh: np.ndarray
    T_urdf_dh0: np.ndarray
    T_dh0_urdf: np.ndarray
    T_dh6_tool: np.ndarray
    T_tool_dh6: np.ndarray


def make_chain(d1: float, a2: float, a3: float, d4: float, d5: float, d6: float, T_urdf_dh0: np.ndarray,
               T_dh6_tool: np.ndarray) -> Chain:
    d = (d1, 0.0, 0.0, d4, d5, d6)
    a = (0.0, a2, a3, 0.0, 0.0, 0.0)
    dh = np.array([[d[i], a[i], ALPHA[i]] for i in range(6)], dtype=np.float64)

    def c(T: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(T, dtype=np.float64)
    return Chain(dh, c(T_urdf_dh0), c(np.linalg.inv(T_urdf_dh0)), c(T_dh6_tool), c(np.linalg.inv(T_dh6_tool)))


def fk_many(chain: Chain, q: np.ndarray) -> np.ndarray:
    """Tool poses (m, 4, 4) in the robot's base frame (base_link) for configurations ``q`` (m, 6)."""
    return _fk(np.ascontiguousarray(q, dtype=np.float64).reshape(-1, 6), chain.dh, chain.T_urdf_dh0,
               chain.T_dh6_tool)


def fk_dh(chain: Chain, q: np.ndarray) -> np.ndarray:
    """DH frame 0 -> DH frame 6 (4, 4) at the configuration ``q`` (6,)."""
    return _fk(np.ascontiguousarray(q, dtype=np.float64).reshape(1, 6), chain.dh, _EYE4, _EYE4)[0]


def branch_many(chain: Chain, T_base_tool: np.ndarray, branch: int) -> tuple[np.ndarray, np.ndarray]:
    """``(q (m, 6) in [-pi, pi), valid (m,))``: branch ``branch`` (index into :data:`BRANCHES`) of
    the closed form at the tool poses ``T_base_tool`` (m, 4, 4, base_link frame); invalid where
    the wrist centre lies inside the shoulder cylinder or the elbow cannot close."""
    i1, s5, s3 = BRANCHES[branch]
    T = np.ascontiguousarray(T_base_tool, dtype=np.float64).reshape(-1, 4, 4)
    q, ok_r, ok3 = _branch(T, chain.dh, chain.T_dh0_urdf, chain.T_tool_dh6, np.array([i1]), np.array([s5]),
                           np.array([s3]))
    return q[0], ok_r & ok3[0]


def follow(chain: Chain, T_base_tool: np.ndarray, q0: np.ndarray, branch: int, lower: np.ndarray,
           upper: np.ndarray, max_step: float) -> tuple[np.ndarray, int]:
    """A joint path along the tool poses ``T_base_tool`` (m, 4, 4) on branch ``branch`` from
    ``q0`` (6,) (which must lie on it at the pose before the first): ``(q (m + 1, 6), code)``,
    each row's joints shifted by multiples of 2 pi to the previous row's; ``code`` 0 ok, 1 a pose
    the branch cannot reach, 2 a joint moving more than ``max_step`` (rad) between rows (a
    singularity passed), 3 outside [``lower``, ``upper``]."""
    i1, s5, s3 = BRANCHES[branch]
    T = np.ascontiguousarray(T_base_tool, dtype=np.float64).reshape(-1, 4, 4)
    return _follow(T, np.ascontiguousarray(q0, dtype=np.float64), chain.dh, chain.T_dh0_urdf, chain.T_tool_dh6,
                   i1, s5, s3, np.ascontiguousarray(lower, dtype=np.float64),
                   np.ascontiguousarray(upper, dtype=np.float64), float(max_step))


def line_deviation(chain: Chain, path: np.ndarray, T_world_base: np.ndarray, T_flange_tcp: np.ndarray,
                   a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance (m) from the segment ``a``-``b`` (world) of the TCP at the joint-space
    midpoints of consecutive rows of ``path`` (k, 6): how far the joint-linear motion between
    waypoints strays from a straight TCP line."""
    pre = np.ascontiguousarray(np.asarray(T_world_base, dtype=np.float64) @ chain.T_urdf_dh0)
    post = np.ascontiguousarray(chain.T_dh6_tool @ np.asarray(T_flange_tcp, dtype=np.float64))
    return float(_line_deviation(np.ascontiguousarray(path, dtype=np.float64), chain.dh, pre, post,
                                 np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)))


def solve_one(chain: Chain, T_base_tool: np.ndarray) -> tuple[np.ndarray, bool, np.ndarray]:
    """The eight branches at one tool pose (4, 4): ``(q (8, 6) in [-pi, pi), wrist centre outside
    the shoulder cylinder, elbow closes (8,))``."""
    T = np.ascontiguousarray(T_base_tool, dtype=np.float64).reshape(1, 4, 4)
    q, ok_r, ok3 = _branch(T, chain.dh, chain.T_dh0_urdf, chain.T_tool_dh6, _I1, _S5, _S3)
    return q[:, 0], bool(ok_r[0]), ok3[:, 0]


@kernel(cache=True, nogil=True)
def _dh_into(out: np.ndarray, theta: float, d: float, a: float, alpha: float) -> None:  # pragma: no cover
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    out[0, 0], out[0, 1], out[0, 2], out[0, 3] = ct, -st * ca, st * sa, a * ct
    out[1, 0], out[1, 1], out[1, 2], out[1, 3] = st, ct * ca, -ct * sa, a * st
    out[2, 0], out[2, 1], out[2, 2], out[2, 3] = 0.0, sa, ca, d
    out[3, 0], out[3, 1], out[3, 2], out[3, 3] = 0.0, 0.0, 0.0, 1.0


@kernel(cache=True, nogil=True)
def _mul(A: np.ndarray, B: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    for i in range(4):
        for j in range(4):
            out[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j] + A[i, 3] * B[3, j]


@kernel(cache=True, nogil=True)
def _inv_rigid_into(T: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    for i in range(3):
        for j in range(3):
            out[i, j] = T[j, i]
        out[i, 3] = -(T[0, i] * T[0, 3] + T[1, i] * T[1, 3] + T[2, i] * T[2, 3])
        out[3, i] = 0.0
    out[3, 3] = 1.0


@kernel(cache=True, nogil=True)
def _fk(q: np.ndarray, dh: np.ndarray, T_pre: np.ndarray, T_post: np.ndarray) -> np.ndarray:  # pragma: no cover
    m = q.shape[0]
    out = np.empty((m, 4, 4))
    A = np.empty((4, 4))
    C = np.empty((4, 4))
    D = np.empty((4, 4))
    for k in range(m):
        C[:, :] = T_pre
        for i in range(6):
            _dh_into(A, q[k, i], dh[i, 0], dh[i, 1], dh[i, 2])
            _mul(C, A, D)
            C[:, :] = D
        _mul(C, T_post, D)
        out[k] = D
    return out


@kernel(cache=True, nogil=True)
def _branch(T_base_tool: np.ndarray, dh: np.ndarray, T_pre: np.ndarray, T_post: np.ndarray, i1s: np.ndarray,
            sign5s: np.ndarray, sign3s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover
    """The branches ``(i1s, sign5s, sign3s)`` (each (b,)) at every pose of ``T_pre @ T_base_tool @
    T_post`` (m, 4, 4; DH frame 0 -> DH frame 6): ``(q (b, m, 6), ok_r (m,), ok3 (b, m))``."""
    m, nb = T_base_tool.shape[0], i1s.shape[0]
    d1, a2, a3, d4, d5, d6 = dh[0, 0], dh[1, 1], dh[2, 1], dh[3, 0], dh[4, 0], dh[5, 0]
    q = np.zeros((nb, m, 6))
    ok_r = np.zeros(m, dtype=np.bool_)
    ok3 = np.zeros((nb, m), dtype=np.bool_)
    T = np.empty((4, 4))
    W = np.empty((4, 4))
    A1 = np.empty((4, 4))
    A1i = np.empty((4, 4))
    A5 = np.empty((4, 4))
    A6 = np.empty((4, 4))
    B = np.empty((4, 4))
    Bi = np.empty((4, 4))
    X = np.empty((4, 4))
    T14 = np.empty((4, 4))
    for k in range(m):
        _mul(T_pre, T_base_tool[k], W)
        _mul(W, T_post, T)
        px = T[0, 3] - d6 * T[0, 2]  # the wrist centre
        py = T[1, 3] - d6 * T[1, 2]
        r = math.hypot(px, py)
        ok_r[k] = r >= abs(d4) - 1e-12
        phi = math.atan2(py, px)
        s = math.asin(min(1.0, max(-1.0, d4 / r)) if r > 0 else 0.0)
        for b in range(nb):
            th1 = phi + s if i1s[b] == 0 else phi + math.pi - s
            s1, c1 = math.sin(th1), math.cos(th1)
            a60 = T[0, 0] * s1 - T[1, 0] * c1  # the common axis of joints 2-4, in frame 6
            a61 = T[0, 1] * s1 - T[1, 1] * c1
            c5 = min(1.0, max(-1.0, T[0, 2] * s1 - T[1, 2] * c1))
            th5 = sign5s[b] * math.acos(c5)
            s5 = math.sin(th5)
            th6 = 0.0 if abs(s5) < 1e-10 else math.atan2(-a61 / s5, a60 / s5)  # wrist singularity: th4 absorbs th6
            _dh_into(A1, th1, d1, 0.0, dh[0, 2])
            _dh_into(A5, th5, d5, 0.0, dh[4, 2])
            _dh_into(A6, th6, d6, 0.0, dh[5, 2])
            _inv_rigid_into(A1, A1i)
            _mul(A5, A6, B)
            _inv_rigid_into(B, Bi)
            _mul(A1i, T, X)
            _mul(X, Bi, T14)
            x, y = T14[0, 3], T14[1, 3]
            c3 = (x * x + y * y - a2 * a2 - a3 * a3) / (2.0 * a2 * a3)
            ok3[b, k] = abs(c3) <= 1.0 + 1e-9
            c3 = min(1.0, max(-1.0, c3))
            th3 = sign3s[b] * math.acos(c3)
            th2 = math.atan2(y, x) - math.atan2(a3 * math.sin(th3), a2 + a3 * math.cos(th3))
            th4 = math.atan2(T14[1, 0], T14[0, 0]) - th2 - th3
            q[b, k, 0], q[b, k, 1], q[b, k, 2] = th1, th2, th3
            q[b, k, 3], q[b, k, 4], q[b, k, 5] = th4, th5, th6
            for j in range(6):
                q[b, k, j] = (q[b, k, j] + math.pi) % TWO_PI - math.pi
    return q, ok_r, ok3


@kernel(cache=True, nogil=True)
def _follow(T: np.ndarray, q0: np.ndarray, dh: np.ndarray, pre: np.ndarray, post: np.ndarray, i1: int, s5: float,
            s3: float, lower: np.ndarray, upper: np.ndarray, max_step: float) -> tuple[np.ndarray, int]:  # pragma: no cover
    m = T.shape[0]
    Q, ok_r, ok3 = _branch(T, dh, pre, post, np.array([i1]), np.array([s5]), np.array([s3]))
    q = np.empty((m + 1, 6))
    q[0] = q0
    q[1:] = Q[0]
    for k in range(m):
        if not (ok_r[k] and ok3[0, k]):
            return q, 1
    unwrap_rows(q)
    for k in range(1, m + 1):
        for j in range(6):
            if abs(q[k, j] - q[k - 1, j]) > max_step:
                return q, 2
    for k in range(m + 1):
        for j in range(6):
            if q[k, j] < lower[j] or q[k, j] > upper[j]:
                return q, 3
    return q, 0


@kernel(cache=True, nogil=True)
def _line_deviation(path: np.ndarray, dh: np.ndarray, pre: np.ndarray, post: np.ndarray, a: np.ndarray,
                    b: np.ndarray) -> float:  # pragma: no cover
    k = path.shape[0] - 1
    if k < 1:
        return 0.0
    mids = np.empty((k, 6))
    for i in range(k):
        for j in range(6):
            mids[i, j] = 0.5 * (path[i, j] + path[i + 1, j])
    F = _fk(mids, dh, pre, post)
    ab0, ab1, ab2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    L2 = ab0 * ab0 + ab1 * ab1 + ab2 * ab2
    worst = 0.0
    for i in range(k):
        p0, p1, p2 = F[i, 0, 3] - a[0], F[i, 1, 3] - a[1], F[i, 2, 3] - a[2]
        t = 0.0 if L2 <= 0 else min(1.0, max(0.0, (p0 * ab0 + p1 * ab1 + p2 * ab2) / L2))
        d0, d1, d2 = p0 - t * ab0, p1 - t * ab1, p2 - t * ab2
        worst = max(worst, math.sqrt(d0 * d0 + d1 * d1 + d2 * d2))
    return worst


@kernel(cache=True, nogil=True)
def unwrap_rows(q: np.ndarray) -> np.ndarray:  # pragma: no cover
    """In place: each row's joints shifted by multiples of 2 pi to the previous row's values."""
    for i in range(1, q.shape[0]):
        for j in range(q.shape[1]):
            q[i, j] += TWO_PI * np.rint((q[i - 1, j] - q[i, j]) / TWO_PI)
    return q


#: :func:`line`'s outcome codes, by index
LINE_CODES = ("ok", "start", "ik", "jump", "limits", "deviation")
#: the start configuration must match its branch's solution within this (rad)
BRANCH_TOL = 1e-6
#: a start configuration this close (sine of the wrist or elbow angle, shoulder distance in m) to a
#: singularity gets every branch compared (:func:`line`), not the one its signs name
SINGULAR = 1e-3


def start_branch(chain: Chain, q0: np.ndarray, T0_base_tool: np.ndarray) -> int | None:
    """The branch (index into :data:`BRANCHES`) configuration ``q0`` (6,) lies on, named by its
    signs (the shoulder solution nearer ``q0[0]``, the signs of ``sin q5`` and ``sin q3``), or None
    within :data:`SINGULAR` of a singularity (where two branches meet). ``T0_base_tool``: the tool
    pose ``q0`` reaches."""
    b = _start_branch(np.ascontiguousarray(q0, dtype=np.float64), np.ascontiguousarray(T0_base_tool, dtype=np.float64),
                      chain.dh, chain.T_dh0_urdf, chain.T_tool_dh6)
    return None if b < 0 else int(b)


def line(chain: Chain, T_world_base: np.ndarray, T_flange_tcp: np.ndarray, T_from: np.ndarray, T_to: np.ndarray,
         q_from: np.ndarray, lower: np.ndarray, upper: np.ndarray, *, sample: float, max_dev: float,
         max_step: float) -> tuple[np.ndarray | None, str]:
    """Joint waypoints (k, 6) moving the TCP straight ``T_from -> T_to`` (world, same orientation)
    from ``q_from``, in one compiled pass: ``(path, "ok")`` or ``(None, why)`` with why in
    :data:`LINE_CODES`.

    TCP waypoints every ``sample`` m are solved exactly on the branch ``q_from`` lies on (the one
    its signs name, :func:`start_branch`, when it matches ``q_from`` within :data:`BRANCH_TOL`;
    else the best match of all eight): ``start`` when ``q_from`` does not reach ``T_from``
    (0.5 ``max_dev``, 1e-4 in the rotation) or lies on no branch; ``ik``, ``jump``, ``limits`` as
    :func:`follow`; ``deviation`` when the joint-linear motion between waypoints strays more than
    ``max_dev`` from the line (:func:`line_deviation`)."""
    c = np.ascontiguousarray
    q, code = _line(c(T_from, dtype=np.float64), c(T_to, dtype=np.float64), c(q_from, dtype=np.float64),
                    c(T_world_base, dtype=np.float64), c(T_flange_tcp, dtype=np.float64), chain.dh, chain.T_urdf_dh0,
                    chain.T_dh0_urdf, chain.T_dh6_tool, chain.T_tool_dh6, c(lower, dtype=np.float64),
                    c(upper, dtype=np.float64), float(sample), float(max_dev), float(max_step))
    return (q, "ok") if code == 0 else (None, LINE_CODES[code])


@kernel(cache=True, nogil=True)
def _start_branch(q0: np.ndarray, T0: np.ndarray, dh: np.ndarray, T_dh0_urdf: np.ndarray,
                  T_tool_dh6: np.ndarray) -> int:  # pragma: no cover
    s5, s3 = math.sin(q0[4]), math.sin(q0[2])
    W = np.empty((4, 4))
    T = np.empty((4, 4))
    _mul(T_dh0_urdf, T0, W)
    _mul(W, T_tool_dh6, T)
    d4, d6 = dh[3, 0], dh[5, 0]
    px, py = T[0, 3] - d6 * T[0, 2], T[1, 3] - d6 * T[1, 2]
    r = math.hypot(px, py)
    if abs(s5) < SINGULAR or abs(s3) < SINGULAR or r < abs(d4) + SINGULAR:
        return -1
    phi, s = math.atan2(py, px), math.asin(max(-1.0, min(1.0, d4 / r)))
    g0 = abs((phi + s - q0[0] + math.pi) % TWO_PI - math.pi)
    g1 = abs((phi + math.pi - s - q0[0] + math.pi) % TWO_PI - math.pi)
    return (0 if g0 <= g1 else 4) + (0 if s5 > 0 else 2) + (0 if s3 > 0 else 1)


@kernel(cache=True, nogil=True)
def _line(T_from: np.ndarray, T_to: np.ndarray, q0: np.ndarray, T_world_base: np.ndarray, T_flange_tcp: np.ndarray,
          dh: np.ndarray, T_urdf_dh0: np.ndarray, T_dh0_urdf: np.ndarray, T_dh6_tool: np.ndarray,
          T_tool_dh6: np.ndarray, lower: np.ndarray, upper: np.ndarray, sample: float, max_dev: float,
          max_step: float) -> tuple[np.ndarray, int]:  # pragma: no cover
    empty = np.zeros((0, 6))
    T_base, T_tcp_flange = np.empty((4, 4)), np.empty((4, 4))
    _inv_rigid_into(T_world_base, T_base)
    _inv_rigid_into(T_flange_tcp, T_tcp_flange)
    d0, d1, d2 = T_to[0, 3] - T_from[0, 3], T_to[1, 3] - T_from[1, 3], T_to[2, 3] - T_from[2, 3]
    m = max(1, int(math.ceil(math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) / sample - 1e-12)))
    # the start: q0 must reach T_from
    T0 = _fk(q0.reshape(1, 6), dh, T_urdf_dh0, T_dh6_tool)[0]
    W, want = np.empty((4, 4)), np.empty((4, 4))
    _mul(T_base, T_from, W)
    _mul(W, T_tcp_flange, want)
    e0, e1, e2 = T0[0, 3] - want[0, 3], T0[1, 3] - want[1, 3], T0[2, 3] - want[2, 3]
    rot = 0.0
    for i in range(3):
        for j in range(3):
            rot = max(rot, abs(T0[i, j] - want[i, j]))
    if math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) > 0.5 * max_dev or rot > 1e-4:
        return empty, 1
    # the waypoints' tool poses in the base frame
    T = np.empty((m, 4, 4))
    Tk = T_from.copy()
    for k in range(m):
        f = (k + 1) / m
        Tk[0, 3], Tk[1, 3], Tk[2, 3] = T_from[0, 3] + d0 * f, T_from[1, 3] + d1 * f, T_from[2, 3] + d2 * f
        _mul(T_base, Tk, W)
        _mul(W, T_tcp_flange, T[k])
    # the branch q0 lies on
    guess = _start_branch(q0, T0, dh, T_dh0_urdf, T_tool_dh6)
    Q0, ok_r, ok3 = _branch(T0.reshape(1, 4, 4), dh, T_dh0_urdf, T_tool_dh6, _I1, _S5, _S3)
    gap = np.full(8, np.inf)
    for b in range(8):
        if ok_r[0] and ok3[b, 0]:
            g = 0.0
            for j in range(6):
                d = Q0[b, 0, j] - q0[j]
                g = max(g, abs(d - TWO_PI * np.rint(d / TWO_PI)))
            gap[b] = g
    b = guess if guess >= 0 and gap[guess] <= BRANCH_TOL else int(np.argmin(gap))
    if not gap[b] <= BRANCH_TOL:
        return empty, 1
    q, code = _follow(T, q0, dh, T_dh0_urdf, T_tool_dh6, _I1[b], _S5[b], _S3[b], lower, upper, max_step)
    if code:
        return empty, code + 1
    pre, post = np.empty((4, 4)), np.empty((4, 4))
    _mul(T_world_base, T_urdf_dh0, pre)
    _mul(T_dh6_tool, T_flange_tcp, post)
    a = np.array([T_from[0, 3], T_from[1, 3], T_from[2, 3]])
    e = np.array([T_to[0, 3], T_to[1, 3], T_to[2, 3]])
    if _line_deviation(q, dh, pre, post, a, e) > max_dev:
        return empty, 5
    return q, 0
