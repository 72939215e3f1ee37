"""The clutter world: the pile world of :mod:`grasplan.sim.pileworld` with a gripper in it.

:class:`ClutterWorld` holds the pile's parts and the gripper, modelled as :mod:`grasplan.sim.simulate`
models it but hung on a kinematically driven **hand** (the arm is not simulated);
:func:`gripper_mjcf` writes the hand, its shapes and its jaws (on pad hinges that carry each
pad's twist) into the pile world's MJCF, :class:`PadArc` a linkage gripper's pad path.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from ..cell.model import Cell
from ..errors import InputError
from ..gripper.model import Box, Gripper, MeshShape, rz180
from ..sim.pileworld import PILE_BIT, ROLLING_LENGTH, PartBody, PileWorld, pile_mjcf
from ..sim.simulate import (
    CLOSE_SPEED, DRIVE_TAU, JAW_MASS, PAD_GRIP_TORSION, SOLREF_TIMECONST, TORSION_LENGTH, pad_twist_caps, pad_xml
)
from ..geometry.transforms import quaternions
from ..grasps.wrench import CONTACTS_PER_GRIP

if TYPE_CHECKING:  # MuJoCo loads with the first world
    import mujoco

#: physics step while the gripper acts (s); the hand's pose is written every CONTROL_DT (s)
PICK_TIMESTEP, CONTROL_DT = 0.001, 0.005
#: the hand's mass (kg): heavy, so a control period of contacts barely moves it off its path
HAND_MASS = 100.0
#: where the parked hand waits (m, world): far below the table and the parked parts
HAND_PARK = (0.0, 0.0, -4.0)
#: weight of the gripper's contact parameters against a part's when MuJoCo mixes them
GRIPPER_SOLMIX = 1000.0
HAND, JAWS = "#hand", ("#jaw0", "#jaw1")
#: each jaw's finger on its pad hinge about the closing axis (body and hinge names)
PADS = ("#pad0", "#pad1")
#: a linkage gripper's pads also slide along the approach axis, on these joints (coupled to the jaws')
JAWS_Z = ("#jaw0z", "#jaw1z")
#: a linkage whose pad path z(x) is no quartic: each pad's arc length on its path, a joint of its own
#: (a weightless body without shapes) that both the jaw's x and its z follow (:class:`PadArc`)
ARCS = ("#arc0", "#arc1")
#: largest error (m) of the quartic fits of a linkage gripper's pad path
ARC_FIT_TOL = 1e-4


@dataclass(frozen=True)
class PadArc:
    """Where a linkage gripper's pad lies along the approach axis as its jaw opens (``moving_tcp``:
    the fingertips move on an arc, :mod:`grasplan.gripper.linkage`), as MuJoCo's joint equalities
    (``polycoef``: one joint a quartic of another) can hold it, each fit within :data:`ARC_FIT_TOL`
    over the whole stroke:

    - ``z_of_x``: the pad's offset along the approach axis a quartic of the jaw's half-opening x
      (the Robotiq 2F-85 and 2F-140); else
    - ``x_of_s``, ``z_of_s``: both quartics of the arc length s along the pad's path, a joint of
      its own (:data:`ARCS`). A path whose slope grows without bound (the OnRobot RG2 and RG6: a
      circle followed nearly to its side, 1 mm off a quartic z(x)) is smooth in its arc length.

    ``x_grid``, ``s_grid``: the arc length at each half-opening (to place the joints)."""

    z_of_x: np.ndarray | None
    x_of_s: np.ndarray | None
    z_of_s: np.ndarray | None
    x_grid: np.ndarray
    s_grid: np.ndarray

    @property
    def chained(self) -> bool:
        return self.z_of_x is None

    def s_at(self, half: float) -> float:
        return float(np.interp(half, self.x_grid, self.s_grid))

    def z_at(self, half: float) -> float:
        poly = np.polynomial.polynomial.polyval
        if self.z_of_x is not None:
            return float(poly(half, self.z_of_x))
        assert self.z_of_s is not None
        return float(poly(self.s_at(half), self.z_of_s))


def pad_arc(gripper: Gripper) -> PadArc | None:
    """The :class:`PadArc` of a gripper whose pads move on an arc, fitted to ``tcp_offset(2 x)``
    over the stroke; None for jaws that slide straight. InputError when neither fit holds."""
    if not getattr(gripper, "moving_tcp", False):
        return None
    P = np.polynomial.polynomial

    def path(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``n`` half-openings x, the pad's offset z at each and the arc length s along the path."""
        x = np.linspace(0.0, 0.5 * gripper.max_opening, n)
        z = np.asarray(gripper.tcp_offset(2.0 * x), dtype=np.float64)
        return x, z, np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(z)))])

    x, z, s = path(201)
    c = P.polyfit(x, z, 4)
    err = float(np.max(np.abs(P.polyval(x, c) - z)))
    if err <= ARC_FIT_TOL:
        return PadArc(c, None, None, x, s)
    x, z, s = path(2001)  # the arc length: finer
    cx, cz = P.polyfit(s, x, 4), P.polyfit(s, z, 4)
    err_s = max(float(np.max(np.abs(P.polyval(s, cx) - x))), float(np.max(np.abs(P.polyval(s, cz) - z))))
    if err_s > ARC_FIT_TOL:
        raise InputError(f"gripper {gripper.name}: its pads' path is neither a quartic in the opening "
                         f"({err * 1e3:.3f} mm off) nor in its arc length ({err_s * 1e3:.3f} mm off), within "
                         f"{ARC_FIT_TOL * 1e3:g} mm; the clutter world cannot model it: use a gripper whose "
                         f"jaws slide straight (e.g. schunk_egp_c_40) or one of robotiq_2f_85, robotiq_2f_140, "
                         f"onrobot_rg2, onrobot_rg6")
    return PadArc(None, cx, cz, x, s)


