"""Plans of every resting pose (``pose_index="all"``): one standalone plan file per stable pose
(``OUT.pose<k>.json``) and ``OUT.json`` = the pose with the most planned grasps predicted to hold
(then the most planned; ties: the more probable, :func:`choice_key`) plus a ``poses`` block with the
counts per pose. ``grasplan plan --pose-index all`` and
``grasplan batch --pose-index all`` both write them with :func:`write_pose_plans`, from one
:class:`PosePlan` (a result or an error) per pose.
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import PlanningError
from ..status import Status
from .compact import DEFAULT_KEEP, REJECTED
from .quality_json import HOLD_FORCE_DECIMALS, hold_force

if TYPE_CHECKING:
    from .plan_result import PlanResult



@dataclass(frozen=True)
class PosePlan:
    """One resting pose's plan (``pose_index="all"``): the stable pose ``index`` (0 = most probable),
    its ``probability`` and either its ``result`` or, when its checks before planning failed, the
    ``error`` message: exactly one of the two."""

    index: int
    probability: float
    result: PlanResult | None = None
    error: str | None = None

    def __post_init__(self) -> None:
        if (self.result is None) == (self.error is None):
            raise ValueError(f"PosePlan of pose {self.index}: give a result or an error, exactly one")


@dataclass(frozen=True)
class PosePlans:
    """What :func:`write_pose_plans` wrote: ``chosen`` (the pose index of ``OUT.json``), its
    ``result`` and ``planned`` count, and ``poses`` (the ``poses`` block's rows, one per pose).
    ``result`` is None when no pose could be planned at all (:meth:`error` says why)."""

    chosen: int | None
    result: PlanResult | None
    planned: int
    poses: tuple[dict[str, Any], ...]

    def error(self, part_name: str) -> PlanningError:
        """The exit-4 error when no pose could be planned at all (every pose failed its checks)."""
        return PlanningError(f"no resting pose of {part_name} could be planned: "
                             + "; ".join(f"pose {b['pose_index']}: {b.get('error', '')}" for b in self.poses))

    def table_rows(self) -> list[tuple[Any, ...]]:
        """``(pose, probability, planned, planned holding, collision-free, holds from N, file or
        error)`` per pose, for a table."""
        return [(p["pose_index"], f"{p['probability'] * 100:.1f} %", "-", "-", "-", "-", p["error"][:60])
                if p["file"] is None
                else (p["pose_index"], f"{p['probability'] * 100:.1f} %", p["planned"], p["planned_holding"],
                      p["collision_free"], "-" if p["hold_force_N"] is None else f"{p['hold_force_N']:.1f}", p["file"])
                for p in self.poses]

    def hold_note(self, grip_force: float) -> str:
        """A line when the chosen pose has no grasp predicted to hold at ``grip_force`` (N) and
        another pose has ("" otherwise): which poses, from which force."""
        chosen = next((p for p in self.poses if p["pose_index"] == self.chosen), None)
        if chosen is None or chosen["hold_force_N"] is None or chosen["hold_force_N"] <= grip_force:
            return ""
        better = [p for p in self.poses if p["hold_force_N"] is not None and p["hold_force_N"] <= grip_force]
        if not better:
            return ""
        return (f"no grasp of pose {self.chosen} is predicted to hold at {grip_force:g} N (it needs "
                f"{chosen['hold_force_N']:.1f} N); " + ", ".join(
                    f"pose {p['pose_index']} ({p['probability'] * 100:.1f} %) holds from {p['hold_force_N']:.1f} N "
                    f"({p['file']})" for p in better))


def choice_key(row: dict[str, Any]) -> tuple[int, int]:
    """What ``OUT.json`` maximises over the poses (the first, most probable, wins ties): the planned
    grasps predicted to hold at the gripper's force, then the planned grasps."""
    return int(row["planned_holding"]), int(row["planned"])


def _planned_holding(res: PlanResult) -> int:
    """Planned grasps of ``res`` predicted to hold (``gravity_margin >= 1``)."""
    gm = res.grasps.gravity_margin
    if gm is None:
        return 0
    planned = res.grasps.status.astype(str) == Status.PLANNED.value
    return int(np.count_nonzero(planned & (np.nan_to_num(gm, nan=0.0) >= 1.0)))


def _min_hold_force(res: PlanResult) -> float | None:
    """The least grip force (N) at which a collision-free grasp of ``res`` is predicted to hold
    (:func:`grasplan.results.quality_json.hold_force`), None when none would."""
    gm = res.grasps.gravity_margin
    if gm is None:
        return None
    free = ~np.isin(res.grasps.status.astype(str), REJECTED)
    hold = hold_force(gm[free], float(res.gripper.grip_force))
    hold = hold[np.isfinite(hold)]
    return round(float(hold.min()), HOLD_FORCE_DECIMALS) if len(hold) else None


def pose_file(output: Path, k: int) -> Path:
    """``OUT.pose<k>.json`` next to ``OUT.json``."""
    return output.with_name(f"{output.stem}.pose{k}{output.suffix}")


def write_pose_plans(runs: Sequence[PosePlan], output: str | os.PathLike, *, min_probability: float,
                     keep: str = DEFAULT_KEEP) -> PosePlans:
    """Write the plans of :func:`grasplan.motion.planning.plan_poses`: ``OUT.pose<k>.json`` per
    planned pose, then ``OUT.json`` (not when no pose could be planned at all: ``result`` None)."""
    output = Path(output)
    block: list[dict[str, Any]] = []
    best: tuple[int, int, PlanResult] | None = None
    best_key: tuple[int, int] = (-1, -1)
    for run in runs:
        k, pr, res = run.index, run.probability, run.result
        if res is None:
            block.append({"pose_index": k, "probability": pr, "planned": 0, "collision_free": 0,
                          "hold_force_N": None, "file": None, "error": run.error})
            continue
        f = pose_file(output, k)
        res.write(f, keep=keep)
        n = res.counts()
        cf = int(np.count_nonzero(~np.isin(res.grasps.status.astype(str), REJECTED)))
        row = {"pose_index": k, "probability": pr, "planned": int(n[Status.PLANNED.value]),
               "planned_holding": _planned_holding(res), "collision_free": cf, "hold_force_N": _min_hold_force(res),
               "file": f.name, "T_world_part": np.asarray(res.T_world_part).tolist()}
        block.append(row)
        if best is None or choice_key(row) > best_key:
            best, best_key = (k, n[Status.PLANNED.value], res), choice_key(row)
    if best is None:
        return PosePlans(chosen=None, result=None, planned=0, poses=tuple(block))
    best[2].write(output, keep=keep,
                  extra={"poses": {"chosen": best[0], "min_probability": min_probability, "poses": block}})
    return PosePlans(chosen=best[0], result=best[2], planned=int(best[1]), poses=tuple(block))
