"""Pick-and-place after the grasp: close, lift, transfer, descend, release, retreat.

Pure functions of a robot, collision scenes and poses; the per-grasp pipeline
(:func:`grasplan.motion.grasp_motion.plan_pick_motion`) calls them for every grasp whose approach
and lift are planned: :func:`place_candidates`, :func:`transfer_path`, and :func:`assemble_motion`,
whose docstring gives the sequence. Every straight move uses the one straight-line tracker
(:func:`grasplan.motion.joint_paths.approach_path_reason`, CLIK seeded by the previous waypoint,
``max_dev`` from the line) and every path is checked at ``interpolation.STEP`` rad.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..robot.ik.solve import solve_ik
from ..geometry.interpolation import STEP
from .joint_paths import approach_path_reason, plan_joint_path
from ..results.joint_motion import GripperEvent, Motion
from ..robot.model import Robot
from .collision_scene import CollisionScene, describe_pairs
from .lift_check import lift_collision, sample_ok, touch_waypoints
from ..status import Status

#: jaw openings checked between the contact width and the pre-grasp opening when releasing
RELEASE_STEPS = 4
#: TCP spacing (m) of the waypoints of the lift, descent and retreat. Tracking (CLIK per waypoint)
#: is most of a straight move's cost; at 4 mm a UR5 joint moves ~0.01 rad per waypoint, the
#: joint-linear motion between two waypoints stays within micrometres of the line (checked at
#: every waypoint and midpoint against ``max_dev``) and collisions are checked at ``interpolation.STEP``
#: rad between them as everywhere else
LINE_SAMPLE = 0.004

_KINEMATIC = {"start": "the start pose does not match", "ik": "IK lost on the line",
              "limits": "a joint limit on the line", "jump": "a joint jump (branch switch) on the line",
              "deviation": "the joint motion leaves the line by more than max_dev"}


@dataclass(frozen=True)
class PlaceCandidate:
    """One way to place: ``descend`` (above-place -> place, attached) and ``retreat`` (place ->
    backed off, released), joint paths (k, n)."""

    descend: np.ndarray
    retreat: np.ndarray

    @property
    def q_above(self) -> np.ndarray:
        return self.descend[0]

    @property
    def q_place(self) -> np.ndarray:
        return self.descend[-1]


@dataclass(frozen=True)
class PlacePoses:
    """TCP poses (4, 4) of the place: at the place, above it (descent start), backed off (retreat end)."""

    place: np.ndarray
    above: np.ndarray
    retreat: np.ndarray


# ------------------------------------------------------------------------------------------------
# poses
# ------------------------------------------------------------------------------------------------
def unit_direction(direction: ArrayLike) -> np.ndarray:
    d = np.asarray(direction, dtype=np.float64).reshape(3)
    n = float(np.linalg.norm(d))
    if not (np.isfinite(n) and n > 0):
        raise ValueError(f"retreat direction must be a non-zero 3-vector, got {direction!r}")
    return d / n


def translate_world(T: np.ndarray, v: ArrayLike) -> np.ndarray:
    """``T`` moved by the world vector ``v`` (orientation unchanged)."""
    out = np.array(T, dtype=np.float64)
    out[:3, 3] += np.asarray(v, dtype=np.float64)
    return out


def lift_pose(T_world_tcp: np.ndarray, direction: ArrayLike, distance: float) -> np.ndarray:
    """The TCP after the lift: ``distance`` along the world ``direction``."""
    return translate_world(T_world_tcp, unit_direction(direction) * float(distance))


def place_poses(T_world_part_place: np.ndarray, T_part_tcp: np.ndarray, direction: ArrayLike, distance: float,
                backoff: float) -> PlacePoses:
    """The place TCP ``T_world_part_place @ T_part_tcp``, above it (``distance`` along the retreat
    ``direction``) and the retreat end (``backoff`` along the place TCP's own -z)."""
    T_place = np.asarray(T_world_part_place, dtype=np.float64) @ np.asarray(T_part_tcp, dtype=np.float64)
    back = np.eye(4)
    back[2, 3] = -float(backoff)
    return PlacePoses(place=T_place, above=lift_pose(T_place, direction, distance), retreat=T_place @ back)


def T_tcp_part_of(T_part_tcp: np.ndarray) -> np.ndarray:
    """The part in the jaws: ``inv(T_part_tcp)`` (= ``inv(T_world_tcp) @ T_world_part``)."""
    T = np.asarray(T_part_tcp, dtype=np.float64)
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def _vec(v: ArrayLike) -> str:
    return "(" + ", ".join(f"{float(x):.3g}" for x in np.asarray(v).reshape(-1)) + ")"


# ------------------------------------------------------------------------------------------------
# place
# ------------------------------------------------------------------------------------------------
def place_candidates(robot: Robot, scene_attached: CollisionScene, scene_released: CollisionScene,
                     poses: PlacePoses, *, width: float, opening: float,
                     max_dev: float, T_flange_tcp: np.ndarray, q_ref: np.ndarray, seed: int = 0,
                     max_solutions: int = 8, limit: int | None = None, sample: float = LINE_SAMPLE,
                     contact: float = 0.002) -> tuple[list[PlaceCandidate], Status, str]:
    """Every IK solution of the place TCP (closest to ``q_ref`` first) whose descent (traced back
    from the place to above it, attached, jaws at ``width``), release (jaws opening to
    ``opening`` with the part static at the place) and retreat (released) are free.

    Returns ``(candidates, status, reason)``: status ``ok`` when there is at least one candidate,
    else ``place_unreachable`` (no IK at the place or above it, the descent or retreat cannot follow
    the line) or ``place_no_path`` (the place pose, the descent, the release or the retreat collides)
    and why, ``"place: ..."``. ``limit``: stop after this many candidates (the caller tries at most
    that many transfer paths). ``contact``: within this TCP travel of the place the part in the
    jaws may touch what it is placed on (the descent is checked as a lift traced back from the
    place, :func:`~grasplan.motion.lift_check.lift_collision`)."""
    T_tcp_flange = np.linalg.inv(np.asarray(T_flange_tcp, dtype=np.float64))
    ik = solve_ik(robot, poses.place @ T_tcp_flange, seed=seed, q_ref=q_ref)
    sols = np.asarray(ik.q, dtype=np.float64).reshape(-1, robot.nq)[:max_solutions]
    if len(sols) == 0:
        above = solve_ik(robot, poses.above @ T_tcp_flange, seed=seed, q_ref=q_ref)
        tail = "" if len(above.q) else f"; nor above it ({above.reason})"
        return [], Status.PLACE_UNREACHABLE, (f"place: no IK solution for the place TCP at {_vec(poses.place[:3, 3])} m "
                                         f"within the joint limits ({ik.reason}){tail}")
    travel = float(np.linalg.norm(poses.above[:3, 3] - poses.place[:3, 3]))
    counts = {"place_coll": 0, "desc_kin": 0, "desc_coll": 0, "release_coll": 0, "ret_kin": 0, "ret_coll": 0}
    first_what: dict[str, str] = {}
    kin_why: dict[str, str] = {}
    out: list[PlaceCandidate] = []
    for q_place in sols:
        if limit is not None and len(out) >= limit:
            break
        back, why = approach_path_reason(robot, None, poses.place, poses.above, q_place, opening=width,
                                         max_dev=max_dev, T_flange_tcp=T_flange_tcp, sample=sample)
        if back is None:
            counts["desc_kin"] += 1
            kin_why.setdefault("desc", _KINEMATIC.get(why, why))
            continue
        pairs = lift_collision(scene_attached, back, width,
                               touch_waypoints(contact, np.linspace(0.0, travel, len(back))))
        if pairs is not None:
            key = "place_coll" if not sample_ok(scene_attached, q_place, width, True, None) else "desc_coll"
            counts[key] += 1
            first_what.setdefault(key, describe_pairs(pairs, 2))
            continue
        hit = _release_collision(scene_released, q_place, width, opening)
        if hit is not None:
            counts["release_coll"] += 1
            first_what.setdefault("release_coll", hit)
            continue
        ret, why = approach_path_reason(robot, None, poses.place, poses.retreat, q_place, opening=opening,
                                        max_dev=max_dev, T_flange_tcp=T_flange_tcp, sample=sample)
        if ret is None:
            counts["ret_kin"] += 1
            kin_why.setdefault("ret", _KINEMATIC.get(why, why))
            continue
        if not scene_released.path_free(ret, opening, step=STEP):
            counts["ret_coll"] += 1
            ret_hit = scene_released.path_collisions(ret, opening)
            first_what.setdefault("ret_coll", describe_pairs(ret_hit[1], 2) if ret_hit else "unknown")
            continue
        out.append(PlaceCandidate(descend=back[::-1].copy(), retreat=ret))
    if out:
        return out, Status.OK, "ok"
    k = len(sols)
    parts = [f"{k} IK solutions at the place"]
    labels = {"place_coll": "collide at the place (part in the jaws)", "desc_coll": "collide on the descent",
              "release_coll": "collide while the jaws open", "ret_coll": "collide on the retreat"}
    for key, text in labels.items():
        if counts[key]:
            parts.append(f"{counts[key]} {text} ({first_what.get(key, '')})")
    if counts["desc_kin"]:
        parts.append(f"{counts['desc_kin']} cannot follow the straight descent ({kin_why['desc']})")
    if counts["ret_kin"]:
        parts.append(f"{counts['ret_kin']} cannot follow the straight retreat ({kin_why['ret']})")
    collided = counts["place_coll"] + counts["desc_coll"] + counts["release_coll"] + counts["ret_coll"]
    status = Status.PLACE_NO_PATH if collided else Status.PLACE_UNREACHABLE
    return [], status, "place: " + ", ".join(parts)


def _release_collision(scene_released: CollisionScene, q_place: np.ndarray, width: float,
                       opening: float) -> str | None:
    """What the jaws hit while opening from ``width`` to ``opening`` at the place (the part static
    there; the contact width itself is skipped: the jaws touch the part there), or None."""
    for o in np.linspace(width, opening, RELEASE_STEPS + 1)[1:]:
        if not scene_released.is_free(q_place, float(o)):
            return f"at opening {o * 1e3:.1f} mm: {scene_released.first_collision(q_place, float(o))}"
    return None


def transfer_path(scene_attached: CollisionScene, q_lifted: np.ndarray, cand: PlaceCandidate, *, lower: np.ndarray,
                  upper: np.ndarray, width: float, seed: int, time_limit: float, attempts: int) -> np.ndarray | None:
    """RRTConnect lifted -> above-place with the part attached and the jaws at ``width`` (None: no
    verified path, a ``place_no_path`` failure)."""
    return plan_joint_path(scene_attached, q_lifted, cand.q_above, lower=lower, upper=upper, opening=width,
                           seed=seed, time_limit=time_limit, attempts=attempts)


# ------------------------------------------------------------------------------------------------
# the whole motion
# ------------------------------------------------------------------------------------------------
def assemble_motion(transit: np.ndarray, approach: np.ndarray, lift: np.ndarray, *, width: float, opening: float,
                    T_tcp_part: np.ndarray, transfer: np.ndarray | None = None,
                    place: PlaceCandidate | None = None, T_world_part_place: np.ndarray | None = None) -> Motion:
    """One path with labelled segments (consecutive segments share their boundary row) and the
    gripper events: close (``width``) at the grasp, open (``opening``) at the place.

    The sequence (world frame, lengths m):

    1. **close** at the grasp (event, width = the grasp's contact width);
    2. **lift**: the TCP moves straight by ``cell.retreat_distance`` along ``cell.retreat_direction``
       with the part attached (``scene.attached(T_tcp_part)``, ``T_tcp_part = inv(T_part_tcp)``)
       (:func:`grasplan.motion.grasp_motion.plan_pick_motion`);
    3. with a place ``T_world_part_place``: the place TCP ``T_world_part_place @ T_part_tcp``, the
       above-place TCP = the place TCP moved back up by ``retreat_distance`` along the retreat
       direction (the descent is the reverse of a lift at the place; :func:`place_poses`). IK at the
       place (the one IK solver, :func:`grasplan.robot.ik.solve_ik`), the straight descent traced back
       from it (above-place -> place, attached), then the straight **retreat** after the **open** event
       (width = the pre-grasp opening) along the TCP's -z by ``backoff`` with the part released at the
       place (``scene.with_part_at(T_world_part_place)``) (:func:`place_candidates`), and the OMPL
       **transfer** lifted -> above-place with the part attached (:func:`transfer_path`).
    """
    pieces = [("transit", transit), ("approach", approach), ("lift", lift)]
    if place is not None:
        if transfer is None or T_world_part_place is None:
            raise ValueError("a place needs its transfer path and T_world_part_place")
        pieces += [("transfer", transfer), ("descend", place.descend), ("retreat", place.retreat)]
    rows = [np.asarray(transit, dtype=np.float64)]
    segments = []
    start = 0
    for label, p in pieces:
        p = np.asarray(p, dtype=np.float64)
        if label != "transit":
            if np.max(np.abs(p[0] - rows[-1][-1])) > 1e-9:
                raise ValueError(f"segment {label!r} does not start where the previous one ends")
            rows.append(p[1:])
        end = start + len(p) - 1
        segments.append((label, start, end))
        start = end
    path = np.concatenate(rows, axis=0)
    seg = {lab: (a, b) for lab, a, b in segments}
    events = [GripperEvent(index=seg["approach"][1], action="close", width=float(width))]
    if place is not None:
        events.append(GripperEvent(index=seg["descend"][1], action="open", width=float(opening)))
    return Motion(q_grasp=path[seg["approach"][1]].copy(), q_pregrasp=path[seg["transit"][1]].copy(), path=path,
                  pregrasp_index=int(seg["transit"][1]), segments=tuple(segments), gripper=tuple(events),
                  T_world_part_place=None if place is None else np.array(T_world_part_place, dtype=np.float64),
                  T_tcp_part=np.array(T_tcp_part, dtype=np.float64))
