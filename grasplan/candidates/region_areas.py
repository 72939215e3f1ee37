"""Regions method, steps 1-2: convex areas and the area pairs that can face each other.

An area is a set of edge-connected admitted faces whose normals differ by less than
``tol.planar_deg`` (coplanar facets; a face of a curved surface is an area of its own), numbered by
lowest face index so that ids do not depend on the part's pose. Neighbour-to-neighbour tolerance
chains: on a finely tessellated curved surface (IPARingScrew, TLess22) adjacent faces differ by less
than ``planar_deg`` although the chain turns by degrees, so a face whose normal is more than
``planar_deg`` from its area's normal marks a curved area: it is cut into patches of faces whose normals
lie within :data:`PATCH_DEG` of each other (a grid on the sphere of normals), so every face of an area is
within about :data:`PATCH_DEG` of the area normal (``Areas.spread``). Samples are held to beta on their
own faces' normals, and the area pairs are gated by beta plus both spreads. Its outline is its directed boundary
edges (:func:`area_edges`). :func:`area_pairs` streams the pairs of areas anti-parallel within beta
whose discs can overlap along the closing axis (the 6D line search of
:func:`grasplan.candidates.antipodal_base.stream_pairs`, over areas).
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .antipodal_base import FaceGeometry, stream_pairs
from ..geometry.meshdata import edge_adjacency
from ..geometry.grouping import group_max, max3, row_ids
from ..geometry.meshdata import connected_components
from ..geometry.tolerance import Tolerance

if TYPE_CHECKING:
    from ..geometry.meshdata import TriangleMesh


#: largest angle, degrees, between the normals of two faces of a patch cut from a curved surface
#: (a tolerance chain of faces each within ``tol.planar_deg`` of its neighbour): patches, not single
#: faces, keep the number of area pairs of a finely tessellated curved surface linear in its faces
PATCH_DEG = 1.0


def _strays(comp: np.ndarray, n: np.ndarray, cr: np.ndarray, k: int, cos_limit: float) -> np.ndarray:
    """(len(comp),) bool: faces (unit normals ``n``, area vectors ``cr``) more than ``arccos(cos_limit)``
    from the area-weighted normal of their component ``comp`` (< ``k``)."""
    vec = np.column_stack([np.bincount(comp, weights=cr[:, d], minlength=k) for d in range(3)])
    cnorm = vec / np.maximum(np.linalg.norm(vec, axis=1), 1e-300)[:, None]
    return np.einsum("ij,ij->i", n, cnorm[comp]) < cos_limit


def normal_cells(n: np.ndarray, step_deg: float) -> np.ndarray:
    """(k,) int64 cell of each unit normal on a cube map: the dominant axis and its sign, and the
    angles of the other two components, in steps of ``step_deg`` centred on the axes (so normals along
    a coordinate axis lie mid-cell). Normals of one cell are at most ``sqrt(2) step_deg`` apart."""
    k = np.argmax(np.abs(n), axis=1)
    r = np.arange(len(n))
    big = n[r, k]
    u = n[r, (k + 1) % 3] / np.abs(big)
    v = n[r, (k + 2) % 3] / np.abs(big)
    step = np.radians(step_deg)
    iu = np.floor(np.arctan(u) / step + 0.5).astype(np.int64)
    iv = np.floor(np.arctan(v) / step + 0.5).astype(np.int64)
    span = int(np.ceil(np.pi / 2 / step)) + 2
    return ((2 * k + (big > 0)) * span + iu + span // 2) * span + iv + span // 2


@dataclass(frozen=True)
class Areas:
    """Convex areas of a mesh.

    label : (m,) int64, area id per face (-1: not convex / degenerate)
    normal : (k, 3) float64, unit area normals
    centroid : (k, 3) float64, area centroids, m
    area : (k,) float64, m^2
    spread : (k,) float64, largest angle between a face normal of the area and the area normal, rad
        (at most ``tol.planar_deg`` on planar areas, :data:`PATCH_DEG` on patches of curved surfaces;
        0 for a single face)
    """

    label: np.ndarray
    normal: np.ndarray
    centroid: np.ndarray
    area: np.ndarray
    spread: np.ndarray


def convex_areas(mesh: TriangleMesh, convex: np.ndarray, tol: Tolerance, adjacency: tuple | None = None,
                 geo: FaceGeometry | None = None) -> Areas:
    """Group convex faces into coplanar, edge-connected areas (no loop over faces). ``adjacency``: the
    mesh's :func:`grasplan.geometry.meshdata.edge_adjacency`, if already known; ``geo``: its
    :class:`grasplan.candidates.antipodal_base.FaceGeometry`, if already known (its triangles are reused)."""
    F = np.asarray(mesh.faces, dtype=np.int64)
    m = len(F)
    tri = geo.tri if geo is not None else np.asarray(mesh.vertices, dtype=np.float64)[F]
    cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    dbl = np.linalg.norm(cr, axis=1)
    use = np.asarray(convex, dtype=bool) & (dbl > 0)
    n = np.zeros_like(cr)
    n[dbl > 0] = cr[dbl > 0] / dbl[dbl > 0, None]
    adj = (edge_adjacency(F) if adjacency is None else adjacency)[0]
    ok = use[adj[:, 0]] & use[adj[:, 1]]
    adj = adj[ok]
    cos_planar = np.cos(np.radians(tol.planar_deg))
    cosang = np.einsum("ij,ij->i", n[adj[:, 0]], n[adj[:, 1]])
    adj = adj[cosang >= cos_planar]
    label = np.full(m, -1, dtype=np.int64)
    ids = np.flatnonzero(use)
    if len(ids) == 0:
        z = np.zeros(0)
        return Areas(label, np.zeros((0, 3)), np.zeros((0, 3)), z, z)
    # components; a component whose faces stray more than planar_deg from its normal is a tolerance
    # chain along a curved surface: cut it into patches by a grid on the normals (cube map, cells of
    # PATCH_DEG across), and detach whatever still strays by more than PATCH_DEG (each round only
    # removes faces, so it ends). Only the curved components' faces are regrouped.
    _, comp = connected_components(m, adj)
    stray = _strays(comp[ids], n[ids], cr[ids], m, cos_planar)
    if stray.any():
        curved = np.zeros(m, dtype=bool)
        curved[comp[ids[stray]]] = True
        face_in = curved[comp] & use
        sub = np.flatnonzero(face_in)
        local = np.full(m, -1, dtype=np.int64)
        local[sub] = np.arange(len(sub))
        e = local[adj[face_in[adj[:, 0]] & face_in[adj[:, 1]]]]
        cell = normal_cells(n[sub], PATCH_DEG / np.sqrt(2.0))
        e = e[cell[e[:, 0]] == cell[e[:, 1]]]
        attached = np.ones(len(sub), dtype=bool)
        cos_patch = np.cos(np.radians(PATCH_DEG))
        while True:
            _, lc = connected_components(len(sub), e)
            out = attached & _strays(lc, n[sub], cr[sub], len(sub), cos_patch)
            if not out.any():
                break
            attached[out] = False
            e = e[attached[e[:, 0]] & attached[e[:, 1]]]
        comp[sub] = m + lc                       # labels apart from the untouched components'
    # renumber by lowest face index (faces are visited in index order): pose-independent ids
    _, first, inv = np.unique(comp[ids], return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    label[ids] = rank[inv.ravel()]
    k = len(first)
    lab = label[ids]
    vec = np.column_stack([np.bincount(lab, weights=cr[ids, d], minlength=k) for d in range(3)])
    normal = vec / np.linalg.norm(vec, axis=1, keepdims=True)
    area = 0.5 * np.bincount(lab, weights=dbl[ids], minlength=k)
    spread = np.zeros(k)
    np.maximum.at(spread, lab, np.arccos(np.clip(np.einsum("ij,ij->i", n[ids], normal[lab]), -1.0, 1.0)))
    c = geo.c[ids] if geo is not None else tri[ids].mean(axis=1)
    centroid = np.column_stack([np.bincount(lab, weights=0.5 * dbl[ids] * c[:, d], minlength=k)
                                for d in range(3)]) / area[:, None]
    return Areas(label, normal, centroid, area, spread)


def area_boundary_edges(F: np.ndarray, label: np.ndarray) -> np.ndarray:
    """(m, 3) bool: edge k (corner k -> k+1) of face i is on the boundary of its area (no other face
    of the same area shares it)."""
    e = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)
    e.sort(axis=1)
    lab = np.repeat(label, 3)
    inv = row_ids(e[:, 0], e[:, 1], lab)
    cnt = np.bincount(inv)
    return (cnt[inv] < 2).reshape(-1, 3) | (lab < 0).reshape(-1, 3)


def area_edges(F: np.ndarray, label: np.ndarray, n_areas: int, adjacency: tuple | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Directed boundary edges of every area (winding of their faces), grouped by area:
    ``(from, to, start, count)``, vertex ids and per-area offsets. With the mesh's
    ``edge_adjacency(F, slots=True)`` an edge is inner when its two faces share an area (edges of
    three or more faces count as boundary), without another sort."""
    if adjacency is None:
        flags = area_boundary_edges(F, label) & (label[:, None] >= 0)
    else:
        adj, slot = adjacency[0], adjacency[3]
        inner = (label[adj[:, 0]] == label[adj[:, 1]]) & (label[adj[:, 0]] >= 0)
        flags = np.repeat(label >= 0, 3)
        flags[slot[inner].ravel()] = False
        flags = flags.reshape(-1, 3)
    f, k = np.nonzero(flags)
    u, v, lab = F[f, k], F[f, (k + 1) % 3], label[f]
    o = np.lexsort((v, u, lab))
    u, v, lab = u[o], v[o], lab[o]
    count = np.bincount(lab, minlength=n_areas)
    return u, v, np.cumsum(count) - count, count


