"""Lift-and-shake check of grasps in MuJoCo, headless, on the CPU.

:func:`simulate_grasps` builds one model per part and gripper (:func:`build_model_xml`) and closes,
lifts and shakes each grasp in it (:func:`_run_grasps`, the protocol of :func:`_profile`), each pad
on a hinge that carries its twist (:func:`pad_twist_caps`); :func:`simulate_result` and
:func:`simulate_plan` simulate the best grasps of a result and rank those that held first.

Deterministic: MuJoCo runs single-threaded from a reset state; ``seed`` only selects the CoACD
decomposition (it is part of the cache key).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from .decomposition import convex_pieces  # also the name the pile world and benchmarks import
from ..errors import InputError
from ..gripper.model import Box, Gripper, Shape
from ..config.materials import DEFAULT_DENSITY
from ..part.mass import MassProperties, mass_properties
from ..geometry.meshdata import TriangleMesh
from ..grasps.patches import contact_patches
from ..grasps.ranking import distinct_order
from ..status import Status
from ..geometry.transforms import check_transform, quaternions
from ..grasps.wrench import CONTACTS_PER_GRIP, LOAD, torsion_length

if TYPE_CHECKING:  # MuJoCo loads with the first simulation
    import mujoco

    from ..results.plan_result import PlanResult

#: lift height (m) and duration (s); shake amplitude (m/s^2), total duration (s, half along world x
#: then half along y), frequency (Hz): the load model :data:`grasplan.grasps.wrench.LOAD`, which
#: ``gravity_margin`` checks (one definition of the shake)
LIFT_HEIGHT, LIFT_S = LOAD.lift_height, LOAD.lift_s
SHAKE_ACCEL, SHAKE_S, SHAKE_HZ = LOAD.shake_accel, LOAD.shake_s, LOAD.shake_hz
#: settle with open jaws, then close (s)
SETTLE_S, CLOSE_S = 0.05, 0.3
#: success thresholds: centre-of-mass displacement (m) and rotation (deg) relative to the jaws
SLIP_TOL, TURN_TOL_DEG = 0.005, 5.0
#: a run stops once the part is this far off the jaws (m): it has fallen
ABORT_SLIP = 0.03
#: physics step and control period (s): gravity and the table pose are updated every control period
TIMESTEP, CONTROL_DT = 0.001, 0.005
#: jaw closing speed under full force (m/s) -> joint damping grip_force / speed; jaw mass (kg)
CLOSE_SPEED, JAW_MASS = 0.05, 0.2
#: time constant (s) in which a jaw reaches its closing speed: the jaw's effective mass is
#: ``DRIVE_TAU * damping``, the rest of it over ``JAW_MASS`` added as ``armature`` (the drive's
#: reflected inertia: a motor through a spindle reflects kilograms onto the jaw). With a
#: bare 0.2 kg jaw and 1400 N s/m of damping, ``m / b`` = 0.14 ms, 7x below the 1 ms timestep, the
#: jaws and a part touching them at many points (CoACD pieces) rang at ~50 Hz (0.2 mm, the contact
#: breaking every 20 ms), ratcheting a light part out by ~0.05 mm per cycle (SileaneGear at
#: 1200 kg/m^3: 6 of the top 20 "slipped" 5.0-5.8 mm while the steel one held). ``DRIVE_TAU`` >= 2
#: timesteps removes the ringing (slip < 0.05 mm), as do a 0.5 ms timestep or a 0.5 kg jaw.
DRIVE_TAU = 0.002
#: contact time constant (s, >= 2 timesteps): stiff enough that grip_force indents well below 1 mm
SOLREF_TIMECONST = 0.002
#: torsional friction length of MuJoCo's soft contacts (m): torque <= mu * this * normal force; the
#: part against the table. Jaw contacts use each grasp's own patch (``wrench.torsion_length``).
TORSION_LENGTH = 1e-3
#: torsional friction length (m) of the pad-part contacts: large, so that a pad grips the part in twist
#: and the twist slips at the pad's hinge, whose friction is the patch's (one torsional resistance
#: per pad, not one per MuJoCo contact point). 5 cm is 5x the largest disc radius a 16 x 40
#: mm pad can touch; at the hinge's capacity the contacts' torsion uses < 4 % of their friction cone.
PAD_GRIP_TORSION = 0.05
#: the pad body on its hinge: mass (kg; part of JAW_MASS in reality), inertia (kg m^2) and the
#: hinge's armature (kg m^2, keeps its time constant above the timestep against stiff contacts)
PAD_MASS, PAD_INERTIA, PAD_ARMATURE = 0.01, 1e-6, 1e-5
#: impedance of the hinge's dry friction (solimp): near-rigid stiction, no creep below the capacity
PAD_SOLIMP = (0.9999, 0.9999, 0.001, 0.5, 2.0)
#: table half extents (m)
TABLE_HALF = (0.5, 0.5, 0.025)
#: gravity, m/s^2
G = 9.81


@dataclass(frozen=True)
class SimResult:
    """Outcome per simulated grasp: ``success`` (k,) bool, ``slip_m`` (k,) m, ``turn_deg`` (k,) deg,
    and the whole run's wall time ``seconds``; ``pieces``: convex pieces of the part's collision;
    ``jaw_torsion_m`` (k, 2): each jaw's torsional friction coefficient (m: torque per newton of
    normal force) in that grasp's run."""

    success: np.ndarray
    slip_m: np.ndarray
    turn_deg: np.ndarray
    seconds: float
    pieces: int
    jaw_torsion_m: np.ndarray | None = None
    #: (k,) kg and (k, 3) m: the load on the flange while the part is carried (the gripper's mass and
    #: centre of mass from its file plus the part in the jaws, flange frame); None without a gripper mass
    payload_kg: np.ndarray | None = None
    payload_com: np.ndarray | None = None

    def to_json(self, i: int) -> dict:
        """The ``sim`` object of grasp ``i``."""
        return {"success": bool(self.success[i]), "slip_m": float(self.slip_m[i]), "turn_deg": float(self.turn_deg[i])}


