"""Straight TCP lines for a UR arm in one NumPy pass: the closed form of :mod:`grasplan.ik.ur`
evaluated for every waypoint of a line at once, on the one branch the start configuration is on.

:func:`ur_line` is what :func:`grasplan.pick.motion.line_path` uses when the robot's IK family is
``ur``: the branch (shoulder, wrist and elbow signs) is the one whose solution at the first pose
equals the start configuration (modulo 2 pi); each waypoint's joints are wrapped to the previous
waypoint's, so the path is continuous unless the branch passes a singularity (then a joint jumps
and the line is refused). Forward kinematics of the same DH chain (proven against Pinocchio when
the closed form is built) measures the joint-linear motion's distance from the line.
"""
from __future__ import annotations

import numpy as np

from ..ik.ur import _ALPHA, URAnalytic

TWO_PI = 2.0 * np.pi
#: the start configuration must match its branch's solution within this (rad)
BRANCH_TOL = 1e-6


def _dh(theta: np.ndarray, d: float, a: float, alpha: float) -> np.ndarray:
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(alpha), np.sin(alpha)
    T = np.zeros(theta.shape + (4, 4))
    T[..., 0, 0], T[..., 0, 1], T[..., 0, 2], T[..., 0, 3] = ct, -st * ca, st * sa, a * ct
    T[..., 1, 0], T[..., 1, 1], T[..., 1, 2], T[..., 1, 3] = st, ct * ca, -ct * sa, a * st
    T[..., 2, 1], T[..., 2, 2], T[..., 2, 3] = sa, ca, d
    T[..., 3, 3] = 1.0
    return T


def _inv(T: np.ndarray) -> np.ndarray:
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


#: the eight branches in the closed form's order: (shoulder th1 choice, wrist sign, elbow sign)
BRANCHES = tuple((i1, s5, s3) for i1 in (0, 1) for s5 in (1.0, -1.0) for s3 in (1.0, -1.0))
#: a start configuration this close (sine of the wrist or elbow angle, shoulder distance in m) to a
#: singularity gets every branch compared (:func:`ur_line`), not the one its signs name
SINGULAR = 1e-3


def branches(ur: URAnalytic, T_base_tool: np.ndarray, only: tuple[int, ...] = tuple(range(8))
             ) -> tuple[np.ndarray, np.ndarray]:
    """``(q (b, m, 6), valid (b, m))``: the closed-form branches ``only`` (indices into
    :data:`BRANCHES`, default all eight) for the tool poses ``T_base_tool`` (m, 4, 4), angles in
    (-pi, pi]."""
    T = np.linalg.inv(ur.T_urdf_dh0) @ T_base_tool @ ur.T_tool_dh6
    d1, a2, a3, d4, d5, d6 = ur.d1, ur.a2, ur.a3, ur.d4, ur.d5, ur.d6
    R, p = T[:, :3, :3], T[:, :3, 3]
    p05 = p - d6 * R[:, :, 2]
    r = np.hypot(p05[:, 0], p05[:, 1])
    ok_r = r >= abs(d4) - 1e-12
    phi = np.arctan2(p05[:, 1], p05[:, 0])
    s = np.arcsin(np.clip(np.where(r > 0, d4 / np.where(r > 0, r, 1.0), 0.0), -1.0, 1.0))
    qs, valid = [], []
    wrist: dict[tuple[int, float], tuple] = {}
    for b in only:
        i1, sign5, sign3 = BRANCHES[b]
        if (i1, sign5) not in wrist:
            th1 = phi + s if i1 == 0 else phi + np.pi - s
            s1, c1 = np.sin(th1), np.cos(th1)
            a6 = np.einsum("mji,mj->mi", R, np.stack([s1, -c1, np.zeros_like(s1)], axis=1))
            c5 = np.clip(a6[:, 2], -1.0, 1.0)
            th5 = sign5 * np.arccos(c5)
            s5 = np.sin(th5)
            sing = np.abs(s5) < 1e-10
            s5s = np.where(sing, 1.0, s5)
            th6 = np.where(sing, 0.0, np.arctan2(-a6[:, 1] / s5s, a6[:, 0] / s5s))
            T14 = _inv(_dh(th1, d1, 0.0, _ALPHA[0])) @ T @ _inv(_dh(th5, d5, 0.0, _ALPHA[4]) @ _dh(th6, d6, 0.0, _ALPHA[5]))
            x, y = T14[:, 0, 3], T14[:, 1, 3]
            c3 = (x * x + y * y - a2 * a2 - a3 * a3) / (2.0 * a2 * a3)
            wrist[(i1, sign5)] = (th1, th5, th6, T14, x, y, np.clip(c3, -1.0, 1.0), np.abs(c3) <= 1.0 + 1e-9)
        th1, th5, th6, T14, x, y, c3, ok3 = wrist[(i1, sign5)]
        th3 = sign3 * np.arccos(c3)
        th2 = np.arctan2(y, x) - np.arctan2(a3 * np.sin(th3), a2 + a3 * np.cos(th3))
        th4 = np.arctan2(T14[:, 1, 0], T14[:, 0, 0]) - th2 - th3
        q = np.stack([th1, th2, th3, th4, th5, th6], axis=1)
        qs.append((q + np.pi) % TWO_PI - np.pi)
        valid.append(ok_r & ok3)
    return np.array(qs), np.array(valid)


