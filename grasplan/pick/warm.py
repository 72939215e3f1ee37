"""What a :class:`grasplan.Picker` keeps between ``plan()`` calls, every cache bounded by entries and
by (estimated) bytes: the bounds are the constants of this module, the one place they are set
(docs/pick.md, "Memory of a long-running picker"). Kept: per cell (:class:`CellState`, at most
:data:`MAX_CELLS`, the least recently used dropped) the gripper checks' world
(:class:`grasplan.pick.world.PickWorld`: a BVH, hull and gripper collider per part), the robot's
collision scenes (:func:`build_scenes`) and their arranged variants (:func:`arranged`); the parts
a scene file names with a mesh (at most :data:`MAX_SCENE_PARTS` beyond the current scene's, the
least recently used dropped; parts given to ``Picker.add_part`` stay); the last cloud read
(:data:`MAX_CLOUDS`, :func:`scene_cloud`).

Not kept here, bounded where they live: a part's depth probes and voxel grid (one per part),
Pinocchio's data and the pathboxes' arguments of a variant (with the variant;
:data:`grasplan.motion.pathboxes.MAX_PREPARED` per variant), the gripper shapes per jaw opening
(:class:`~grasplan.pick.world.PickWorld`, the last few).
"""
from __future__ import annotations

from collections import OrderedDict
from collections.abc import Hashable, Mapping
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

import numpy as np

from ..cell.model import Cell
from ..gripper.model import Gripper
from ..robot.model import Robot
from ..motion.collision_scene import CollisionScene, ExtraBody
from ..piles.scene_file import Instance, Scene
from .budget import UNLIMITED, Budget
from .world import CLOUD, INSTANCE_PREFIX, PickWorld

#: arranged scene variants kept between plan() calls per cell: at most this many ...
MAX_SCENE_VARIANTS = 16
#: ... and at most this many bytes (estimated, :func:`variant_bytes`)
MAX_SCENE_VARIANT_BYTES = 16 << 20
#: the estimate of one kept arrangement (its static and attached variants): bytes per collision
#: pair of the scene model and per arrangement (the UR5's: 4.9-5.2 kB per pair for 900 to 1,700
#: pairs, ``pin.GeometryData`` holding a request, a result and a functor per pair)
VARIANT_PAIR_BYTES = 5_500
VARIANT_BASE_BYTES = 100_000
#: instance bodies (id, part) of earlier scenes the robot scenes keep besides the current scene's
MAX_KEPT_EXTRAS = 16
#: cells whose warm state is kept (each: a pick world and robot scenes)
MAX_CELLS = 4
#: parts named with a mesh by scene files kept beyond those of the current scene
MAX_SCENE_PARTS = 16
#: point clouds kept (read and turned into an octree; the same file, unchanged, is not read again)
MAX_CLOUDS = 1

K = TypeVar("K", bound=Hashable)
V = TypeVar("V")


class LRU(Generic[K, V]):
    """A mapping of at most ``max_entries`` entries and ``max_bytes`` bytes (each entry's size as
    given to :meth:`put`), the least recently used (put or got) dropped first; an entry larger
    than ``max_bytes`` is not kept."""

    def __init__(self, max_entries: int, max_bytes: float = float("inf")):
        self.max_entries, self.max_bytes = int(max_entries), float(max_bytes)
        self._d: OrderedDict[K, tuple[V, int]] = OrderedDict()
        self.bytes = 0

    def get(self, key: K) -> V | None:
        hit = self._d.get(key)
        if hit is None:
            return None
        self._d.move_to_end(key)
        return hit[0]

    def put(self, key: K, value: V, size: int = 0) -> None:
        self.pop(key)
        if size > self.max_bytes or self.max_entries <= 0:
            return
        while self._d and (len(self._d) >= self.max_entries or self.bytes + size > self.max_bytes):
            _, (_, s) = self._d.popitem(last=False)
            self.bytes -= s
        self._d[key] = (value, int(size))
        self.bytes += int(size)

    def pop(self, key: K) -> V | None:
        hit = self._d.pop(key, None)
        if hit is None:
            return None
        self.bytes -= hit[1]
        return hit[0]

    def clear(self) -> None:
        self._d.clear()
        self.bytes = 0

    def values(self) -> list[V]:
        return [v for v, _ in self._d.values()]

    def keys(self) -> list[K]:
        return list(self._d)

    def __getitem__(self, key: K) -> V:
        hit = self.get(key)
        if hit is None:
            raise KeyError(key)
        return hit

    def __contains__(self, key: object) -> bool:
        return key in self._d

    def __len__(self) -> int:
        return len(self._d)


def variant_bytes(scene: CollisionScene) -> int:
    """Estimated bytes of one kept arrangement of ``scene``'s model (static and attached variant)."""
    return VARIANT_BASE_BYTES + VARIANT_PAIR_BYTES * len(scene.geom_model.collisionPairs)