def flange_payload(gripper: Gripper, mass_props: MassProperties, T_part_tcp: np.ndarray, width: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray] | None:
    """The load on the flange while grasp ``i`` carries the part: ``(kg (k,), centre of mass (k, 3) in
    the flange frame, m)``: the gripper's ``mass`` / ``com`` (its file) plus the part (its mass at
    its centre of mass, placed by ``T_part_tcp`` (k, 4, 4) and the TCP at each ``width`` (k,)). None
    when the gripper file gives no mass."""
    if gripper.mass is None or gripper.com is None:
        return None
    T_tcp_part = np.linalg.inv(np.asarray(T_part_tcp, dtype=np.float64))
    T_flange_tcp = np.stack([gripper.T_flange_tcp_at(float(wi)) for wi in np.asarray(width, dtype=np.float64)])
    T_flange_part = T_flange_tcp @ T_tcp_part
    c_part = T_flange_part[:, :3, :3] @ np.asarray(mass_props.com, dtype=np.float64) + T_flange_part[:, :3, 3]
    m_g, m_p = float(gripper.mass), float(mass_props.mass)
    total = np.full(len(c_part), m_g + m_p)
    com = (m_g * np.asarray(gripper.com, dtype=np.float64) + m_p * c_part) / (m_g + m_p)
    return total, com


# ------------------------------------------------------------------------------------------------
# the MuJoCo model
# ------------------------------------------------------------------------------------------------
def _fmt(a: ArrayLike) -> str:
    return " ".join(f"{x:.9g}" for x in np.asarray(a, dtype=np.float64).ravel())


def _shape_xml(shape: Shape, name: str, assets: list, attrs: str) -> str:
    if isinstance(shape, Box):
        q = quaternions(shape.T_tcp_box[:3, :3])
        return (f'<geom name="{name}" type="box" size="{_fmt(0.5 * np.asarray(shape.extents))}" '
                f'pos="{_fmt(shape.T_tcp_box[:3, 3])}" quat="{_fmt(q)}" {attrs}/>')
    assets.append(f'<mesh name="{name}" vertex="{_fmt(shape.vertices)}"/>')  # MuJoCo collides with its hull
    return f'<geom name="{name}" type="mesh" mesh="{name}" {attrs}/>'


def _arena(n_pieces: int) -> str:
    """MuJoCo arena size (``<size memory=...>``) for a part of ``n_pieces`` convex pieces: contacts
    and constraints grow with the pieces touching the jaws and the table, and a full arena silently
    drops them (:func:`simulate_grasps` refuses such a run)."""
    return f"{32 + n_pieces // 2}M"


def pad_xml(name: str, geom: str, body_attrs: str = "") -> str:
    """A jaw's finger on its pad hinge: a body ``name`` (its hinge joint too) turning about the
    closing axis (the x axis of its parent, the jaw, through the jaw's origin) whose dry friction
    (``frictionloss``, set per grasp and control period by :func:`pad_twist_caps`) is the pad patch's
    torsional friction (:func:`pad_twist_caps`); ``geom`` the finger's shape. Also the clutter world's pads
    (:mod:`grasplan.clutter.world`)."""
    return (f'<body name="{name}" pos="0 0 0" {body_attrs}><inertial pos="0 0 0" mass="{PAD_MASS}" '
            f'diaginertia="{_fmt([PAD_INERTIA] * 3)}"/><joint name="{name}" type="hinge" axis="1 0 0" pos="0 0 0" '
            f'frictionloss="0" armature="{PAD_ARMATURE:.6g}" solreffriction="{SOLREF_TIMECONST:.6g} 1" '
            f'solimpfriction="{_fmt(PAD_SOLIMP)}"/>{geom}</body>')


