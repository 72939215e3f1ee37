"""The robot model: an immutable, shared :class:`Robot` around a Pinocchio model (no ``Data``).

Loaded from a robot YAML by :func:`grasplan.robot.description.load_robot` (once per name). Solvers (IK,
collision scenes) own their scratch ``pin.Data``; :meth:`Robot.fk` and :meth:`Robot.link_poses`
use a private per-thread ``Data`` for convenience. The frames: :class:`Robot`.
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from ..errors import InputError, unknown_name

#: the IK family (:mod:`grasplan.robot.ik.registry`) of a robot whose YAML names no ``kind``: CLIK only
DEFAULT_IK_FAMILY = "generic"

_VISUAL_LOCK = threading.Lock()


def read_only(a: ArrayLike) -> np.ndarray:
    """A float64 copy of ``a`` that cannot be written to (the arrays a shared model holds)."""
    out = np.array(a, dtype=float)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class Robot:
    """An immutable, shared robot model (load with :func:`grasplan.robot.description.load_robot`).

    Arrays are read-only float64: ``q_home``, ``lower``, ``upper``, ``velocity_limit`` (n,),
    ``T_world_base`` (4, 4). ``disabled_pairs`` holds sorted (link, link) name pairs from the
    SRDF. ``mounted_links`` are exempt from table checks; ``kind`` names the robot's IK family
    (:mod:`grasplan.robot.ik.registry`: ``"ur"`` or ``"generic"`` today).

    Frames:

    * The Pinocchio model's universe is the robot's URDF root link (``base_link`` for the UR5,
      ``panda_link0`` for the Panda). ``T_world_base`` places that root link in the world
      (identity for every shipped robot), so ``fk(q) = T_world_base @ T_base_tool(q)``.
    * Extra fixed frames listed in the YAML's ``frames`` are added to the model at load time. The
      UR5 URDF of example-robot-data already defines ``tool0`` and ``base`` as ``ur_description`` does
      for the UR controller: ``tool0`` = ``wrist_3_link`` translated (0, 0.0823, 0) and rotated
      -90 deg about x (z along the flange normal), ``base`` = ``base_link`` rotated 180 deg about z
      (the controller's base frame, used for URScript poses).
    """

    name: str
    model: pin.Model
    collision_model: pin.GeometryModel
    joint_names: tuple[str, ...]
    q_home: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    velocity_limit: np.ndarray
    tool_frame: str
    tool_frame_id: int
    T_world_base: np.ndarray
    disabled_pairs: tuple[tuple[str, str], ...]
    urdf_path: Path
    srdf_path: Path | None
    package_dirs: tuple[str, ...]
    mounted_links: tuple[str, ...] = ()
    kind: str = DEFAULT_IK_FAMILY
    config_path: Path | None = None
    source_yaml: str = ""                 #: the robot YAML's text (embedded in plans)
    package: str | None = None            #: the package holding the URDF/SRDF (e.g. example-robot-data)
    joint_sign: np.ndarray | None = None  #: (n,) controller angle [deg] = sign * degrees(q) + offset_deg
    joint_offset_deg: np.ndarray | None = None
    controller_base_frame: str | None = None  #: model frame of the controller's base (UR: "base")
    _tls: threading.local = field(default_factory=threading.local, repr=False, compare=False)
    #: builds the visual geometry on first use (:attr:`visual_model`): the UR5's visual meshes take
    #: 0.33 s to load, 95 % of building the robot, and only a viewer asking for them needs them
    _visual_loader: Callable[[], pin.GeometryModel] | None = field(default=None, repr=False, compare=False)
    _visual: list[pin.GeometryModel] = field(default_factory=list, repr=False, compare=False)

    # ---- basic properties -------------------------------------------------------------------
    @property
    def visual_model(self) -> pin.GeometryModel:
        """The URDF's visual geometry, built on first use (same joints, locks and removed links
        as :attr:`collision_model`)."""
        if not self._visual:
            with _VISUAL_LOCK:
                if not self._visual:
                    self._visual.append(self._visual_loader() if self._visual_loader is not None
                                        else pin.GeometryModel())
        return self._visual[0]

    @property
    def nq(self) -> int:
        return int(self.model.nq)

    @property
    def tool_joint_id(self) -> int:
        """Index of the joint the tool frame (and the gripper) moves with."""
        return int(self.model.frames[self.tool_frame_id].parentJoint)

    @property
    def T_joint_tool(self) -> np.ndarray:
        """(4, 4) placement of the tool frame in its parent joint's frame."""
        return self.model.frames[self.tool_frame_id].placement.homogeneous.copy()

    def new_data(self) -> pin.Data:
        """A fresh scratch ``pin.Data`` for a solver to own."""
        return self.model.createData()

    def _data(self) -> pin.Data:
        d = getattr(self._tls, "data", None)
        if d is None:
            d = self._tls.data = self.model.createData()
        return d

    def check_q(self, q: ArrayLike, *, where: str = "q") -> np.ndarray:
        """``q`` as a float (n,) array; raises InputError on a wrong shape or non-finite values."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.nq,):
            raise InputError(f"{where}: expected shape ({self.nq},) for robot {self.name!r}, got {q.shape}")
        if not np.all(np.isfinite(q)):
            raise InputError(f"{where}: contains NaN/inf")
        return q

    def within_limits(self, q: ArrayLike, *, tol: float = 1e-9) -> bool | np.ndarray:
        """True where q (n,) or (k, n) lies within [lower - tol, upper + tol]."""
        q = np.asarray(q, dtype=float)
        ok = np.all((q >= self.lower - tol) & (q <= self.upper + tol), axis=-1)
        return bool(ok) if ok.ndim == 0 else ok

    # ---- kinematics ---------------------------------------------------------------------------
    def fk(self, q: ArrayLike) -> np.ndarray:
        """T_world_tool (4, 4) for joint vector q (n,)."""
        q = self.check_q(q)
        d = self._data()
        pin.forwardKinematics(self.model, d, q)
        M = pin.updateFramePlacement(self.model, d, self.tool_frame_id)
        return self.T_world_base @ M.homogeneous

    def fk_batch(self, qs: ArrayLike) -> np.ndarray:
        """T_world_tool (k, 4, 4) for qs (k, n)."""
        qs = np.asarray(qs, dtype=float)
        if qs.ndim != 2 or qs.shape[1] != self.nq:
            raise InputError(f"qs: expected shape (k, {self.nq}), got {qs.shape}")
        return np.stack([self.fk(q) for q in qs]) if len(qs) else np.zeros((0, 4, 4))

    def frame_pose(self, q: ArrayLike, frame: str) -> np.ndarray:
        """T_world_frame (4, 4) of any model frame (e.g. ``"base"`` or ``"wrist_3_link"``)."""
        q = self.check_q(q)
        if not self.model.existFrame(frame):
            raise unknown_name("frame", frame, [f.name for f in self.model.frames])
        d = self._data()
        pin.forwardKinematics(self.model, d, q)
        M = pin.updateFramePlacement(self.model, d, self.model.getFrameId(frame))
        return self.T_world_base @ M.homogeneous

    def link_poses(self, q: ArrayLike, *, which: str = "collision") -> list[tuple[str, np.ndarray, str, np.ndarray]]:
        """For the viewer: ``[(geometry_name, T_world_geom (4,4), mesh_path, mesh_scale (3,))]``.

        ``which`` = ``"collision"`` (STL meshes, default) or ``"visual"``. ``mesh_path`` is ""
        for primitive shapes (e.g. the UR5's tiny ``ee_link`` box).
        """
        q = self.check_q(q)
        gm = {"collision": self.collision_model, "visual": self.visual_model}.get(which)
        if gm is None:
            raise InputError(f"which: expected 'collision' or 'visual', got {which!r}")
        d = self._data()
        pin.forwardKinematics(self.model, d, q)
        out: list[tuple[str, np.ndarray, str, np.ndarray]] = []
        for g in gm.geometryObjects:
            T = self.T_world_base @ (d.oMi[g.parentJoint] * g.placement).homogeneous
            mesh = str(g.meshPath or "")
            if mesh.upper() in ("BOX", "SPHERE", "CYLINDER", "CAPSULE", "CONE") or not Path(mesh).is_file():
                mesh = ""  # a primitive (pinocchio names it "BOX" etc.)
            out.append((g.name, T, mesh, np.array(g.meshScale, dtype=float)))
        return out

    def link_name(self, geom: pin.GeometryObject) -> str:
        """The URDF link a geometry object belongs to."""
        return self.model.frames[geom.parentFrame].name

    def to_json(self, *, source: bool = False) -> dict[str, Any]:
        """The ``robot`` block of a plan; with ``source`` also where the model came from (package,
        URDF/SRDF paths relative to it, the YAML text), so :func:`grasplan.robot.description.robot_from_json`
        rebuilds it."""
        out: dict[str, Any] = {"name": self.name, "joint_names": list(self.joint_names),
                               "T_world_base": self.T_world_base.tolist(), "q_home": self.q_home.tolist()}
        if source:
            out["source"] = {"package": self.package, "urdf": str(self.urdf_path),
                             "srdf": str(self.srdf_path) if self.srdf_path else None,
                             "yaml_path": str(self.config_path) if self.config_path else None,
                             "yaml": self.source_yaml}
        return out

    def T_world_controller_base(self) -> np.ndarray:
        """(4, 4) pose of the controller's base frame (``controller_base_frame``, else the model root)."""
        if not self.controller_base_frame:
            return self.T_world_base.copy()
        d = self.model.createData()
        pin.framesForwardKinematics(self.model, d, pin.neutral(self.model))
        return self.T_world_base @ d.oMf[self.model.getFrameId(self.controller_base_frame)].homogeneous