def _fmt(a: object) -> str:
    return " ".join(f"{x:.12g}" for x in np.asarray(a, dtype=np.float64).ravel())


def _shape_xml(shape: Box | MeshShape, name: str, assets: list[str], attrs: str) -> str:
    if isinstance(shape, Box):
        T = np.asarray(shape.T_tcp_box)
        return (f'<geom name="{name}" type="box" size="{_fmt(0.5 * np.asarray(shape.extents))}" '
                f'pos="{_fmt(T[:3, 3])}" quat="{_fmt(quaternions(T[:3, :3]))}" {attrs}/>')
    assets.append(f'<mesh name="{name}" vertex="{_fmt(shape.vertices)}"/>')  # MuJoCo collides with its hull
    return f'<geom name="{name}" type="mesh" mesh="{name}" {attrs}/>'


def gripper_mjcf(gripper: Gripper, *, mu: float, grip_force: float, arc: PadArc | None = None) -> tuple[str, str, str]:
    """MJCF fragments ``(asset, worldbody, extra)`` of the hand, its body shapes and its two jaws
    (:class:`ClutterWorld`), for :func:`grasplan.sim.pileworld.pile_mjcf`; ``arc``: the gripper's
    :func:`pad_arc` when the caller already has it.

    The gripper's contacts use :data:`grasplan.sim.simulate.SOLREF_TIMECONST` (stiff: the grip force
    indents well below 1 mm) and win the mix against the parts' softer contacts (``solmix``). Each
    jaw's finger sits on a hinge about the closing axis (:func:`grasplan.sim.simulate.pad_xml`,
    bodies :data:`PADS`) whose dry friction is the pad's twist capacity
    (:meth:`ClutterWorld.set_jaw_torsion`). The pads' own contacts grip in twist: the pad geoms have
    the higher ``priority``, so every pad contact takes their parameters (``condim`` 4, torsional
    friction ``mu`` x :data:`grasplan.sim.simulate.PAD_GRIP_TORSION`, no rolling friction, the
    gripper's stiff ``solref``), and the twist slips at the hinge whatever the number of contact
    points MuJoCo makes."""
    assets: list[str] = []
    attrs = (f'contype="{PILE_BIT}" conaffinity="{PILE_BIT}" condim="6" solmix="{GRIPPER_SOLMIX:g}" '
             f'friction="{mu:.9g} {mu * TORSION_LENGTH:.6g} {mu * ROLLING_LENGTH:.6g}" '
             f'solref="{SOLREF_TIMECONST:.6g} 1"')
    body = "".join(_shape_xml(s, f"{HAND}#{i}", assets, attrs) for i, s in enumerate(gripper.body))
    # the pads grip in twist (their parameters win by priority); the twist slips at each pad's hinge
    pad = (f'contype="{PILE_BIT}" conaffinity="{PILE_BIT}" condim="4" priority="1" '
           f'friction="{mu:.9g} {mu * PAD_GRIP_TORSION:.6g} 0" solref="{SOLREF_TIMECONST:.6g} 1"')
    jaw1 = pad_xml(PADS[1], _shape_xml(gripper.finger, JAWS[1], assets, pad), 'gravcomp="1"')
    jaw0 = pad_xml(PADS[0], _shape_xml(gripper.finger.moved(rz180()), JAWS[0], assets, pad), 'gravcomp="1"')
    half = 0.5 * gripper.max_opening
    jaw_force = grip_force / CONTACTS_PER_GRIP
    damping = jaw_force / CLOSE_SPEED
    armature = max(DRIVE_TAU * damping - JAW_MASS, 0.0)
    inertia = _fmt([JAW_MASS * 1e-4] * 3)
    hand_inertia = _fmt([HAND_MASS * 0.01] * 3)

    arc = pad_arc(gripper) if arc is None else arc

    def jaw(k: int, axis: str, geom: str) -> str:
        z = "" if arc is None else (f'<joint name="{JAWS_Z[k]}" type="slide" axis="0 0 1" limited="false" '
                                    f'armature="{JAW_MASS:.6g}"/>')
        return (f'<body name="{JAWS[k]}" gravcomp="1"><inertial pos="0 0 0" mass="{JAW_MASS}" diaginertia="{inertia}"/>'
                f'<joint name="{JAWS[k]}" type="slide" axis="{axis}" range="0 {half:.9g}" limited="true" '
                f'damping="{damping:.6g}" armature="{armature:.6g}"/>{z}{geom}</body>')

    # a chained arc: each pad's arc length on a weightless body of its own, no shapes (PadArc)
    arcs = "" if arc is None or not arc.chained else "".join(
        f'<body name="{ARCS[k]}" gravcomp="1"><inertial pos="0 0 0" mass="{JAW_MASS}" diaginertia="{inertia}"/>'
        f'<joint name="{ARCS[k]}" type="slide" axis="0 0 1" range="0 {arc.s_grid[-1]:.9g}" limited="true" '
        f'armature="{JAW_MASS:.6g}"/></body>' for k in (0, 1))
    world = (f'<body name="{HAND}" pos="{_fmt(HAND_PARK)}" gravcomp="1"><freejoint name="{HAND}"/>'
             f'<inertial pos="0 0 0" mass="{HAND_MASS:g}" diaginertia="{hand_inertia}"/>{body}'
             f'{jaw(0, "-1 0 0", jaw0)}{jaw(1, "1 0 0", jaw1)}{arcs}</body>')
    sol = f'solref="{SOLREF_TIMECONST:.6g} 1"'
    if arc is None:
        on_arc = ""
    elif not arc.chained:  # the pads on their arc: z = quartic(x)
        on_arc = "".join(f'<joint joint1="{JAWS_Z[k]}" joint2="{JAWS[k]}" polycoef="{_fmt(arc.z_of_x)}" {sol}/>'
                         for k in (0, 1))
    else:  # x = quartic(s), z = quartic(s)
        on_arc = "".join(f'<joint joint1="{JAWS[k]}" joint2="{ARCS[k]}" polycoef="{_fmt(arc.x_of_s)}" {sol}/>'
                         f'<joint joint1="{JAWS_Z[k]}" joint2="{ARCS[k]}" polycoef="{_fmt(arc.z_of_s)}" {sol}/>'
                         for k in (0, 1))
    extra = (f'<contact><exclude body1="{PADS[0]}" body2="{PADS[1]}"/><exclude body1="{HAND}" body2="{PADS[0]}"/>'
             f'<exclude body1="{HAND}" body2="{PADS[1]}"/></contact>'
             f'<equality><joint joint1="{JAWS[0]}" joint2="{JAWS[1]}" polycoef="0 1 0 0 0" {sol}/>'
             + on_arc + '</equality>'
             f'<actuator><motor name="close0" joint="{JAWS[0]}" gear="-1" ctrlrange="{-jaw_force:.9g} {jaw_force:.9g}" '
             f'ctrllimited="true"/><motor name="close1" joint="{JAWS[1]}" gear="-1" '
             f'ctrlrange="{-jaw_force:.9g} {jaw_force:.9g}" ctrllimited="true"/></actuator>')
    return "".join(assets), world, extra