def build_model_xml(pieces: list[np.ndarray], mass_props: MassProperties, gripper: Gripper, *, mu: float,
                    grip_force: float) -> str:
    """MJCF text of the part (free body, convex ``pieces``), the gripper (world = TCP frame) and a
    mocap table:

    - the **part** is a free body of uniform density (:mod:`grasplan.part.mass`: mass, centre of mass
      and inertia), colliding through convex pieces: a CoACD convex decomposition (``decomposition=
      "coacd"``, cached per part geometry in ``$GRASPLAN_CACHE_DIR`` or ``~/.cache/grasplan``, written
      atomically) or the part's convex hull (``"hull"``: a cheap stand-in, exact for convex parts, for
      tests);
    - the **gripper**: its body shapes fixed, its two jaws (the gripper's own finger shapes) on
      prismatic joints along the closing axis, coupled (centric, as the real gripper) and each pushed
      by a motor of at most ``grip_force / 2`` N (``grip_force`` is the datasheet gripping force, the
      sum of both jaws' forces, as in :mod:`grasplan.grasps.wrench`), with damping so they close at
      about 5 cm/s and the drive's reflected inertia (``armature``) so they reach that speed in
      ``DRIVE_TAU``; each finger on its pad hinge (:func:`pad_xml`, :func:`pad_twist_caps`);
    - the **table**: a box whose top is the cell's table plane, touching only the part.

    Contacts: friction ``mu`` (elliptic cones); part against table: ``TORSION_LENGTH``."""
    assets: list[str] = []
    fr = f'friction="{mu:.6g} {mu * TORSION_LENGTH:.6g} 0" condim="4" solref="{SOLREF_TIMECONST:.6g} 1"'
    grip_geoms = " ".join(_shape_xml(s, f"body{i}", assets, f'contype="1" conaffinity="0" {fr}')
                          for i, s in enumerate(gripper.body))
    # the pads grip the part in twist (PAD_GRIP_TORSION); the twist slips at each pad's hinge
    fj = f'friction="{mu:.6g} {mu * PAD_GRIP_TORSION:.6g} 0" condim="4" solref="{SOLREF_TIMECONST:.6g} 1"'
    jaw1 = _shape_xml(gripper.finger, "jaw1", assets, f'contype="1" conaffinity="0" {fj}')
    T180 = np.diag([-1.0, -1.0, 1.0, 1.0])
    jaw0 = _shape_xml(gripper.finger.moved(T180), "jaw0", assets, f'contype="1" conaffinity="0" {fj}')
    part_geoms = []
    for i, v in enumerate(pieces):
        assets.append(f'<mesh name="piece{i}" vertex="{_fmt(v)}"/>')
        part_geoms.append(f'<geom type="mesh" mesh="piece{i}" contype="3" conaffinity="1" {fr}/>')
    I = mass_props.inertia
    full = [I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]]
    half = 0.5 * gripper.max_opening
    jaw_force = grip_force / CONTACTS_PER_GRIP  # grip_force is the sum over both jaws
    damping = jaw_force / CLOSE_SPEED
    armature = max(DRIVE_TAU * damping - JAW_MASS, 0.0)
    jaw_inertia = _fmt([JAW_MASS * 1e-4] * 3)
    return f"""<mujoco model="grasplan_lift_shake">
  <compiler angle="radian" inertiafromgeom="false" boundmass="1e-6" boundinertia="1e-12"/>
  <option timestep="{TIMESTEP}" cone="elliptic" impratio="10" integrator="implicitfast"/>
  <size memory="{_arena(len(pieces))}"/>
  <asset>{''.join(assets)}</asset>
  <worldbody>
    {grip_geoms}
    <body name="jaw0" pos="0 0 0">
      <inertial pos="0 0 0" mass="{JAW_MASS}" diaginertia="{jaw_inertia}"/>
      <joint name="jaw0" type="slide" axis="-1 0 0" range="0 {half:.9g}" limited="true" damping="{damping:.6g}"
             armature="{armature:.6g}"/>
      {pad_xml("pad0", jaw0)}
    </body>
    <body name="jaw1" pos="0 0 0">
      <inertial pos="0 0 0" mass="{JAW_MASS}" diaginertia="{jaw_inertia}"/>
      <joint name="jaw1" type="slide" axis="1 0 0" range="0 {half:.9g}" limited="true" damping="{damping:.6g}"
             armature="{armature:.6g}"/>
      {pad_xml("pad1", jaw1)}
    </body>
    <body name="part">
      <freejoint name="part"/>
      <inertial pos="{_fmt(mass_props.com)}" mass="{mass_props.mass:.9g}" fullinertia="{_fmt(full)}"/>
      {''.join(part_geoms)}
    </body>
    <body name="table" mocap="true">
      <geom type="box" size="{_fmt(TABLE_HALF)}" contype="0" conaffinity="2" {fr}/>
    </body>
  </worldbody>
  <equality><joint joint1="jaw0" joint2="jaw1" polycoef="0 1 0 0 0" solref="{SOLREF_TIMECONST:.6g} 1"/></equality>
  <actuator>
    <motor name="close0" joint="jaw0" gear="-1" ctrlrange="0 {jaw_force:.9g}" ctrllimited="true"/>
    <motor name="close1" joint="jaw1" gear="-1" ctrlrange="0 {jaw_force:.9g}" ctrllimited="true"/>
  </actuator>
</mujoco>"""


