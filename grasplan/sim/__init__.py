"""Physics in MuJoCo, headless: the lift-and-shake check of grasps, piles dropped into a bin, and
the convex pieces a part collides with.

Every name below is imported from its module on first use (:mod:`grasplan._lazy`).
"""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "simulate_grasps": ".simulate", "simulate_plan": ".simulate", "SimResult": ".simulate",
    "drop_pile": ".drop", "DropParams": ".drop", "DropResult": ".drop",
    "PileWorld": ".pileworld",
    "convex_pieces": ".decomposition",
})
