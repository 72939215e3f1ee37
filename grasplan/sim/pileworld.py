"""A MuJoCo world of a bin cell holding many free parts: the physics of ``grasplan scene drop``
(:mod:`grasplan.sim.drop`) and of the clutter loop, which adds a gripper to the same world.

:func:`pile_mjcf` writes the world (the static cell and one free body per part,
:class:`PartBody`); :class:`PileWorld` compiles it, places and parks the parts and steps it until
they are at rest. Deterministic: MuJoCo runs single-threaded from a reset state; the same calls
give the same bits.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..cell.model import Cell, Obstacle
from ..errors import InputError
from ..part.mass import MassProperties, mass_properties
from ..geometry.meshdata import MeshData, convex_hull
from ..piles.scene_file import NAME_RE, NAME_RULE
from ..geometry.transforms import check_transform, quaternions

#: physics step (s) and the period (s) at which rest is checked
TIMESTEP, CHECK_DT = 0.002, 0.01
#: contact time constant (s, >= 2 timesteps); damping ratio 1. Soft enough for a 2 ms step,
#: stiff enough that a resting part sinks well below 1 mm into what it rests on
SOLREF_TIMECONST = 0.004
#: the table reaches this far (m) beyond the bin (or the cell's obstacles) on every side; its thickness
TABLE_MARGIN, TABLE_THICKNESS = 0.3, 0.05
#: contact dimensionality (6: sliding, torsional and rolling friction) and the torsional and rolling
#: friction lengths (m; times ``mu``: torque per newton of normal force). Rolling resistance
#: ``mu * ROLLING_LENGTH`` = 0.6 mm at mu 0.3 (a rolling-resistance coefficient of ~0.01 on a
#: 50 mm radius: the upper end of plastics'): without it (condim 3) a slender part rocking on two
#: contacts loses little energy per impact (Housner's rocking block) and IPARingScrew rocked on the
#: bin floor for up to 9 s; with it, it stops within 1.5 s
CONDIM, TORSION_LENGTH, ROLLING_LENGTH = 6, 1e-3, 2e-3
#: collision bit of everything in the pile world (static and parts)
PILE_BIT = 1
#: parked bodies rest this far (m) below the table, spaced along x
PARK_DEPTH, PARK_SPACING = 2.0, 0.5
#: MuJoCo arena (MB): a base plus a share per convex piece (contacts grow with the pieces touching)
ARENA_BASE_MB, ARENA_PER_PIECE_MB = 64, 0.25


@dataclass(frozen=True, eq=False)
class PartBody:
    """What the world needs of one part instance: its MJCF body ``name``, convex ``pieces``
    (vertices (n_i, 3), part frame, m), ``mass`` properties and the part's convex-hull vertices
    ``hull`` (h, 3) (part frame, m: the part's extents, heights and containment in the bin are read
    from them: a convex region holds the mesh if and only if it holds these)."""

    name: str
    pieces: tuple[np.ndarray, ...]
    mass: MassProperties
    hull: np.ndarray


def part_body(name: str, mesh: MeshData, *, density: float, decomposition: str = "coacd", cache: bool = True,
              pieces: Sequence[np.ndarray] | None = None, mass: MassProperties | None = None) -> PartBody:
    """A :class:`PartBody` of a part mesh (part frame, metres) at uniform ``density`` (kg/m^3):
    its convex pieces from :func:`grasplan.sim.simulate.convex_pieces` (CoACD seed 0, cached; or
    ``pieces`` already computed, e.g. shared by every instance of the part)."""
    from .simulate import convex_pieces

    if pieces is None:
        pieces = convex_pieces(mesh.trimesh, decomposition=decomposition, cache=cache)
    mp = mass if mass is not None else mass_properties(mesh, density=density)
    hull = np.ascontiguousarray(convex_hull(mesh.vertices).vertices)
    return PartBody(name=name, pieces=tuple(np.asarray(p, dtype=np.float64) for p in pieces), mass=mp, hull=hull)


# ------------------------------------------------------------------------------------------------
# MJCF
# ------------------------------------------------------------------------------------------------
def _fmt(a: ArrayLike) -> str:
    return " ".join(f"{x:.17g}" for x in np.asarray(a, dtype=np.float64).ravel())


def _pose_attrs(T: np.ndarray) -> str:
    return f'pos="{_fmt(T[:3, 3])}" quat="{_fmt(quaternions(T[:3, :3]))}"'


def _static_xml(o: Obstacle, assets: list[str]) -> str:
    """The geoms of one fixed obstacle (world body)."""
    T = np.asarray(o.T_world_obstacle)
    if o.kind == "box":
        return f'<geom name="{o.name}" type="box" size="{_fmt(0.5 * np.asarray(o.size))}" {_pose_attrs(T)}/>'
    if o.kind == "sphere":
        return f'<geom name="{o.name}" type="sphere" size="{o.radius:.17g}" {_pose_attrs(T)}/>'
    if o.kind == "cylinder":
        assert o.radius is not None and o.length is not None  # a cylinder obstacle has both
        return (f'<geom name="{o.name}" type="cylinder" size="{o.radius:.17g} {0.5 * float(o.length):.17g}" '
                f'{_pose_attrs(T)}/>')
    from .simulate import convex_pieces

    out = []
    for k, v in enumerate(convex_pieces(o.local_mesh())):
        assets.append(f'<mesh name="obstacle#{o.name}#{k}" vertex="{_fmt(v)}"/>')
        out.append(f'<geom name="{o.name}#{k}" type="mesh" mesh="obstacle#{o.name}#{k}" {_pose_attrs(T)}/>')
    return "".join(out)


def _table_box(cell: Cell) -> tuple[np.ndarray, np.ndarray]:
    """Centre (3,) and half extents (3,) of the table box under the cell's obstacles."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for o in cell.obstacles:
        a, b = o.aabb()
        lo, hi = np.minimum(lo, a), np.maximum(hi, b)
    if not np.all(np.isfinite(lo)):
        lo = hi = np.array([cell.part_xy[0], cell.part_xy[1], cell.table_z])
    half = np.array([0.5 * (hi[0] - lo[0]) + TABLE_MARGIN, 0.5 * (hi[1] - lo[1]) + TABLE_MARGIN,
                     0.5 * TABLE_THICKNESS])
    centre = np.array([0.5 * (hi[0] + lo[0]), 0.5 * (hi[1] + lo[1]), cell.table_z - 0.5 * TABLE_THICKNESS])
    return centre, half


