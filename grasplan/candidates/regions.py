"""Antipodal contact *regions* (``method="regions"``), sampled at a fixed spacing.

A candidate of the paper (:mod:`grasplan.candidates.antipodal`) is one contact pair per pair of
faces, so the count grows with the square of the tessellation. Here a candidate is a sample of a
*region*: the overlap of two opposing convex areas projected along their closing axis, sampled on
a lattice of pitch ``spacing`` (:func:`find_regions`). Cost and memory follow the areas' outline
lengths and the samples, never faces^2, samples x faces or the triangle count of an area's interior.

The steps live in their own modules: areas and area pairs in :mod:`grasplan.candidates.region_areas`,
the crease admission in :mod:`grasplan.candidates.region_creases`, outlines, overlaps, scanlines and
point location in :mod:`grasplan.candidates.region_overlap`; this module runs them and bounds the work.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .antipodal_base import Candidates, FaceGeometry, perpendicular_frame
from .convexity import mesh_edge_adjacency
from ..errors import InputError
from ..geometry.grouping import expand, unique_values, weight_batches
from .region_areas import Areas, area_edges, area_pairs, convex_areas
from .region_creases import admitted_faces, near_creases
from .region_overlap import green_moments, inside_parts, locate, region_edges, row_intervals
from .thinning import closest_to_mean, cluster_ids, thin_candidates
from ..geometry.tolerance import Tolerance

if TYPE_CHECKING:
    from ..geometry.meshdata import TriangleMesh

#: ``contacts (n, 2, 3)``, ``normals (n, 2, 3)``, ``width (n,)``, ``faces (n, 2)``, ``region (n,)``
Samples = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]

#: closing-axis quantisation of the curved-surface deduplication, degrees: regions smaller than one
#: lattice cell (single faces of curved surfaces) give one sample each, deduplicated on the spacing
#: grid (grasp-centre cell x closing-axis direction, :func:`grasplan.candidates.thinning.thin_candidates`)
CURVED_AXIS_STEP_DEG = 10.0
#: Q's projection is shifted by this fraction of the part scale along a fixed generic direction of the
#: region's temporary frame, so coinciding outlines (every prism) become generic; moves results by
#: about this fraction of the part size (far below the 1e-9 m the tests ask for)
_SHIFT = 1e-10
_SHIFT_DIR = (np.cos(1.0), np.sin(1.0))
#: boundary-edge rows per region batch (bounds every temporary array)
_EDGE_CHUNK = 400_000
#: the streamed area pairs may not exceed this many (else InputError naming what would run): a
#: triangle soup's pairs grow with the square of its triangles; a finely tessellated sphere has ~3.6 M
MAX_AREA_PAIRS = 5_000_000
#: sub-cell pairs (both areas smaller than a lattice cell: patches of curved surfaces) whose outlines
#: hold more boundary rows than this are thinned before their overlaps are computed: at most
#: :data:`CURVED_PAIRS_PER_CELL` per cell of the curved-surface deduplication (grasp centre predicted
#: as the midpoint of the two areas' centroids), those nearest the cell's mean. The paper parts stay
#: far below (SileaneGear 54 k rows, TLess22 61 k); a 20 mm sphere of 200 k triangles has 9.7 M
CURVED_ROWS_BUDGET = 2_000_000
#: sub-cell pairs kept per deduplication cell when :data:`CURVED_ROWS_BUDGET` is exceeded
CURVED_PAIRS_PER_CELL = 8
#: lattice samples (estimated from the overlaps' areas before sampling) allowed per part; above it an
#: InputError names the ``--spacing`` that fits
MAX_SAMPLES = 500_000


def _bounded_pairs(RP: np.ndarray, RQ: np.ndarray, areas: Areas, ecount: np.ndarray, spacing: float,
                   notes: list[str] | None) -> tuple[np.ndarray, np.ndarray]:
    """The area pairs whose overlaps are computed: all of them, unless the sub-cell pairs' outlines
    exceed :data:`CURVED_ROWS_BUDGET` rows; then at most :data:`CURVED_PAIRS_PER_CELL` sub-cell pairs per
    deduplication cell (:func:`grasplan.candidates.thinning.cluster_ids` of the centroids' midpoint and the
    closing axis), nearest the cell's mean. Order kept (sorted ``(P, Q)``)."""
    sub = np.minimum(areas.area[RP], areas.area[RQ]) < spacing * spacing
    rows = int((ecount[RP] + ecount[RQ])[sub].sum())
    if rows <= CURVED_ROWS_BUDGET:
        return RP, RQ
    idx = np.flatnonzero(sub)
    centre = 0.5 * (areas.centroid[RP[idx]] + areas.centroid[RQ[idx]])
    cl = cluster_ids(centre, areas.normal[RP[idx]] - areas.normal[RQ[idx]], spacing=spacing,
                     axis_step_deg=CURVED_AXIS_STEP_DEG)
    keep = ~sub
    keep[idx[closest_to_mean(centre, cl, per_cluster=CURVED_PAIRS_PER_CELL)]] = True
    if notes is not None:
        notes.append(f"regions: {len(idx):,} pairs of sub-cell areas (curved surfaces, {rows:,} outline edges, over "
                     f"grasplan.candidates.regions.CURVED_ROWS_BUDGET {CURVED_ROWS_BUDGET:,}): examined the "
                     f"{int(keep[idx].sum()):,} nearest the middle of each {spacing * 1e3:g} mm x "
                     f"{CURVED_AXIS_STEP_DEG:g} deg cell ({CURVED_PAIRS_PER_CELL} per cell)")
    return RP[keep], RQ[keep]


