"""The lift's collision check with the part in the jaws (:func:`lift_collision`), the one of
``plan`` and ``pick`` (and of the descent at the place, a lift traced back): which contacts a lift
may make (resting on a support within ``lift_contact`` of travel, a neighbour within the depth
rule all along) and which pairs the checks before IK already decided (:func:`lift_precheck_drop`);
the lift's waypoints (:func:`lift_travel`, :data:`LIFT_SAMPLE`)."""
from __future__ import annotations

import weakref
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..geometry.grouping import expand
from ..geometry.interpolation import interpolate_path
from .collision_scene import PART, CollisionScene
from .pathboxes import scene_open

#: what the part in the jaws may rest on at the start of the lift (body name or prefix)
SUPPORT_BODIES = ("table", "obstacle:", "instance:")
#: the lift's TCP waypoints are this far apart (m), half the approach's
#: (:data:`~grasplan.motion.pickplace.LINE_SAMPLE`): fine enough that the UR5's joints move less than
#: ``interpolation.STEP`` between two of them, so the lift's checked configurations are its
#: waypoints, which the checks before IK cover (:func:`lift_collision`)
LIFT_SAMPLE = 0.002


def gripper_world_pairs(scene: CollisionScene) -> np.ndarray:
    """Per pair of ``scene`` (:meth:`~grasplan.motion.collision_scene.CollisionScene.pair_rows`): a gripper shape
    (body or jaw) against anything but the robot itself."""
    return np.array([(a.startswith("gripper:") or b.startswith("gripper:")) and kind != "self"
                     for a, b, kind, _, _ in scene.pair_rows()], dtype=bool)


def _support_only(pairs: list[tuple[str, str, str]]) -> bool:
    for a, b, _ in pairs:
        other = b if a == "part" else a if b == "part" else None
        if other is None or not other.startswith(SUPPORT_BODIES):
            return False
    return True


def _part_vs_instances(pairs: list[tuple[str, str, str]]) -> list[str] | None:
    """The neighbours (``instance:<id>``) of pairs that are all the carried part against an
    instance, else None."""
    out = []
    for a, b, _ in pairs:
        other = b if a == "part" else a if b == "part" else None
        if other is None or not other.startswith("instance:"):
            return None
        out.append(other)
    return out


_SUPPORT: "weakref.WeakKeyDictionary[Any, np.ndarray]" = weakref.WeakKeyDictionary()


def _support_pairs(scene: CollisionScene) -> np.ndarray:
    """Indices of the pairs of ``scene`` (an attached variant) between the carried part and what it
    may rest on (:data:`SUPPORT_BODIES`), once per scene model."""
    idx = _SUPPORT.get(scene._shared)
    if idx is None:
        idx = _SUPPORT[scene._shared] = np.array(
            [k for k, (a, b, _, _, _) in enumerate(scene.pair_rows())
             if (a == "part" and b.startswith(SUPPORT_BODIES)) or (b == "part" and a.startswith(SUPPORT_BODIES))],
            dtype=np.int64)
    return idx


def sample_ok(scene: CollisionScene, q: np.ndarray, width: float, support: bool,
               shallow: Callable[[np.ndarray, list[str]], bool] | None) -> bool:
    """Configuration ``q`` of the lift is free, or its contacts are allowed (module docstring):
    with ``support`` (it may rest) every pair the carried part against what it may rest on
    (:data:`SUPPORT_BODIES`), else every pair the part against neighbours within the depth rule
    ``shallow``. :func:`lift_collision` checks a resting configuration of a CollisionScene with
    those pairs switched off instead (the same answer, without coal finding the contacts)."""
    if scene.is_free(q, width):
        return True
    pairs = scene.colliding_pairs(q, width)
    if support and _support_only(pairs):
        return True
    names = None if shallow is None else _part_vs_instances(pairs)
    return bool(names and shallow is not None and shallow(q, names))


def lift_travel(dist: float) -> np.ndarray:
    """TCP travel (m) at each waypoint of a straight lift of ``dist`` (:func:`line_path` with
    :data:`LIFT_SAMPLE`: equal steps of at most that), from 0 to ``dist``: the one definition the
    lift's line, its gripper check before IK and the picker's part-alone checks share."""
    m = max(1, int(np.ceil(dist / LIFT_SAMPLE - 1e-12)))
    return dist * np.arange(m + 1) / m


