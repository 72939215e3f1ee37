"""The lift directions of one instance's pick (:class:`LiftSearch`): which are free for the part
alone, in the order the grasps try them, and what blocks the straight one; the waypoints that
decide it (:class:`LiftLine`). The rules of the lift: :mod:`grasplan.pick.lift`."""
from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..cell.model import Cell
from ..motion.pickplace import unit_direction
from ..piles.scene_file import Instance
from .budget import Budget
from .depth import PartDepth
from .lift import Carry, RestDepth, free_to_rise, inside_walls, lift_directions, wall_away
from ..motion.lift_check import lift_travel
from .params import PickParams
from .reasons import lift_blocked_report
from .result import InstanceReport
from .warm import CellState
from .world import CLOUD, INSTANCE_PREFIX


@dataclass(frozen=True, eq=False)
class LiftLine:
    """A cell's straight lift: ``retreat`` (unit) and ``dist`` (m); TCP travel (m) along it at the
    waypoints of :func:`grasplan.motion.lift_check.lift_travel` beyond ``lift_contact`` and at
    ``lift_contact`` itself (where resting contact stops being allowed: between it and the next
    waypoint a part may be deep already): every second one and the far end (``steps``) decide
    whether a direction is free for the part alone; the others (``between``) are checked when a
    grasp is first motion-planned along it."""

    retreat: np.ndarray
    dist: float
    steps: np.ndarray
    between: np.ndarray

    @classmethod
    def of(cls, cell: Cell, p: PickParams) -> LiftLine:
        dist = float(cell.retreat_distance)
        fine = lift_travel(dist)
        lc = min(p.lift_contact, dist)
        steps = np.unique(np.append(fine[::2][fine[::2] >= lc - 1e-12], [lc, dist]))
        return cls(unit_direction(cell.retreat_direction), dist, steps, np.setdiff1d(fine[fine >= lc - 1e-12], steps))


