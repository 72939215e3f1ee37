"""``grasplan.Picker``: picks from a pile of known parts at poses from vision, planned against the
bin and the neighbours, with the robot, the grasp sets and the collision objects kept warm.

Per :meth:`Picker.plan` call:

1. the scene (:func:`grasplan.piles.scene_file.load_scene`), its parts (added on first use) and grasp
   databases (:func:`grasplan.grasps.graspdb.database_for`: from the cache folder, else computed once and
   cached; or the scene's ``grasps`` file), the cloud's octree, the world of
   the gripper checks (:class:`grasplan.pick.world.PickWorld`) and the robot's collision scenes (one
   per part, every instance an extra body) are ready: ``timing_s["load"]``; then the geometric
   checks (:mod:`grasplan.piles.checks`: exit 3 for a part below the floor, warnings for
   interpenetrating instances);
2. instances are tried in the accessibility order (:mod:`grasplan.pick.rank`), in passes (the
   best :data:`FIRST_PASS` grasps of every instance whose straight lift is free, then, in the same
   order, the deferred and paused ones: the tilted-lift search of those whose straight lift is
   blocked, the rest of the undecided ones' grasps); per instance first the lift: the part moved along the
   cell's retreat, at the line's waypoints beyond ``lift_contact``, against the neighbours and the cloud (the
   same for every grasp: a hit there fails the robot's lift check whatever the arm does, so only tilted lifts
   can pick the instance, :mod:`grasplan.pick.lift`; and the cell, when a grasp first uses that lift); then
   its grasps posed in the world are ranked, gripper-checked in chunks against neighbours, cloud, bin and
   table (the first body hit names the blocker), and the collision-free ones motion-planned
   (:mod:`grasplan.pick.motion`) until one is planned or ``grasps_per_instance`` were tried;
3. ``sequence``: after each pick the instance is removed and the rest re-planned (the next pick is
   the first feasible one in the new order), until none is left or none is feasible. Otherwise each
   instance gets its best pick with every other instance in place; picks are listed in trying order.

``timing_s["first_pick"]``: seconds from the ready scene (end of step 1 and the checks) to the
first feasible pick. ``budget_s`` (:mod:`grasplan.pick.budget`) counts from the loaded parts and
cell (step 1 but the parts' meshes and grasp databases) and is checked inside every long stage.
What stays warm between calls, and its bounds: :mod:`grasplan.pick.warm`.
"""
from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..cell.model import Cell, load_cell
from ..errors import InputError
from ..gripper.load import load_gripper
from ..gripper.model import Gripper
from ..part.mesh import Part, load_part
from ..config.params import DEFAULT_GRIPPER, GraspParams
from ..motion.pickplace import lift_pose, unit_direction
from ..robot.description import load_robot
from ..robot.model import Robot
from ..motion.collision_scene import CollisionScene
from ..piles.scene_file import Instance, Scene, load_scene
from ..grasps.graspdb import GraspDatabase, database_for, load_database
from .budget import Budget, BudgetSpent
from .depth import PartDepth
from .lift import LIFTS_PER_GRASP, Carry, RestDepth, free_to_rise, inside_walls, lift_directions, wall_away
from .motion import MotionContext, Outcome, lift_travel, plan_pick_motion
from .params import PickParams
from .rank import check_chunks, instance_order, rank_grasps
from .reasons import blockers_of, hits_text, tilts_text
from .result import InstanceReport, Pick, PickResult
from .warm import (MAX_CELLS, MAX_CLOUDS, MAX_SCENE_PARTS, MAX_SCENE_VARIANTS, LRU, CellState, arranged,
                   build_scenes, scene_cloud)
from .world import CLOUD, INSTANCE_PREFIX, PickWorld

#: the first pass over the instances checks this many grasps of each (best ranked) before any instance's
#: further grasps: a part whose good grasps are free is found before the deep search of a boxed-in one
FIRST_PASS = 256
__all__ = ["FIRST_PASS", "MAX_SCENE_VARIANTS", "Picker"]
_TIMING_KEYS = ("gripper_check", "lift_check", "lift_depth", "ik", "collision", "approach", "lift", "transit", "place")

def _looks_like_path(ref: str) -> bool:
    return "/" in ref or os.sep in ref or ref.lower().endswith((".yaml", ".yml"))