def touch_waypoints(lift_contact: float, travel: np.ndarray) -> int:
    """``n_touch`` of :func:`lift_collision` for a lift whose waypoints lie at ``travel``
    (:func:`lift_travel`): the index of the first waypoint beyond ``lift_contact`` of travel (0
    when no contact is allowed). The waypoints before it, one lying at ``lift_contact`` itself
    included, may rest where ``resting(q)`` says so; from it on none may."""
    return int(np.searchsorted(travel, lift_contact + 1e-9, side="right")) if lift_contact > 0 else 0


def lift_collision(scene: CollisionScene, path: np.ndarray, width: float, n_touch: int,
                   shallow: Callable[[np.ndarray, list[str]], bool] | None = None,
                   covered: np.ndarray | None = None, drop: np.ndarray | Sequence[np.ndarray] | None = None,
                   resting: Callable[[np.ndarray], np.ndarray] | None = None
                   ) -> list[tuple[str, str, str]] | None:
    """The colliding pairs where the lift ``path`` (k, n) first hits something with the part
    attached (None: free), checked at ``interpolation.STEP``. Within the first ``n_touch``
    waypoints the part resting on a support (the table, the bin, an obstacle, a neighbour:
    :data:`SUPPORT_BODIES`) is allowed; all along, contacts of the part with
    neighbours only for which ``shallow(q, names)`` is true (their penetration depth within the
    tolerance, :mod:`grasplan.pick.depth`).

    ``covered`` (per waypoint a level, 0 none; a bool array: level 1), ``drop`` (pair indices of
    ``scene``, one array per level, or one array for level 1): at the waypoints of level ``l`` the
    pairs ``drop[l - 1]`` that the checks before IK already decided the same way
    (:func:`lift_precheck_drop`) are switched off; those waypoints are checked first, the highest
    level first, then the configurations between waypoints with every pair, up to the first
    waypoint that failed (the first failing configuration in path order is the one reported).

    ``resting(qs)``: (k,) bool, whether each configuration of ``qs`` (k, n) of the first
    ``n_touch`` waypoints is still within ``lift_contact`` of TCP travel (the waypoints are
    :data:`LIFT_SAMPLE` apart, so the last of them may lie beyond it); where it is not, resting
    contact is not allowed either. None: every configuration up to waypoint ``n_touch`` may rest."""
    n_touch = int(min(max(n_touch, 0), len(path) - 1))
    drops: list[np.ndarray] = [] if drop is None else [drop] if isinstance(drop, np.ndarray) else list(drop)
    # the whole lift densified once; each part's configurations are its rows (a segment is split
    # on its own: the same as densifying the part alone)
    dense_all, rows_all = interpolate_path(np.asarray(path, dtype=np.float64), return_index=True)
    support_ids = _support_pairs(scene) if isinstance(scene, CollisionScene) else None
    if support_ids is not None:
        support_ids = support_ids[scene._active[support_ids]]
    # the pairs whose oriented boxes overlap, per configuration, with every pair now active: one
    # pass for the whole lift (grasplan.motion.pathboxes: coal can find no other pair colliding);
    # each group below drops the pairs it switches off
    open_all = None
    if isinstance(scene, CollisionScene):
        scene.set_opening(width)
        open_all = scene_open(scene, dense_all)
    for k0, k1, support in ((n_touch, len(path), False), (0, n_touch + 1, True)):
        if support and n_touch == 0:
            continue
        dense = dense_all[rows_all[k0]:rows_all[k1 - 1] + 1]
        rows = rows_all[k0:k1] - rows_all[k0]
        level = np.zeros(len(dense), dtype=np.int64)
        if covered is not None and drops:
            level[rows] = np.minimum(np.asarray(covered[k0:k1], dtype=np.int64), len(drops))
        # a configuration that may rest (within lift_contact of travel) is free exactly when it is
        # with the part's support pairs off (:func:`sample_ok`): those are switched off for it too
        if not support:
            may_rest = np.zeros(len(dense), dtype=bool)
        elif resting is None:
            may_rest = np.ones(len(dense), dtype=bool)
        else:
            may_rest = np.asarray(resting(dense), dtype=bool).reshape(len(dense))
        rests = may_rest & (support_ids is not None)
        bad: int | None = None
        groups = np.unique(2 * level + rests)[::-1]  # (level, rest), the highest level first
        for lv, rest in zip((groups // 2).tolist(), (groups % 2 == 1).tolist()):
            idx = np.flatnonzero((level == lv) & (rests == rest))
            offs = ([drops[lv - 1]] if lv else []) + ([support_ids] if rest and support_ids is not None else [])
            off = np.union1d(*offs) if len(offs) == 2 else offs[0] if offs else None
            if off is not None:
                scene.switch_pairs(off, False)
            try:
                # free where coal finds none of the pairs whose oriented boxes overlap colliding
                # (grasplan.motion.pathboxes: the others cannot); only the rest needs the allowances
                found = None if open_all is None else _open_rows(open_all, rows_all[k0] + idx, off)
                if found is not None:  # only the configurations with pairs left to coal
                    starts, pair_ids = found
                    keep = np.flatnonzero(starts[1:] > starts[:-1])
                    spans = list(zip(starts[keep].tolist(), starts[keep + 1].tolist()))
                    idx = idx[keep]
                for j, i in enumerate(idx.tolist()):
                    if bad is not None and i > bad:
                        break
                    if found is not None and not scene.pairs_collide(dense[i], pair_ids[spans[j][0]:spans[j][1]]):
                        continue
                    if rest:  # with its support pairs off: colliding is a hit (no boxes: coal decides)
                        if found is None and scene.is_free(dense[i], width):
                            continue
                    elif sample_ok(scene, dense[i], width, bool(may_rest[i]), shallow):
                        continue
                    bad = i
                    break
            finally:
                if off is not None:
                    scene.switch_pairs(off, True)
        if bad is not None:
            return scene.colliding_pairs(dense[bad], width)
    return None


def _open_rows(open_all: tuple[np.ndarray, np.ndarray], rows: np.ndarray, off: np.ndarray | None
               ) -> tuple[np.ndarray, np.ndarray]:
    """``(starts, pair ids)`` of :func:`grasplan.motion.pathboxes.scene_open` for the configurations
    ``rows`` of the call that gave ``open_all``, without the pairs ``off`` (switched off there)."""
    starts_all, ids_all = open_all
    first = starts_all[rows]
    own, k = expand(starts_all[rows + 1] - first)
    ids = ids_all[first[own] + k]
    if off is not None and len(ids):
        keep = ~np.isin(ids, off)
        own, ids = own[keep], ids[keep]
    return np.concatenate([[0], np.cumsum(np.bincount(own, minlength=len(rows)))]), ids


def lift_precheck_drop(scene: CollisionScene, cell: bool = True) -> np.ndarray:
    """Per pair of ``scene``: decided at the lift's waypoints by the checks before IK, the closed
    gripper (body and jaws) against the world (``MotionContext.lift_gripper_check``: the same
    shapes at the same poses) and the carried part against all but the robot's links: the
    neighbours and the cloud, and with ``cell`` the table and the obstacles
    (``MotionContext.lift_part_checked``, the picker's straight lift)."""
    return gripper_world_pairs(scene) | np.array([group == "attached" and kind != PART and (cell or extra != "")
                                                  for _, _, kind, group, extra in scene.pair_rows()], dtype=bool)


_DROP: "weakref.WeakKeyDictionary[Any, tuple[np.ndarray, np.ndarray]]" = weakref.WeakKeyDictionary()


def _drop_pairs(att: CollisionScene) -> tuple[np.ndarray, np.ndarray]:
    """The active pairs of ``att`` that :func:`lift_precheck_drop` names: without the cell (the
    waypoints of level 1 of :func:`_lift_covered`) and with it (level 2); the masks once per scene model."""
    masks = _DROP.get(att._shared)
    if masks is None:
        masks = _DROP[att._shared] = (lift_precheck_drop(att, cell=False), lift_precheck_drop(att))
    return np.flatnonzero(att._active & masks[0]), np.flatnonzero(att._active & masks[1])