def _lattice_angle(S: np.ndarray, reg: np.ndarray, xa: np.ndarray, ya: np.ndarray, area_tol: float) -> np.ndarray:
    """(r,) lattice angle of regions with moments ``S`` (r, 6): their principal axes; isotropic second
    moments (squares, disks): the direction to the overlap's farthest corner (start points ``xa, ya``
    of the clipped outline segments of region ``reg``), turned by 45 deg (a square gets an
    edge-aligned lattice); ties: smallest angle mod 90 deg."""
    R = len(S)
    A = S[:, 0]
    live = A > area_tol
    A = np.where(live, A, 1.0)
    gx, gy = S[:, 1] / A, S[:, 2] / A
    cxx, cyy, cxy = S[:, 3] / A - gx * gx, S[:, 4] / A - gy * gy, S[:, 5] / A - gx * gy
    aniso = np.hypot(cxx - cyy, 2 * cxy) > 1e-6 * np.abs(cxx + cyy)
    theta = 0.5 * np.arctan2(2 * cxy, cxx - cyy)
    iso = live & ~aniso
    if iso.any():
        sel = iso[reg]
        c_r, dx, dy = reg[sel], xa[sel] - gx[reg[sel]], ya[sel] - gy[reg[sel]]
        d2 = dx * dx + dy * dy
        far_d = np.full(R, -np.inf)
        np.maximum.at(far_d, c_r, d2)
        tied = d2 >= far_d[c_r] * (1 - 1e-9)
        far_t = np.full(R, np.inf)
        np.minimum.at(far_t, c_r[tied], np.mod(np.arctan2(dy[tied], dx[tied]), np.pi / 2))
        theta[iso] = far_t[iso] + np.pi / 4
    return theta