def park_pose(i: int) -> np.ndarray:
    """Where body ``i`` rests while parked: (4, 4), far below the table, one spot per body."""
    T = np.eye(4)
    T[:3, 3] = [PARK_SPACING * i, 0.0, -PARK_DEPTH]
    return T


def arena_mb(bodies: Sequence[PartBody]) -> int:
    """The MuJoCo arena (``<size memory>``, MB) of a world of these bodies."""
    return int(ARENA_BASE_MB + ARENA_PER_PIECE_MB * sum(len(b.pieces) for b in bodies))


def pile_mjcf(cell: Cell, bodies: Sequence[PartBody], *, mu: float, extra_asset: str = "",
              extra_worldbody: str = "", extra: str = "", arena: int | None = None) -> str:
    """MJCF text of the pile world: the cell's table and obstacles (static), one free body per entry
    of ``bodies`` (named ``body.name``, each parked: :func:`park_pose`), friction ``mu``.

    - **static**: the table (a box whose top is the cell's ``table_z``, reaching :data:`TABLE_MARGIN`
      beyond the bin), the bin's floor and four walls (``cell.bin.obstacles()``, exact boxes) and every
      other obstacle of the cell (boxes, cylinders, spheres; mesh obstacles as their convex pieces);
    - **parts**: one free body per part instance (:class:`PartBody`), uniform density
      (:func:`grasplan.part.mass.mass_properties`: mass, centre of mass, inertia), colliding through its
      convex pieces: the CoACD decomposition of :func:`grasplan.sim.simulate.convex_pieces`, cached in the
      same place ``grasplan simulate`` caches it (``decomposition="hull"``: the convex hull).

    **Frames.** A part body's frame *is* the part (mesh) frame: the MJCF body is placed at
    ``T_world_part``, its inertial frame (centre of mass, principal axes) is given explicitly inside it
    and ``alignfree`` is off, so MuJoCo's body pose (``xpos``, ``xmat``; a free joint's ``qpos``) is
    the part frame's pose and never the centre-of-mass frame (:meth:`PileWorld.pose`).

    **Contacts.** Friction ``mu`` (elliptic cones) with torsional and rolling resistance
    (``condim`` 6, :data:`ROLLING_LENGTH`); MuJoCo's multi-contact convex collision, on by default,
    keeps flat faces from rocking on one point. Contact time constant
    :data:`SOLREF_TIMECONST` (>= 2 timesteps). Collision bits: every geom of the pile world has
    ``contype`` = ``conaffinity`` = :data:`PILE_BIT`; a gripper added through ``extra_worldbody``
    collides with the pile when its geoms share that bit.

    A caller adds its own things as MJCF fragments: ``extra_asset`` (inside ``<asset>``),
    ``extra_worldbody`` (inside ``<worldbody>``: e.g. a gripper on mocap or joints; give its geoms
    ``contype``/``conaffinity`` :data:`PILE_BIT` to collide with the parts) and ``extra``
    (top-level sections: ``<actuator>``, ``<equality>``, ``<contact>``). ``arena``: MB of MuJoCo
    memory (default :func:`arena_mb`)."""
    if not (np.isfinite(mu) and mu >= 0):
        raise InputError(f"pile world: mu must be a finite number >= 0, got {mu!r}")
    names = [b.name for b in bodies]
    if len(set(names)) != len(names):
        raise InputError("pile world: body names must be unique")
    bad = [n for n in names if not NAME_RE.match(n)]
    if bad:
        raise InputError(f"pile world: body name {bad[0][:40]!r} is not valid ({NAME_RULE})")
    assets: list[str] = []
    statics = "".join(_static_xml(o, assets) for o in cell.obstacles)
    centre, half = _table_box(cell)
    table = f'<geom name="#table" type="box" size="{_fmt(half)}" pos="{_fmt(centre)}"/>'
    parts = []
    for i, b in enumerate(bodies):
        geoms = []
        for k, v in enumerate(b.pieces):
            assets.append(f'<mesh name="{b.name}#{k}" vertex="{_fmt(v)}"/>')
            geoms.append(f'<geom class="part" mesh="{b.name}#{k}"/>')
        I = b.mass.inertia
        full = [I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]]
        parts.append(f'<body name="{b.name}" {_pose_attrs(park_pose(i))} gravcomp="1">'
                     f'<freejoint name="{b.name}"/>'
                     f'<inertial pos="{_fmt(b.mass.com)}" mass="{b.mass.mass:.17g}" fullinertia="{_fmt(full)}"/>'
                     f'{"".join(geoms)}</body>')
    contact = (f'contype="{PILE_BIT}" conaffinity="{PILE_BIT}" condim="{CONDIM}" '
               f'friction="{mu:.17g} {mu * TORSION_LENGTH:.6g} {mu * ROLLING_LENGTH:.6g}" '
               f'solref="{SOLREF_TIMECONST:.6g} 1"')
    return f"""<mujoco model="grasplan_pile">
  <compiler angle="radian" inertiafromgeom="false" alignfree="false" boundmass="1e-6" boundinertia="1e-12"/>
  <option timestep="{TIMESTEP}" cone="elliptic" integrator="implicitfast" solver="Newton"/>
  <size memory="{arena if arena is not None else arena_mb(bodies)}M"/>
  <default>
    <geom {contact}/>
    <default class="part"><geom type="mesh"/></default>
  </default>
  <asset>{''.join(assets)}{extra_asset}</asset>
  <worldbody>
    {table}{statics}
    {''.join(parts)}
    {extra_worldbody}
  </worldbody>
  {extra}
</mujoco>"""


