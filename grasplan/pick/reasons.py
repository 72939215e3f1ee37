"""The words of a pick's instance reports: who blocked it, how many grasps hit what, which tilted
lifts were tried (:class:`grasplan.pick.result.InstanceReport`'s ``reason`` and ``blocked_by``)."""
from __future__ import annotations

from .world import INSTANCE_PREFIX
from .lift import LIFT_TILTS_DEG


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
