"""Stable poses: how the part rests on a plane (the table top or the bin floor).

:func:`stable_poses` gives the part's quasi-static resting orientations with their probabilities
(the toppling model of Goldberg et al. 1999 on the convex hull, about the part's centre of mass);
:mod:`grasplan.cell.resting` puts the part in one of them on a cell's support. The centre of mass comes from
:func:`grasplan.part.mass.mass_properties` (of the solid when the mesh is watertight, else of its convex
hull); a flat part has no mass, so there its area-weighted surface centroid is used
(:func:`part_centre_of_mass`). Lengths in metres; rotations ``R_world_part`` (3, 3).
"""
from __future__ import annotations

import numpy as np

from ..errors import InputError
from .mass import mass_properties
from ..geometry.meshdata import MeshData, TriangleMesh

#: a part whose thickness along its thinnest principal axis is at most this fraction of its
#: bounding-box diagonal is flat (a plane, an n-gon, a flattened box): it lies on either side
FLAT_RELATIVE_THICKNESS = 1e-6


def _principal_axes(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """``(axes (3, 3) rows, thickness along each axis (3,), bounding-box diagonal)`` of ``(n, 3)``
    vertices; axes sorted from the widest to the thinnest spread."""
    V = np.asarray(vertices, dtype=np.float64)
    c = V - V.mean(axis=0)
    _, _, axes = np.linalg.svd(c, full_matrices=False)
    axes = np.vstack([axes, np.zeros((3 - len(axes), 3))]) if len(axes) < 3 else axes
    spread = np.ptp(c @ axes.T, axis=0)
    diag = float(np.linalg.norm(np.ptp(V, axis=0)))
    return axes, spread, diag


def _flatness(mesh: TriangleMesh) -> tuple[np.ndarray | None, float]:
    """``(unit plane normal (3,) or None, diagonal)``: the normal when the part is flat."""
    axes, spread, diag = _principal_axes(mesh.vertices)
    if diag <= 0 or spread[1] <= FLAT_RELATIVE_THICKNESS * diag:
        raise InputError("the part is a line or a point (all its vertices are collinear): it has no resting pose "
                         "on a table; check the mesh")
    if spread[2] > FLAT_RELATIVE_THICKNESS * diag:
        return None, diag
    n = axes[2] / np.linalg.norm(axes[2])
    n = n if n[np.argmax(np.abs(n))] > 0 else -n  # deterministic sign
    return n + 0.0, diag


def part_centre_of_mass(mesh: TriangleMesh) -> np.ndarray:
    """``(3,)`` the part's centre of mass, part frame (m), that its resting poses turn about:
    :func:`grasplan.part.mass.mass_properties` ``.com`` (of the solid when the mesh is watertight, else
    of its convex hull). A flat part (a hull without volume) has no mass: there, the area-weighted
    centroid of its surface. A part whose vertices are collinear is refused (InputError).
    Computed once per MeshData (cached with it)."""
    md = _meshdata(mesh)

    def compute() -> np.ndarray:
        try:
            return mass_properties(md).com
        except InputError:  # flat or degenerate: no volume to integrate
            _flatness(md)  # a line or a point is refused with its own message
            w = np.asarray(md.area_faces, dtype=np.float64)
            return (np.asarray(md.triangles_center) * w[:, None]).sum(axis=0) / w.sum()

    return md.derived("part_centre_of_mass", compute)


def _meshdata(mesh: TriangleMesh) -> MeshData:
    """``mesh`` as a :class:`MeshData` (a trimesh's arrays wrapped; a MeshData as it is, with its caches)."""
    return mesh if isinstance(mesh, MeshData) else MeshData(mesh.vertices, mesh.faces)


def _resting_rotation(down: np.ndarray) -> np.ndarray:
    """``R_world_part (k, 3, 3)`` turning the part-frame unit normals ``down (k, 3)`` to -z (the
    construction of ``trimesh.poses.compute_stable_poses``)."""
    z = -np.asarray(down, dtype=np.float64)
    x = np.stack([-z[:, 1], z[:, 0], np.zeros(len(z))], axis=1)
    nx = np.linalg.norm(x, axis=1)
    x = np.where(nx[:, None] > 0, x / np.where(nx > 0, nx, 1.0)[:, None], [1.0, 0.0, 0.0])
    y = np.cross(z, x)
    y /= np.linalg.norm(y, axis=1)[:, None]
    return np.stack([x, y, z], axis=1)


def _solid_angle(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Solid angle (sr) of triangles seen from the origin; ``a, b, c (k, 3)`` (Van Oosterom and
    Strackee 1983)."""
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    num = np.abs(np.einsum("ij,ij->i", a, np.cross(b, c)))
    den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb
           + np.einsum("ij,ij->i", b, c) * la)
    return 2.0 * np.arctan2(num, den)


#: the com projected within this fraction of the part's diagonal of a hull face's edge is on it
_ON_EDGE = 1e-9


def _topple(hull: MeshData, com: np.ndarray, diag: float) -> tuple[np.ndarray, np.ndarray]:
    """The quasi-static toppling model of Goldberg et al. (1999) on a convex hull, vectorised.

    Each hull face ``i`` gets the probability that the part dropped at a uniformly random
    orientation lands on it (solid angle of the face seen from ``com`` / 4 pi). A face is stable
    when ``com`` projects inside it; otherwise the part topples across the edge the projected
    ``com`` lies beyond, onto the neighbouring face. Following the toppling pointers (pointer
    jumping: ceil(log2 k) + 1 rounds, so bounded even if rounding made a cycle) gives each face's
    resting face. ``com`` (3,) and ``diag`` (the part's bounding-box diagonal) in metres.
    Returns ``(rest (k,) int, prob (k,))``.
    """
    T = np.asarray(hull.triangles, dtype=np.float64)          # (k, 3, 3)
    N = np.asarray(hull.face_normals, dtype=np.float64)       # (k, 3)
    F = np.asarray(hull.faces, dtype=np.int64)
    k = len(F)
    prob = _solid_angle(T[:, 0] - com, T[:, 1] - com, T[:, 2] - com) / (4.0 * np.pi)
    p = com - np.einsum("ij,ij->i", N, com - T[:, 0])[:, None] * N  # com projected on each face's plane
    # signed areas of (v_k, v_k+1, p) against the face normal: all >= 0 <=> p inside the face
    vk, vk1 = T, np.roll(T, -1, axis=1)
    edge_side = np.einsum("ikj,ij->ik", np.cross(vk1 - vk, p[:, None, :] - vk), N)
    edge_len = np.linalg.norm(vk1 - vk, axis=2)
    stable = (edge_side >= -_ON_EDGE * diag * edge_len).all(axis=1)  # on an edge (rounding) counts as inside
    # wedge of local edge j seen from the face centroid: p between the rays centroid->v_j and
    # centroid->v_j+1 (the faces are counter-clockwise about their outward normal)
    ctr = T.mean(axis=1)
    left = np.einsum("ikj,ij->ik", np.cross(vk - ctr[:, None], (p - ctr)[:, None, :]), N)
    right = np.einsum("ikj,ij->ik", np.cross(vk1 - ctr[:, None], (p - ctr)[:, None, :]), N)
    edge = np.argmax(np.minimum(left, -right), axis=1)        # the edge the com lies beyond
    # neighbour across each (face, local edge): the other face holding the same undirected edge
    a, b = F, np.roll(F, -1, axis=1)
    key = (np.minimum(a, b) * (F.max() + 1) + np.maximum(a, b)).ravel()
    order = np.argsort(key, kind="stable")
    neighbour = np.full(3 * k, -1, dtype=np.int64)
    pair = key[order[:-1]] == key[order[1:]]
    i0, i1 = order[:-1][pair], order[1:][pair]
    neighbour[i0], neighbour[i1] = i1 // 3, i0 // 3
    succ = np.where(stable, np.arange(k), neighbour.reshape(k, 3)[np.arange(k), edge])
    succ = np.where(succ < 0, np.arange(k), succ)            # an open hull edge: stays (never for qhull)
    for _ in range(int(np.ceil(np.log2(max(k, 2)))) + 1):
        succ = succ[succ]
    # a face not reaching a stable one is in a toppling cycle, which only rounding makes (the com
    # projected onto the edge between coplanar faces): it rests on the face it reached
    return succ, prob


def stable_poses(mesh: TriangleMesh) -> tuple[np.ndarray, np.ndarray]:
    """Quasi-static resting poses of ``mesh`` on a plane: the toppling model of Goldberg et al.
    (the model of ``trimesh.poses.compute_stable_poses`` with ``sigma = 0``: no random
    perturbation of the centre of mass), vectorised and bounded (:func:`_topple`): deterministic.

    A flat part (thinner than :data:`FLAT_RELATIVE_THICKNESS` of its size: a plane, an n-gon, a
    flattened box) lies on either side of its plane (its largest face), probability 1/2 each. A
    part whose vertices are collinear is refused (InputError).

    Returns ``(R (k, 3, 3), prob (k,))``, most probable first (ties: by the resting normal in the
    part frame, so the order is deterministic). ``R`` is ``R_world_part``: it turns the part so
    that it rests on its face; the translation is left to :func:`stable_pose`. Computed once per
    mesh when the mesh caches derived data (a part's grasp database stores them too:
    :func:`grasplan.grasps.graspdb.GraspDatabase.prime_resting_poses`).
    """
    derived = getattr(mesh, "derived", None)
    if derived is not None:
        R, prob = derived("stable_poses", lambda: _stable_poses(mesh))
        return R.copy(), prob.copy()
    return _stable_poses(mesh)


def _stable_poses(mesh: TriangleMesh) -> tuple[np.ndarray, np.ndarray]:
    with np.errstate(all="ignore"):
        normal, diag = _flatness(mesh)
        if normal is not None:
            downs, probs = np.stack([normal, -normal]), np.array([0.5, 0.5])
        else:
            downs, probs = _hull_poses(_meshdata(mesh), diag)
    R = _resting_rotation(downs)
    down = np.round(np.einsum("kji,j->ki", R, [0.0, 0.0, -1.0]), 6) + 0.0  # resting normal, part frame
    order = np.lexsort((down[:, 2], down[:, 1], down[:, 0], -np.round(probs, 9)))
    return R[order], probs[order] / probs.sum()


def _hull_poses(mesh: MeshData, diag: float) -> tuple[np.ndarray, np.ndarray]:
    """``(resting normals (k, 3), prob (k,))`` of a part with volume, from its convex hull."""
    try:
        hull = mesh.convex_hull
    except Exception:  # qhull refuses (near-)degenerate input; the flatness test should have caught it
        raise InputError("the part is too thin to compute its resting poses (its convex hull is degenerate); "
                         "give the pose with --part-pose x,y,z,roll,pitch,yaw") from None
    com = part_centre_of_mass(mesh)
    inside = np.einsum("ij,ij->i", com - hull.triangles_center, hull.face_normals)
    if len(hull.faces) < 4 or not np.all(inside < -FLAT_RELATIVE_THICKNESS * diag):
        raise InputError("the part's centre of mass is not inside its convex hull (the mesh is too thin or "
                         "degenerate) so it has no defined resting pose; give the pose with --part-pose "
                         "x,y,z,roll,pitch,yaw")
    rest, prob = _topple(hull, com, diag)
    ok = np.isfinite(prob) & (prob > 0)
    # faces of one hull facet (same normal to 3 decimals) are one pose; sum their probabilities
    N = np.asarray(hull.face_normals, dtype=np.float64)
    sinks = rest[ok]
    total = np.bincount(sinks, weights=prob[ok], minlength=len(N))
    faces = np.flatnonzero(total > 0)
    keys = np.round(N[faces], 3) + 0.0
    _, first, group = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    group = group.ravel()
    p = np.bincount(group, weights=total[faces])
    normals = N[faces[first]]
    keep = p > 0
    return normals[keep], p[keep]
