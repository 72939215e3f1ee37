"""The ``generic`` IK family: damped least squares CLIK on the tool frame, the numeric solver
every family shares (:mod:`grasplan.robot.ik` runs it from several deterministic seeds, after the
family's closed form, if any, found nothing verified)."""
from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..model import DEFAULT_IK_FAMILY, Robot
from ...geometry.transforms import inv_rigid, pose_error
from .registry import IKFamily, register


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

    def fk(self, q: np.ndarray) -> np.ndarray:
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


FAMILY = register(IKFamily(
    name=DEFAULT_IK_FAMILY,
    description="any arm of revolute/prismatic joints: CLIK from q_ref, q_home and seeded random "
                "configurations"))