class Picker:
    """Plans picks from piles (see the module docstring).

    ``robot``, ``gripper``: models or names/paths; ``cell``: a model, name or path, or None for
    each scene's own cell; ``params``: :class:`~grasplan.pick.params.PickParams`; ``database``:
    the options of the grasp databases it computes (:class:`~grasplan.config.params.GraspParams`, e.g. the
    parts' ``density``: the gravity margin and the score depend on the mass); ``progress``: gets
    a line when a grasp database is computed; ``clock``: seconds (monotonic) the planning budget
    is measured on."""

    def __init__(self, robot: Robot | str = "ur5", *, gripper: Gripper | str = DEFAULT_GRIPPER,
                 cell: Cell | str | None = None, params: PickParams = PickParams(),
                 database: GraspParams = GraspParams(),
                 progress: Callable[[str], None] | None = None, clock: Callable[[], float] = time.perf_counter):
        self.robot = robot if isinstance(robot, Robot) else load_robot(robot)
        self.gripper = gripper if isinstance(gripper, Gripper) else load_gripper(gripper)
        self.cell = None if cell is None else (cell if isinstance(cell, Cell) else load_cell(cell))
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
                 grasps: str | os.PathLike | GraspDatabase | None = None) -> None:
        """Make part ``name`` known: a mesh file (read in ``units``) or a loaded Part; ``grasps``:
        its grasp database (a ``.graspdb.npz`` file or a loaded one; refused for another part or
        gripper; default: :func:`grasplan.grasps.graspdb.database_for`, cached)."""
        part = mesh if isinstance(mesh, Part) else load_part(mesh, units=units)
        if grasps is None:
            db = database_for(part, self.gripper, grasps=self.database, progress=self.progress)
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
                if name in self._parts and Path(self._parts[name].path) == path:
                    self._scene_parts.get(name)  # used again
                    continue
                self.add_part(name, path, units=sp.units,
                              grasps=None if sp.grasps is None else scene.resolve(sp.grasps))
                self._scene_parts.put(name, None)
            elif name not in self._parts:
                known = ", ".join(self._parts) or "(none)"
                raise InputError(f"scene: part {name!r} has no mesh in the scene and was not added to the picker "
                                 f"(Picker.add_part); known parts: {known}")
        now = set(scene.part_names())  # parts of earlier scene files beyond MAX_SCENE_PARTS: dropped
        for name in [n for n in self._scene_parts.keys() if n not in now][: max(len(self._scene_parts) - len(now)
                                                                              - MAX_SCENE_PARTS, 0)]:
            self._scene_parts.pop(name)
            self._drop_part(name)

    # -- warm state ---------------------------------------------------------------------------------
    def _cell_for(self, scene: Scene) -> CellState:
        if self.cell is not None:
            cell = self.cell
        else:  # by name or path, read once (a path again when the file changed)
            ref = str(scene.resolve(scene.cell)) if _looks_like_path(scene.cell) else scene.cell
            try:
                stamp = Path(ref).stat().st_mtime_ns if _looks_like_path(ref) else 0
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
             sequence: bool = False, seed: int | None = None) -> PickResult:
        """Plan picks for ``scene`` (a Scene, a scene file or a parsed document); see the module docstring."""
        from ..piles.checks import check_instances

        t0 = time.perf_counter()
        sc = load_scene(scene)
        self._ensure_parts(sc)
        st = self._cell_for(sc)
        p = self.params if seed is None else PickParams.from_json({**self.params.to_json(), "seed": int(seed)})
        budget = Budget(p.budget_s, self.clock)  # the parts and the cell are loaded: the budget counts from here
        timing: dict[str, float] = {k: 0.0 for k in ("load", "checks", *_TIMING_KEYS)}
        stats = {"grasps_checked": 0, "grasps_tried": 0}
        reports: dict[str, InstanceReport] = {}
        picks: list[Pick] = []
        warnings: list[str] = []
        cloud = None
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
            self._plan_pile(st, sc, cloud is not None, p, budget, max_picks, sequence, reports, picks, timing,
                            stats, t_ready)
        except BudgetSpent:
            pass  # the instance being planned and those not reached: not_tried (below)
        finally:
            timing["load"] = timing["load"] or time.perf_counter() - t0
        spent = "the planning budget spent" if budget.spent() else "max_picks reached"
        for i in sc.instances:
            if i.id not in reports:
                reports[i.id] = InstanceReport(i.id, i.part, "not_tried", f"not tried: {spent}")
        timing.setdefault("first_pick", float("nan"))
        timing["plan"] = time.perf_counter() - t_ready
        timing["total"] = time.perf_counter() - t0
        timing_out = {k: v for k, v in timing.items() if np.isfinite(v)}
        return PickResult(picks=tuple(picks), instances=tuple(reports[i.id] for i in sc.instances), timing_s=timing_out,
                          scene=sc, robot=self.robot, gripper=self.gripper, cell=st.cell, params=p,
                          parts={n: self._parts[n].to_json() for n in sc.part_names()}, warnings=tuple(warnings),
                          sequence=sequence, stats=stats)

    def _plan_pile(self, st: CellState, sc: Scene, with_cloud: bool, p: PickParams, budget: Budget,
                   max_picks: int | None, sequence: bool, reports: dict[str, InstanceReport], picks: list[Pick],
                   timing: dict[str, float], stats: dict[str, int], t_ready: float) -> None:
        """The passes over the instances (module docstring), filling ``reports`` and ``picks``;
        :class:`BudgetSpent` leaves the instance being planned without a report."""
        cpu_ready = time.process_time()
        present = list(sc.instances)
        rank_of: dict[str, int] = {}

        def out_of_budget() -> bool:
            return (max_picks is not None and len(picks) >= max_picks) or budget.spent()

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
                paused: list[tuple[str, Iterator[tuple[Pick | None, InstanceReport | None]]]] = []
                # pass 1: every instance's best FIRST_PASS grasps with its straight lift, in order (an
                # instance whose straight lift is blocked is deferred before its tilted-lift search);
                # then the paused ones, in order, until each is decided
                for k, iid in enumerate(order):
                    if out_of_budget():
                        break
                    if iid in reports and reports[iid].status == "picked":
                        continue
                    gen = self._plan_instance(st, by_id[iid], present, with_cloud, p, timing, stats, k, rises, budget)
                    pick, rep = next(gen)
                    if rep is None:
                        paused.append((iid, gen))
                    elif take(iid, pick, rep):
                        picked_now = iid
                        break
                while paused and picked_now is None and not out_of_budget():  # the next passes, in order
                    later: list[tuple[str, Iterator[tuple[Pick | None, InstanceReport | None]]]] = []
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

    def _plan_instance(self, st: CellState, inst: Instance, present: list[Instance], with_cloud: bool, p: PickParams,
                       timing: dict[str, float], stats: dict[str, int], seed_base: int, rises: dict[str, bool],
                       budget: Budget) -> Iterator[tuple[Pick | None, InstanceReport | None]]:
        """Yields ``(pick or None, report)`` once the instance is decided, before that ``(None, None)``
        when its straight lift is blocked (before the tilted-lift search) and when its best
        :data:`FIRST_PASS` grasps gave nothing yet (the caller resumes it in a later pass).
        :class:`BudgetSpent` once ``budget`` is spent (checked in every loop below)."""
        budget.check()
        db = self._grasps[inst.part]
        rows, T_wt = rank_grasps(inst.T_world_part, db.T_part_tcp, db.score, p)
        if len(rows) == 0:
            yield None, InstanceReport(inst.id, inst.part, "no_grasp", (
                f"none of the part's {len(db)} grasps approaches within {p.max_tilt_deg:g} deg of straight down at this pose"
                if len(db) else f"its grasp database is empty: no contact pair fits the gripper {self.gripper.name}"))
            return
        bodies = st.world.bodies(inst.id)
        hit_counts: dict[str, int] = {}
        first_fail: Outcome | None = None
        tried = 0
        rows, T_wt = rows[: p.max_checked], T_wt[: p.max_checked]
        # checks and motions in the frame the gripper's shapes and T_flange_tcp are given in: for a
        # gripper whose TCP moves with the opening, the grasp TCP moved to it (as grasplan plan does)
        T_tcp_g = self.gripper.T_tcp_gripper(db.width[rows]) if self.gripper.moving_tcp else None
        T_plan = T_wt if T_tcp_g is None else T_wt @ T_tcp_g
        T_place = p.place_matrix() if p.place is not None else (None if st.cell.place is None
                                                                  else np.asarray(st.cell.place, dtype=np.float64))
        retreat = unit_direction(st.cell.retreat_direction)
        dist = float(st.cell.retreat_distance)
        fine = lift_travel(dist)  # the lift's waypoints (plan_pick_motion's)
        # the line's waypoints beyond lift_contact, and the lift_contact point itself (where resting
        # contact stops being allowed: between it and the next waypoint a part may be deep already);
        # every second one and the far end (`steps`) decide whether a direction is free for the part
        # alone; the others (`between`) are checked when a grasp is first motion-planned along it
        lc = min(p.lift_contact, dist)
        steps = np.unique(np.append(fine[::2][fine[::2] >= lc - 1e-12], [lc, dist]))
        between = np.setdiff1d(fine[fine >= lc - 1e-12], steps)
        by_name = {INSTANCE_PREFIX + i.id: i for i in present}

        def pile_of(i: Instance) -> tuple[list[Any], RestDepth]:
            """The bodies the part of ``i`` lifted alone may hit (the other instances, the cloud; the
            cell's boxes are the robot check's) and its depth into them beyond the resting one."""
            return ([b for b in st.world.bodies(i.id) if b.name.startswith(INSTANCE_PREFIX) or b.name == CLOUD],
                    RestDepth(self._depth_of(st, i.part), i.T_world_part,
                              lambda n: (self._depth_of(st, by_name[n].part), by_name[n].T_world_part),
                              tol=p.lift_depth, cap=p.overlap_tol, budget=budget))
        pile, rest = pile_of(inst)
        carry = Carry(lambda n: free_to_rise(st.world, by_name[n].part, by_name[n].T_world_part,  # --lift-carry
                                             steps[:, None] * retreat, *pile_of(by_name[n]), set(by_name)), rises)

        def lift_depth(T_world_part: np.ndarray, names: list[str], carrying: bool = False) -> float:
            """Deepest penetration of the carried part at ``T_world_part`` into the neighbours
            ``names`` beyond their resting one (:class:`grasplan.pick.lift.RestDepth`); ``carrying``:
            but into those lying on it (:class:`grasplan.pick.lift.Carry`)."""
            t_d = time.perf_counter()
            d = rest.excess(T_world_part, [n for n in names if not (carrying and n in by_name and carry.free(n))])
            timing["lift_depth"] += time.perf_counter() - t_d
            return d

        def shallow_hit(T_world_part: np.ndarray, b: Any) -> bool:
            if not (p.lift_depth > 0 and b.name in by_name):
                return False
            if carry.raises(b.name):  # lying on the part: any contact raises it
                return True
            t_d = time.perf_counter()  # lift_depth(...) <= lift_depth, a deep contact found on coarse samples first
            deep = rest.exceeds(T_world_part, [b.name])
            timing["lift_depth"] += time.perf_counter() - t_d
            return not deep

        hull_w = st.world.parts[inst.part].hull @ inst.T_world_part[:3, :3].T + inst.T_world_part[:3, 3]
        dirs: list[tuple[float, np.ndarray]] = [(0.0, retreat)]
        carrying: list[bool] = [False]  # per direction: lifted raising the neighbours lying on the part
        lift_free: list[bool | None] = [None]
        hit_first: dict[str, Any] = {}

        def lift_ok(j: int) -> bool:
            """Whether lifting the part alone along direction ``j`` is free (the same motion for every
            grasp: when it drags the part through a neighbour or the cloud beyond lift_contact, or
            a tilted one through a bin wall, no grasp can lift it that way)."""
            if lift_free[j] is None:
                budget.check()
                t, (carry.on, carry.direction) = time.perf_counter(), (carrying[j], j)
                shifts = steps[:, None] * dirs[j][1]
                ok = dirs[j][0] == 0.0 or inside_walls(hull_w, shifts, st.cell.bin)
                if ok:
                    # the straight lift's first hit names the blocker; a tilted one only needs yes or no
                    lh = st.world.part_hits(inst.part, inst.T_world_part, shifts, pile, shallow_hit, first_only=True,
                                            far_first=dirs[j][0] > 0.0)
                    ok = not np.any(lh >= 0)
                    if dirs[j][0] == 0.0 and not ok:  # what blocks the straight lift (raising nothing / some)
                        k_hit = int(np.flatnonzero(lh >= 0)[0])
                        if j == 0:
                            hit_first.update(name=pile[int(lh[k_hit])].name, step=float(steps[k_hit]))
                        else:
                            hit_first["carry_name"] = pile[int(lh[k_hit])].name
                lift_free[j] = ok
                timing["lift_check"] += time.perf_counter() - t
            return bool(lift_free[j])

        grasp_blocker: list[str] = []  # the neighbour the last grasp's lift (or approach) hit

        def tilted(blocker: str, carrying_: bool) -> None:
            """Add the tilted lifts leading away from the walls and the neighbour ``blocker``."""
            away = wall_away(hull_w, st.cell.bin)
            b = by_name.get(blocker)
            if b is not None:
                v = st.world.instances[inst.id].center - st.world.instances[b.id].center
                away = away + v / max(float(np.linalg.norm(v)), 1e-9)
            more = lift_directions(retreat, away, p.max_lift_tilt_deg)[1:]
            dirs.extend(more)
            carrying.extend([carrying_] * len(more))
            lift_free.extend([None] * len(more))

        def lifts() -> Iterator[int]:
            """Indices of the free lift directions, the straight one first, then the tilted ones
            (:func:`grasplan.pick.lift.lift_directions`) leading away from the walls and the
            neighbour that blocked the straight lift (the part alone, else the last grasp's); with
            ``lift_carry`` (a neighbour blocked the part's straight lift) then the same raising the
            neighbours lying on the part, the tilted ones leading away from what still blocks."""
            if lift_ok(0):
                yield 0
            if len(dirs) == 1:
                tilted(hit_first.get("name") or (grasp_blocker[0] if grasp_blocker else ""), False)
                if p.lift_carry and p.lift_depth > 0 and hit_first.get("name") in by_name:
                    dirs.append((0.0, retreat))
                    carrying.append(True)
                    lift_free.append(None)
            j = 1
            while j < len(dirs):
                if lift_ok(j):
                    yield j
                if carrying[j] and dirs[j][0] == 0.0 and j == len(dirs) - 1:
                    tilted(hit_first.get("carry_name") or hit_first["name"], True)
                j += 1

        if not lift_ok(0):
            yield None, None  # deferred: the tilted-lift search after every instance's first pass
        if not any(True for _ in lifts()):
            name, deep = hit_first["name"], None
            if name in by_name and p.lift_depth > 0:
                T_hit = inst.T_world_part.copy()
                T_hit[:3, 3] += hit_first["step"] * retreat
                deep = rest.excess(T_hit, [name], exact=True)  # the whole depth for the report
            rd = rest.rest(name) if name in by_name else 0.0
            yield None, InstanceReport(
                inst.id, inst.part, "blocked" if name.startswith(INSTANCE_PREFIX) else "cloud",
                f"lifting it {1e3 * dist:g} mm along the retreat drags it through {name} "
                f"after {1e3 * hit_first['step']:.0f} mm" + (
                    (f" ({1e3 * deep:.1f} mm deep" if rd < 5e-5 else
                     f" ({1e3 * deep:.1f} mm deeper than the {1e3 * rd:.1f} mm of resting overlap counted")
                    + f"; at most {1e3 * p.lift_depth:g} mm allowed)" if deep is not None else
                    f" (more than the {1e3 * p.lift_contact:g} mm of resting contact allowed)")
                + (f", and so does every one of the {carrying.count(False) - 1} tilted lifts "
                   f"({tilts_text(p.max_lift_tilt_deg)})" if carrying.count(False) > 1 else "")
                + (", raising what lies on it or not" if any(carrying) else "")
                + ", whatever the grasp",
                blockers_of({name: 1}))
            return
        ctxs: dict[int, MotionContext] = {}
        paused = False
        for c0, c1 in check_chunks(len(rows)):
            if c0 >= FIRST_PASS and not paused:
                paused = True
                ctxs.clear()  # a paused instance holds no robot scene variant (rebuilt, or kept, for its next pass)
                yield None, None  # paused: the other instances' best grasps first
            budget.check()
            sel = slice(c0, c1)
            t = time.perf_counter()
            # the bodies that blocked most grasps so far first: a blocked grasp needs fewer coal calls
            order = sorted(bodies, key=lambda b: -hit_counts.get(b.name, 0))
            first, _ = st.world.gripper_hits(inst.part, inst.id, T_plan[sel], db.width[rows[sel]], order)
            timing["gripper_check"] += time.perf_counter() - t
            stats["grasps_checked"] += len(first)
            for k_local, b in enumerate(first):
                if b >= 0:
                    name = order[b].name
                    hit_counts[name] = hit_counts.get(name, 0) + 1
                    continue
                k = c0 + k_local
                r = int(rows[k])
                tried += 1
                stats["grasps_tried"] += 1
                T_part_g = db.T_part_tcp[r] if T_tcp_g is None else db.T_part_tcp[r] @ T_tcp_g[k]
                out = None
                n_dirs = [0, 0]  # per grasp LIFTS_PER_GRASP clean lifts, then as many raising a neighbour
                for j in lifts():
                    if (out is not None and not out.lift_may_help) or n_dirs[1] >= LIFTS_PER_GRASP:
                        break
                    if n_dirs[carrying[j]] >= LIFTS_PER_GRASP:
                        continue
                    n_dirs[carrying[j]] += 1
                    ctx = ctxs.get(j)
                    if ctx is None:
                        static, att = self._variants(st, inst, present, with_cloud)
                        # the lift's other waypoints, the part alone (as lift_ok); then all against the cell
                        t_b, (carry.on, carry.direction) = time.perf_counter(), (carrying[j], j)
                        hits_b = st.world.part_hits(inst.part, inst.T_world_part, between[:, None] * dirs[j][1],
                                                    pile, shallow_hit)
                        checked = np.concatenate([steps, between[hits_b < 0]])
                        clear = st.world.clear_of_cell(inst.part, inst.T_world_part, checked, dirs[j][1])
                        timing["lift_check"] += time.perf_counter() - t_b
                        ctx = ctxs[j] = MotionContext(
                            self.robot, self.gripper, p, static, att, dirs[j][1], dist, timing, T_place=T_place,
                            lift_gripper_check=lambda T, w: st.world.gripper_at_hits(T, w, bodies),
                            approach_sweep=st.world.gripper_swept_free,  # against every body, the grasped part's too
                            body_names=tuple(b.name for b in bodies), lift_depth=None if p.lift_depth <= 0 else
                            lambda T, names, c=carrying[j]: lift_depth(T, names, c),
                            lift_part_checked=(inst.T_world_part, checked[:, None] * dirs[j][1], clear),  # lift_ok(j)
                            budget=budget)
                    out = plan_pick_motion(ctx, T_plan[k], T_part_g, float(db.width[r]),
                                           seed=p.seed * 1_000_003 + seed_base * 10_007 + r)
                    grasp_blocker[:] = list(out.blockers[:1])
                    if out.motion is not None:
                        tilt = dirs[j][0]
                        up = tuple(sorted(by_name[n].id for n in carry.raised.get(j, ())))
                        yield self._pick(inst, db, r, k, T_wt[k], out, dirs[j][1], dist, up), InstanceReport(
                            inst.id, inst.part, "picked", f"grasp ranked {k} of {len(rows)}: {out.reason}"
                            + ("" if not up else f"; the lift raises {', '.join(up)} lying on it")
                            + ("" if tilt == 0 else f"; lifted {tilt:g} deg from the retreat (the straight lift "
                               + ("drags the part through " + hit_first["name"] if "name" in hit_first
                                  else "is blocked for this grasp") + ")")
                            + hits_text(hit_counts, " better-ranked grasps"), blockers_of(hit_counts))
                        return
                assert out is not None
                first_fail = first_fail or out
                for b in out.blockers:  # neighbours hit by the robot or the carried part
                    hit_counts[b] = hit_counts.get(b, 0) + 1
                if tried >= p.grasps_per_instance:
                    break
            if tried >= p.grasps_per_instance:
                break
        if first_fail is not None:
            status = "blocked" if first_fail.blockers else first_fail.status
            yield None, InstanceReport(inst.id, inst.part, status,
                                       f"{tried} collision-free grasps tried, none planned; the best: "
                                       f"{first_fail.reason}" + hits_text(hit_counts, " grasps"),
                                       blockers_of(hit_counts))
            return
        blockers = blockers_of(hit_counts)
        n_cloud = hit_counts.get(CLOUD, 0)
        status = "blocked" if blockers else "cloud" if n_cloud else "bin"
        yield None, InstanceReport(inst.id, inst.part, status,
                                   f"every one of the {len(rows)} best-ranked grasps from above collides"
                                   + hits_text(hit_counts, " grasps"), blockers)

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
        score = float(db.score_at(self._parts[inst.part].mesh, inst.T_world_part, rows, quality=q)[0])
        return Pick(instance=inst.id, part=inst.part, T_world_part=np.array(inst.T_world_part),
                    T_part_tcp=db.T_part_tcp[r].copy(), contacts=db.contacts[r].copy(), normals=db.normals[r].copy(),
                    width=float(db.width[r]), opening=out.opening, score=score, quality=quality,
                    motion=out.motion, T_world_tcp=T_world_tcp.copy(), T_world_pregrasp=T_pre,
                    T_world_lifted=lift_pose(T_world_tcp, lift_dir, lift_dist), rank=k, carries=carries)
