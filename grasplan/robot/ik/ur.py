"""The ``ur`` IK family: closed-form IK of Universal Robots arms (all eight branches).

UR frame conventions (derived from the Pinocchio model, proven by tests): the closed form uses the
classic UR DH chain whose frame 0 is the URDF frame ``base`` (``base_link`` rotated 180 deg about
z) and whose frame 6 is a flange frame on the wrist-3 axis; the joint angles are identical to the
URDF's (no offsets). The DH lengths d1, a2, a3, d4, d5, d6 are read from the model's joint
placements; the constant transform from DH frame 6 to the robot's tool frame is measured once at
q = 0, and the whole chain is verified against Pinocchio FK on random configurations when the
solver is built (if that check fails, ``ok`` is False and :mod:`grasplan.robot.ik` uses CLIK).

Eligible robots (:func:`ur_eligibility`): six joints, the tool frame on joint 6, whose axis is the
joint's local y (the ``ur_description`` URDFs of the UR3/5/10/16 and their e-series).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from ..model import Robot
from ...geometry.transforms import inv_rigid, pose_error
from .registry import IKFamily, register

if TYPE_CHECKING:
    from .ur_batch import Chain


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
        # the compiled kernels (numba) load with the first closed form, not with the robot
        from . import ur_batch

        self._kernels = ur_batch
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
        lengths = (self.d1, self.a2, self.a3, self.d4, self.d5, self.d6)
        # DH frame 6 -> tool frame, measured at q = 0
        data = m.createData()
        q0 = np.zeros(6)
        pin.forwardKinematics(m, data, q0)
        T_tool0 = pin.updateFramePlacement(m, data, robot.tool_frame_id).homogeneous
        T_dh6_0 = ur_batch.fk_dh(ur_batch.make_chain(*lengths, self.T_urdf_dh0, np.eye(4)), q0)
        self.T_dh6_tool = inv_rigid(T_dh6_0) @ inv_rigid(self.T_urdf_dh0) @ T_tool0
        self.T_tool_dh6 = inv_rigid(self.T_dh6_tool)
        #: the kernels' view of this arm (:mod:`grasplan.robot.ik.ur_batch`)
        self.chain: Chain = ur_batch.make_chain(*lengths, self.T_urdf_dh0, self.T_dh6_tool)
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
        """DH frame 0 -> DH frame 6 (4, 4) at ``q`` (6,)."""
        return self._kernels.fk_dh(self.chain, q)

    def solve(self, T_base_tool: np.ndarray) -> tuple[np.ndarray, str]:
        """Up to eight raw solutions (k, 6) (angles in [-pi, pi), in
        :data:`~grasplan.robot.ik.ur_batch.BRANCHES` order) for T_base_tool (the robot's model
        frame, i.e. base_link) and a reason when there are none
        (:func:`grasplan.robot.ik.ur_batch.solve_one`)."""
        q, ok_r, ok3 = self._kernels.solve_one(self.chain, T_base_tool)
        if not ok_r:
            return q[:0], "out_of_reach: wrist centre inside the shoulder cylinder (|p05_xy| < d4)"
        sols = q[ok3]
        return sols, ("ok" if len(sols) else "out_of_reach: target beyond the arm's reach")


FAMILY = register(IKFamily(
    name="ur", closed_form=URAnalytic, eligible=ur_eligibility, controller_base_frame="base",
    description="Universal Robots arms: closed form (8 branches, each checked by FK), CLIK where it "
                "finds nothing verified"))