def _profile() -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Per control period: gripper acceleration (P, 3) m/s^2 and height (P,) m in the world, the
    close flag (P,) and the index where the jaws have closed.

    The protocol: settle ``SETTLE_S``, close ``CLOSE_S`` (from the pre-grasp opening
    ``gripper.pregrasp_opening(width)``), lift ``LIFT_HEIGHT`` (10 cm) in ``LIFT_S`` (0.5 s, cosine
    profile, peak 2 m/s^2), shake ``SHAKE_ACCEL`` (+-5 m/s^2) along world x then y for ``SHAKE_S``
    (1 s in all, ``SHAKE_HZ`` sine): :data:`grasplan.grasps.wrench.LOAD`, the load model
    ``gravity_margin`` checks (the margin takes their peaks: lift +-2 m/s^2, shake +-5 m/s^2 in any
    horizontal direction, x and y among them)."""
    n_settle = round(SETTLE_S / CONTROL_DT)
    n_close = round(CLOSE_S / CONTROL_DT)
    n_lift = round(LIFT_S / CONTROL_DT)
    n_shake = round(SHAKE_S / CONTROL_DT)
    P = n_settle + n_close + n_lift + n_shake
    acc = np.zeros((P, 3))
    z = np.zeros(P)
    t = (np.arange(n_lift) + 0.5) * CONTROL_DT
    w = math.pi / LIFT_S
    s = slice(n_settle + n_close, n_settle + n_close + n_lift)
    acc[s, 2] = 0.5 * LIFT_HEIGHT * w * w * np.cos(w * t)
    z[s] = 0.5 * LIFT_HEIGHT * (1.0 - np.cos(w * t))
    z[n_settle + n_close + n_lift:] = LIFT_HEIGHT
    ts = (np.arange(n_shake) + 0.5) * CONTROL_DT
    half = n_shake // 2
    a = SHAKE_ACCEL * np.sin(2.0 * math.pi * SHAKE_HZ * ts)
    acc[P - n_shake:P - n_shake + half, 0] = a[:half]
    acc[P - n_shake + half:, 1] = a[half:]
    close = np.zeros(P, dtype=bool)
    close[n_settle:] = True
    return acc, z, close, n_settle + n_close


def pad_twist_caps(model: mujoco.MjModel, data: mujoco.MjData, jaw_geom: list[int], part_body: int,
                   torsion: np.ndarray, mu: float, nominal: np.ndarray) -> np.ndarray:
    """(2,) twist capacity (N m) of each pad's hinge now: the soft-finger ellipse of the pad's patch
    under its present contact forces, ``torsion * sqrt(N^2 - (|t| / mu)^2)`` (``N``: the pad's total
    normal force on the part, ``t``: the vector sum of its tangential forces, ``torsion``: the
    patch's torsional friction per newton, :func:`grasplan.grasps.wrench.torsion_length` times ``mu``).
    A pad touching nothing keeps ``nominal``.

    **Twist: one torsional resistance per pad.** MuJoCo touches a pad at several points (the corners
    of each convex piece's overlap with the pad, one per piece and pad for curved pieces); when each
    point carried its own soft-finger torsion sized for the whole patch, and their spread added the
    torque tangential friction gives, a pad resisted twist according to how many points it got (a
    box face: 4 corners, twice the patch's torsion; a grasp and its mirror image split). Each finger
    therefore sits on a **hinge about the closing axis** (``pad0``/``pad1``, :func:`pad_xml`) whose
    dry friction (``frictionloss``) is this capacity, ``mu (2/3) a sqrt(N^2 - (|t| / mu)^2)`` with
    ``a = sqrt(area / pi)`` of the patch between the pad and the part
    (:func:`grasplan.grasps.patches.contact_patches`), updated every control period: the soft-finger
    ellipse ``gravity_margin`` uses. The pad-part contacts themselves grip in twist (``condim`` 4 with
    ``PAD_GRIP_TORSION``), so the twist slips at the hinge, whatever the number of points; their
    normal and tangential forces, and the pressure moment their spread carries, stay MuJoCo's. The
    hinge's stiction is near rigid (``PAD_SOLIMP``: no creep below the capacity)."""
    normal = np.zeros(2)
    tangent = np.zeros((2, 3))
    if data.ncon:
        con = data.contact  # struct-of-arrays view over the active contacts
        geom, addr = np.asarray(con.geom), np.asarray(con.efc_address)
        frame = np.asarray(con.frame).reshape(-1, 3, 3)
        body = model.geom_bodyid
        for j in range(2):
            mine = (addr >= 0) & (((geom[:, 0] == jaw_geom[j]) & (body[geom[:, 1]] == part_body))
                                  | ((geom[:, 1] == jaw_geom[j]) & (body[geom[:, 0]] == part_body)))
            if mine.any():
                a = addr[mine]  # elliptic cones: the force rows are (normal, t1, t2, ...) in the contact frame
                f = data.efc_force
                normal[j] = f[a].sum()
                tangent[j] = (f[a + 1][:, None] * frame[mine, 1] + f[a + 2][:, None] * frame[mine, 2]).sum(axis=0)
    t = np.linalg.norm(tangent, axis=1) / max(mu, 1e-12)
    cap = np.asarray(torsion, dtype=np.float64) * np.sqrt(np.maximum(normal * normal - t * t, 0.0))
    return np.where(normal > 0, cap, nominal)


def _rotation_angle_deg(R: np.ndarray) -> float:
    return math.degrees(math.acos(float(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


def simulate_grasps(part_mesh: TriangleMesh, gripper: Gripper, T_world_part: np.ndarray, T_part_tcp: np.ndarray,
                    width: np.ndarray, *, table_z: float = 0.0, density: float = DEFAULT_DENSITY,
                    mass: float | None = None, mass_props: MassProperties | None = None,
                    grip_force: float | None = None, mu: float = 0.3, seed: int = 0,
                    decomposition: str = "coacd", cache: bool = True,
                    contact_area: np.ndarray | None = None) -> SimResult:
    """Close, lift and shake each grasp (:func:`build_model_xml`, :func:`_run_grasps`).

    Parameters
    ----------
    part_mesh : TriangleMesh
        Part frame, metres.
    gripper : Gripper
    T_world_part : (4, 4)
        The part resting on the table.
    T_part_tcp : (k, 4, 4)
        Grasps (TCP frames in the part frame).
    width : (k,)
        Contact distance per grasp, m (sets the pre-grasp opening).
    table_z : float
        Height of the table top in the world, m.
    density, mass, mass_props
        Uniform density (kg/m^3) or total mass (kg), or precomputed mass properties.
    grip_force : float, optional
        Gripping force, N, the sum of both jaws (each pushes with half); default ``gripper.grip_force``.
    mu : float
        Friction coefficient of every contact.
    seed : int
        Selects the CoACD decomposition.
    decomposition : "coacd" | "hull"
        The part's collision shape (``"hull"``: its convex hull; cheap, for tests or convex parts).
    cache : bool
        Read and write the CoACD cache.
    contact_area : (k, 2), optional
        Patch area (m^2) of each jaw (jaw 0 on the TCP's -x side), e.g. a grasp's recorded
        ``quality.contact``; computed here (:func:`grasplan.grasps.patches.contact_patches`) when not
        given or not finite. Sets each jaw's torsional friction (:func:`pad_twist_caps`).
    """
    import mujoco

    t_start = time.perf_counter()
    Twp = check_transform(T_world_part, "T_world_part")
    T = np.asarray(T_part_tcp, dtype=np.float64)
    T = check_transform(T.reshape(-1, 4, 4), "T_part_tcp", batch=True)
    w = np.asarray(width, dtype=np.float64).reshape(-1)
    if len(w) != len(T) or not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise InputError(f"simulate: expected one positive width (m) per grasp ({len(T)}), got {np.shape(width)}")
    if np.any(w > gripper.max_opening + 1e-9):
        raise InputError(f"simulate: a grasp is wider ({w.max():.4f} m) than the gripper opens "
                         f"({gripper.max_opening:.4f} m); simulate grasps from the same gripper")
    if not (math.isfinite(mu) and mu >= 0):
        raise InputError(f"simulate: mu must be a finite number >= 0, got {mu!r}")
    F = float(gripper.grip_force if grip_force is None else grip_force)
    if not (math.isfinite(F) and F > 0):
        raise InputError(f"simulate: grip_force must be > 0 N, got {grip_force!r}")
    mp = mass_props if mass_props is not None else mass_properties(part_mesh, density=density, mass=mass)
    area = None if contact_area is None else np.asarray(contact_area, dtype=np.float64)
    if area is not None and area.shape != (len(T), 2):
        raise InputError(f"simulate: expected contact areas (k, 2) for k = {len(T)} grasps, got {area.shape}")
    if area is None or not np.all(np.isfinite(area)):
        x = T[:, :3, 0] * (0.5 * w)[:, None]
        C = np.stack([T[:, :3, 3] - x, T[:, :3, 3] + x], axis=1)
        computed = contact_patches(part_mesh, gripper, T, C)[0]
        area = computed if area is None else np.where(np.isfinite(area), area, computed)
    jaw_torsion = float(mu) * torsion_length(area)  # (k, 2) m: MuJoCo's torsional friction per jaw
    pieces = convex_pieces(part_mesh, decomposition=decomposition, seed=seed, cache=cache)
    model = mujoco.MjModel.from_xml_string(build_model_xml(pieces, mp, gripper, mu=mu, grip_force=F))
    data = mujoco.MjData(model)
    q_part = model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "part")]
    q_jaw = [model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"jaw{j}")] for j in range(2)]
    part_body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "part")
    # table box centre in the world: under the part, top face on table_z
    T_world_table = np.eye(4)
    T_world_table[:3, 3] = [Twp[0, 3], Twp[1, 3], table_z - TABLE_HALF[2]]

    k = len(T)
    # MuJoCo writes its warnings to MUJOCO_LOG.TXT in the current folder: silence them while we run
    # (the only one that matters, a full arena, is read from data.warning and refused)
    previous_handler = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda msg: None)
    try:
        res = _run_grasps(model, data, pieces, Twp, T, w, gripper, F, q_part, q_jaw, part_body, T_world_table,
                          t_start, k, jaw_torsion, float(mu))
        load = flange_payload(gripper, mp, T, w)  # the gripper's mass and centre of mass + the part
        return res if load is None else replace(res, payload_kg=load[0], payload_com=load[1])
    finally:
        mujoco.set_mju_user_warning(previous_handler)