def _check_samples(area: np.ndarray, spacing: float, n_faces: int) -> None:
    """InputError when the overlaps of ``area`` (m^2, one per region) would give more than
    :data:`MAX_SAMPLES` lattice samples (about ``max(1, area / spacing^2)`` each); the message names the
    smallest ``--spacing`` (0.1 mm steps) that fits, or asks for a repaired or decimated mesh when even
    one sample per region is too many."""
    def estimate(sp: float) -> float:
        return float(np.maximum(1.0, area / (sp * sp)).sum())

    est = estimate(spacing)
    if est <= MAX_SAMPLES:
        return
    head = (f"the contact regions would give about {int(est):,} candidate samples at --spacing {spacing * 1e3:g}mm, "
            f"more than grasplan.candidates.regions.MAX_SAMPLES ({MAX_SAMPLES:,})")
    if len(area) > MAX_SAMPLES // 2:
        raise InputError(f"{head}, with {len(area):,} overlapping pairs of surface areas among {n_faces:,} triangles "
                         f"(a triangle soup?): repair the mesh or decimate it (quadric decimation in MeshLab or "
                         f"Blender) to at most {max(1000, n_faces // 2000 * 1000):,} triangles")
    lo, hi = spacing, spacing * max(2.0, np.sqrt(est / MAX_SAMPLES) * 2.0)
    while estimate(hi) > 0.8 * MAX_SAMPLES:
        hi *= 2.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if estimate(mid) > 0.8 * MAX_SAMPLES else (lo, mid)
    fit = np.ceil(hi * 1e4 - 1e-9) / 1e4
    raise InputError(f"{head}: use --spacing {fit * 1e3:.1f}mm or more (samples grow with the overlaps' area over "
                     f"spacing^2), or repair the mesh if its surfaces should not overlap")


def _no_samples() -> Samples:
    """The empty :data:`Samples`."""
    return np.zeros((0, 2, 3)), np.zeros((0, 2, 3)), np.zeros(0), np.zeros((0, 2), np.int64), np.zeros(0, np.int64)