def area_pairs(areas: Areas, geo: FaceGeometry, ids: np.ndarray, *, max_opening: float, beta_deg: float,
               tol: Tolerance, progress: dict | None = None) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Chunks ``(P, Q, a)`` of area pairs that can form a region: normals anti-parallel within
    ``beta + spread_P + spread_Q`` (so every pair of their faces anti-parallel within beta is among
    them; the samples are held to beta on their own faces' normals, :func:`grasplan.candidates.regions.finish_samples`)
    and the two areas' discs (centroid, radius = farthest face corner) able to overlap along the
    closing axis ``a = (n_P - n_Q) / |n_P - n_Q|`` within ``max_opening``. ``ids``: the faces that
    belong to an area. Streams the 6D line search (:func:`grasplan.candidates.antipodal_base.stream_pairs`;
    ``progress`` as there)."""
    nA = len(areas.area)
    lab = areas.label
    beta = np.radians(beta_deg)
    wide_deg = beta_deg + 2.0 * np.degrees(float(areas.spread.max(initial=0.0)))
    eps = tol.distance
    # area radius: largest distance of its faces' corners from the area centroid
    arad = group_max(lab[ids], max3(np.linalg.norm(geo.tri[ids] - areas.centroid[lab[ids]][:, None], axis=2)), nA)
    for P, Q in stream_pairs(areas.centroid, areas.normal, arad, reach=max_opening, beta_deg=wide_deg, tol=tol,
                             progress=progress):
        limit = np.minimum(beta + areas.spread[P] + areas.spread[Q], np.pi)
        ok = np.einsum("ij,ij->i", areas.normal[P], areas.normal[Q]) <= -np.cos(limit) + 1e-12
        P, Q, limit = P[ok], Q[ok], limit[ok]
        sin_half = np.sin(limit / 2.0)
        a = areas.normal[P] - areas.normal[Q]
        a /= np.linalg.norm(a, axis=1, keepdims=True)
        d = areas.centroid[Q] - areas.centroid[P]
        ax = -np.einsum("ij,ij->i", d, a)                   # closing distance of the centroids
        rr = arad[P] + arad[Q]
        lateral = np.linalg.norm(d + ax[:, None] * a, axis=1)
        ok = (lateral <= rr + 4 * eps) & (ax >= -rr * sin_half - 4 * eps) & (ax <= max_opening + rr * sin_half + 4 * eps)
        yield P[ok], Q[ok], a[ok]