class LiftSearch:
    """The lifts of instance ``inst`` among ``present`` in cell state ``st``: direction 0 the
    straight one along the retreat, then (once it or a grasp's lift is blocked) the tilted ones
    leading away from the walls and the blocker, and with ``lift_carry`` the same raising the
    neighbours lying on the part (:class:`~grasplan.pick.lift.Carry`; ``rises`` caches which
    neighbours are free to rise, shared by a plan's instances). ``depth_of(part)``: a part's depth
    probes. Seconds go to ``timing["lift_check"]`` and ``timing["lift_depth"]``."""

    def __init__(self, st: CellState, inst: Instance, present: list[Instance], line: LiftLine, p: PickParams,
                 budget: Budget, timing: dict[str, float], depth_of: Callable[[str], PartDepth],
                 rises: dict[str, bool]):
        self.st, self.inst, self.line, self.p, self.budget, self.timing = st, inst, line, p, budget, timing
        self._depth_of = depth_of
        self.by_name = {INSTANCE_PREFIX + i.id: i for i in present}
        self.pile, self.rest = self._pile_of(inst)
        by_name = self.by_name
        self.carry = Carry(lambda n: free_to_rise(st.world, by_name[n].part, by_name[n].T_world_part,  # --lift-carry
                                                  line.steps[:, None] * line.retreat, *self._pile_of(by_name[n]),
                                                  set(by_name)), rises)
        self.hull_w = st.world.parts[inst.part].hull @ inst.T_world_part[:3, :3].T + inst.T_world_part[:3, 3]
        #: per direction: (tilt from the retreat in deg, unit direction), raising the neighbours
        #: lying on the part, free for the part alone (None: not checked yet)
        self.dirs: list[tuple[float, np.ndarray]] = [(0.0, line.retreat)]
        self.carrying: list[bool] = [False]
        self.lift_free: list[bool | None] = [None]
        #: the body the straight lift first hits (the part alone), the travel there, and the one
        #: it hits while raising the neighbours lying on the part
        self.blocker: str | None = None
        self.blocker_step = 0.0
        self.carry_blocker: str | None = None
        #: the neighbour the last grasp's lift (or approach) hit
        self.grasp_blocker: tuple[str, ...] = ()

    def _pile_of(self, i: Instance) -> tuple[list[Any], RestDepth]:
        """The bodies the part of ``i`` lifted alone may hit (the other instances, the cloud; the
        cell's boxes are the robot check's) and its depth into them beyond the resting one."""
        p, by_name = self.p, self.by_name
        return ([b for b in self.st.world.bodies(i.id) if b.name.startswith(INSTANCE_PREFIX) or b.name == CLOUD],
                RestDepth(self._depth_of(i.part), i.T_world_part,
                          lambda n: (self._depth_of(by_name[n].part), by_name[n].T_world_part),
                          tol=p.lift_depth, cap=p.overlap_tol, budget=self.budget))

    def depth(self, T_world_part: np.ndarray, names: list[str], carrying: bool = False) -> float:
        """Deepest penetration of the carried part at ``T_world_part`` into the neighbours
        ``names`` beyond their resting one (:class:`grasplan.pick.lift.RestDepth`); ``carrying``:
        but into those lying on it (:class:`grasplan.pick.lift.Carry`)."""
        t_d = time.perf_counter()
        carry, by_name = self.carry, self.by_name
        d = self.rest.excess(T_world_part, [n for n in names if not (carrying and n in by_name and carry.free(n))])
        self.timing["lift_depth"] += time.perf_counter() - t_d
        return d

    def shallow_hit(self, T_world_part: np.ndarray, b: Any) -> bool:
        """Whether the part alone at ``T_world_part`` touching body ``b`` is allowed: ``b`` a
        neighbour lying on it (raised), or one it is no deeper in than ``lift_depth`` beyond rest."""
        if not (self.p.lift_depth > 0 and b.name in self.by_name):
            return False
        if self.carry.raises(b.name):  # lying on the part: any contact raises it
            return True
        t_d = time.perf_counter()  # lift_depth(...) <= lift_depth, a deep contact found on coarse samples first
        deep = self.rest.exceeds(T_world_part, [b.name])
        self.timing["lift_depth"] += time.perf_counter() - t_d
        return not deep

    def ok(self, j: int) -> bool:
        """Whether lifting the part alone along direction ``j`` is free (the same motion for every
        grasp: when it drags the part through a neighbour or the cloud beyond lift_contact, or
        a tilted one through a bin wall, no grasp can lift it that way)."""
        if self.lift_free[j] is None:
            self.budget.check()
            t, (self.carry.on, self.carry.direction) = time.perf_counter(), (self.carrying[j], j)
            tilt, u = self.dirs[j]
            shifts = self.line.steps[:, None] * u
            ok = tilt == 0.0 or inside_walls(self.hull_w, shifts, self.st.cell.bin)
            if ok:
                # the straight lift's first hit names the blocker; a tilted one only needs yes or no
                lh = self.st.world.part_hits(self.inst.part, self.inst.T_world_part, shifts, self.pile, self.shallow_hit,
                                             first_only=True, far_first=tilt > 0.0)
                ok = not np.any(lh >= 0)
                if tilt == 0.0 and not ok:  # what blocks the straight lift (raising nothing / some)
                    k_hit = int(np.flatnonzero(lh >= 0)[0])
                    if j == 0:
                        self.blocker, self.blocker_step = self.pile[int(lh[k_hit])].name, float(self.line.steps[k_hit])
                    else:
                        self.carry_blocker = self.pile[int(lh[k_hit])].name
            self.lift_free[j] = ok
            self.timing["lift_check"] += time.perf_counter() - t
        return bool(self.lift_free[j])

    def _add_tilted(self, blocker: str, carrying: bool) -> None:
        """Add the tilted lifts leading away from the walls and the neighbour ``blocker``."""
        away = wall_away(self.hull_w, self.st.cell.bin)
        b = self.by_name.get(blocker)
        if b is not None:
            v = self.st.world.instances[self.inst.id].center - self.st.world.instances[b.id].center
            away = away + v / max(float(np.linalg.norm(v)), 1e-9)
        more = lift_directions(self.line.retreat, away, self.p.max_lift_tilt_deg)[1:]
        self.dirs.extend(more)
        self.carrying.extend([carrying] * len(more))
        self.lift_free.extend([None] * len(more))

    def free_directions(self) -> Iterator[int]:
        """Indices of the free lift directions, the straight one first, then the tilted ones
        (:func:`grasplan.pick.lift.lift_directions`) leading away from the walls and the
        neighbour that blocked the straight lift (the part alone, else the last grasp's); with
        ``lift_carry`` (a neighbour blocked the part's straight lift) then the same raising the
        neighbours lying on the part, the tilted ones leading away from what still blocks."""
        if self.ok(0):
            yield 0
        if len(self.dirs) == 1:
            self._add_tilted(self.blocker or (self.grasp_blocker[0] if self.grasp_blocker else ""), False)
            if self.p.lift_carry and self.p.lift_depth > 0 and self.blocker in self.by_name:
                self.dirs.append((0.0, self.line.retreat))
                self.carrying.append(True)
                self.lift_free.append(None)
        j = 1
        while j < len(self.dirs):
            if self.ok(j):
                yield j
            if self.carrying[j] and self.dirs[j][0] == 0.0 and j == len(self.dirs) - 1:
                blocker = self.carry_blocker or self.blocker
                assert blocker is not None  # a carrying lift is added only after the straight one was blocked
                self._add_tilted(blocker, True)
            j += 1

    def any_free(self) -> bool:
        """Whether some lift direction is free for the part alone (searching until one is)."""
        return any(True for _ in self.free_directions())

    def part_checked(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        """The part alone along direction ``j`` at the waypoints :meth:`ok` skipped (``between``):
        ``(TCP travel of every waypoint found free, whether the part is clear of the cell there)``."""
        line, u = self.line, self.dirs[j][1]
        t_b, (self.carry.on, self.carry.direction) = time.perf_counter(), (self.carrying[j], j)
        hits_b = self.st.world.part_hits(self.inst.part, self.inst.T_world_part, line.between[:, None] * u,
                                         self.pile, self.shallow_hit)
        checked = np.concatenate([line.steps, line.between[hits_b < 0]])
        clear = self.st.world.clear_of_cell(self.inst.part, self.inst.T_world_part, checked, u)
        self.timing["lift_check"] += time.perf_counter() - t_b
        return checked, clear

    def raised(self, j: int) -> tuple[str, ...]:
        """Ids of the neighbours lying on the part that the lift along direction ``j`` raises."""
        return tuple(sorted(self.by_name[n].id for n in self.carry.raised.get(j, ())))

    def blocked(self) -> InstanceReport:
        """The report when no lift is free (:meth:`any_free` False): what the straight lift drags the
        part through, how deep (with ``lift_depth``) and which other lifts were tried."""
        name, deep, p = self.blocker, None, self.p
        assert name is not None  # the straight lift was blocked
        if name in self.by_name and p.lift_depth > 0:
            T_hit = self.inst.T_world_part.copy()
            T_hit[:3, 3] += self.blocker_step * self.line.retreat
            deep = self.rest.excess(T_hit, [name], exact=True)  # the whole depth for the report
        rd = self.rest.rest(name) if name in self.by_name else 0.0
        return lift_blocked_report(self.inst, name, self.blocker_step, self.line.dist, deep, rd,
                                   (p.lift_depth, p.lift_contact), self.carrying.count(False) - 1,
                                   p.max_lift_tilt_deg, any(self.carrying))