@dataclass
class CellState:
    """Warm state per cell: the gripper world and the robot scenes (per part) with their extras."""

    cell: Cell
    world: PickWorld
    scenes: dict[str, CollisionScene] = field(default_factory=dict)
    extras: frozenset = frozenset()  # (instance id, part) pairs the scenes hold
    cloud_key: Any = None
    variants: LRU[Any, tuple[CollisionScene, CollisionScene]] = field(
        default_factory=lambda: LRU(MAX_SCENE_VARIANTS, MAX_SCENE_VARIANT_BYTES))

    def forget(self) -> None:
        """Drop the robot scenes and their variants (rebuilt when next needed)."""
        self.scenes = {}
        self.extras = frozenset()
        self.variants.clear()


def build_scenes(st: CellState, robot: Robot, gripper: Gripper, meshes: Mapping[str, Any], scene: Scene,
                 cloud: tuple | None, budget: Budget = UNLIMITED) -> None:
    """Make ``st``'s robot scenes (one per part, every instance an extra body named by its id) hold
    every instance of ``scene`` (and the cloud): nothing when they do (an id seen again soon
    rebuilds nothing); else rebuilt, once per part, with the scene's instances and, when few
    enough, the earlier ones they held (:data:`MAX_KEPT_EXTRAS`): a scene's size, not the number of
    ids ever seen, bounds them. ``meshes``: each part's mesh. The new scenes replace the old ones
    only once all are built (``budget`` is checked before each)."""
    need = frozenset((i.id, i.part) for i in scene.instances)
    cloud_key = None if cloud is None else id(cloud[0])
    if need <= st.extras and cloud_key == st.cloud_key and all(p in st.scenes for p in scene.part_names()):
        return
    ids = {i for i, _ in need}
    kept = frozenset(x for x in st.extras if x[0] not in ids and x[1] in st.world.parts)
    extras_set = need | kept if len(kept) <= MAX_KEPT_EXTRAS else need
    bodies = [ExtraBody(INSTANCE_PREFIX + i, st.world.parts[p].bvh, "instance") for i, p in sorted(extras_set)]
    if cloud is not None:
        bodies.append(ExtraBody(CLOUD, cloud[0], "cloud"))
    scenes = {}
    for p in sorted({p for _, p in extras_set}):
        budget.check()
        scenes[p] = CollisionScene(robot, gripper, meshes[p], np.eye(4), st.cell, extras=bodies)
    st.scenes = scenes
    st.extras, st.cloud_key = extras_set, cloud_key
    st.variants.clear()


def extras_of(inst: Instance, present: list[Instance], with_cloud: bool) -> dict[str, np.ndarray]:
    """The extra bodies of ``inst``'s robot scene: every other instance of ``present`` at its pose
    (and the cloud when ``with_cloud``)."""
    extras: dict[str, np.ndarray] = {INSTANCE_PREFIX + i.id: i.T_world_part for i in present if i.id != inst.id}
    if with_cloud:
        extras[CLOUD] = np.eye(4)
    return extras


def arranged(st: CellState, inst: Instance, present: list[Instance], with_cloud: bool
             ) -> tuple[CollisionScene, CollisionScene]:
    """The static and attached variants of the robot scene of ``inst``'s part with the part at its
    pose and the other instances of ``present`` (and the cloud when ``with_cloud``) placed; kept
    in ``st.variants`` for a scene seen again with the same poses: at most
    :data:`MAX_SCENE_VARIANTS` and :data:`MAX_SCENE_VARIANT_BYTES` (each estimated from the scene
    model's collision pairs, :func:`variant_bytes`: Pinocchio's per-pair data dominates), the least
    recently used dropped first; a variant larger than the byte bound is used and not kept."""
    key = (inst.id, inst.part, inst.T_world_part.tobytes(),
           tuple((i.id, i.T_world_part.tobytes()) for i in present if i.id != inst.id), with_cloud)
    v = st.variants.get(key)
    if v is None:
        base = st.scenes[inst.part]
        static = base.arranged(inst.T_world_part, extras_of(inst, present, with_cloud))
        v = (static, static.attached(np.eye(4)))
        st.variants.put(key, v, variant_bytes(base))
    return v


def scene_cloud(cache: LRU[tuple, tuple[Any, np.ndarray, float]], scene: Scene) -> tuple[Any, np.ndarray, float] | None:
    """``(octree, points, resolution)`` of ``scene``'s cloud (None: it has none), from ``cache``
    when the same file, unchanged, was read at the same resolution."""
    if scene.cloud is None:
        return None
    from ..piles.cloud import cloud_octree, read_cloud

    path = scene.resolve(scene.cloud.path)
    try:
        stt = path.stat()
        key: tuple | None = (str(path), stt.st_mtime_ns, stt.st_size, scene.cloud.resolution)
    except OSError:
        key = None
    hit = None if key is None else cache.get(key)
    if hit is not None:
        return hit
    pts = read_cloud(path).points
    out = (cloud_octree(pts, scene.cloud.resolution), pts, float(scene.cloud.resolution))
    if key is not None:
        cache.put(key, out)
    return out