def _area_pair_keys(areas: Areas, geo: FaceGeometry, ids: np.ndarray, n_faces: int, *, max_opening: float,
                    beta_deg: float, tol: Tolerance) -> np.ndarray:
    """The candidate regions: sorted keys ``P * n_areas + Q`` of the area pairs (``P < Q``, contact 0
    on P) whose normals are anti-parallel within beta plus both areas' spreads and whose discs
    (centroid, largest corner distance) can overlap along the closing axis ``a = (n_P - n_Q) / |n_P -
    n_Q|`` within ``max_opening`` (:func:`grasplan.candidates.region_areas.area_pairs`, streamed).
    More than :data:`MAX_AREA_PAIRS` pairs raise an InputError naming the triangle count that fits."""
    nA = len(areas.area)
    keys, n_pairs, progress = [], 0, {"done": 0.0}
    for P, Q, _ in area_pairs(areas, geo, ids, max_opening=max_opening, beta_deg=beta_deg, tol=tol,
                              progress=progress):
        keys.append(P * nA + Q)
        n_pairs += len(P)
        if n_pairs > MAX_AREA_PAIRS:
            # overlapping pairs grow with the square of the triangles; the estimate from the share of the
            # search done runs low on mixed triangle sizes, hence the margin
            est = n_pairs / max(progress["done"], 1e-3)
            fit = max(1000, int(n_faces * np.sqrt(0.25 * MAX_AREA_PAIRS / est)) // 1000 * 1000)
            raise InputError(
                f"more than {MAX_AREA_PAIRS:,} pairs of opposing surface areas (grasplan.candidates.regions.MAX_AREA_PAIRS; "
                f"about {int(est):,} in all) among {n_faces:,} triangles: the surfaces overlap many times (a triangle "
                f"soup?) or are tessellated very finely; repair the mesh or decimate it (quadric decimation in "
                f"MeshLab or Blender) to at most {fit:,} triangles")
    return unique_values(np.concatenate(keys)) if keys else np.zeros(0, np.int64)


@dataclass(frozen=True)
class _Outlines:
    """The regions examined and the outlines their overlaps are cut from.

    RP, RQ : (R,) int64, the two areas of each region (contact 0 on P)
    eu, ev, estart, ecount : the areas' directed boundary edges (vertex ids), grouped per area
        (:func:`grasplan.candidates.region_areas.area_edges`)
    V : (n, 3) the mesh's vertices
    shift3 : (R, 3) Q's generic shift (:data:`_SHIFT`)
    """

    RP: np.ndarray
    RQ: np.ndarray
    eu: np.ndarray
    ev: np.ndarray
    estart: np.ndarray
    ecount: np.ndarray
    V: np.ndarray
    shift3: np.ndarray

    def segments(self, s: int, e: int, origin: np.ndarray, b1: np.ndarray, b2: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(reg, poly, x0, y0, x1, y1)``: the outline segments of regions ``s:e`` (``reg`` counted
        from ``s``; ``poly`` 0 for P's, 1 for Q's, shifted), in each region's plane frame ``origin``,
        ``b1``, ``b2`` (R, 3)."""
        reg, poly, u, v = region_edges(self.RP[s:e], self.RQ[s:e], self.eu, self.ev, self.estart, self.ecount)
        gr = reg + s
        sh = np.where(poly[:, None] == 1, self.shift3[gr], 0.0)
        A3, B3 = self.V[u] + sh - origin[gr], self.V[v] + sh - origin[gr]
        return (reg, poly, np.einsum("ij,ij->i", A3, b1[gr]), np.einsum("ij,ij->i", A3, b2[gr]),
                np.einsum("ij,ij->i", B3, b1[gr]), np.einsum("ij,ij->i", B3, b2[gr]))


def _overlap_moments(outl: _Outlines, batches: list[tuple[int, int]], org: np.ndarray, t1: np.ndarray,
                     t2: np.ndarray, eps: float, area_tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact overlap of each region, ``(S (R, 6) area, first and second moments, theta (R,) lattice angle)``.

    A region is ``proj(P) & proj(Q)`` along the closing axis. Only the areas' boundary edges are
    used: the parts of P's outline inside Q and of Q's outline inside P (crossings found on a grid,
    inside/outside by the parity of a vertical ray) give the overlap's moments by Green's theorem,
    exact, so they do not depend on how the inside of an area is triangulated."""
    R = len(outl.RP)
    S = np.zeros((R, 6))
    theta = np.zeros(R)
    for s, e in batches:
        reg, poly, x0, y0, x1, y1 = outl.segments(s, e, org, t1, t2)
        L = np.hypot(x1 - x0, y1 - y0)
        nr = e - s
        h = np.bincount(reg, weights=L, minlength=nr) / np.maximum(np.bincount(reg, minlength=nr), 1)
        h = np.maximum(h, 1e-6 * eps)[reg]
        r, xa, ya, xb, yb = inside_parts(reg, poly, x0, y0, x1, y1, h)
        M = green_moments(xa, ya, xb, yb)
        for c in range(6):
            S[s:e, c] += np.bincount(reg[r], weights=M[:, c], minlength=nr)
        theta[s:e] = _lattice_angle(S[s:e], reg[r], xa, ya, area_tol)
    return S, theta


@dataclass(frozen=True)
class _Lattice:
    """Each region's sampling lattice.

    live : (R,) bool, the overlap has an area; small : (R,) bool, it is smaller than a lattice cell
    g3 : (R, 3) its centroid (in the plane through P's centroid); e1, e2 : (R, 3) the lattice axes
    """

    live: np.ndarray
    small: np.ndarray
    g3: np.ndarray
    e1: np.ndarray
    e2: np.ndarray


def _lattice(S: np.ndarray, theta: np.ndarray, org: np.ndarray, t1: np.ndarray, t2: np.ndarray, spacing: float,
             area_tol: float, n_faces: int) -> _Lattice:
    """The lattices of the regions with moments ``S`` and lattice angles ``theta``, after checking the
    samples they would give (:func:`_check_samples`)."""
    A = S[:, 0]
    live = A > area_tol
    A = np.where(live, A, 1.0)
    gx, gy = S[:, 1] / A, S[:, 2] / A
    _check_samples(A[live], spacing, n_faces)
    ct, st = np.cos(theta)[:, None], np.sin(theta)[:, None]
    e1, e2 = ct * t1 + st * t2, -st * t1 + ct * t2
    g3 = org + gx[:, None] * t1 + gy[:, None] * t2      # centroid, in the plane through P's centroid
    small = A < spacing * spacing
    return _Lattice(live, small, g3, e1, e2)


def _lattice_points(outl: _Outlines, batches: list[tuple[int, int]], lat: _Lattice, spacing: float, eps: float
                    ) -> tuple[np.ndarray, np.ndarray] | None:
    """The samples ``(reg (k,), q (k, 2) lattice coordinates)``, sorted by region then scanline, or
    ``None`` when no region has a scanline.

    Each region is sampled on a square lattice of pitch ``spacing`` centred on its centroid and
    aligned with its principal axes (:func:`_lattice_angle`). A lattice point is a sample when the
    cross of points ``+-eps`` around it lies in both projections (scanlines at ``y - eps, y, y + eps``,
    even-odd intervals), so points on an outline are never sampled whatever the tessellation. A
    region the lattice misses (thinner than a pitch and off it, or a sub-cell region whose centroid
    lies outside it) gets the middle of its widest interval on the centroid's scanline; a strip's
    centroid line is always sampled. A sub-cell region gives at most its centroid."""
    live, small = lat.live, lat.small
    s_reg, s_q, f_reg, f_q, f_w = [], [], [], [], []
    offsets = (-eps, 0.0, eps)
    for s, e in batches:
        reg, poly, x0, y0, x1, y1 = outl.segments(s, e, lat.g3, lat.e1, lat.e2)
        keep = live[reg + s]
        reg, poly, x0, y0, x1, y1 = reg[keep], poly[keep], x0[keep], y0[keep], x1[keep], y1[keep]
        if len(reg) == 0:
            continue
        ir, j, xa, xb = row_intervals(reg, poly, x0, y0, x1, y1, spacing, offsets, small[reg + s])
        gr = ir + s
        i0 = np.ceil((xa + eps) / spacing).astype(np.int64)
        i1 = np.floor((xb - eps) / spacing).astype(np.int64)
        sm = small[gr]
        i0, i1 = np.where(sm, np.maximum(i0, 0), i0), np.where(sm, np.minimum(i1, 0), i1)
        row, k = expand(np.maximum(i1 - i0 + 1, 0))
        s_reg.append(gr[row])
        s_q.append(np.column_stack([(i0[row] + k) * spacing, j[row] * spacing]))
        z = (j == 0) & (xb - xa > 2 * eps)
        f_reg.append(gr[z])
        f_q.append(np.column_stack([0.5 * (xa[z] + xb[z]), np.zeros(int(z.sum()))]))
        f_w.append(xb[z] - xa[z])
    if not s_reg:
        return None
    reg, q = np.concatenate(s_reg), np.concatenate(s_q)
    fr, fq, fw = np.concatenate(f_reg), np.concatenate(f_q), np.concatenate(f_w)
    miss = ~np.isin(fr, reg)
    if miss.any():
        fr, fq, fw = fr[miss], fq[miss], fw[miss]
        o = np.lexsort((-fw, fr))
        o = o[np.r_[True, fr[o][1:] != fr[o][:-1]]]
        reg, q = np.concatenate([reg, fr[o]]), np.vstack([q, fq[o]])
    o = np.lexsort((q[:, 0], q[:, 1], reg))
    return reg[o], q[o]


def _faces_under(x: np.ndarray, ax: np.ndarray, ar: np.ndarray, areas: Areas, geo: FaceGeometry,
                 members: np.ndarray, count: np.ndarray, start: np.ndarray) -> np.ndarray:
    """(k,) the face of area ``ar`` (k,) each sample ``x`` (k, 3) lies over along its axis ``ax``, or
    -1: 2D point location in each area's own plane. ``members`` are the areas' faces grouped by
    area (``count`` faces from ``start`` each)."""
    n_a, c_a = areas.normal[ar], areas.centroid[ar]
    y = x + (np.einsum("ij,ij->i", n_a, c_a - x) / np.einsum("ij,ij->i", n_a, ax))[:, None] * ax
    used = unique_values(ar)
    b1, b2 = perpendicular_frame(areas.normal[used])
    pos = np.searchsorted(used, ar)
    qa = np.column_stack([np.einsum("ij,ij->i", y - areas.centroid[ar], b1[pos]),
                          np.einsum("ij,ij->i", y - areas.centroid[ar], b2[pos])])
    rr, kk = expand(count[used])
    faces = members[start[used][rr] + kk]
    T = geo.tri[faces] - areas.centroid[used][rr][:, None]
    tri2 = np.stack([np.einsum("bkj,bj->bk", T, b1[rr]), np.einsum("bkj,bj->bk", T, b2[rr])], axis=-1)
    pick = locate(pos, qa, rr, tri2)
    return np.where(pick >= 0, faces[np.maximum(pick, 0)], -1)


def _lift(x: np.ndarray, ax: np.ndarray, geo: FaceGeometry, f: np.ndarray) -> np.ndarray:
    """(k, 3) the samples ``x`` moved along their axes ``ax`` onto the planes of faces ``f``."""
    return x + (np.einsum("ij,ij->i", geo.n[f], geo.tri[f, 0] - x)
                / np.einsum("ij,ij->i", geo.n[f], ax))[:, None] * ax


def find_regions(mesh: TriangleMesh, convex: np.ndarray, geo: FaceGeometry, *, max_opening: float, beta_deg: float,
                 mu: float, spacing: float, tol: Tolerance, notes: list[str] | None = None) -> Samples:
    """Region samples: ``contacts (n, 2, 3)``, ``normals (n, 2, 3)``, ``width (n,)``, ``faces (n, 2)``,
    ``region (n,)`` for :class:`grasplan.candidates.antipodal_base.Candidates`.

    1. Convex areas (:func:`grasplan.candidates.region_areas.convex_areas`) of the admitted faces: a
       face is admitted when the convexity stage calls it convex, or when it is concave only because
       neighbours rise above it across some (not all) of its edges, a shallow crease the BLM does
       not split (:func:`grasplan.candidates.region_creases.admitted_faces`).
    2. Candidate regions: opposing area pairs (:func:`_area_pair_keys`), bounded (:func:`_bounded_pairs`).
    3. Their exact overlaps (:func:`_overlap_moments`); Q's projection is shifted by :data:`_SHIFT`.
    4. Lattice samples of each overlap (:func:`_lattice_points`), each located in a face of P and of
       Q (:func:`_faces_under`) and lifted along the closing axis onto both; samples near a rising
       crease edge are dropped; then the paper's rules per sample (:func:`finish_samples`).

    The region id is the rank of the area pair among the regions with a positive overlap, in sorted
    ``(P, Q)`` order. Unlike the paper's rule, regions need the projections to overlap (contacts
    exactly opposite along the axis); the paper's epsilon offset is not used. The work is bounded
    (:data:`MAX_AREA_PAIRS`, :data:`CURVED_ROWS_BUDGET`, :data:`MAX_SAMPLES`): an
    :class:`~grasplan.errors.InputError` says what would run; ``notes`` (a list) receives a line when
    sub-cell pairs were thinned. Outlines are processed in batches of :data:`_EDGE_CHUNK` edges. The
    tests hold an independent reference implementation over every overlapping triangle pair
    (``tests/regions_reference.py``). ``geo``: the mesh's
    :class:`grasplan.candidates.antipodal_base.FaceGeometry`; lengths in metres."""
    adjacency = mesh_edge_adjacency(mesh)
    admit, creases = admitted_faces(mesh, convex, geo, tol, adjacency)
    areas = convex_areas(mesh, admit, tol, adjacency, geo=geo)
    lab = areas.label
    ids = np.flatnonzero(lab >= 0)
    if len(ids) < 2:
        return _no_samples()
    V = np.asarray(mesh.vertices, dtype=np.float64)
    F = np.asarray(mesh.faces, dtype=np.int64)
    nA = len(areas.area)
    eps = tol.distance
    key = _area_pair_keys(areas, geo, ids, len(F), max_opening=max_opening, beta_deg=beta_deg, tol=tol)
    if len(key) == 0:
        return _no_samples()
    eu, ev, estart, ecount = area_edges(F, lab, nA, adjacency)
    RP, RQ = _bounded_pairs(key // nA, key % nA, areas, ecount, spacing, notes)
    a = areas.normal[RP] - areas.normal[RQ]
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    t1, t2 = perpendicular_frame(a)
    org = areas.centroid[RP]
    scale = 1e6 * eps
    shift3 = _SHIFT * scale * (_SHIFT_DIR[0] * t1 + _SHIFT_DIR[1] * t2)      # Q's generic shift (3D)
    outl = _Outlines(RP, RQ, eu, ev, estart, ecount, V, shift3)
    batches = weight_batches(ecount[RP] + ecount[RQ], _EDGE_CHUNK)
    S, theta = _overlap_moments(outl, batches, org, t1, t2, eps, tol.area)
    lat = _lattice(S, theta, org, t1, t2, spacing, tol.area, len(F))
    found = _lattice_points(outl, batches, lat, spacing, eps)
    if found is None:
        return _no_samples()
    reg, q = found
    if len(reg) == 0:
        return _no_samples()
    x = lat.g3[reg] + q[:, :1] * lat.e1[reg] + q[:, 1:] * lat.e2[reg]
    ax = a[reg]
    members = ids[np.argsort(lab[ids], kind="stable")]
    count = np.bincount(lab[ids], minlength=nA)
    start = np.cumsum(count) - count
    si, sj = (_faces_under(x, ax, side[reg], areas, geo, members, count, start) for side in (RP, RQ))
    ok = (si >= 0) & (sj >= 0)
    reg, x, ax, si, sj = reg[ok], x[ok], ax[ok], si[ok], sj[ok]
    p0, p1 = _lift(x, ax, geo, si), _lift(x, ax, geo, sj)
    ok = ~near_creases(p0, p1, creases)
    reg, si, sj, p0, p1 = reg[ok], si[ok], sj[ok], p0[ok], p1[ok]
    # region ids: rank among the live regions (pose- and tessellation-independent)
    rid = np.cumsum(lat.live) - 1
    return finish_samples(reg, rid[reg], si, sj, p0, p1, lat.small, geo, mu, eps, max_opening, spacing, beta_deg)


def finish_samples(reg: np.ndarray, rid: np.ndarray, si: np.ndarray, sj: np.ndarray, p0: np.ndarray,
                   p1: np.ndarray, small: np.ndarray, geo: FaceGeometry, mu: float, eps: float,
                   max_opening: float, spacing: float, beta_deg: float) -> Samples:
    """The paper's per-sample rules and the curved-surface deduplication; the Candidates arrays.

    Rules, on the normals of the two faces a sample touches (an area's normal is a mean: the faces
    of an area may stray from it by ``Areas.spread``): anti-parallel within beta, contacts facing
    away, closing axis inside both friction cones, width ``<= max_opening``. Samples of ``small``
    regions (one each, from curved surfaces) are deduplicated on the spacing grid
    (:data:`CURVED_AXIS_STEP_DEG`)."""
    d = p1 - p0
    w = np.linalg.norm(d, axis=1)
    dn = d / np.maximum(w, 1e-300)[:, None]
    cosf = np.cos(np.arctan(mu)) - 1e-12
    cosb = np.cos(np.radians(beta_deg))
    ok = ((np.einsum("ij,ij->i", geo.n[si], geo.n[sj]) <= -cosb)
          & (np.einsum("ij,ij->i", geo.n[si], -d) > 0) & (np.einsum("ij,ij->i", geo.n[sj], d) > 0) & (w > eps)
          & (np.einsum("ij,ij->i", -geo.n[si], dn) >= cosf) & (np.einsum("ij,ij->i", geo.n[sj], dn) >= cosf)
          & (w <= max_opening))
    reg, rid, si, sj, p0, p1, w = reg[ok], rid[ok], si[ok], sj[ok], p0[ok], p1[ok], w[ok]
    contacts = np.stack([p0, p1], axis=1)
    normals = np.stack([geo.n[si], geo.n[sj]], axis=1)
    faces = np.stack([si, sj], axis=1).astype(np.int64)
    sm = small[reg]
    if sm.any():
        idx = np.flatnonzero(sm)
        sub = Candidates(contacts[idx], normals[idx], w[idx], faces[idx])
        drop = np.ones(len(idx), dtype=bool)
        drop[thin_candidates(sub, spacing=spacing, axis_step_deg=CURVED_AXIS_STEP_DEG)] = False
        keep = np.ones(len(reg), dtype=bool)
        keep[idx[drop]] = False
        contacts, normals, w, faces, rid = contacts[keep], normals[keep], w[keep], faces[keep], rid[keep]
    return contacts, normals, w, faces, rid.astype(np.int64)