# ------------------------------------------------------------------------------------------------
# the world
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Settled:
    """Outcome of :meth:`PileWorld.settle`: ``at_rest``; simulated seconds ``sim_s`` and physics
    ``steps`` it took; the largest centre-of-mass speed ``lin`` (m/s) and turning rate ``ang``
    (rad/s) of the present parts at the end, and ``moving``: the name of the body that moved most
    relative to the thresholds ('' when none is present)."""

    at_rest: bool
    sim_s: float
    steps: int
    lin: float
    ang: float
    moving: str


class PileWorld:
    """One compiled pile world (:func:`pile_mjcf`) and its state.

    ``PileWorld(cell, bodies, mu=...)``, or ``PileWorld.from_xml(xml, cell, bodies)`` for a model
    a caller extended (:func:`pile_mjcf`'s ``extra_*``). ``model`` and ``data`` are MuJoCo's, open
    to a caller that drives more (a gripper's actuators, mocap); the methods here handle the parts.

    **Present and parked.** Every body exists from the start (one compile); a body is either present
    (colliding, under gravity) or *parked*: its geoms collide with nothing (``contype`` =
    ``conaffinity`` = 0), its weight is cancelled (``gravcomp`` 1), it is at rest far below the table.
    :meth:`place` makes a body present at a pose, :meth:`park` takes it out of the world (a dropped
    part not yet released, a picked part): nothing is recompiled.
    """

    def __init__(self, cell: Cell, bodies: Sequence[PartBody], *, mu: float, xml: str | None = None):
        import mujoco

        self.cell = cell
        self.bodies = tuple(bodies)
        text = xml if xml is not None else pile_mjcf(cell, self.bodies, mu=mu)
        try:
            self.model = mujoco.MjModel.from_xml_string(text)
        except ValueError as exc:  # MuJoCo's compiler: a piece it cannot use (degenerate hull, ...)
            raise InputError(f"pile world: MuJoCo refused the model: {str(exc).splitlines()[0][:200]}") from None
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._body = np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, b.name) for b in self.bodies], dtype=int)
        jnt = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, b.name) for b in self.bodies]
        self._qpos = np.array([m.jnt_qposadr[j] for j in jnt], dtype=int)
        self._qvel = np.array([m.jnt_dofadr[j] for j in jnt], dtype=int)
        self._geoms = [np.flatnonzero(m.geom_bodyid == b) for b in self._body]
        self.present = np.zeros(len(self.bodies), dtype=bool)
        self.steps = 0
        mujoco.mj_forward(m, self.data)

    @classmethod
    def from_xml(cls, xml: str, cell: Cell, bodies: Sequence[PartBody]) -> PileWorld:
        """A world from MJCF made by :func:`pile_mjcf` (possibly with a caller's extras)."""
        return cls(cell, bodies, mu=0.0, xml=xml)

    @property
    def body_ids(self) -> np.ndarray:
        """MuJoCo body id of each part body (n,), in :attr:`bodies` order."""
        return self._body.copy()

    def index(self, name: str) -> int:
        for i, b in enumerate(self.bodies):
            if b.name == name:
                return i
        raise InputError(f"pile world: no body {name!r}")

    # -- poses -------------------------------------------------------------------------------------
    def pose(self, i: int) -> np.ndarray:
        """``T_world_part`` (4, 4) of body ``i`` (the part mesh's frame: :func:`pile_mjcf`'s frames)."""
        T = np.eye(4)
        b = self._body[i]
        T[:3, :3] = self.data.xmat[b].reshape(3, 3)
        T[:3, 3] = self.data.xpos[b]
        return T

    def hull_world(self, i: int) -> np.ndarray:
        """Body ``i``'s convex-hull vertices (h, 3) in the world, m."""
        T = self.pose(i)
        return self.bodies[i].hull @ T[:3, :3].T + T[:3, 3]

    def _set(self, i: int, T: np.ndarray) -> None:
        a, v = self._qpos[i], self._qvel[i]
        self.data.qpos[a:a + 3] = T[:3, 3]
        self.data.qpos[a + 3:a + 7] = quaternions(T[:3, :3])
        self.data.qvel[v:v + 6] = 0.0

    def place(self, i: int, T_world_part: np.ndarray) -> None:
        """Make body ``i`` present at ``T_world_part``, at rest (colliding, under gravity)."""
        import mujoco

        T = check_transform(T_world_part, f"{self.bodies[i].name}: T_world_part")
        self._set(i, T)
        g = self._geoms[i]
        self.model.geom_contype[g] = PILE_BIT
        self.model.geom_conaffinity[g] = PILE_BIT
        self.model.body_gravcomp[self._body[i]] = 0.0
        self.present[i] = True
        mujoco.mj_forward(self.model, self.data)

    def park(self, i: int) -> None:
        """Take body ``i`` out of the world (no contacts, weightless, at :func:`park_pose`)."""
        import mujoco

        self._set(i, park_pose(i))
        g = self._geoms[i]
        self.model.geom_contype[g] = 0
        self.model.geom_conaffinity[g] = 0
        self.model.body_gravcomp[self._body[i]] = 1.0
        self.present[i] = False
        mujoco.mj_forward(self.model, self.data)

    def remove_statics(self, names: Sequence[str]) -> list[str]:
        """Take the fixed obstacles ``names`` (e.g. the bin's walls) out of the world: their geoms
        collide with nothing from now on and draw nothing (nothing is recompiled). Returns the geom
        names removed; ValueError naming the obstacles that exist when a name matches none."""
        import mujoco

        m = self.model
        wanted = set(names)
        removed = []
        for g in range(m.ngeom):
            if m.geom_bodyid[g] != 0:
                continue
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or ""
            if name in wanted or name.split("#")[0] in wanted:
                m.geom_contype[g] = m.geom_conaffinity[g] = 0
                m.geom_rgba[g, 3] = 0.0
                removed.append(name)
        missing = wanted - {n.split("#")[0] for n in removed} - set(removed)
        if missing:
            have = sorted({(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or "").split("#")[0]
                           for g in range(m.ngeom) if m.geom_bodyid[g] == 0} - {""})
            raise ValueError(f"remove_statics: no fixed obstacle {sorted(missing)}; the world has {have}")
        mujoco.mj_forward(m, self.data)
        return removed

    # -- state -------------------------------------------------------------------------------------
    def snapshot(self) -> tuple[np.ndarray, np.ndarray]:
        """The whole simulation state (MuJoCo's integration state and which bodies are present),
        for :meth:`restore`: e.g. to undo a drop and try it again."""
        import mujoco

        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        state = np.empty(mujoco.mj_stateSize(self.model, spec))
        mujoco.mj_getState(self.model, self.data, state, spec)
        return state, self.present.copy()

    def restore(self, snap: tuple[np.ndarray, np.ndarray]) -> None:
        """Return to a :meth:`snapshot` (bodies placed or parked since are parked or placed again)."""
        import mujoco

        state, present = snap
        for i in np.flatnonzero(present != self.present):
            g, on = self._geoms[i], bool(present[i])
            self.model.geom_contype[g] = self.model.geom_conaffinity[g] = PILE_BIT if on else 0
            self.model.body_gravcomp[self._body[i]] = 0.0 if on else 1.0
        self.present = present.copy()
        mujoco.mj_setState(self.model, self.data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
        mujoco.mj_forward(self.model, self.data)

    # -- motion ------------------------------------------------------------------------------------
    def speeds(self) -> tuple[np.ndarray, np.ndarray]:
        """Centre-of-mass speed (m/s) and turning rate (rad/s) of every body, (n,) each (parked: 0)."""
        d = self.data
        qv = d.qvel[self._qvel[:, None] + np.arange(6)]                   # (n, 6): origin velocity, local omega
        R = d.xmat[self._body].reshape(-1, 3, 3)
        w = np.einsum("nij,nj->ni", R, qv[:, 3:])                          # world angular velocity
        v_com = qv[:, :3] + np.cross(w, d.xipos[self._body] - d.xpos[self._body])
        lin = np.where(self.present, np.linalg.norm(v_com, axis=1), 0.0)
        ang = np.where(self.present, np.linalg.norm(qv[:, 3:], axis=1), 0.0)
        return lin, ang

    def step(self, seconds: float) -> int:
        """Advance the simulation by ``seconds`` (whole timesteps); returns the steps taken."""
        import mujoco

        n = max(1, round(seconds / self.model.opt.timestep))
        try:
            mujoco.mj_step(self.model, self.data, nstep=n)
        except mujoco.FatalError as exc:
            raise RuntimeError(f"MuJoCo failed: {exc}; the world has {self.model.ngeom} geoms") from exc
        self.steps += n
        self._check_arena()
        return n

    def _check_arena(self) -> None:
        import mujoco

        full = [w for w in (mujoco.mjtWarning.mjWARN_CNSTRFULL, mujoco.mjtWarning.mjWARN_CONTACTFULL)
                if self.data.warning[w].number > 0]
        if full:
            raise RuntimeError(f"MuJoCo ran out of contact memory ({self.model.ngeom} geoms); the pile would be "
                               f"wrong: build the world with a larger arena (pile_mjcf(..., arena=MB))")
        bad = self.data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number
        if bad > 0:
            raise RuntimeError("MuJoCo's simulation became unstable (bad accelerations); the pile would be wrong")

    def settle(self, *, lin: float, ang: float, hold: float, max_s: float, min_s: float = 0.0) -> Settled:
        """Step until every present part has been at rest (speeds below ``lin`` m/s and ``ang``
        rad/s: its centre of mass moves slower than ``lin`` and it turns slower than ``ang``,
        :meth:`speeds`, checked every :data:`CHECK_DT`) for ``hold`` simulated seconds, at least
        ``min_s`` and at most ``max_s`` seconds."""
        n_check = max(1, round(CHECK_DT / self.model.opt.timestep))
        dt = n_check * self.model.opt.timestep
        need = max(1, round(hold / dt))
        t, steps, calm = 0.0, 0, 0
        v, w = self.speeds()
        while True:
            steps += self.step(dt)
            t += dt
            v, w = self.speeds()
            calm = calm + 1 if (v.max(initial=0.0) < lin and w.max(initial=0.0) < ang) else 0
            if (calm >= need and t >= min_s - 1e-12) or t >= max_s - 1e-12:
                break
        worst = int(np.argmax(np.maximum(v / lin, w / ang))) if self.present.any() else -1
        return Settled(at_rest=calm >= need, sim_s=t, steps=steps, lin=float(v.max(initial=0.0)),
                       ang=float(w.max(initial=0.0)), moving=self.bodies[worst].name if worst >= 0 else "")
