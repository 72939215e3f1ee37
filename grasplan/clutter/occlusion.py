"""How much of each part in a pile an overhead camera cannot see: :func:`occlusion`.

The **camera** is a point (a pinhole; no image plane, no field of view, no resolution): by default
:func:`camera_point`, :data:`CAMERA_HEIGHT` above the centre of the bin floor's top (above the table at
``part_xy`` in a cell without a bin). A part's **occlusion** is the share of its silhouette,
as seen from that point, behind something else: another part or a static geom of the cell (table,
bin floor and walls, obstacles). What a part hides of itself does not count: its own upper side
covering its underside is seen, as the part.

It is measured by casting rays in the compiled MuJoCo world (:class:`grasplan.sim.pileworld.PileWorld`)
from the camera to points on each part's surface, so it sees exactly the geometry the physics
collides: the parts' convex pieces and the cell's static geoms.
"""
from __future__ import annotations

import weakref

import numpy as np
from numpy.typing import ArrayLike

from ..cell.model import Cell
from ..errors import InputError
from ..sim.pileworld import PileWorld

#: height (m) of the default camera above the centre of the surface the parts rest on
CAMERA_HEIGHT = 0.7
#: rays cast to each part (surface points sampled per part)
RAYS = 256
#: a ray whose first hit lies farther than its target point plus this (m) passed the target point
#: with nothing in front of it (it slipped past the part's surface through a sliver): visible
HIT_TOL = 1e-3
#: at most this many non-occluding bodies (a parked part, the gripper) a ray is continued through
MAX_PASS_THROUGH = 16


def camera_point(cell: Cell) -> np.ndarray:
    """The default camera position (3,), m, world: :data:`CAMERA_HEIGHT` straight above the centre
    of the bin floor's top (the translation of ``cell.bin.T_world_bin``); in a cell without a bin,
    above ``(part_xy, table_z)``."""
    if cell.bin is not None:
        c = np.asarray(cell.bin.T_world_bin, dtype=np.float64)[:3, 3]
        return np.array([c[0], c[1], c[2] + CAMERA_HEIGHT])
    return np.array([float(cell.part_xy[0]), float(cell.part_xy[1]), float(cell.table_z) + CAMERA_HEIGHT])


#: per world, per body: its pieces' geom ids, each triangle's piece, the triangles (f, 3, 3) in
#: their pieces' mesh frames and the cumulated triangle areas (the compiled meshes never change)
_SURFACES: weakref.WeakKeyDictionary[PileWorld, dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]] = \
    weakref.WeakKeyDictionary()