def _run_grasps(model: mujoco.MjModel, data: mujoco.MjData, pieces: list[np.ndarray], Twp: np.ndarray,
                T: np.ndarray, w: np.ndarray, gripper: Gripper, F: float, q_part: int, q_jaw: list[int],
                part_body: int, T_world_table: np.ndarray, t_start: float, k: int, jaw_torsion: np.ndarray,
                mu: float) -> SimResult:
    """The lift-and-shake of :func:`simulate_grasps` for each of the ``k`` poses ``T``;
    ``jaw_torsion`` (k, 2): each jaw's torsional friction coefficient (m) per grasp.

    The simulation runs in the gripper's (TCP) frame, which only translates: lifting and shaking the
    gripper is exactly a change of the effective gravity ``R_world_tcp^T (g - a_gripper(t))`` and a
    table moving away (:func:`_profile`). Success: at the end the part moved less than ``SLIP_TOL``
    (5 mm, its centre of mass) and turned less than ``TURN_TOL_DEG`` (5 deg) relative to the jaws
    since they closed. A part more than ``ABORT_SLIP`` off stops its run early (``slip_m`` is then
    the distance then)."""
    import mujoco

    jaw_geom = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"jaw{j}") for j in range(2)]
    pad_dof = [model.jnt_dofadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"pad{j}")] for j in range(2)]

    acc, lift_z, close, i_closed = _profile()
    nstep = round(CONTROL_DT / TIMESTEP)
    g_world = np.array([0.0, 0.0, -G])
    success = np.zeros(k, dtype=bool)
    slip = np.zeros(k)
    turn = np.zeros(k)
    torsion_used = np.zeros((k, 2))
    for i in range(k):
        T_world_tcp = Twp @ T[i]
        R_wt = T_world_tcp[:3, :3]
        T_tcp_part = np.linalg.inv(T[i])
        torsion_used[i] = jaw_torsion[i]
        nominal = jaw_torsion[i] * (F / CONTACTS_PER_GRIP)  # each pad's twist capacity at the nominal grip
        model.dof_frictionloss[pad_dof] = nominal
        mujoco.mj_resetData(model, data)
        data.qpos[q_part:q_part + 3] = T_tcp_part[:3, 3]
        data.qpos[q_part + 3:q_part + 7] = quaternions(T_tcp_part[:3, :3])
        half_open = 0.5 * float(gripper.pregrasp_opening(w[i]))
        data.qpos[q_jaw[0]] = data.qpos[q_jaw[1]] = half_open
        # table pose in the TCP frame as the gripper rises by lift_z (P,)
        T_tcp_table0 = np.linalg.inv(T_world_tcp) @ T_world_table
        down_tcp = R_wt.T @ np.array([0.0, 0.0, -1.0])
        table_quat = quaternions(T_tcp_table0[:3, :3])
        data.mocap_quat[0] = table_quat
        gravity = (g_world - acc) @ R_wt  # (P, 3): R_wt^T (g - a) per control period
        ref = None
        for p in range(len(acc)):
            model.opt.gravity[:] = gravity[p]
            if close[p]:
                model.dof_frictionloss[pad_dof] = pad_twist_caps(model, data, jaw_geom, part_body, jaw_torsion[i],
                                                                  mu, nominal)
            data.mocap_pos[0] = T_tcp_table0[:3, 3] + lift_z[p] * down_tcp
            data.ctrl[:] = F / CONTACTS_PER_GRIP if close[p] else 0.0
            try:
                mujoco.mj_step(model, data, nstep=nstep)
            except mujoco.FatalError as e:  # the arena overflowed outright
                raise RuntimeError(f"MuJoCo ran out of contact/constraint memory simulating grasp {i} with "
                                   f"{len(pieces)} convex pieces (arena {_arena(len(pieces))}): {e}") from e
            if p + 1 == i_closed:
                ref = (data.xpos[part_body].copy(), data.xmat[part_body].reshape(3, 3).copy(),
                       data.xipos[part_body].copy())
            elif ref is not None and p % 10 == 0 and np.linalg.norm(data.xipos[part_body] - ref[2]) > ABORT_SLIP:
                break
        full = [w for w in (mujoco.mjtWarning.mjWARN_CNSTRFULL, mujoco.mjtWarning.mjWARN_CONTACTFULL)
                if data.warning[w].number > 0]
        if full:
            raise RuntimeError(f"MuJoCo ran out of contact/constraint memory simulating grasp {i} with "
                               f"{len(pieces)} convex pieces (arena {_arena(len(pieces))}): the result "
                               f"would be wrong; use --decomposition hull or a coarser decomposition")
        assert ref is not None  # the jaws closed: the run breaks off only after recording ref
        com_now = data.xipos[part_body]
        R_now = data.xmat[part_body].reshape(3, 3)
        slip[i] = float(np.linalg.norm(com_now - ref[2]))
        turn[i] = _rotation_angle_deg(R_now @ ref[1].T)
        success[i] = slip[i] < SLIP_TOL and turn[i] < TURN_TOL_DEG
    return SimResult(success=success, slip_m=slip, turn_deg=turn, seconds=time.perf_counter() - t_start,
                     pieces=len(pieces), jaw_torsion_m=torsion_used)


