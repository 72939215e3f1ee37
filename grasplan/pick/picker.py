"""``grasplan.Picker``: picks from a pile of known parts at poses from vision, planned against the
bin, the neighbours and a point cloud, with the robot, the grasp sets and the collision objects
kept warm between calls (:mod:`grasplan.pick.warm`). Per :meth:`Picker.plan` call the scene's
parts, grasp databases, cloud and cell are made ready and the scene checked; then the instances
are tried in the accessibility order (:mod:`grasplan.pick.rank`), in passes: per instance its
lifts (:mod:`grasplan.pick.lift_search`), its grasps posed in the world, ranked and
gripper-checked, the collision-free ones motion-planned (:mod:`grasplan.motion.grasp_motion`).
"""
from __future__ import annotations

import os
import time
from collections.abc import Callable, Collection, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..cell.model import Cell, load_cell
from ..config.lookup import document_ref, is_path_like
from ..config.params import DEFAULT_GRIPPER, DEFAULT_ROBOT, GraspParams
from ..errors import InputError
from ..results.quality_json import HOLD_FORCE_DECIMALS
from ..gripper.load import load_gripper
from ..gripper.model import Gripper
from ..grasps.graspdb import GraspDatabase, database_for, load_database
from ..motion.collision_scene import CollisionScene
from ..motion.pickplace import lift_pose
from ..part.mesh import Part, load_part
from ..piles.scene_file import Instance, Scene, ScenePart, load_scene
from ..robot.description import load_robot
from ..robot.model import Robot
from .budget import Budget, BudgetSpent
from .codes import LIFT_MAY_HELP, pushable
from .cover import approach_cover
from .depth import PartDepth
from .lift import LIFTS_PER_GRASP
from .lift_search import LiftLine, LiftSearch
from ..motion.grasp_motion import MotionContext, Outcome, plan_pick_motion
from .params import PickParams
from .push import Push, plan_push
from .rank import check_chunks, instance_order, rank_grasps
from .reasons import (collides_report, no_grasp_report, not_tried_report, picked_report, unplanned_report,
                      weak_report)
from .result import InstanceReport, Pick, PickResult
from .warm import (MAX_CELLS, MAX_CLOUDS, MAX_SCENE_PARTS, MAX_SCENE_VARIANTS, LRU, CellState, arranged, extras_of,
                   build_scenes, scene_cloud)
from .world import Body, PickWorld

#: the first pass over the instances checks this many grasps of each (best ranked) before any instance's
#: further grasps: a part whose good grasps are free is found before the deep search of a boxed-in one
FIRST_PASS = 256
__all__ = ["FIRST_PASS", "MAX_SCENE_VARIANTS", "Picker"]
_TIMING_KEYS = ("gripper_check", "lift_check", "lift_depth", "ik", "collision", "approach", "lift", "transit", "place")
#: what an instance's planning yields: ``(pick or None, its report)``, ``(None, None)`` when paused
Step = tuple[Pick | None, InstanceReport | None]


@dataclass(frozen=True, eq=False)
class PlanRun:
    """What every instance of one :meth:`Picker.plan` call shares: the cell's warm state, the
    options, the budget, the seconds per stage (``timing``) and counters (``stats``) it adds to,
    whether the scene has a cloud, the cell's lift and the place (pick-and-place; None: none)."""

    st: CellState
    params: PickParams
    budget: Budget
    timing: dict[str, float]
    stats: dict[str, int]
    with_cloud: bool
    line: LiftLine
    T_place: np.ndarray | None