@dataclass(frozen=True)
class Contact:
    """One contact of the gripper: which of its bodies (``hand``, ``jaw0``, ``jaw1``), what it
    touches (a part body index, or -1 for the cell: table, bin, obstacles; ``other`` its name),
    the penetration ``depth`` (m, > 0 inside), the normal ``force`` (N) and where it is, ``pos``
    (3,) (m, world: MuJoCo's contact point, midway between the two surfaces)."""

    gripper: str
    part: int
    other: str
    depth: float
    force: float
    pos: np.ndarray = field(default_factory=lambda: np.zeros(3), compare=False, repr=False)


class ClutterWorld:
    """A :class:`grasplan.sim.pileworld.PileWorld` holding the pile's parts and a gripper.
    ``world`` is the pile world (its parts, poses, settling), the rest drives the hand.

    The gripper is modelled as :mod:`grasplan.sim.simulate` models it (its own shapes; two jaws on
    prismatic joints along the closing axis, coupled, each pushed by a motor of at most half the
    datasheet ``grip_force``, damped to close at :data:`grasplan.sim.simulate.CLOSE_SPEED`, with the
    drive's reflected inertia so they reach that speed in :data:`grasplan.sim.simulate.DRIVE_TAU`), but
    instead of a fixed TCP frame it hangs on a **hand**: a free body whose frame is the TCP frame,
    weightless (``gravcomp``) and heavy (:data:`HAND_MASS`), driven kinematically. Before every
    control period (:data:`CONTROL_DT`) the executor writes the hand's pose and velocity from the
    planned TCP path (:meth:`set_hand`), so contacts see the hand move at its real speed (friction
    lifts a held part) but cannot push it off its path: the arm is not simulated, its stiffness is
    taken as infinite, as a position-controlled industrial arm's nearly is. While the gripper is not
    in use it is parked far below the table (:meth:`park_hand`). A pick steps at
    :data:`PICK_TIMESTEP` (1 ms, as :mod:`grasplan.sim.simulate`; the drop itself runs at the pile
    world's 2 ms). Contact parameters: :func:`gripper_mjcf`."""

    def __init__(self, cell: Cell, bodies: Sequence[PartBody], gripper: Gripper, *, mu: float,
                 grip_force: float | None = None):
        import mujoco

        self.gripper = gripper
        self.mu = float(mu)
        self.grip_force = float(gripper.grip_force if grip_force is None else grip_force)
        self._arc = pad_arc(gripper)  # one fit: the MJCF's equalities and set_jaws use the same
        asset, worldbody, extra = gripper_mjcf(gripper, mu=self.mu, grip_force=self.grip_force, arc=self._arc)
        xml = pile_mjcf(cell, bodies, mu=self.mu, extra_asset=asset, extra_worldbody=worldbody, extra=extra)
        self.world = PileWorld.from_xml(xml, cell, bodies)
        m = self.model
        self._hand = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, HAND)
        j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, HAND)
        self._hq, self._hv = int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])
        self._jaw_body = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in JAWS]
        self._jaw_q = [int(m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)]) for n in JAWS]
        self._jaw_v = [int(m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)]) for n in JAWS]
        self._jaw_geom = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, n) for n in JAWS]
        self._pad_body = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in PADS]
        pad_joints = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in PADS]
        self._pad_q = [int(m.jnt_qposadr[j]) for j in pad_joints]
        self._pad_v = [int(m.jnt_dofadr[j]) for j in pad_joints]
        #: per pick: each pad's torsional friction per newton (m, mu included) and the target's body (-1: none)
        self._torsion = np.full(2, self.mu * TORSION_LENGTH)
        self._target_body = -1

        def adr(names: Sequence[str]) -> list[tuple[int, int]]:
            ids = (mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in names)
            return [(int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])) for j in ids]
        self._jaw_z = [] if self._arc is None else adr(JAWS_Z)
        self._arc_s = [] if self._arc is None or not self._arc.chained else adr(ARCS)
        # per geom: which gripper body it belongs to ("" none) and which part body (-1 none)
        gripper_bodies = {self._hand: "hand", self._jaw_body[0]: "jaw0", self._jaw_body[1]: "jaw1",
                          self._pad_body[0]: "jaw0", self._pad_body[1]: "jaw1"}
        self._geom_gripper = np.array([gripper_bodies.get(int(b), "") for b in m.geom_bodyid], dtype=object)
        part_of_body = np.full(m.nbody, -1, dtype=int)
        part_of_body[self.world.body_ids] = np.arange(len(self.world.bodies))
        self._geom_part = part_of_body[m.geom_bodyid]

    @property
    def model(self) -> mujoco.MjModel:
        return self.world.model

    @property
    def data(self) -> mujoco.MjData:
        return self.world.data

    # -- the hand ----------------------------------------------------------------------------------
    def set_hand(self, T_world_tcp: np.ndarray, v: np.ndarray | None = None, w: np.ndarray | None = None) -> None:
        """Put the hand (TCP frame; a linkage gripper's at full opening, the frame its shapes are given
        in: :meth:`grasplan.gripper.model.Gripper.T_tcp_gripper`) at ``T_world_tcp`` moving at linear velocity ``v`` (m/s,
        world) and angular velocity ``w`` (rad/s, world); zero when not given."""
        d = self.data
        T = np.asarray(T_world_tcp, dtype=np.float64)
        d.qpos[self._hq:self._hq + 3] = T[:3, 3]
        d.qpos[self._hq + 3:self._hq + 7] = quaternions(T[:3, :3])
        d.qvel[self._hv:self._hv + 3] = 0.0 if v is None else v
        d.qvel[self._hv + 3:self._hv + 6] = 0.0 if w is None else T[:3, :3].T @ w  # a free joint: body frame

    def set_jaws(self, opening: float) -> None:
        """Open the jaws to ``opening`` (m), at rest, motors off."""
        half = float(np.clip(0.5 * opening, 0.0, 0.5 * self.gripper.max_opening))
        for q, v in zip(self._jaw_q, self._jaw_v):
            self.data.qpos[q] = half
            self.data.qvel[v] = 0.0
        for q, v in zip(self._pad_q, self._pad_v):  # the pads back square on their hinges
            self.data.qpos[q] = 0.0
            self.data.qvel[v] = 0.0
        for q, v in self._jaw_z:  # a linkage's pads on their arc
            assert self._arc is not None
            self.data.qpos[q] = self._arc.z_at(half)
            self.data.qvel[v] = 0.0
        for q, v in self._arc_s:  # and where on it (a chained arc)
            assert self._arc is not None
            self.data.qpos[q] = self._arc.s_at(half)
            self.data.qvel[v] = 0.0
        self.data.ctrl[:] = 0.0

    def squeeze(self, force: float) -> None:
        """Push the jaws closed with ``force`` (N, the sum of both; negative opens them)."""
        self.data.ctrl[:] = float(np.clip(force, -self.grip_force, self.grip_force)) / CONTACTS_PER_GRIP

    def opening(self) -> float:
        """The jaws' opening now (m)."""
        return float(self.data.qpos[self._jaw_q[0]] + self.data.qpos[self._jaw_q[1]])

    def hand_pose(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = self.data.xmat[self._hand].reshape(3, 3)
        T[:3, 3] = self.data.xpos[self._hand]
        return T

    def park_hand(self) -> None:
        """Take the gripper out of the way (:data:`HAND_PARK`), jaws open, motors off."""
        import mujoco

        T = np.eye(4)
        T[:3, 3] = HAND_PARK
        self.set_hand(T)
        self.set_jaws(self.gripper.max_opening)
        mujoco.mj_forward(self.model, self.data)

    def set_jaw_torsion(self, torsion: ArrayLike | None, target: int | None = None) -> None:
        """For the next pick: each pad's torsional friction per newton of normal force (m, ``mu``
        included: ``mu * torsion_length(patch area)``; None: ``mu * TORSION_LENGTH``) and the
        ``target`` part (body index in :attr:`world`) whose contacts with a pad set that pad's hinge
        friction every control period; the hinges start at the capacity under the nominal grip (half
        the grip force per pad).

        Twist: one torsional resistance per pad, as :mod:`grasplan.sim.simulate` models it: each pad
        hinge's dry friction (``frictionloss``) is the pad patch's soft-finger torsion under the pad's
        present contact forces on the target part, ``torsion * sqrt(N^2 - (|t| / mu)^2)``, set before
        every control period by :func:`grasplan.sim.simulate.pad_twist_caps` (the same function);
        ``torsion`` comes per pick from the pick's contact patches
        (:func:`grasplan.grasps.patches.contact_patches`, :func:`grasplan.grasps.wrench.torsion_length`)."""
        t = np.full(2, self.mu * TORSION_LENGTH) if torsion is None else np.asarray(torsion, dtype=np.float64)
        if t.shape != (2,) or not np.all(np.isfinite(t)) or np.any(t < 0):
            raise ValueError(f"set_jaw_torsion: expected two torsional friction lengths >= 0 (m), got {torsion!r}")
        self._torsion = t
        self._target_body = -1 if target is None else int(self.world.body_ids[target])
        self.model.dof_frictionloss[self._pad_v] = self._nominal_twist()

    def _nominal_twist(self) -> np.ndarray:
        return self._torsion * (self.grip_force / CONTACTS_PER_GRIP)

    def pad_twist(self) -> np.ndarray:
        """(2,) each pad hinge's dry friction now (N m): its twist capacity."""
        return np.array(self.model.dof_frictionloss[self._pad_v])

    def step(self, seconds: float) -> None:
        """Advance ``seconds`` in control periods (:data:`CONTROL_DT`), each pad hinge's friction set
        before each from its present contacts with the target (:func:`grasplan.sim.simulate.pad_twist_caps`)."""
        n = max(1, round(seconds / CONTROL_DT))
        for _ in range(n):
            self.model.dof_frictionloss[self._pad_v] = pad_twist_caps(
                self.model, self.data, self._jaw_geom, self._target_body, self._torsion, self.mu, self._nominal_twist())
            self.world.step(seconds / n)

    # -- contacts ----------------------------------------------------------------------------------
    def contacts(self) -> list[Contact]:
        """The gripper's contacts now (after a step or ``mj_forward``)."""
        import mujoco

        d, m = self.data, self.model
        n = d.ncon
        if n == 0:
            return []
        g1 = np.asarray(d.contact.geom1[:n])
        g2 = np.asarray(d.contact.geom2[:n])
        grip1, grip2 = self._geom_gripper[g1], self._geom_gripper[g2]
        out = []
        f6 = np.zeros(6)
        for k in np.flatnonzero((grip1 != "") | (grip2 != "")):
            mine, other = (g1[k], g2[k]) if grip1[k] != "" else (g2[k], g1[k])
            if self._geom_gripper[other] != "":
                continue  # jaw against its own hand: excluded by MuJoCo, kept out here too
            mujoco.mj_contactForce(m, d, int(k), f6)
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, int(other)) or f"geom{int(other)}"
            part = int(self._geom_part[other])
            out.append(Contact(gripper=str(self._geom_gripper[mine]), part=part,
                               other=self.world.bodies[part].name if part >= 0 else name.split("#")[0] or name,
                               depth=float(-d.contact.dist[k]), force=float(f6[0]),
                               pos=np.array(d.contact.pos[k], dtype=np.float64)))
        return out