# ------------------------------------------------------------------------------------------------
# results: simulate the best grasps of a grasps/plan result and rank those that held first
# ------------------------------------------------------------------------------------------------
#: statuses a grasp must have to be simulated (collision-free; in a plan, also the reachable ones)
SIMULATED_STATUSES: tuple[str, ...] = tuple(s.value for s in (
    Status.OK, Status.PLANNED, Status.NOT_TRIED, Status.UNREACHABLE, Status.IK_COLLISION, Status.NO_PATH))


def select_grasps(status: np.ndarray, score: np.ndarray, top: int, rank: np.ndarray | None = None) -> np.ndarray:
    """Rows of the ``top`` grasps to simulate: in a plan (``rank`` given and some grasp planned)
    the planned grasps in rank order; else the collision-free ones (``SIMULATED_STATUSES``) by
    score (NaN last, ties by row)."""
    st = np.asarray(status).astype(str)
    planned = np.flatnonzero(st == Status.PLANNED.value)
    if rank is not None and len(planned):
        r = np.where(rank[planned] < 0, np.iinfo(np.int64).max, rank[planned])
        return planned[np.lexsort((planned, r))][:top]
    ok = np.flatnonzero(np.isin(st, SIMULATED_STATUSES))
    s = np.where(np.isnan(score[ok]), -np.inf, score[ok])
    return ok[np.lexsort((ok, -s))][:top]