def start_branch(ur: URAnalytic, q0: np.ndarray, T0_base_tool: np.ndarray) -> int | None:
    """The branch (index into :data:`BRANCHES`) configuration ``q0`` lies on, named by its signs
    (the shoulder solution nearer ``q0[0]``, the signs of ``sin q5`` and ``sin q3``), or None
    within :data:`SINGULAR` of a singularity (where two branches meet)."""
    s5, s3 = float(np.sin(q0[4])), float(np.sin(q0[2]))
    T = np.linalg.inv(ur.T_urdf_dh0) @ T0_base_tool @ ur.T_tool_dh6
    p05 = T[:3, 3] - ur.d6 * T[:3, 2]
    r = float(np.hypot(p05[0], p05[1]))
    if abs(s5) < SINGULAR or abs(s3) < SINGULAR or r < abs(ur.d4) + SINGULAR:
        return None
    phi, s = float(np.arctan2(p05[1], p05[0])), float(np.arcsin(np.clip(ur.d4 / r, -1.0, 1.0)))
    gap = [abs((th - q0[0] + np.pi) % TWO_PI - np.pi) for th in (phi + s, phi + np.pi - s)]
    return BRANCHES.index((int(np.argmin(gap)), 1.0 if s5 > 0 else -1.0, 1.0 if s3 > 0 else -1.0))


def fk_base_tool(ur: URAnalytic, q: np.ndarray) -> np.ndarray:
    """Tool poses (m, 4, 4) in the robot's base frame for configurations ``q`` (m, 6)."""
    d = (ur.d1, 0.0, 0.0, ur.d4, ur.d5, ur.d6)
    a = (0.0, ur.a2, ur.a3, 0.0, 0.0, 0.0)
    T = np.broadcast_to(ur.T_urdf_dh0, (len(q), 4, 4)).copy()
    for i in range(6):
        T = T @ _dh(q[:, i], d[i], a[i], _ALPHA[i])
    return T @ ur.T_dh6_tool


def ur_line(ur: URAnalytic, T_base_tool: np.ndarray, q_from: np.ndarray, lower: np.ndarray, upper: np.ndarray,
            max_joint_step: float) -> tuple[np.ndarray | None, str]:
    """Joint path (m + 1, 6) starting at ``q_from`` through the tool poses ``T_base_tool`` (m, 4, 4)
    (the first reached by ``q_from`` itself is not included), or ``(None, why)``: ``start`` (no
    branch matches ``q_from``), ``ik``, ``jump``, ``limits``. The branch is the one
    :func:`start_branch` names when it matches ``q_from`` (away from singularities, the only one
    that can), else the best match of all eight."""
    q0 = np.asarray(q_from, dtype=np.float64)
    T_all = np.concatenate([fk_base_tool(ur, q0[None]), T_base_tool], axis=0)
    guess = start_branch(ur, q0, T_all[0])
    Q, valid = branches(ur, T_all, tuple(range(8)) if guess is None else (guess,))
    d0 = Q[:, 0, :] - q0
    d0 = np.max(np.abs(d0 - TWO_PI * np.round(d0 / TWO_PI)), axis=1)
    b = int(np.argmin(np.where(valid[:, 0], d0, np.inf)))
    if guess is not None and (not valid[b, 0] or d0[b] > BRANCH_TOL):  # not where its signs say: compare all
        Q, valid = branches(ur, T_all)
        d0 = Q[:, 0, :] - q0
        d0 = np.max(np.abs(d0 - TWO_PI * np.round(d0 / TWO_PI)), axis=1)
        b = int(np.argmin(np.where(valid[:, 0], d0, np.inf)))
    if not valid[b, 0] or d0[b] > BRANCH_TOL:
        return None, "start"
    if not valid[b].all():
        return None, "ik"
    q = Q[b].copy()
    q[0] = q0
    for i in range(1, len(q)):  # unwrap each joint to the previous waypoint's value
        q[i] += TWO_PI * np.round((q[i - 1] - q[i]) / TWO_PI)
    if np.any(np.max(np.abs(np.diff(q, axis=0)), axis=1) > max_joint_step):
        return None, "jump"
    if np.any(q < lower) or np.any(q > upper):
        return None, "limits"
    return q, "ok"
