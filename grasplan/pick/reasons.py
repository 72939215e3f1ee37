"""The words of a pick's instance reports: who blocked it, how many grasps hit what, which tilted
lifts were tried, and each report an instance can end with (:class:`grasplan.pick.result.InstanceReport`'s
``status``, ``reason``, ``code`` and ``blocked_by``)."""
from __future__ import annotations

from ..piles.scene_file import Instance
from .codes import GRASP_STATUS, PickStatus
from ..motion.codes import Reason
from .lift import LIFT_TILTS_DEG
from ..motion.grasp_motion import Outcome
from .result import InstanceReport
from .world import CLOUD, INSTANCE_PREFIX


def blockers_of(hits: dict[str, int]) -> tuple[str, ...]:
    """The instance ids among the body names ``hits`` (sorted): the neighbours that blocked."""
    return tuple(sorted(n[len(INSTANCE_PREFIX):] for n in hits if n.startswith(INSTANCE_PREFIX)))


def hits_text(hits: dict[str, int], what: str) -> str:
    """``"; 12 grasps collide: instance:b (7), bin (5)"``, the 8 most hit bodies first (empty without hits)."""
    if not hits:
        return ""
    rows = sorted(hits.items(), key=lambda kv: (-kv[1], kv[0]))
    return f"; {sum(hits.values())}{what} collide: " + ", ".join(f"{n} ({c})" for n, c in rows[:8])


def tilts_text(max_lift_tilt_deg: float) -> str:
    """The tilts of the lifts tried up to ``max_lift_tilt_deg``: ``"15/30/45 deg from the retreat"``."""
    return "/".join(f"{t:g}" for t in LIFT_TILTS_DEG if t <= max_lift_tilt_deg + 1e-9) + " deg from the retreat"


def no_grasp_report(inst: Instance, n_grasps: int, max_tilt_deg: float, gripper: str) -> InstanceReport:
    """No grasp of the part's ``n_grasps`` approaches within ``max_tilt_deg`` of straight down (or
    its database is empty)."""
    if n_grasps:
        return InstanceReport(inst.id, inst.part, PickStatus.NO_GRASP, f"none of the part's {n_grasps} grasps "
                              f"approaches within {max_tilt_deg:g} deg of straight down at this pose",
                              code=Reason.NO_GRASP_FROM_ABOVE)
    return InstanceReport(inst.id, inst.part, PickStatus.NO_GRASP,
                          f"its grasp database is empty: no contact pair fits the gripper {gripper}",
                          code=Reason.EMPTY_DATABASE)


def lift_blocked_report(inst: Instance, name: str, after: float, dist: float, deep: float | None, rest: float,
                        allowed: tuple[float, float], n_tilted: int, max_lift_tilt_deg: float,
                        carried: bool) -> InstanceReport:
    """Every lift drags the part through body ``name`` (a neighbour or the cloud), whatever the
    grasp: the straight lift of ``dist`` after ``after`` of travel, ``deep`` into it beyond the
    ``rest`` depth of the two at rest (None: not measured, any contact is one), ``allowed``:
    ``(lift_depth, lift_contact)``; ``n_tilted`` tilted lifts tried too; ``carried``: also
    raising what lies on the part."""
    lift_depth, lift_contact = allowed
    if deep is None:
        depth = f" (more than the {1e3 * lift_contact:g} mm of resting contact allowed)"
    else:
        depth = ((f" ({1e3 * deep:.1f} mm deep" if rest < 5e-5 else
                  f" ({1e3 * deep:.1f} mm deeper than the {1e3 * rest:.1f} mm of resting overlap counted")
                 + f"; at most {1e3 * lift_depth:g} mm allowed)")
    text = (f"lifting it {1e3 * dist:g} mm along the retreat drags it through {name} after {1e3 * after:.0f} mm"
            + depth
            + (f", and so does every one of the {n_tilted} tilted lifts ({tilts_text(max_lift_tilt_deg)})"
               if n_tilted > 0 else "")
            + (", raising what lies on it or not" if carried else "")
            + ", whatever the grasp")
    return InstanceReport(inst.id, inst.part, PickStatus.BLOCKED if name.startswith(INSTANCE_PREFIX) else PickStatus.CLOUD,
                          text, blockers_of({name: 1}), code=Reason.LIFT_BLOCKED)


def picked_report(inst: Instance, rank: int, n_ranked: int, out: Outcome, raised: tuple[str, ...], tilt: float,
                  straight_blocker: str | None, hits: dict[str, int]) -> InstanceReport:
    """Picked with the grasp ranked ``rank`` of ``n_ranked`` (its motion ``out``), raising the
    neighbours ``raised``, lifted ``tilt`` deg from the retreat (the straight lift dragging the part
    through ``straight_blocker``, or None: blocked for this grasp); ``hits``: the better-ranked grasps'."""
    text = (f"grasp ranked {rank} of {n_ranked}: {out.reason}"
            + ("" if not raised else f"; the lift raises {', '.join(raised)} lying on it")
            + ("" if tilt == 0 else f"; lifted {tilt:g} deg from the retreat (the straight lift "
               + ("drags the part through " + straight_blocker if straight_blocker is not None
                  else "is blocked for this grasp") + ")")
            + hits_text(hits, " better-ranked grasps"))
    return InstanceReport(inst.id, inst.part, PickStatus.PICKED, text, blockers_of(hits), code=out.code)


def unplanned_report(inst: Instance, tried: int, best: Outcome, hits: dict[str, int]) -> InstanceReport:
    """``tried`` collision-free grasps, none planned: the best one's outcome ``best`` (``blocked``
    when the robot or the carried part hit a neighbour)."""
    return InstanceReport(inst.id, inst.part, PickStatus.BLOCKED if best.blockers else GRASP_STATUS[best.code],
                          f"{tried} collision-free grasps tried, none planned; the best: {best.reason}"
                          + hits_text(hits, " grasps"), blockers_of(hits), code=best.code)


def collides_report(inst: Instance, n_ranked: int, hits: dict[str, int]) -> InstanceReport:
    """Every one of the ``n_ranked`` best-ranked grasps collides (the gripper check's ``hits``)."""
    blockers = blockers_of(hits)
    status = PickStatus.BLOCKED if blockers else PickStatus.CLOUD if hits.get(CLOUD, 0) else PickStatus.BIN
    return InstanceReport(inst.id, inst.part, status, f"every one of the {n_ranked} best-ranked grasps from above "
                          "collides" + hits_text(hits, " grasps"), blockers, code=Reason.GRASPS_COLLIDE)


def weak_report(inst: Instance, n_weak: int, min_margin: float, hits: dict[str, int]) -> InstanceReport:
    """Every collision-free grasp checked (``n_weak``) is predicted to slip at the instance's pose."""
    return InstanceReport(inst.id, inst.part, PickStatus.NO_GRASP, f"its {n_weak} collision-free grasps are all "
                          f"predicted to slip at this pose (gravity margin < {min_margin:g}; more grip force or "
                          f"another resting pose would hold)" + hits_text(hits, " other grasps"),
                          code=Reason.GRASPS_WEAK)


def not_tried_report(inst: Instance, budget_spent: bool) -> InstanceReport:
    """Not reached: the planning budget spent, else ``max_picks`` reached."""
    return InstanceReport(inst.id, inst.part, PickStatus.NOT_TRIED, "not tried: " + (
        "the planning budget spent" if budget_spent else "max_picks reached"),
        code=Reason.BUDGET_SPENT if budget_spent else Reason.MAX_PICKS)