def rank_held_first(rank: np.ndarray, success: np.ndarray) -> np.ndarray:
    """New ranks: ranked grasps (rank >= 0) that held (``success`` == 1) first, then the others,
    each group keeping its previous (score and diversity) order; unranked stay -1."""
    rank = np.asarray(rank, dtype=np.int64)
    ranked = np.flatnonzero(rank >= 0)
    order = ranked[np.argsort(rank[ranked], kind="stable")]
    held = np.asarray(success)[order] == 1
    new = np.full(len(rank), -1, dtype=np.int64)
    new[np.concatenate([order[held], order[~held]])] = np.arange(len(order))
    return new


def simulate_result(result: PlanResult, top: int, *, mass_props: MassProperties | None = None,
                    grip_force: float | None = None, seed: int = 0, decomposition: str = "coacd", cache: bool = True
                    ) -> tuple[np.ndarray, SimResult, MassProperties, float]:
    """Simulate the ``top`` best grasps of a :class:`grasplan.results.plan_result.PlanResult` (a plan: its planned
    grasps in rank order; a grasps result: the collision-free ones by score with the diversity
    rule of the plan's ranking, ``distinct_order``).

    Returns ``(rows, SimResult, MassProperties, mu)``. Mass properties default to the result's
    recorded density/mass (``params.grasps``); ``mu`` is the candidates' friction coefficient."""
    mesh = result.part_mesh if result.part_mesh is not None else result.mesh()
    gp = result.params.grasps
    mp = mass_props if mass_props is not None else mass_properties(mesh, density=gp.density, mass=gp.mass, material=gp.material)
    mu = float(result.params.candidates.mu)
    g = result.grasps
    if result.robot is not None:
        rows = select_grasps(g.status, np.asarray(g.score, dtype=np.float64), top, rank=g.rank)
    else:  # a grasps result: by score with the plan's diversity rule (grasplan.grasps.ranking.distinct_order)
        pp = result.params.planning
        rows = select_grasps(g.status, np.asarray(g.score, dtype=np.float64), len(g))
        rows = distinct_order(g.T_part_tcp, rows, min_distance=pp.distinct_distance,
                              min_angle_deg=pp.distinct_angle_deg)[0][:top]
    if len(rows) == 0:
        st = sorted(set(np.asarray(g.status).astype(str)))
        raise InputError("simulate: no collision-free or planned grasp to simulate ("
                         + (f"statuses: {', '.join(st)}" if st else "the file has no grasp at all: no contact pair "
                            "fits the gripper; try another gripper") + ")")
    area = getattr(g, "contact_area", None)  # the recorded patches (NaN rows are computed)
    sim = simulate_grasps(mesh, result.gripper, result.T_world_part, g.T_part_tcp[rows], g.width[rows],
                          table_z=float(result.cell.table_z), mass_props=mp, grip_force=grip_force, mu=mu, seed=seed,
                          decomposition=decomposition, cache=cache,
                          contact_area=None if area is None else np.asarray(area, dtype=np.float64)[rows])
    return rows, sim, mp, mu


