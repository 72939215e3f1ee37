"""The ``ur`` IK family: closed-form IK of Universal Robots arms (all eight branches).

UR frame conventions (derived from the Pinocchio model, proven by tests): the closed form uses the
classic UR DH chain whose frame 0 is the URDF frame ``base`` (``base_link`` rotated 180 deg about
z) and whose frame 6 is a flange frame on the wrist-3 axis; the joint angles are identical to the
URDF's (no offsets). The DH lengths d1, a2, a3, d4, d5, d6 are read from the model's joint
placements; the constant transform from DH frame 6 to the robot's tool frame is measured once at
q = 0, and the whole chain is verified against Pinocchio FK on random configurations when the
solver is built (if that check fails, ``ok`` is False and :mod:`grasplan.ik` uses CLIK).

Eligible robots (:func:`ur_eligibility`): six joints, the tool frame on joint 6, whose axis is the
joint's local y (the ``ur_description`` URDFs of the UR3/5/10/16 and their e-series).
"""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from ..robot_model import Robot
from ..transforms import inv_rigid, pose_error
from .registry import IKFamily, register

def ur_eligibility(robot: Robot) -> str:
    """Why the UR closed form cannot serve ``robot`` ("" when its structure fits)."""
    m = robot.model
    if m.nq != 6:
        return f"{m.nq} joints, not 6"
    if robot.tool_joint_id != 6:
        return "the tool frame does not move with joint 6"
    if m.joints[6].shortname() != "JointModelRY":
        return f"wrist 3 axis is not y ({m.joints[6].shortname()})"
    return ""


def _dh(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
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
        self.why = ur_eligibility(robot)
        if self.why:
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
        self.d6 = float(T_j6_tool.translation @ np.array([0.0, 1.0, 0.0]))
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

    def fk_dh(self, q: np.ndarray) -> np.ndarray:
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
                    sols.append((q + math.pi) % math.tau - math.pi)
        return sols, ("ok" if sols else reason)


FAMILY = register(IKFamily(
    name="ur", closed_form=URAnalytic, eligible=ur_eligibility, controller_base_frame="base",
    description="Universal Robots arms: closed form (8 branches, each checked by FK), CLIK where it "
                "finds nothing verified"))