def _surface(world: PileWorld, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Body ``i``'s surface as :data:`_SURFACES` keeps it, computed on first use."""
    import mujoco

    per_body = _SURFACES.setdefault(world, {})
    if i in per_body:
        return per_body[i]
    m = world.model
    geoms = np.flatnonzero(m.geom_bodyid == world.body_ids[i])
    if np.any(m.geom_type[geoms] != mujoco.mjtGeom.mjGEOM_MESH):  # a part collides through mesh pieces only
        raise InputError(f"occlusion: body {world.bodies[i].name!r} has a geom that is not a mesh")
    mesh = m.geom_dataid[geoms]
    nf = m.mesh_facenum[mesh]
    piece = np.repeat(np.arange(len(geoms)), nf)                         # each triangle's piece
    rows = np.arange(nf.sum()) + np.repeat(m.mesh_faceadr[mesh] - (np.cumsum(nf) - nf), nf)
    t = m.mesh_vert[m.mesh_face[rows] + m.mesh_vertadr[mesh][piece, None]].astype(np.float64)  # (f, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)  # a pose keeps areas
    cdf = np.cumsum(area)
    if not (len(cdf) and cdf[-1] > 0):
        raise InputError(f"occlusion: body {world.bodies[i].name!r} has no surface area")
    per_body[i] = (geoms, piece, t, cdf)
    return per_body[i]


def surface_points(world: PileWorld, i: int, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points (n, 3), m, world, uniformly distributed by area over the surfaces of body
    ``i``'s convex pieces: the triangles of each piece's hull as MuJoCo compiled it (``mesh_vert``,
    ``mesh_face``) at the piece's current pose (``geom_xpos``, ``geom_xmat``), the very surfaces
    :func:`mujoco.mj_ray` intersects. Faces two pieces share inside the part are sampled too."""
    geoms, piece, t, cdf = _surface(world, i)
    k = np.minimum(np.searchsorted(cdf, rng.random(n) * cdf[-1], side="right"), len(t) - 1)
    u, w = rng.random((2, n))
    s = np.sqrt(u)                                                        # uniform over each triangle
    local = (1.0 - s)[:, None] * t[k, 0] + (s * (1.0 - w))[:, None] * t[k, 1] + (s * w)[:, None] * t[k, 2]
    g = geoms[piece[k]]
    d = world.data
    return np.einsum("nij,nj->ni", d.geom_xmat[g].reshape(-1, 3, 3), local) + d.geom_xpos[g]


def occlusion(world: PileWorld, camera: ArrayLike, *, rays: int = RAYS, seed: int = 0) -> np.ndarray:
    """The occlusion of every body of ``world`` seen from ``camera``: (n,) float64 in [0, 1] in
    :attr:`PileWorld.bodies` order, NaN for a parked body.

    **Meaning.** The fraction of the body's silhouette, seen from the point ``camera`` (3,), m, world
    (e.g. :func:`camera_point`), that something else covers: another present part or a static geom
    (table, bin, obstacles). 0: fully in view; 1: nothing of it is seen. Self-occlusion is not
    occlusion.

    **Method.** Per present body, ``rays`` points sampled on its surface (:func:`surface_points`,
    from ``numpy.random.default_rng((seed, i))`` for body ``i``: the same seed gives the same
    array, and a body's points depend on no other body); one ray from the camera through each
    (:func:`mujoco.mj_multiRay`, static geoms included, no body excluded, no geom-group filter), in
    the world's current kinematics (geom poses of its last ``mj_forward`` or ``mj_step``). A ray's
    first hit decides:

    - the body itself: seen (also when it meets the body's front before an underside target);
    - another present part or a static geom, no farther than the target point + :data:`HIT_TOL`:
      hidden (the target is behind it or touching it);
    - nothing, or anything farther than the target + :data:`HIT_TOL`: seen. The ray passed the
      target point with nothing in front of it; it slipped past the body's own surface through a
      sliver (a target on an edge, grazing incidence), and counts as seen;
    - a body that is neither a present part nor static (a parked part, a gripper: neither is in the
      camera's scene) is passed through, the ray continued beyond it.

    Geoms drawn invisible (alpha 0, e.g. static obstacles taken out of the world) are not in the
    scene: MuJoCo's ray casting skips them.

    Occlusion = hidden rays / ``rays``; its standard error is at most 0.5 / sqrt(``rays``) (0.03 at
    the default 256).

    **Sampling bias.** Target points are uniform over surface *area*, not over the silhouette's image
    pixels: a stretch of silhouette counts in proportion to the surface area behind it along the
    line of sight, every layer of it (the front, the back seen through it, faces between the
    convex pieces inside the part), so a face seen edge-on weighs as much as one seen square-on.
    For a flat part seen from far above, the fraction is close to the covered share of its
    footprint (upper and lower faces count alike), its side faces counted by how much of the rim is
    covered."""
    import mujoco

    cam = np.asarray(camera, dtype=np.float64)
    if cam.shape != (3,) or not np.all(np.isfinite(cam)):
        raise InputError(f"occlusion: camera must be a finite point (3,), got shape {cam.shape}")
    if int(rays) != rays or rays < 1:
        raise InputError(f"occlusion: rays must be an integer >= 1, got {rays!r}")
    rays = int(rays)
    m, d = world.model, world.data
    n = len(world.bodies)
    out = np.full(n, np.nan)
    present = np.flatnonzero(world.present)
    if len(present) == 0:
        return out
    body_ids = world.body_ids
    # per MuJoCo body: 1 occludes (a present part, or static: welded to the world), 0 passed through
    occludes = (m.body_weldid == 0).astype(bool)
    occludes[body_ids[present]] = True
    occludes[body_ids[~world.present]] = False

    targets = np.concatenate([surface_points(world, int(i), rays, np.random.default_rng((seed, int(i))))
                              for i in present])
    vec = targets - cam
    reach = np.linalg.norm(vec, axis=1)                                   # camera to target (m)
    if reach.min() < 1e-9:
        raise InputError("occlusion: the camera lies on a part's surface")
    dirs = np.ascontiguousarray(vec / reach[:, None])
    nray = len(dirs)
    geom = np.empty(nray, dtype=np.int32)
    dist = np.empty(nray, dtype=np.float64)
    cutoff = float(reach.max() + 2.0 * HIT_TOL)  # anything farther decides nothing
    mujoco.mj_multiRay(m, d, cam, dirs.ravel(), None, True, -1, geom, dist, None, nray, cutoff)
    hit_body = np.where(geom >= 0, m.geom_bodyid[np.maximum(geom, 0)], -1)

    # a ray whose first hit is passed through goes on past it
    one = np.empty(1, dtype=np.int32)
    for j in np.flatnonzero((hit_body >= 0) & ~occludes[np.maximum(hit_body, 0)]):
        t, b = float(dist[j]), int(hit_body[j])
        for _ in range(MAX_PASS_THROUGH):
            more = mujoco.mj_ray(m, d, cam + t * dirs[j], dirs[j], None, True, b, one)
            if more < 0:
                t, b = -1.0, -1
                break
            t, b = t + more, int(m.geom_bodyid[one[0]])
            if occludes[b]:
                break
        dist[j], hit_body[j] = t, b

    own = np.repeat(body_ids[present], rays)
    far = (hit_body < 0) | (dist > reach + HIT_TOL)
    hidden = ~far & (hit_body != own) & occludes[np.maximum(hit_body, 0)]
    out[present] = hidden.reshape(len(present), rays).mean(axis=1)
    return out