def with_sim(result: PlanResult, rows: np.ndarray, sim: SimResult, *, rerank: bool = True) -> PlanResult:
    """``result`` with the ``sim`` columns of ``rows`` set (others not simulated) and, for a plan
    (``rerank``), the grasps that held ranked first."""
    g = result.grasps
    M = len(g)
    succ = np.full(M, -1, dtype=np.int8) if g.sim_success is None else g.sim_success.copy()
    slip = np.full(M, np.nan) if g.sim_slip_m is None else g.sim_slip_m.copy()
    turn = np.full(M, np.nan) if g.sim_turn_deg is None else g.sim_turn_deg.copy()
    succ[rows], slip[rows], turn[rows] = sim.success.astype(np.int8), sim.slip_m, sim.turn_deg
    table = replace(g, sim_success=succ, sim_slip_m=slip, sim_turn_deg=turn)
    if rerank and result.robot is not None:
        table = replace(table, rank=rank_held_first(g.rank, succ))
    timing = {**result.timing_s, "simulate": float(sim.seconds)}
    return replace(result, grasps=table, timing_s=timing)


def simulate_plan(result: PlanResult, top: int, *, mass_props: MassProperties | None = None, seed: int = 0,
                  decomposition: str = "coacd") -> PlanResult:
    """``plan --simulate N``: simulate the top ``N`` planned grasps of a plan result, record ``sim``
    per grasp and rank the grasps that held first (a plan without planned grasps is returned as is)."""
    if not np.any(np.asarray(result.grasps.status).astype(str) == Status.PLANNED.value):
        return result
    rows, sim, _, _ = simulate_result(result, top, mass_props=mass_props, seed=seed, decomposition=decomposition)
    return with_sim(result, rows, sim)
