"""Pushes: when no grasp of a pile can be planned, move a part that a wall or a neighbour boxes in
into the open, so that the next plan may grasp it (``grasplan pick --push``, the clutter rounds).

:func:`plan_push` tries the parts :func:`candidates` finds (nearest to a wall or a neighbour
first), each with the gripper poses of :func:`push_poses` (jaws closed, closing axis across the
push, straight down or tilted: :data:`TILTS_DEG`), checked like a grasp (:func:`_gripper_free`,
then IK, the straight lines and the transit through the robot scene: :func:`_plan_one`). The
first push planned wins (a :class:`Push`); none: None. Deterministic for the planner's seed.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..cell.model import BIN_NAMES
from ..cell.regions import Workspace
from ..motion.grasp_motion import line_path, transit_path
from ..part.stability import part_centre_of_mass
from ..piles.scene_file import Instance
from ..robot.ik.solve import solve_ik

if TYPE_CHECKING:
    from ..gripper.model import Gripper
    from ..robot.model import Robot
    from .warm import CellState
    from .world import Body

#: a part whose hull keeps less than this (m) from a wall or a neighbour is a push candidate
NEAR = 0.05
#: push until the part keeps this far (m) from what boxed it in
CLEAR = 0.07
#: the TCP's travel while pushing (m): at least, at most
MIN_PUSH, MAX_PUSH = 0.01, 0.08
#: the pushing finger starts this far (m) behind the part
TIP_GAP = 0.003
#: the fingertips reach this far (m) below the part's top (at most half its height) ...
DEPTH = 0.015
#: ... and stay this far (m) above its lowest point
FLOOR_GAP = 0.003
#: the descent starts, and the retreat ends, this far (m) above the part's top
ABOVE = 0.03
#: the closed gripper is checked every this many metres along the descent, the push and the retreat
SAMPLE = 0.002
#: at most this many (part, direction) candidates are tried per plan, nearest first
MAX_CANDIDATES = 8
#: segment labels of a push's joint path, in order
PUSH_SEGMENTS = ("transit", "approach", "push", "retreat")


@dataclass(frozen=True, eq=False)
class Push:
    """A planned push of ``instance`` (``part``) away from ``against`` (a wall's obstacle name or
    ``instance:<id>``), which it kept ``gap`` (m) from: the TCP moves ``distance`` (m) along the
    horizontal world ``direction`` (3,) with the jaws at ``opening`` (m). TCP poses (4, 4, world):
    ``T_world_above`` (the descent's start), ``T_world_start``, ``T_world_end``,
    ``T_world_retreat``. ``path`` (k, n) joints (rad) with ``segments`` ``(label, start, end)``
    (:data:`PUSH_SEGMENTS`, inclusive rows, consecutive segments share their boundary row)."""

    instance: str
    part: str
    against: str
    gap: float
    direction: np.ndarray
    distance: float
    opening: float
    T_world_above: np.ndarray
    T_world_start: np.ndarray
    T_world_end: np.ndarray
    T_world_retreat: np.ndarray
    path: np.ndarray
    segments: tuple[tuple[str, int, int], ...]

    def to_json(self) -> dict[str, Any]:
        """The ``push`` entry of a ``grasplan.picks/1`` document (docs/pick.md)."""
        return {"instance": self.instance, "part": self.part, "against": self.against, "gap_m": float(self.gap),
                "direction": [float(x) for x in self.direction], "distance_m": float(self.distance),
                "opening": float(self.opening), "T_world_above": self.T_world_above.tolist(),
                "T_world_start": self.T_world_start.tolist(), "T_world_end": self.T_world_end.tolist(),
                "T_world_retreat": self.T_world_retreat.tolist(), "path": np.asarray(self.path).tolist(),
                "segments": [[a, int(s), int(e)] for a, s, e in self.segments]}


@dataclass(frozen=True)
class Candidate:
    """A part that may be pushed: ``inst``, what boxes it in (``against``), the ``gap`` (m) and the
    horizontal unit ``direction`` (3,) away from it."""

    inst: Instance
    against: str
    gap: float
    direction: np.ndarray


def _horizontal(v: np.ndarray) -> np.ndarray | None:
    h = np.array([v[0], v[1], 0.0])
    n = float(np.linalg.norm(h))
    return None if n < 1e-9 else h / n


def candidates(st: CellState, instances: list[Instance]) -> list[Candidate]:
    """The push candidates among ``instances``, nearest first: per instance its nearest bin wall
    and its nearest neighbour, each when its convex hull keeps less than :data:`NEAR` from it (a
    part boxed in by a wall and a neighbour may be pushed away from either)."""
    import coal

    world, cell = st.world, st.cell
    out: list[Candidate] = []
    req = coal.DistanceRequest()
    for inst in instances:
        g = world.parts[inst.part]
        hull_w = g.hull @ inst.T_world_part[:3, :3].T + inst.T_world_part[:3, 3]
        if cell.bin is not None:
            gaps, inward = cell.bin.wall_gaps(hull_w)
            k = int(np.argmin(gaps))
            away = _horizontal(inward[k])
            if gaps[k] < NEAR and away is not None:
                out.append(Candidate(inst, BIN_NAMES[1 + k], float(gaps[k]), away))
        body = world.instances.get(inst.id)
        best: tuple[float, str, np.ndarray] | None = None
        for other in instances:
            if other.id == inst.id or body is None or other.id not in world.instances:
                continue
            ob = world.instances[other.id]
            res = coal.DistanceResult()
            d = float(coal.distance(g.convex, body.tf, world.parts[other.part].convex, ob.tf, req, res))
            if best is None or d < best[0]:
                away = _horizontal(np.asarray(res.getNearestPoint1()) - np.asarray(res.getNearestPoint2()))
                if away is None or d <= 0.0:  # touching: away from the neighbour's centre
                    away = _horizontal(body.center - ob.center)
                if away is not None:
                    best = (d, f"instance:{other.id}", away)
        if best is not None and best[0] < NEAR:
            out.append(Candidate(inst, best[1], max(best[0], 0.0), best[2]))
    out.sort(key=lambda c: (c.gap, c.inst.id, c.against))
    return out[:MAX_CANDIDATES]


def _samples(T_a: np.ndarray, T_b: np.ndarray) -> np.ndarray:
    """TCP poses (k, 4, 4) every :data:`SAMPLE` from ``T_a`` to ``T_b`` (same orientation), both ends."""
    n = max(2, int(np.ceil(np.linalg.norm(T_b[:3, 3] - T_a[:3, 3]) / SAMPLE)) + 1)
    out = np.repeat(T_a[None], n, axis=0)
    out[:, :3, 3] = T_a[:3, 3] + np.linspace(0.0, 1.0, n)[:, None] * (T_b[:3, 3] - T_a[:3, 3])
    return out


@dataclass(frozen=True)
class PushPoses:
    """The TCP poses and travel of one candidate's push (module docstring, steps 2-3)."""

    T_above: np.ndarray
    T_start: np.ndarray
    T_end: np.ndarray
    T_retreat: np.ndarray
    distance: float


def push_poses(c: Candidate, hull: np.ndarray, com: np.ndarray, gripper: Gripper, opening: float, *,
               tilt_deg: float = 0.0, depth: float = DEPTH) -> PushPoses:
    """The push of candidate ``c`` (its part's convex hull ``hull`` (h, 3) and centre of mass
    ``com`` (3,), part frame) for ``gripper`` with its jaws at ``opening``: the TCP's x (the
    closing axis) across the push, its y along it, its z down, tilted ``tilt_deg`` about x so that
    the fingertips lead towards what boxed the part in and the gripper's body leans over the part
    (away from a wall). The fingertips reach ``depth`` below the part's top (at most half its
    height, at least :data:`FLOOR_GAP` above its lowest point), in line with its centre of mass;
    the fingers' leading face (their +y face), up to the part's top, keeps :data:`TIP_GAP` behind
    the part's back (tilted, its upper points lean forward); the descent and the retreat run along
    the TCP's z."""
    T_wp = np.asarray(c.inst.T_world_part, dtype=np.float64)
    hull_w = hull @ T_wp[:3, :3].T + T_wp[:3, 3]
    com_w = T_wp[:3, :3] @ com + T_wp[:3, 3]
    d = c.direction
    up = np.array([0.0, 0.0, 1.0])
    e = np.cross(up, d)
    top, low = float(hull_w[:, 2].max()), float(hull_w[:, 2].min())
    z_tip = max(low + FLOOR_GAP, top - min(depth, 0.5 * (top - low)))
    a = np.radians(tilt_deg)
    z_tool = -np.cos(a) * up - np.sin(a) * d
    R = np.column_stack([e, np.cross(z_tool, e), z_tool])  # untilted: y = d
    finger = np.vstack([f.corners() for f in gripper.fingers(opening)])
    y_face, z_tips, z_base = float(finger[:, 1].max()), float(finger[:, 2].max()), float(finger[:, 2].min())
    corner = np.array([0.0, y_face, z_tips])  # the leading face at the tips
    above = hull_w[hull_w[:, 2] >= z_tip - 1e-9]
    s_min = float(((above if len(above) else hull_w) @ d).min())  # the part's back, at and above the tips
    T_start = np.eye(4)
    T_start[:3, :3] = R
    T_start[:3, 3] = e * float(com_w @ e) + up * z_tip - R @ corner  # the tips at z_tip, in line with the centre
    # the leading face's points (tips up to the fingers' base) below the part's top: the one furthest
    # forward (a tilted face leans over the part) keeps TIP_GAP behind the part's back
    face = (T_start[:3, :3] @ np.column_stack([np.zeros(64), np.full(64, y_face), np.linspace(z_tips, z_base, 64)]).T
            ).T + T_start[:3, 3]
    face = face[face[:, 2] <= top + 1e-9]
    T_start[:3, 3] += d * (s_min - TIP_GAP - float((face @ d).max()))
    distance = float(np.clip(CLEAR - c.gap + TIP_GAP, MIN_PUSH, MAX_PUSH))
    T_end = T_start.copy()
    T_end[:3, 3] += d * distance
    back = (top - z_tip + ABOVE) / max(np.cos(a), 0.1)  # along -z_tool: ABOVE over the part's top
    T_above, T_retreat = T_start.copy(), T_end.copy()
    T_above[:3, 3] -= z_tool * back
    T_retreat[:3, 3] -= z_tool * back
    return PushPoses(T_above, T_start, T_end, T_retreat, distance)


#: the gripper's tilts (deg) and fingertip depths (m) tried per candidate, in order
TILTS_DEG = (0.0, 30.0, 50.0)
DEPTHS = (DEPTH, 0.005)


def _gripper_free(st: CellState, poses: PushPoses, inst: Instance, opening: float, bodies_all: list[Body],
                  bodies_others: list[Body]) -> str:
    """'' when the closed gripper and the pushed part pass the Cartesian checks (module docstring,
    step 4), else why not."""
    w = st.world
    for what, T_a, T_b, bodies in (("descent", poses.T_above, poses.T_start, bodies_all),
                                   ("push", poses.T_start, poses.T_end, bodies_others),
                                   ("retreat", poses.T_end, poses.T_retreat, bodies_others)):
        hit = w.gripper_at_hits(_samples(T_a, T_b), opening, bodies)
        if np.any(hit >= 0):
            return f"the gripper hits {bodies[int(hit[hit >= 0][0])].name} on the {what}"
    travel = np.linspace(0.0, max(poses.distance - TIP_GAP, 0.0), 1 + int(np.ceil(poses.distance / SAMPLE)))
    d = (poses.T_end[:3, 3] - poses.T_start[:3, 3]) / max(poses.distance, 1e-12)
    if not w.clear_of_cell(inst.part, inst.T_world_part, travel, d).all():
        return "the part would be pushed into the cell (a wall or an obstacle)"
    return ""


def free_travel(st: CellState, inst: Instance, poses: PushPoses) -> float:
    """How far (m) the TCP may push before the part, moved along with it, would touch another
    instance (:meth:`grasplan.pick.world.PickWorld.part_hits` every :data:`SAMPLE`): the push's
    own ``distance`` when nothing is in the way."""
    w = st.world
    others = [b for i, b in w.instances.items() if i != inst.id]
    if not others:
        return poses.distance
    d = (poses.T_end[:3, 3] - poses.T_start[:3, 3]) / max(poses.distance, 1e-12)
    travel = np.linspace(0.0, max(poses.distance - TIP_GAP, 0.0), 1 + int(np.ceil(poses.distance / SAMPLE)))
    hit = w.part_hits(inst.part, inst.T_world_part, travel[:, None] * d, others)
    if not np.any(hit >= 0):
        return poses.distance
    first = int(np.flatnonzero(hit >= 0)[0])
    return float(travel[first - 1] + TIP_GAP) if first > 0 else 0.0


def plan_push(robot: Robot, gripper: Gripper, st: CellState, instances: list[Instance], ctx_of: Any,
              *, seed: int, max_ik_solutions: int, max_dev: float, timing: dict[str, float] | None = None,
              log: list[str] | None = None, targets: set[str] | None = None) -> Push | None:
    """The first push planned among ``instances``; ``ctx_of(inst) -> (static scene with the part,
    scene without it, MotionContext for the transit)`` gives the robot scenes; ``log`` collects
    why each candidate failed; ``targets``: the ids that may be pushed (None: any; every instance
    is still an obstacle and a neighbour to push away from).

    1. **Which part, which way** (:func:`candidates`): every instance whose convex hull keeps less
       than :data:`NEAR` from a bin wall or from another instance's hull (coal's distance),
       nearest first; the push goes horizontally away from what it is close to.
    2. **Where the fingers go** (:func:`push_poses`): their tips :data:`DEPTHS` below the part's
       top, their leading face :data:`TIP_GAP` behind the part, in line with its centre of mass;
       the descent along the TCP's z from :data:`ABOVE` over the part's top.
    3. **How far**: until the part would keep :data:`CLEAR` from what boxed it in
       (:data:`MIN_PUSH` .. :data:`MAX_PUSH` of TCP travel), shortened to where the part, moved
       along, would touch another instance (:func:`free_travel`); then back along the TCP's z.
    4. **Checked like a grasp**: the closed gripper every :data:`SAMPLE` along the descent
       against every body (the part too), along the push and the retreat against every body but
       the part; the part moved along the push clear of the cell's table and obstacles; IK at the
       push's start (the one IK solver), the straight lines traced
       (:func:`grasplan.motion.grasp_motion.line_path`) and checked through the robot scene (the
       part present on the descent, away on the push and retreat), and the transit from home
       (:func:`grasplan.motion.grasp_motion.transit_path`)."""
    t0 = time.perf_counter()
    opening = float(gripper.min_opening)
    T_tcp_flange = np.linalg.inv(np.asarray(gripper.T_flange_tcp, dtype=np.float64))
    out: Push | None = None
    for c in candidates(st, instances):
        if targets is not None and c.inst.id not in targets:
            continue
        why = _plan_one(robot, gripper, st, c, ctx_of, opening, T_tcp_flange, seed, max_ik_solutions, max_dev)
        if isinstance(why, Push):
            out = why
            break
        if log is not None:
            log.append(f"{c.inst.id} (gap {c.gap * 1e3:.1f} mm to {c.against}): {why}")
    if timing is not None:
        timing["push"] = timing.get("push", 0.0) + time.perf_counter() - t0
    return out


#: a push needs the part to reach this far (m) past a closed finger's inner face, across the push
MIN_BITE = 0.002


def passes_between_jaws(c: Candidate, hull: np.ndarray, com: np.ndarray, opening: float) -> bool:
    """Whether the part of candidate ``c`` (convex hull ``hull`` (h, 3) and centre of mass ``com``,
    part frame) would pass between jaws closed to ``opening`` (a short-stroke gripper's fingers
    stay ``min_opening`` apart): :func:`push_poses` centres the fingers on the centre of mass across
    the push, so the part's upper half (where the fingertips reach) must extend :data:`MIN_BITE`
    past a finger's inner face on at least one side."""
    T_wp = np.asarray(c.inst.T_world_part, dtype=np.float64)
    hull_w = hull @ T_wp[:3, :3].T + T_wp[:3, 3]
    e = np.cross([0.0, 0.0, 1.0], c.direction)
    mid = 0.5 * (float(hull_w[:, 2].max()) + float(hull_w[:, 2].min()))
    s = (hull_w[hull_w[:, 2] >= mid - 1e-9] - (T_wp[:3, :3] @ com + T_wp[:3, 3])) @ e
    return bool(s.max() < 0.5 * opening + MIN_BITE and -s.min() < 0.5 * opening + MIN_BITE)


def workspace_travel(ws: Workspace | None, c: Candidate, com: np.ndarray) -> float:
    """The TCP travel (m) of a push of candidate ``c`` that keeps its part's centre of mass (``com``,
    part frame) in the cell's workspace (the part moves :data:`TIP_GAP` less than the TCP);
    ``inf`` without a workspace."""
    if ws is None:
        return math.inf
    T_wp = np.asarray(c.inst.T_world_part, dtype=np.float64)
    com_w = T_wp[:3, :3] @ com + T_wp[:3, 3]
    if not ws.contains(com_w):
        return 0.0
    return ws.travel_inside(com_w, c.direction) + TIP_GAP


def _plan_one(robot: Robot, gripper: Gripper, st: CellState, c: Candidate, ctx_of: Any, opening: float,
              T_tcp_flange: np.ndarray, seed: int, max_ik_solutions: int, max_dev: float) -> Push | str:
    g = st.world.parts[c.inst.part]
    com = np.asarray(part_centre_of_mass(g.part.mesh), dtype=np.float64)
    if passes_between_jaws(c, g.hull, com, opening):
        return f"it would pass between the closed jaws ({opening * 1e3:.1f} mm apart)"
    bodies_others = st.world.bodies(c.inst.id)
    bodies_all = [st.world.instances[c.inst.id], *bodies_others]
    inside = workspace_travel(st.cell.workspace, c, com)
    why, poses = "", None
    for tilt in TILTS_DEG:
        for depth in DEPTHS:
            poses = push_poses(c, g.hull, com, gripper, opening, tilt_deg=tilt, depth=depth)
            room = free_travel(st, c.inst, poses)
            if room < MIN_PUSH:
                why = f"another part is within {MIN_PUSH * 1e3:g} mm along the push"
                continue
            if inside < room:  # the part's centre of mass stays in the cell's workspace
                room = inside
                if room < MIN_PUSH:
                    why = f"the workspace's edge is within {MIN_PUSH * 1e3:g} mm along the push"
                    continue
            if room < poses.distance:  # pushed only as far as the part has room
                T_end, T_ret = poses.T_end.copy(), poses.T_retreat.copy()
                T_end[:3, 3] -= c.direction * (poses.distance - room)
                T_ret[:3, 3] -= c.direction * (poses.distance - room)
                poses = PushPoses(poses.T_above, poses.T_start, T_end, T_ret, room)
            why = _gripper_free(st, poses, c.inst, opening, bodies_all, bodies_others)
            if not why:
                break
        if not why:
            break
    if why or poses is None:
        return why + f" (tilts {', '.join(f'{t:g}' for t in TILTS_DEG)} deg)"
    static, away, ctx = ctx_of(c.inst)
    T_flange = np.asarray(gripper.T_flange_tcp, dtype=np.float64)
    ik = solve_ik(robot, poses.T_start @ T_tcp_flange, seed=seed, max_solutions=max_ik_solutions)
    sols = np.asarray(ik.q, dtype=np.float64).reshape(-1, robot.nq)[:max_ik_solutions]
    if not len(sols):
        return f"no IK solution at the push's start ({ik.reason})"
    fails: dict[str, int] = {}
    for q in sols:
        back, _ = line_path(robot, poses.T_start, poses.T_above, q, max_dev=max_dev, T_flange_tcp=T_flange)
        if back is None or not static.path_free(back, opening):
            fails["descent"] = fails.get("descent", 0) + 1
            continue
        push, _ = line_path(robot, poses.T_start, poses.T_end, q, max_dev=max_dev, T_flange_tcp=T_flange)
        if push is None or not away.path_free(push, opening):
            fails["push"] = fails.get("push", 0) + 1
            continue
        up, _ = line_path(robot, poses.T_end, poses.T_retreat, push[-1], max_dev=max_dev, T_flange_tcp=T_flange)
        if up is None or not away.path_free(up, opening):
            fails["retreat"] = fails.get("retreat", 0) + 1
            continue
        approach = back[::-1]
        transit = transit_path(ctx, approach[0], poses.T_above, opening, seed)
        if transit is None:
            fails["transit"] = fails.get("transit", 0) + 1
            continue
        pieces = [("transit", transit), ("approach", approach), ("push", push), ("retreat", up)]
        rows, segments, start = [np.asarray(transit, dtype=np.float64)[:1]], [], 0
        for label, p in pieces:
            p = np.asarray(p, dtype=np.float64)
            rows.append(p[1:])
            segments.append((label, start, start + len(p) - 1))
            start += len(p) - 1
        return Push(instance=c.inst.id, part=c.inst.part, against=c.against, gap=c.gap, direction=c.direction.copy(),
                    distance=poses.distance, opening=opening, T_world_above=poses.T_above,
                    T_world_start=poses.T_start, T_world_end=poses.T_end, T_world_retreat=poses.T_retreat,
                    path=np.vstack(rows), segments=tuple(segments))
    return f"{len(sols)} IK solutions: " + ", ".join(f"{n} fail on the {k}" for k, n in fails.items())