@dataclass(frozen=True, eq=False)
class RankedGrasps:
    """An instance's grasps to check, best ranked first (at most ``max_checked``): database
    ``rows``, world TCP poses ``T_wt`` and the poses checked and planned ``T_plan``: for a gripper
    whose TCP moves with the opening, the TCP moved to the frame its shapes and ``T_flange_tcp``
    are given in (``T_tcp_g``, as ``grasplan plan`` does), else ``T_wt``."""

    rows: np.ndarray
    T_wt: np.ndarray
    T_plan: np.ndarray
    T_tcp_g: np.ndarray | None

    @classmethod
    def of(cls, inst: Instance, db: GraspDatabase, p: PickParams, gripper: Gripper) -> RankedGrasps | None:
        """None when no grasp approaches within ``max_tilt_deg`` of straight down."""
        rows, T_wt = rank_grasps(inst.T_world_part, db.T_part_tcp, db.score, p)
        if len(rows) == 0:
            return None
        rows, T_wt = rows[: p.max_checked], T_wt[: p.max_checked]
        T_tcp_g = gripper.T_tcp_gripper(db.width[rows]) if gripper.moving_tcp else None
        return cls(rows, T_wt, T_wt if T_tcp_g is None else T_wt @ T_tcp_g, T_tcp_g)

    def T_part_grasp(self, db: GraspDatabase, k: int) -> np.ndarray:
        """The grasp ranked ``k`` in the part's frame, in the frame it is planned in."""
        r = int(self.rows[k])
        return db.T_part_tcp[r] if self.T_tcp_g is None else db.T_part_tcp[r] @ self.T_tcp_g[k]


