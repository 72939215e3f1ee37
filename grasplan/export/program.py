"""The motion of one planned grasp, resolved for a robot program (URScript, KRL, RAPID, ...).

:func:`motion_program` turns a :class:`grasplan.results.plan_result.PlanResult` and a grasp id into a
:class:`MotionProgram`: joint path, approach, TCP poses in the controller's base frame, tool,
openings, and labels reduced to a safe character set. Every program exporter renders from it, so
the pre-grasp opening, the FK of the poses and the joint checks exist once.

Safety: text that comes from inputs (file names, gripper and robot names) only ever reaches a
program through :func:`safe_text`, which keeps ``[A-Za-z0-9 _.,:/+=()-]`` and replaces everything
else (newlines, CR, U+2028, quotes, ``;``, ``!``, ``#``, ``<``) by ``_``: such a label cannot leave
the comment or string it is placed in.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

import numpy as np

from ..errors import InputError
from ..results.export_registry import ExportOptions

if TYPE_CHECKING:
    from ..results.joint_motion import GripperEvent, Motion
    from ..results.plan_result import GraspView, PlanResult
    from ..robot.model import Robot

#: slack (deg) when checking controller angles against the limits: the URDF limits are rad and the
#: plan's joint values may sit exactly on a limit
LIMIT_TOL_DEG = 1e-6

_UNSAFE = re.compile(r"[^A-Za-z0-9 _.,:/+=()\-]")


def safe_text(s: object, max_len: int = 80) -> str:
    """``s`` reduced to ``[A-Za-z0-9 _.,:/+=()-]`` (others -> ``_``), at most ``max_len`` characters."""
    s = _UNSAFE.sub("_", str(s))
    return s if len(s) <= max_len else s[: max_len - 3] + "..."


#: how each segment label is driven: joint moves (verified with straight joint interpolation) or
#: one straight Cartesian move of the TCP to the segment's end
JOINT_SEGMENTS = ("transit", "transfer")
LINEAR_SEGMENTS = ("approach", "lift", "descend", "retreat")
#: what each segment does, for the comments / labels of the programs
SEGMENT_TEXT = {
    "transit": "q_home -> pre-grasp (joint moves, jaws open)",
    "approach": "straight approach to the grasp (jaws at the pre-grasp opening)",
    "lift": "straight lift along the retreat direction, part in the jaws",
    "transfer": "lifted pose -> above the place (joint moves, part in the jaws)",
    "descend": "straight descent to the place, part in the jaws",
    "retreat": "straight retreat along the TCP -z, part released",
}
#: FK tolerances of the sequence checks (m, rad): place pose, lift displacement
SEQ_POS_TOL = 1e-3
SEQ_ROT_TOL = 1e-2


@dataclass(frozen=True)
class ProgramSegment:
    """One labelled segment of the path: rows ``start..end`` (inclusive; consecutive segments share
    their boundary row). ``linear``: driven as ONE straight TCP move to ``T_base_tcp_end`` (the
    planned samples were checked to lie within the plan's ``max_dev`` of that line); else joint
    moves to every row after ``start``. ``attached``: the part rides in the jaws."""

    label: str
    start: int
    end: int
    linear: bool
    attached: bool
    T_base_tcp_end: np.ndarray


@dataclass(frozen=True)
class ProgramEvent:
    """The jaws are commanded to ``width`` (m) once the robot stands at path row ``index``."""

    index: int
    action: str
    width: float


@dataclass(frozen=True)
class MotionProgram:
    """Everything one planned grasp's robot program needs, checked: finite, within the joint
    limits, FK-consistent. Lengths m, joint angles rad, transforms 4x4.

    ``path`` (k, n): q_home -> ... -> q_pregrasp (joint moves, verified with straight joint
    interpolation: do not blend); ``approach`` (a, n): q_pregrasp -> q_grasp (the straight
    Cartesian approach, joint samples). ``T_base_tcp_*``: TCP poses in the controller's base frame
    (``T_world_base``: the robot YAML's ``controller_base_frame``, else the model root). Controller
    joint angle [deg] = ``joint_sign * degrees(q) + joint_offset_deg`` (robot YAML
    ``controller_joint_map``)."""

    grasp_id: int
    score: float | None
    robot_name: str
    joint_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    joint_sign: np.ndarray
    joint_offset_deg: np.ndarray
    path: np.ndarray
    approach: np.ndarray
    q_home: np.ndarray
    q_pregrasp: np.ndarray
    q_grasp: np.ndarray
    T_world_base: np.ndarray
    T_flange_tcp: np.ndarray
    T_base_tcp_pregrasp: np.ndarray
    T_base_tcp_grasp: np.ndarray
    T_base_tcp_retreat: np.ndarray
    backoff: float
    retreat_distance: float
    pregrasp_opening: float
    width: float
    gripper_name: str
    part_label: str
    part_sha256: str
    part_scale_to_m: float
    source: str
    #: the whole planned path (k, n) and its segments / gripper events (pick-and-place plans); an
    #: old pick-only plan has ``sequence`` False and is exported as before (path, approach, retreat)
    full_path: np.ndarray | None = None
    segments: tuple[ProgramSegment, ...] = ()
    events: tuple[ProgramEvent, ...] = ()
    sequence: bool = False
    #: the gripper's load from its YAML: kg and (3,) centre of mass in the flange frame, m (None: not given)
    gripper_mass: float | None = None
    gripper_com: np.ndarray | None = None

    @property
    def placed(self) -> bool:
        """True for a pick-and-place sequence (it has a place and an ``open`` event)."""
        return any(s.label == "descend" for s in self.segments)

    def events_at(self, row: int) -> list[ProgramEvent]:
        """The gripper events at path row ``row``, in order."""
        return [e for e in self.events if e.index == row]

    def controller_deg(self, q: np.ndarray) -> np.ndarray:
        """Joint angles (rad, (..., n)) as the controller counts them, degrees."""
        return self.joint_sign * np.degrees(np.asarray(q, dtype=np.float64)) + self.joint_offset_deg


def motion_program(plan: PlanResult, grasp_id: int | None = None, *, source: str = "") -> MotionProgram:
    """The :class:`MotionProgram` of planned grasp ``grasp_id`` (default: the best) of ``plan``."""
    g = plan.select(grasp_id)
    m = cast("Motion", g.motion)        # select() returns a planned grasp: it has its motion
    robot = cast("Robot", plan.robot)   # select() refuses a result without a robot
    gripper = plan.gripper
    k = int(m.pregrasp_index)
    path = np.asarray(m.path, dtype=np.float64)
    if not np.all(np.isfinite(path)) or not np.all(robot.within_limits(path, tol=1e-6)):
        raise InputError(f"grasp {g.id}: the path has non-finite values or leaves the joint limits of {robot.name!r}")
    T_world_ctrl = robot.T_world_controller_base()
    T_ctrl_world = np.linalg.inv(T_world_ctrl)
    # the TCP with the jaws on this grasp's width (it moves with the opening on a Robotiq 2F)
    T_flange_tcp = np.asarray(gripper.T_flange_tcp_at(float(g.width)), dtype=np.float64)
    fk_grasp = robot.fk(m.q_grasp) @ T_flange_tcp
    dp = float(np.linalg.norm(fk_grasp[:3, 3] - g.T_world_tcp[:3, 3]))
    if dp > 1e-3:
        raise InputError(f"grasp {g.id}: FK(q_grasp) is {dp * 1e3:.1f} mm from the grasp TCP; the plan does not "
                         f"belong to robot {robot.name!r} with gripper {gripper.name!r}")
    T_pre = T_ctrl_world @ robot.fk(m.q_pregrasp) @ T_flange_tcp
    sign = robot.joint_sign if robot.joint_sign is not None else np.ones(robot.nq)
    offset = robot.joint_offset_deg if robot.joint_offset_deg is not None else np.zeros(robot.nq)
    width = float(g.width)
    seq = _sequence(plan, g, m, path, T_ctrl_world, T_flange_tcp)
    return MotionProgram(
        grasp_id=int(g.id), score=g.score, robot_name=safe_text(robot.name, 40),
        joint_names=tuple(safe_text(j, 40) for j in robot.joint_names), lower=np.asarray(robot.lower),
        upper=np.asarray(robot.upper), joint_sign=np.asarray(sign, dtype=np.float64),
        joint_offset_deg=np.asarray(offset, dtype=np.float64), path=path[: k + 1], approach=path[k:],
        q_home=path[0], q_pregrasp=np.asarray(m.q_pregrasp), q_grasp=np.asarray(m.q_grasp),
        T_world_base=T_world_ctrl, T_flange_tcp=T_flange_tcp, T_base_tcp_pregrasp=T_pre,
        T_base_tcp_grasp=T_ctrl_world @ g.T_world_tcp, T_base_tcp_retreat=T_pre,
        backoff=float(plan.params.planning.backoff), retreat_distance=plan.retreat_distance,
        pregrasp_opening=float(gripper.pregrasp_opening(width)), width=width,
        gripper_name=safe_text(gripper.name, 40), part_label=safe_text(plan.part.label, 80),
        part_sha256=safe_text(plan.part.sha256, 64), part_scale_to_m=float(plan.part.scale_to_m),
        source=safe_text(source, 80), full_path=path, gripper_mass=gripper.mass, gripper_com=gripper.com, **seq)


def motion_segments(m: Motion) -> list[tuple[str, int, int]]:
    """``(label, start, end)`` of a :class:`~grasplan.results.joint_motion.Motion` (transit + approach for a
    motion without segments)."""
    if hasattr(m, "segment_list"):
        return m.segment_list()
    k = int(m.pregrasp_index)
    return [("transit", 0, k), ("approach", k, len(m.path) - 1)]


def is_sequence(m: Motion) -> bool:
    """True when a motion goes beyond the pick (it has a lift: the part is lifted in the jaws)."""
    return len(motion_segments(m)) > 2


def _line_deviation(p: np.ndarray) -> float:
    """Largest distance (m) of the points (s, 3) from the segment p[0] -> p[-1]."""
    a, b = p[0], p[-1]
    ab = b - a
    L2 = float(ab @ ab)
    t = np.clip(((p - a) @ ab) / L2, 0.0, 1.0) if L2 > 0 else np.zeros(len(p))
    return float(np.max(np.linalg.norm(p - (a + t[:, None] * ab), axis=1)))


def _rot_angle(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """Rotation angles (rad) between rotation matrices (..., 3, 3)."""
    c = (np.einsum("...ij,...ij->...", Ra, Rb) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def _sequence(plan: PlanResult, g: GraspView, m: Motion, path: np.ndarray, T_ctrl_world: np.ndarray, T_flange_tcp: np.ndarray) -> dict:
    """The segments and gripper events of a pick(-and-place) motion, checked: every linear
    segment's samples within ``max_dev`` (+0.1 mm) of the straight line and at a constant
    orientation (0.01 rad), the lift along the cell's retreat direction by its distance and the
    place TCP at ``T_world_part_place`` (1 mm, 0.01 rad). ``{}`` for an old pick-only motion."""
    if not is_sequence(m):
        return {}
    robot = cast("Robot", plan.robot)   # the caller's select() refused a result without a robot
    segs = motion_segments(m)
    where = f"grasp {g.id}"
    labels = [s[0] for s in segs]
    unknown = [lab for lab in labels if lab not in JOINT_SEGMENTS + LINEAR_SEGMENTS]
    if unknown:
        raise InputError(f"{where}: unknown segment label(s) {unknown}; this grasplan exports "
                         f"{', '.join(JOINT_SEGMENTS + LINEAR_SEGMENTS)}. Update grasplan or plan again")
    T_tcp = robot.fk_batch(path) @ T_flange_tcp  # (k, 4, 4) world
    tol = float(getattr(plan.params.planning, "max_dev", 0.002)) + 1e-4
    c0, c1 = m.attached_range() if hasattr(m, "attached_range") else (len(path) - 1, len(path) - 1)
    out = []
    for lab, s, e in segs:
        linear = lab in LINEAR_SEGMENTS
        if linear:
            dev = _line_deviation(T_tcp[s:e + 1, :3, 3])
            rot = float(np.max(_rot_angle(T_tcp[s:e + 1, :3, :3], T_tcp[s, :3, :3][None])))
            if dev > tol or rot > SEQ_ROT_TOL:
                raise InputError(f"{where}: the {lab} segment (rows {s}..{e}) is not one straight TCP move: "
                                 f"{dev * 1e3:.2f} mm from the line (max {tol * 1e3:.2f}), {rot:.4f} rad turn; "
                                 "the controller's linear move would leave the verified path. Plan again")
        out.append(ProgramSegment(label=lab, start=int(s), end=int(e), linear=linear,
                                  attached=bool(c0 <= s and e <= c1),
                                  T_base_tcp_end=T_ctrl_world @ T_tcp[e]))
    cell = plan.cell
    lift = next((x for x in out if x.label == "lift"), None)
    direction = getattr(cell, "retreat_direction", None)
    distance = getattr(cell, "retreat_distance", None)
    if lift is not None and direction is not None and distance is not None:
        d = T_tcp[lift.end, :3, 3] - T_tcp[lift.start, :3, 3]
        want = float(distance) * np.asarray(direction, dtype=np.float64)
        if np.linalg.norm(d - want) > SEQ_POS_TOL:
            raise InputError(f"{where}: the lift moves the TCP by {np.round(d, 4).tolist()} m, the cell's retreat is "
                             f"{np.round(want, 4).tolist()} m; the plan was made with another cell. Plan again")
    T_place = getattr(m, "T_world_part_place", None)
    T_tcp_part = getattr(m, "T_tcp_part", None)
    if T_place is not None and T_tcp_part is not None and hasattr(m, "event") and m.event("open") is not None:
        i = cast("GripperEvent", m.event("open")).index  # not None: tested above
        T_fk_part = T_tcp[i] @ np.asarray(T_tcp_part, dtype=np.float64)
        dp = float(np.linalg.norm(T_fk_part[:3, 3] - np.asarray(T_place)[:3, 3]))
        dr = float(_rot_angle(T_fk_part[:3, :3], np.asarray(T_place)[:3, :3]))
        if dp > SEQ_POS_TOL or dr > SEQ_ROT_TOL:
            raise InputError(f"{where}: at the release (row {i}) the part would be {dp * 1e3:.1f} mm / {dr:.3f} rad "
                             "from the plan's place pose; the plan is inconsistent. Plan again")
    events = tuple(ProgramEvent(index=int(ev.index), action=str(ev.action), width=float(ev.width))
                   for ev in getattr(m, "gripper", ()))
    for ev in events:
        if ev.action not in ("close", "open") or not (np.isfinite(ev.width) and 0 <= ev.width <= 10):
            raise InputError(f"{where}: gripper event {ev}: expected close/open with a width in [0, 10] m")
        if ev.index not in {x.end for x in out}:
            raise InputError(f"{where}: gripper {ev.action} at row {ev.index} is not at a segment boundary")
    return {"segments": tuple(out), "events": events, "sequence": True}


def program_steps(mp: MotionProgram) -> list[tuple]:
    """The robot program of a sequence, format-neutral, in order:

    - ``("segment", ProgramSegment)``: a segment begins (a comment / label);
    - ``("joint", row, q)``: a joint move to path row ``row`` (transit: every row from ``q_home``;
      transfer: every row after its start);
    - ``("linear", row, ProgramSegment)``: one straight TCP move to the segment's end;
    - ``("gripper", ProgramEvent)``: command the jaws, once the robot stands at the event's row.

    The program starts by opening the jaws to the pre-grasp opening (not a step)."""
    steps: list[tuple] = []
    path = mp.full_path
    if path is None:
        raise ValueError("program_steps: the plan has no labelled sequence (full_path)")
    for seg in mp.segments:
        steps.append(("segment", seg))
        if seg.linear:
            steps.append(("linear", seg.end, seg))
        else:
            first = 0 if seg.start == 0 else seg.start + 1
            steps += [("joint", r, path[r]) for r in range(first, seg.end + 1)]
        steps += [("gripper", ev) for ev in mp.events_at(seg.end)]
    return steps


def row_label(mp: MotionProgram, row: int) -> str:
    """A comment for path row ``row`` of a sequence: q_home, q_pregrasp, q_grasp, a segment's end
    or ``<segment> waypoint i``."""
    if row == 0:
        return "q_home"
    for seg in mp.segments:
        if row == seg.end:
            return {"transit": "q_pregrasp", "approach": "q_grasp", "lift": "lifted", "transfer": "above place",
                    "descend": "place", "retreat": "retreated"}.get(seg.label, f"{seg.label} end")
        if seg.start < row < seg.end:
            return f"{seg.label} waypoint {row - seg.start}"
    return f"row {row}"


# -- shared by the program exporters (KRL, RAPID) --------------------------------------------------

def controller_joint_deg(mp: MotionProgram, qs: np.ndarray, what: str) -> np.ndarray:
    """Controller joint angles, degrees ``(k, n)``, of joint vectors ``qs`` ``(k, n)`` or ``(n,)`` rad.

    ``MotionProgram.controller_deg``: ``sign * degrees(q) + offset_deg`` per joint.
    Raises :class:`InputError` (naming ``what``, the waypoint and the joint) for a wrong shape, a
    non-finite value or a value outside the URDF limits mapped the same way.
    """
    n = len(mp.joint_names)
    q = np.atleast_2d(np.asarray(qs, dtype=np.float64))
    sign = np.asarray(mp.joint_sign, dtype=np.float64)
    offset = np.asarray(mp.joint_offset_deg, dtype=np.float64)
    lower = np.asarray(mp.lower, dtype=np.float64)
    upper = np.asarray(mp.upper, dtype=np.float64)
    for name, a in (("joint_sign", sign), ("joint_offset_deg", offset), ("lower", lower), ("upper", upper)):
        if a.shape != (n,) or not np.all(np.isfinite(a)):
            raise InputError(f"robot {mp.robot_name}: {name} must be {n} finite numbers (one per joint); "
                             "fix controller_joint_map / the joint limits in the robot YAML")
    if not np.all(np.abs(sign) == 1.0):
        raise InputError(f"robot {mp.robot_name}: controller_joint_map signs must be +1 or -1, got {sign.tolist()}")
    if q.ndim != 2 or q.shape[1] != n:
        raise InputError(f"{what}: expected joint vectors of {n} values, got shape {q.shape}")
    bad = ~np.isfinite(q)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise InputError(f"{what}: waypoint {i} joint {mp.joint_names[j]} is not finite; the plan is corrupt, "
                         "plan again")
    deg = mp.controller_deg(q)
    lo = np.minimum(sign * np.degrees(lower), sign * np.degrees(upper)) + offset
    hi = np.maximum(sign * np.degrees(lower), sign * np.degrees(upper)) + offset
    out = (deg < lo - LIMIT_TOL_DEG) | (deg > hi + LIMIT_TOL_DEG)
    if out.any():
        i, j = np.argwhere(out)[0]
        raise InputError(f"{what}: waypoint {i} joint {mp.joint_names[j]} = {deg[i, j]:.4f} deg is outside the "
                         f"robot's limits [{lo[j]:.4f}, {hi[j]:.4f}] deg; plan again with this robot")
    return deg + 0.0  # no -0.0


def num(x: float, digits: int = 6) -> str:
    """A finite number as a fixed-point literal (no exponent, no ``-0``): valid in KRL and RAPID."""
    x = float(x)
    if not np.isfinite(x):
        raise InputError(f"refusing to write a non-finite number ({x!r}) into a robot program")
    s = f"{x:.{digits}f}"
    return s.lstrip("-") if float(s) == 0.0 else s  # "-0.000" -> "0.000"


def redundant_joint_deg(mp: MotionProgram, q_grasp_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Controller degrees of the joints beyond 6 (joint 7 of a 7-joint arm; ``(0,)`` for 6 joints)
    for the grasp and the retreat target: at the retreat, the pre-grasp value when the retreat ends
    at the pre-grasp pose (1 um, 1e-6 rad), else the grasp value (held)."""
    ext_grasp = q_grasp_deg[6:]
    T_r, T_p = np.asarray(mp.T_base_tcp_retreat), np.asarray(mp.T_base_tcp_pregrasp)
    if np.allclose(T_r[:3, 3], T_p[:3, 3], rtol=0, atol=1e-6) and np.allclose(T_r[:3, :3], T_p[:3, :3], rtol=0, atol=1e-6):
        return ext_grasp, controller_joint_deg(mp, mp.q_pregrasp, "q_pregrasp")[0, 6:]
    return ext_grasp, ext_grasp


def header_lines(mp: MotionProgram, comment: str, units: str) -> list[str]:
    """The header comment lines every robot program starts with (inputs only through ``safe_text``)."""
    score = "none" if mp.score is None else f"{float(mp.score):.4f}"
    lines = [
        f"grasplan: {program_kind(mp)} program for grasp {int(mp.grasp_id)} (score {score})",
        f"plan: {safe_text(mp.source) or '(in memory)'}",
        (f"part: {safe_text(mp.part_label)} (sha256 {safe_text(mp.part_sha256)[:16]}..., "
        f"scale_to_m {num(mp.part_scale_to_m, 9)})"),
        f"robot: {safe_text(mp.robot_name)}; gripper: {safe_text(mp.gripper_name)}",
        f"grasp width {num(mp.width * 1000, 2)} mm, pre-grasp opening {num(mp.pregrasp_opening * 1000, 2)} mm",
        units,
        "Joint angles: controller = sign * URDF angle + offset (controller_joint_map in the robot YAML).",
        *sequence_lines(mp),
    ]
    return [f"{comment} {line}" for line in lines]


def program_kind(mp: MotionProgram) -> str:
    """``pick`` (old plans), ``pick-and-lift`` or ``pick-and-place``."""
    return "pick" if not mp.sequence else ("pick-and-place" if mp.placed else "pick-and-lift")


def sequence_lines(mp: MotionProgram) -> list[str]:
    """Comment lines (no comment marker) that summarise a sequence: its segments and gripper events."""
    if not mp.sequence:
        return []
    out = ["Sequence: " + ", ".join(f"{s.label} (rows {s.start}-{s.end})" for s in mp.segments) + "."]
    out += [f"Gripper: {e.action} to {e.width * 1000:.2f} mm at row {e.index}." for e in mp.events]
    return out


def check_program_name(name: str) -> str:
    """``name`` if it is a valid program name (:func:`grasplan.results.program_names.program_name_problem`,
    the rule :class:`ExportOptions` applies: a letter, then letters, digits or ``_``, at most 24
    characters, no KRL/RAPID reserved word, no name the program itself declares); InputError else."""
    return ExportOptions(program_name=name).program_name


def waypoint_labels(k: int) -> list[str]:
    """Comments of the ``k`` joint-path waypoints: q_home, waypoint 1, ..., q_pregrasp."""
    if k == 1:
        return ["q_home = q_pregrasp"]
    return ["q_home"] + [f"waypoint {i}" for i in range(1, k - 1)] + ["q_pregrasp"]


@dataclass(frozen=True)
class ProgramTargets:
    """What a KRL or RAPID program writes, checked once: the program name, controller degrees of
    the path ``(k, n)`` and the grasp ``(n,)``, the tool, base, grasp and retreat frames (4, 4), and
    the controller degrees of the joints beyond 6 at the grasp and the retreat."""

    name: str
    path_deg: np.ndarray
    q_grasp_deg: np.ndarray
    T_tool: np.ndarray
    T_base: np.ndarray
    T_grasp: np.ndarray
    T_retreat: np.ndarray
    ext_grasp: np.ndarray
    ext_retreat: np.ndarray
    #: sequences: controller degrees of every path row (k, n), checked; None for an old plan
    full_deg: np.ndarray | None = None

    def sequence_deg(self) -> np.ndarray:
        """:attr:`full_deg`, which a sequence program needs (ValueError for a plan without one)."""
        if self.full_deg is None:
            raise ValueError("the plan has no labelled sequence (full_path); write the pick-only program")
        return self.full_deg


def program_targets(mp: MotionProgram, program_name: str, language: str, axes: str) -> ProgramTargets:
    """The checks and conversions every KRL/RAPID program starts with. ``language`` and ``axes``
    (how 6 and 7 joints are laid out) only word the error for an arm with another joint count.
    Raises :class:`InputError` for a bad program name, joint count, non-finite value, joint value
    outside the limits or non-rigid frame."""
    from ..geometry.transforms import check_transform

    name = check_program_name(program_name)
    n = len(mp.joint_names)
    if n not in (6, 7):
        raise InputError(f"{language} export supports arms with 6 joints {axes}; robot "
                         f"{safe_text(mp.robot_name)} has {n}. Use --format joint-trajectory")
    q_grasp = controller_joint_deg(mp, mp.q_grasp, "q_grasp")[0]
    for what, v in (("width", mp.width), ("pregrasp_opening", mp.pregrasp_opening)):
        if not (np.isfinite(v) and v >= 0):
            raise InputError(f"{what}: expected a finite length >= 0 m, got {v!r}")
    ext_grasp, ext_retreat = redundant_joint_deg(mp, q_grasp)  # joint 7; empty for 6 joints
    return ProgramTargets(name=name, path_deg=controller_joint_deg(mp, mp.path, "path"), q_grasp_deg=q_grasp,
                          T_tool=check_transform(mp.T_flange_tcp, "T_flange_tcp"),
                          T_base=check_transform(mp.T_world_base, "T_world_base"),
                          T_grasp=check_transform(mp.T_base_tcp_grasp, "T_base_tcp_grasp"),
                          T_retreat=check_transform(mp.T_base_tcp_retreat, "T_base_tcp_retreat"),
                          ext_grasp=ext_grasp, ext_retreat=ext_retreat,
                          # a sequence has its full path
                          full_deg=(controller_joint_deg(mp, cast(np.ndarray, mp.full_path), "path")
                                    if mp.sequence else None))