class Picker:
    """Plans picks from piles (see the module docstring).

    ``robot``, ``gripper``: models or names/paths; ``cell``: a model, name or path, or None for
    each scene's own cell; ``params``: :class:`~grasplan.pick.params.PickParams`; ``database``:
    the options of the grasp databases it computes (:class:`~grasplan.config.params.GraspParams`, e.g. the
    parts' ``density``: the gravity margin and the score depend on the mass); ``progress``: gets
    a line when a grasp database is computed; ``clock``: seconds (monotonic) the planning budget
    is measured on."""

    def __init__(self, robot: Robot | str = DEFAULT_ROBOT, *, gripper: Gripper | str = DEFAULT_GRIPPER,
                 cell: Cell | str | None = None, params: PickParams = PickParams(),
                 database: GraspParams = GraspParams(),
                 progress: Callable[[str], None] | None = None, clock: Callable[[], float] = time.perf_counter):
        self.robot = load_robot(robot)
        self.gripper = load_gripper(gripper)
        self.cell = None if cell is None else load_cell(cell)
        self.params = params
        self.database = database
        self.progress = progress
        self.clock = clock
        self._parts: dict[str, Part] = {}
        self._grasps: dict[str, GraspDatabase] = {}
        self._cells: LRU[Cell, CellState] = LRU(MAX_CELLS)
        self._clouds: LRU[tuple, tuple[Any, np.ndarray, float]] = LRU(MAX_CLOUDS)
        self._cell_refs: LRU[str, tuple[int, Cell]] = LRU(MAX_CELLS)
        self._depth: dict[str, PartDepth] = {}  # per part name: depth probes (grasplan.pick.depth)
        self._scene_parts: LRU[str, None] = LRU(1 << 30)  # parts added from scene files, least recent first

    # -- parts --------------------------------------------------------------------------------------
    def add_part(self, name: str, mesh: str | os.PathLike | Part, *, units: str = "auto",
                 grasps: str | os.PathLike | GraspDatabase | None = None, material: str | None = None,
                 density: float | None = None) -> None:
        """Make part ``name`` known: a mesh file (read in ``units``) or a loaded Part; ``grasps``:
        its grasp database (a ``.graspdb.npz`` file or a loaded one; refused for another part or
        gripper; default: :func:`grasplan.grasps.graspdb.database_for`, cached, computed with
        :attr:`database` or, given ``material`` / ``density``, at that part's density)."""
        part = mesh if isinstance(mesh, Part) else load_part(mesh, units=units)
        if grasps is None:
            db = database_for(part, self.gripper, grasps=self._database_params(material, density),
                              progress=self.progress)
        elif isinstance(grasps, GraspDatabase):
            grasps.check_for(part, self.gripper)
            db = grasps
        else:
            db = load_database(Path(grasps), part=part, gripper=self.gripper)
        self._parts[name] = part
        self._grasps[name] = db
        self._depth.pop(name, None)
        self._scene_parts.pop(name)
        for st in self._cells.values():  # scenes holding the old geometry are rebuilt
            st.world.add_part(name, part)
            st.forget()

    def _database_params(self, material: str | None, density: float | None) -> GraspParams:
        """:attr:`database` at a part's own ``material`` / ``density`` (both None: as it is)."""
        if material is None and density is None:
            return self.database
        return self.database.with_material(material, density)

    def material_of(self, name: str) -> dict[str, Any]:
        """``{material, density}`` part ``name``'s grasp database was computed with (kg/m^3)."""
        g = self._grasps[name].grasps
        mp = self._grasps[name].mass_props
        return {"material": g.material, "density": float(mp.density if mp is not None else g.density)}

    def _drop_part(self, name: str) -> None:
        self._parts.pop(name, None)
        self._grasps.pop(name, None)
        self._depth.pop(name, None)
        for st in self._cells.values():
            st.world.parts.pop(name, None)
            st.forget()

    def parts(self) -> list[str]:
        return list(self._parts)

    def _ensure_parts(self, scene: Scene) -> None:
        for name in scene.part_names():
            sp = scene.part(name)
            if sp is not None and sp.mesh is not None:
                path = scene.resolve(sp.mesh)
                if name in self._parts and Path(self._parts[name].path) == path and self._fits(name, sp):
                    self._scene_parts.get(name)  # used again
                    continue
                part = load_part(path, units=sp.units)
                _check_sha256(sp, part, str(path))
                self.add_part(name, part, grasps=None if sp.grasps is None else scene.resolve(sp.grasps),
                              material=sp.material, density=sp.density)
                self._scene_parts.put(name, None)
            elif name not in self._parts:
                known = ", ".join(self._parts) or "(none)"
                raise InputError(f"scene: part {name!r} has no mesh in the scene and was not added to the picker "
                                 f"(Picker.add_part); known parts: {known}")
            elif sp is not None:
                _check_sha256(sp, self._parts[name], self._parts[name].path)
                if not self._fits(name, sp):  # the scene gives the part another material: its database at it
                    self.add_part(name, self._parts[name], material=sp.material, density=sp.density)
        now = set(scene.part_names())  # parts of earlier scene files beyond MAX_SCENE_PARTS: dropped
        for name in [n for n in self._scene_parts.keys() if n not in now][: max(len(self._scene_parts) - len(now)
                                                                              - MAX_SCENE_PARTS, 0)]:
            self._scene_parts.pop(name)
            self._drop_part(name)

    def _fits(self, name: str, sp: ScenePart) -> bool:
        """Part ``name`` as loaded is the scene part ``sp``: the same mesh (sha256, when the scene
        records it) and a grasp database at its density (when it gives a material or density and
        no database file)."""
        if sp.sha256 is not None and self._parts[name].sha256 != sp.sha256:
            return False
        if (sp.material is None and sp.density is None) or sp.grasps is not None:
            return True  # a database file keeps the density it was computed with
        want = self._database_params(sp.material, sp.density)
        return want.density == self._grasps[name].grasps.density and want.mass == self._grasps[name].grasps.mass

    # -- warm state ---------------------------------------------------------------------------------
    def _cell_for(self, scene: Scene) -> CellState:
        if self.cell is not None:
            cell = self.cell
        else:  # by name or path (relative to the scene's folder), read once (a path again when the file changed)
            ref = document_ref(scene.cell, scene.base)
            try:
                stamp = Path(ref).stat().st_mtime_ns if is_path_like(scene.cell, scene.base) else 0
            except OSError:
                stamp = -1
            cached = self._cell_refs.get(ref)
            if cached is None or cached[0] != stamp:
                cached = (stamp, load_cell(ref))
                self._cell_refs.put(ref, cached)
            cell = cached[1]
        return self._state_of(cell)

    def _state_of(self, cell: Cell) -> CellState:
        st = self._cells.get(cell)
        if st is None:
            world = PickWorld(self.gripper, cell)
            for name, part in self._parts.items():
                world.add_part(name, part)
            st = CellState(cell=cell, world=world)
            self._cells.put(cell, st)
        return st

    def warm(self) -> None:
        """Build now what the first plan would build for every part: the scene checks' probe data,
        the depth probes and each part's voxel grid (:mod:`grasplan.geometry.insidegrid`; with a fixed
        ``cell`` also its pick world), so that the first plan is as fast as the next (the pick
        service calls this at start)."""
        from ..piles.checks import prepare

        for part in self._parts.values():
            prepare(part.mesh)
        if self.cell is not None:
            st = self._state_of(self.cell)
            for name in self._parts:
                self._depth_of(st, name)

    def _cloud(self, scene: Scene) -> tuple[Any, np.ndarray, float] | None:
        return scene_cloud(self._clouds, scene)

    def _variants(self, st: CellState, inst: Instance, present: list[Instance], with_cloud: bool
                  ) -> tuple[CollisionScene, CollisionScene]:
        return arranged(st, inst, present, with_cloud)

    # -- planning -----------------------------------------------------------------------------------
    def plan(self, scene: Scene | str | os.PathLike | Mapping, *, max_picks: int | None = None,
             sequence: bool = False, seed: int | None = None, push: bool = False,
             push_skip: Collection[str] = ()) -> PickResult:
        """Plan picks for ``scene`` (a loaded Scene, a scene file or a parsed document).

        1. The scene's parts (added on first use) and grasp databases (:func:`grasplan.grasps.graspdb.database_for`:
           from the cache folder, else computed once and cached; or the scene's ``grasps`` file), its
           cell, the cloud's octree, the world of the gripper checks (:class:`grasplan.pick.world.PickWorld`)
           and the robot's collision scenes (one per part, every instance an extra body) are made
           ready (``timing_s["load"]``); then the geometric checks (:mod:`grasplan.piles.checks`:
           exit 3 for a part below the floor, warnings for interpenetrating instances).
        2. The instances are tried in the accessibility order, in passes (:meth:`_plan_pile`).
        3. ``sequence``: after each pick the instance is removed and the rest re-planned, until none
           is left or none is feasible; otherwise each instance gets its best pick with every other
           instance in place, the picks listed in the accessibility order.

        ``timing_s["first_pick"]``: seconds from the ready scene to the first feasible pick.
        ``budget_s`` counts from the loaded parts and cell (:mod:`grasplan.pick.budget`) and is
        checked inside every long stage; the instance being planned and those not reached when it is
        spent are ``not_tried``. ``seed``: this call's instead of ``params.seed``. ``push``: when
        no pick is planned, plan a push of a part whose grasps a wall or a neighbour blocks
        (:func:`grasplan.pick.codes.pushable`; not those in ``push_skip``; :mod:`grasplan.pick.push`,
        ``PickResult.push``)."""
        from ..piles.checks import check_instances

        t0 = time.perf_counter()
        sc = scene if isinstance(scene, Scene) else load_scene(scene)
        self._ensure_parts(sc)
        st = self._cell_for(sc)
        p = self.params if seed is None else PickParams.from_json({**self.params.to_json(), "seed": int(seed)})
        budget = Budget(p.budget_s, self.clock)  # the parts and the cell are loaded: the budget counts from here
        timing: dict[str, float] = {k: 0.0 for k in ("load", "checks", *_TIMING_KEYS)}
        stats = {"grasps_checked": 0, "grasps_tried": 0}
        reports: dict[str, InstanceReport] = {}
        picks: list[Pick] = []
        warnings: list[str] = []
        push_tried: list[str] = []
        planned_push = None
        t_ready = time.perf_counter()
        try:
            cloud = self._cloud(sc)
            st.world.set_cloud(*(cloud or (None, None, 0.0)))
            build_scenes(st, self.robot, self.gripper, {n: q.mesh for n, q in self._parts.items()}, sc, cloud, budget)
            timing["load"] = time.perf_counter() - t0
            t = time.perf_counter()
            warnings = check_instances(sc.instances, {n: self._parts[n].mesh for n in sc.part_names()}, st.cell,
                                       tol=self.params.overlap_tol,
                                       bvhs={n: st.world.parts[n].bvh for n in sc.part_names()}, spent=budget.spent,
                                       hulls={n: st.world.parts[n].hull for n in sc.part_names()})
            timing["checks"] = time.perf_counter() - t
            t_ready = time.perf_counter()
            run = PlanRun(st, p, budget, timing, stats, cloud is not None, LiftLine.of(st.cell, p), _place_of(p, st.cell))
            self._plan_pile(run, sc, max_picks, sequence, reports, picks, t_ready)
            if push and not picks:
                targets = {i for i, rep in reports.items() if pushable(rep.status, rep.code) and i not in push_skip}
                planned_push = self._push(run, list(sc.instances), push_tried, targets)
        except BudgetSpent:
            pass  # the instance being planned and those not reached: not_tried (below)
        finally:
            timing["load"] = timing["load"] or time.perf_counter() - t0
        spent = budget.spent()  # else max_picks reached
        for i in sc.instances:
            if i.id not in reports:
                reports[i.id] = not_tried_report(i, spent)
        timing.setdefault("first_pick", float("nan"))
        timing["plan"] = time.perf_counter() - t_ready
        timing["total"] = time.perf_counter() - t0
        timing_out = {k: v for k, v in timing.items() if np.isfinite(v)}
        return PickResult(picks=tuple(picks), instances=tuple(reports[i.id] for i in sc.instances), timing_s=timing_out,
                          scene=sc, robot=self.robot, gripper=self.gripper, cell=st.cell, params=p,
                          parts={n: {**self._parts[n].to_json(), **self.material_of(n)} for n in sc.part_names()},
                          warnings=tuple(warnings), sequence=sequence, stats=stats, push=planned_push,
                          push_asked=push, push_tried=tuple(push_tried))

    def _plan_pile(self, run: PlanRun, sc: Scene, max_picks: int | None, sequence: bool,
                   reports: dict[str, InstanceReport], picks: list[Pick], t_ready: float) -> None:
        """The passes over the instances, filling ``reports`` and ``picks``: first every instance's
        best :data:`FIRST_PASS` grasps with its straight lift, in order (an instance whose straight
        lift is blocked is deferred before its tilted-lift search), then the deferred and paused
        ones, in order, until each is decided; with ``sequence`` again without each picked
        instance. :class:`BudgetSpent` leaves the instance being planned without a report."""
        cpu_ready = time.process_time()
        present = list(sc.instances)
        rank_of: dict[str, int] = {}
        timing, st = run.timing, run.st

        def out_of_budget() -> bool:
            return (max_picks is not None and len(picks) >= max_picks) or run.budget.spent()

        def take(iid: str, pick: Pick | None, rep: InstanceReport) -> bool:
            reports[iid] = rep
            if pick is None:
                return False
            picks.append(pick)
            if "first_pick" not in timing:
                timing["first_pick"] = time.perf_counter() - t_ready
                timing["first_pick_cpu"] = time.process_time() - cpu_ready
            return sequence

        try:
            while present:
                st.world.set_instances(present)
                boxes = {i.id: (st.world.instances[i.id].center, st.world.instances[i.id].half) for i in present}
                order = instance_order([i.id for i in present], boxes)
                rank_of = {iid: n for n, iid in enumerate(order)}
                by_id = {i.id: i for i in present}
                picked_now: str | None = None
                rises: dict[str, bool] = {}  # per instance: free to rise (lift_carry), whichever part is lifted
                paused: list[tuple[str, Iterator[Step]]] = []
                for k, iid in enumerate(order):  # the first pass
                    if out_of_budget():
                        break
                    if iid in reports and reports[iid].status == "picked":
                        continue
                    gen = self._plan_instance(run, by_id[iid], present, k, rises)
                    pick, rep = next(gen)
                    if rep is None:
                        paused.append((iid, gen))
                    elif take(iid, pick, rep):
                        picked_now = iid
                        break
                while paused and picked_now is None and not out_of_budget():  # the next passes, in order
                    later: list[tuple[str, Iterator[Step]]] = []
                    for iid, gen in paused:
                        if out_of_budget():
                            break
                        pick, rep = next(gen)
                        if rep is None:  # paused again (a deferred instance's own best grasps done)
                            later.append((iid, gen))
                        elif take(iid, pick, rep):
                            picked_now = iid
                            break
                    paused = later
                if not sequence or picked_now is None:
                    break
                present = [i for i in present if i.id != picked_now]
        finally:
            if not sequence:  # picks listed in the accessibility order, also when the budget stops the passes
                picks.sort(key=lambda q: rank_of[q.instance])

    def _plan_instance(self, run: PlanRun, inst: Instance, present: list[Instance], seed_base: int,
                       rises: dict[str, bool]) -> Iterator[Step]:
        """Yields ``(pick or None, report)`` once the instance is decided, before that ``(None, None)``
        when its straight lift is blocked (before the tilted-lift search) and when its best
        :data:`FIRST_PASS` grasps gave nothing yet (the caller resumes it in a later pass).
        :class:`BudgetSpent` once the budget is spent (checked in every loop). First the lift: the
        part moved along the cell's retreat, against the neighbours and the cloud, the same for
        every grasp (a hit there fails every grasp's lift: only tilted lifts can pick the
        instance); then its grasps (:meth:`_grasps_of`)."""
        run.budget.check()
        db = self._grasps[inst.part]
        ranked = RankedGrasps.of(inst, db, run.params, self.gripper)
        if ranked is None:
            yield None, no_grasp_report(inst, len(db), run.params.max_tilt_deg, self.gripper.name)
            return
        lifts = LiftSearch(run.st, inst, present, run.line, run.params, run.budget, run.timing,
                           lambda part: self._depth_of(run.st, part), rises)
        if not lifts.ok(0):
            yield None, None  # deferred: the tilted-lift search after every instance's first pass
        if not lifts.any_free():
            yield None, lifts.blocked()
            return
        yield from self._grasps_of(run, inst, present, db, ranked, lifts, seed_base)

    def _grasps_of(self, run: PlanRun, inst: Instance, present: list[Instance], db: GraspDatabase,
                   ranked: RankedGrasps, lifts: LiftSearch, seed_base: int) -> Iterator[Step]:
        """The ranked grasps gripper-checked in chunks against neighbours, cloud, bin and table (the
        bodies that blocked most grasps so far first; the first body hit names the blocker), the
        collision-free ones motion-planned until one is planned or ``grasps_per_instance`` were
        tried; paused once after the first :data:`FIRST_PASS` (see :meth:`_plan_instance`)."""
        p, st, rows = run.params, run.st, ranked.rows
        bodies = st.world.bodies(inst.id)
        hit_counts: dict[str, int] = {}
        first_fail: Outcome | None = None
        tried = weak = 0
        ctxs: dict[int, MotionContext] = {}
        paused = False
        for c0, c1 in check_chunks(len(rows)):
            if c0 >= FIRST_PASS and not paused:
                paused = True
                ctxs.clear()  # a paused instance holds no robot scene variant (rebuilt, or kept, for its next pass)
                yield None, None  # paused: the other instances' best grasps first
            run.budget.check()
            t = time.perf_counter()
            order = sorted(bodies, key=lambda b: -hit_counts.get(b.name, 0))
            first, _ = st.world.gripper_hits(inst.part, inst.id, ranked.T_plan[c0:c1], db.width[rows[c0:c1]], order)
            run.timing["gripper_check"] += time.perf_counter() - t
            run.stats["grasps_checked"] += len(first)
            for k_local, b in enumerate(first):
                if b >= 0:
                    hit_counts[order[b].name] = hit_counts.get(order[b].name, 0) + 1
                    continue
                k = c0 + k_local
                r = int(rows[k])
                if p.min_gravity_margin > 0 and not self._holds(db, inst, r, p.min_gravity_margin):
                    weak += 1
                    continue
                tried += 1
                run.stats["grasps_tried"] += 1
                out, j = self._grasp_motion(run, inst, present, lifts, bodies, ctxs, ranked.T_plan[k],
                                            ranked.T_part_grasp(db, k), float(db.width[r]),
                                            seed=p.seed * 1_000_003 + seed_base * 10_007 + r)
                if out.motion is not None:
                    tilt, u = lifts.dirs[j]
                    yield (self._pick(inst, db, r, k, ranked.T_wt[k], out, u, run.line.dist, lifts.raised(j)),
                           picked_report(inst, k, len(rows), out, lifts.raised(j), tilt, lifts.blocker, hit_counts))
                    return
                first_fail = first_fail or out
                for name in out.blockers:  # neighbours hit by the robot or the carried part
                    hit_counts[name] = hit_counts.get(name, 0) + 1
                if tried >= p.grasps_per_instance:
                    break
            if tried >= p.grasps_per_instance:
                break
        if first_fail is not None:
            yield None, unplanned_report(inst, tried, first_fail, hit_counts)
        elif weak:
            yield None, weak_report(inst, weak, p.min_gravity_margin, hit_counts)
        else:
            yield None, collides_report(inst, len(rows), hit_counts)

    @staticmethod
    def _holds(db: GraspDatabase, inst: Instance, r: int, min_margin: float) -> bool:
        """Whether database grasp ``r`` reaches ``min_margin`` of gravity margin at the instance's
        pose (a part without mass properties: not known, planned)."""
        q = db.quality_at(inst.T_world_part, np.array([r]))
        return q is None or bool(q.gravity_margin[0] >= min_margin)

    def _grasp_motion(self, run: PlanRun, inst: Instance, present: list[Instance], lifts: LiftSearch,
                      bodies: list[Body], ctxs: dict[int, MotionContext], T_world_tcp: np.ndarray,
                      T_part_tcp: np.ndarray, width: float, seed: int) -> tuple[Outcome, int]:
        """One grasp motion-planned along the free lift directions (per grasp
        :data:`~grasplan.pick.lift.LIFTS_PER_GRASP` clean lifts, then as many raising a neighbour)
        until it is planned or another lift cannot help: the last outcome and its direction."""
        out: Outcome | None = None
        j_out = 0
        n_dirs = [0, 0]
        for j in lifts.free_directions():
            if (out is not None and out.code not in LIFT_MAY_HELP) or n_dirs[1] >= LIFTS_PER_GRASP:
                break
            c = int(lifts.carrying[j])
            if n_dirs[c] >= LIFTS_PER_GRASP:
                continue
            n_dirs[c] += 1
            ctx = ctxs.get(j)
            if ctx is None:
                ctx = ctxs[j] = self._motion_context(run, inst, present, lifts, bodies, j)
            out, j_out = plan_pick_motion(ctx, T_world_tcp, T_part_tcp, width, seed=seed), j
            lifts.grasp_blocker = out.blockers[:1]
            if out.motion is not None:
                break
        assert out is not None  # the caller found a free direction
        return out, j_out

    def _motion_context(self, run: PlanRun, inst: Instance, present: list[Instance], lifts: LiftSearch,
                        bodies: list[Body], j: int) -> MotionContext:
        """What every grasp of ``inst`` lifted along direction ``j`` shares: the arranged robot
        scenes, the lift, and what the checks before IK decided (the lift's other waypoints for
        the part alone, as :meth:`LiftSearch.ok`; then all of them against the cell)."""
        st, p = run.st, run.params
        static, att = self._variants(st, inst, present, run.with_cloud)
        checked, clear = lifts.part_checked(j)
        u = lifts.dirs[j][1]
        return MotionContext(
            self.robot, self.gripper, p, static, att, u, run.line.dist, run.timing, lift_contact=p.lift_contact,
            depth_limit=p.lift_depth, T_place=run.T_place,
            lift_gripper_check=lambda T, w: st.world.gripper_at_hits(T, w, bodies),
            # against every body, the grasped part's too
            approach_sweep=approach_cover(st.world, self.robot, self.gripper.T_flange_tcp, static),
            body_names=tuple(b.name for b in bodies), lift_depth=None if p.lift_depth <= 0 else
            lambda T, names, c=lifts.carrying[j]: lifts.depth(T, names, c),
            lift_part_checked=(inst.T_world_part, checked[:, None] * u, clear), budget=run.budget)

    def _push(self, run: PlanRun, present: list[Instance], tried: list[str], targets: set[str]) -> Push | None:
        """The first push planned among ``present`` (:func:`grasplan.pick.push.plan_push`), with
        this plan's robot scenes: the part present on the descent, away on the push."""
        st, p = run.st, run.params
        st.world.set_instances(present)

        def ctx_of(inst: Instance) -> tuple[CollisionScene, CollisionScene, MotionContext]:
            static, att = self._variants(st, inst, present, run.with_cloud)
            away = st.scenes[inst.part].arranged(None, extras_of(inst, present, run.with_cloud))
            ctx = MotionContext(self.robot, self.gripper, p, static, att, np.array([0.0, 0.0, 1.0]), 0.0,
                                run.timing, budget=run.budget)
            return static, away, ctx

        return plan_push(self.robot, self.gripper, st, present, ctx_of, seed=p.seed,
                         max_ik_solutions=p.max_ik_solutions, max_dev=p.max_dev, timing=run.timing, log=tried,
                         targets=targets)

    def _depth_of(self, st: CellState, part: str) -> PartDepth:
        d = self._depth.get(part)
        if d is None:
            d = self._depth[part] = PartDepth.build(self._parts[part].mesh, st.world.parts[part].bvh,
                                                     st.world.parts[part].hull)
        return d

    def _pick(self, inst: Instance, db: GraspDatabase, r: int, k: int, T_world_tcp: np.ndarray, out: Outcome,
              lift_dir: np.ndarray, lift_dist: float, carries: tuple[str, ...] = ()) -> Pick:
        assert out.motion is not None
        T_pre = T_world_tcp.copy()
        T_pre[:3, 3] -= self.params.backoff * T_world_tcp[:3, 2]
        rows = np.array([r])
        q = db.quality_at(inst.T_world_part, rows)  # at the instance's pose (the gravity margin depends on it)
        quality: dict[str, float] = {"epsilon": float(db.epsilon[r])}
        if q is not None:
            quality["gravity_margin"] = float(q.gravity_margin[0])
            hold = float(q.hold_force[0])
            if hold == hold:  # NaN: no force holds it (left out)
                quality["hold_force_N"] = round(hold, HOLD_FORCE_DECIMALS)
        score = float(db.score_at(self._parts[inst.part].mesh, inst.T_world_part, rows, quality=q)[0])
        return Pick(instance=inst.id, part=inst.part, T_world_part=np.array(inst.T_world_part),
                    T_part_tcp=db.T_part_tcp[r].copy(), contacts=db.contacts[r].copy(), normals=db.normals[r].copy(),
                    width=float(db.width[r]), opening=out.opening, score=score, quality=quality,
                    motion=out.motion, T_world_tcp=T_world_tcp.copy(), T_world_pregrasp=T_pre,
                    T_world_lifted=lift_pose(T_world_tcp, lift_dir, lift_dist), rank=k, carries=carries)


def _check_sha256(sp: ScenePart, part: Part, path: str) -> None:
    """InputError (exit 3) when the scene records a sha256 for part ``sp`` that its mesh does not have."""
    if sp.sha256 is not None and part.sha256 != sp.sha256:
        raise InputError(f"scene: parts.{sp.name}.sha256: the mesh {path} has sha256 {part.sha256[:16]}..., the scene "
                         f"recorded {sp.sha256[:16]}...: the mesh changed since the scene was written; write the "
                         f"scene again (grasplan scene drop) or give the mesh it was written with")


def _place_of(p: PickParams, cell: Cell) -> np.ndarray | None:
    """The picked part's pose after release: ``p.place``, else the cell's place, else None."""
    if p.place is not None:
        return p.place_matrix()
    return None if cell.place is None else np.asarray(cell.place, dtype=np.float64)
