"""Which surface elements can touch a finger pad: the near tests of the contact patches.

An element (:func:`grasplan.grasps.patches.patch_elements`) can touch the pad at a contact when its
centroid lies within its slab tolerance of the plane through the contact normal to the closing
axis, laterally within the pad's reach, and it faces the jaw. :func:`near_faces_dense` tests every
(element, contact) pair in bounded chunks; :func:`near_faces_slab` visits only the grid cells each
contact's slab crosses (large parts). Both feed :func:`grasplan.grasps.patches.contact_patches`.
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ..compiled.jit import kernel
from ..geometry.grouping import expand

#: contacts per step of :func:`near_faces_slab` (bounds its cell and pair arrays)
_SLAB_CONTACTS = 256


def near_faces_dense(cent: np.ndarray, fn: np.ndarray, cent_sq: np.ndarray, slab_tol: np.ndarray,
                     lat_tol: np.ndarray, cu: np.ndarray, axu: np.ndarray, j: int, max_pairs: int
                     ) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Chunks ``(face, contact, n . axis)`` of the elements (centroids ``cent``, normals ``fn``, squared
    centroid norms ``cent_sq``) near each contact ``cu`` (axis ``axu``) facing jaw ``j``: a dense
    (elements x contacts) test on centroids (:func:`near_pairs`, compiled), chunked so that at most
    ``max_pairs`` (element, contact) pairs are tested at once; within a chunk sorted by (face,
    contact). Empty chunks are skipped."""
    F, U = len(cent), len(cu)
    step = max(1, max_pairs // max(F, 1))
    cent = np.ascontiguousarray(cent, dtype=np.float64)
    fn = np.ascontiguousarray(fn, dtype=np.float64)
    cent_sq = np.ascontiguousarray(cent_sq, dtype=np.float64)
    slab_tol = np.ascontiguousarray(slab_tol, dtype=np.float64)
    lat_tol = np.ascontiguousarray(lat_tol, dtype=np.float64)
    for start in range(0, U if F else 0, step):
        stop = min(U, start + step)
        f, b, nx = near_pairs(cent, fn, cent_sq, slab_tol, lat_tol, np.ascontiguousarray(cu[start:stop]),
                              np.ascontiguousarray(axu[start:stop]), int(j))
        if len(f) == 0:
            continue
        yield f, start + b, nx


@kernel(cache=True, nogil=True)
def near_pairs(cent: np.ndarray, fn: np.ndarray, cent_sq: np.ndarray, slab_tol: np.ndarray, lat_tol: np.ndarray,
               cu: np.ndarray, axu: np.ndarray, j: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(face (k,), contact (k,), n . axis (k,))`` of the (element, contact) pairs whose element
    centroid lies within ``slab_tol`` of the plane through the contact normal to its axis, laterally
    within ``sqrt(lat_tol)``, with the normal facing jaw ``j`` (``n . axis`` < 0 for jaw 0, > 0 for
    jaw 1); sorted by (face, contact). Two passes (count, fill): nothing grows with faces x contacts."""
    F = cent.shape[0]
    B = cu.shape[0]
    cax = np.empty(B)
    cc = np.empty(B)
    for b in range(B):
        cax[b] = cu[b, 0] * axu[b, 0] + cu[b, 1] * axu[b, 1] + cu[b, 2] * axu[b, 2]
        cc[b] = cu[b, 0] * cu[b, 0] + cu[b, 1] * cu[b, 1] + cu[b, 2] * cu[b, 2]
    n = 0
    fo = np.empty(0, dtype=np.int64)
    bo = np.empty(0, dtype=np.int64)
    no = np.empty(0)
    for stage in range(2):
        if stage == 1:
            fo = np.empty(n, dtype=np.int64)
            bo = np.empty(n, dtype=np.int64)
            no = np.empty(n)
            n = 0
        for f in range(F):
            x0, x1, x2 = cent[f, 0], cent[f, 1], cent[f, 2]
            n0, n1, n2 = fn[f, 0], fn[f, 1], fn[f, 2]
            st, lt, cs = slab_tol[f], lat_tol[f], cent_sq[f]
            for b in range(B):
                a0, a1, a2 = axu[b, 0], axu[b, 1], axu[b, 2]
                nx = n0 * a0 + n1 * a1 + n2 * a2
                if (j == 0 and not nx < 0.0) or (j != 0 and not nx > 0.0):
                    continue
                xs = (x0 * a0 + x1 * a1 + x2 * a2) - cax[b]
                if not abs(xs) <= st:
                    continue
                d2 = cs - 2.0 * (x0 * cu[b, 0] + x1 * cu[b, 1] + x2 * cu[b, 2]) + cc[b]
                if not d2 - xs * xs <= lt:
                    continue
                if stage == 1:
                    fo[n] = f
                    bo[n] = b
                    no[n] = nx
                n += 1
    return fo, bo, no


@dataclass(frozen=True)
class _CellGrid:
    """The centroids of elements ``rows`` binned on a grid of pitch ``h`` from ``lo`` (``dims`` cells
    per axis): the sorted cell keys ``ukey`` holding ``ucount`` elements from ``first`` each, in
    ``order``; the class's largest slab half-thickness ``slab`` and reach ``r3``."""

    rows: np.ndarray
    slab: float
    r3: float
    h: float
    lo: np.ndarray
    dims: np.ndarray
    order: np.ndarray
    first: np.ndarray
    ukey: np.ndarray
    ucount: np.ndarray


def _cell_grid(cent: np.ndarray, slab_tol: np.ndarray, lat_tol: np.ndarray, rows: np.ndarray) -> _CellGrid:
    """The :class:`_CellGrid` of the elements ``rows``: cells at least twice the slab thick."""
    slab = float(slab_tol[rows].max())
    r3 = float(np.sqrt(slab * slab + lat_tol[rows].max()))
    h = max(2.0 * slab, r3 / 16.0)
    lo = cent[rows].min(axis=0)
    cell = np.floor((cent[rows] - lo) / h).astype(np.int64)
    dims = cell.max(axis=0) + 1
    key = np.ravel_multi_index(cell.T, tuple(int(d) for d in dims))
    order = np.argsort(key, kind="stable")
    ks = key[order]
    first = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
    return _CellGrid(rows, slab, r3, h, lo, dims, order, first, ks[first], np.diff(np.r_[first, len(ks)]))


def _crossed_cells(g: _CellGrid, cu: np.ndarray, axu: np.ndarray, b_all: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """``(element, contact)`` of the elements of ``g`` in the cells the slabs of contacts ``b_all``
    cross: per column along the axis' dominant coordinate, the few cells within the slab's
    half-thickness (plus the plane's rise across a cell) of the plane at the column's centre."""
    slab, r3, h, dims = g.slab, g.r3, g.h, g.dims
    a = axu[b_all]
    k = np.argmax(np.abs(a), axis=1)
    i1, i2 = (k + 1) % 3, (k + 2) % 3
    r = np.arange(len(b_all))
    p = cu[b_all] - g.lo
    c1_lo = np.floor((p[r, i1] - r3) / h).astype(np.int64)
    c2_lo = np.floor((p[r, i2] - r3) / h).astype(np.int64)
    n1 = np.floor((p[r, i1] + r3) / h).astype(np.int64) - c1_lo + 1
    n2 = np.floor((p[r, i2] + r3) / h).astype(np.int64) - c2_lo + 1
    own, q = expand(n1 * n2)
    c1 = c1_lo[own] + q // n2[own]
    c2 = c2_lo[own] + q % n2[own]
    ak, a1, a2 = a[own, k[own]], a[own, i1[own]], a[own, i2[own]]
    t = np.einsum("ki,ki->k", p, a)[own]
    xk = (t - a1 * (c1 + 0.5) * h - a2 * (c2 + 0.5) * h) / ak          # the plane at the column centre
    ht = (slab + 0.5 * h * (np.abs(a1) + np.abs(a2))) / np.abs(ak) * (1 + 1e-9) + 1e-12
    k0 = np.floor((xk - ht) / h).astype(np.int64)
    own2, q2 = expand(np.floor((xk + ht) / h).astype(np.int64) - k0 + 1)
    ck = k0[own2] + q2
    o3 = own[own2]
    cc = np.zeros((len(o3), 3), dtype=np.int64)
    rr = np.arange(len(o3))
    cc[rr, k[o3]], cc[rr, i1[o3]], cc[rr, i2[o3]] = ck, c1[own2], c2[own2]
    inside = np.all((cc >= 0) & (cc < dims), axis=1)
    cc, o3 = cc[inside], o3[inside]
    qk = np.ravel_multi_index(cc.T, tuple(int(d) for d in dims)) if len(cc) else np.zeros(0, np.int64)
    pos = np.minimum(np.searchsorted(g.ukey, qk), max(len(g.ukey) - 1, 0))
    hit = (g.ukey[pos] == qk) if len(g.ukey) else np.zeros(len(qk), dtype=bool)
    pos, o3 = pos[hit], o3[hit]
    ow, q3 = expand(g.ucount[pos])
    return g.rows[g.order[g.first[pos][ow] + q3]], b_all[o3[ow]]


def near_faces_slab(cent: np.ndarray, fn: np.ndarray, face_rad: np.ndarray, cu: np.ndarray, axu: np.ndarray,
                    slab_tol: np.ndarray, lat_tol: np.ndarray, pad_reach: float, j: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(face, contact, n . axis)`` of every element whose centroid passes the near test of
    :func:`grasplan.grasps.patches.contact_patches` (within ``slab_tol`` of the plane through contact
    ``cu`` normal to its axis ``axu``, laterally within ``sqrt(lat_tol)``, facing the jaw), sorted by
    (face, contact).

    Centroids are binned on a grid (faces in classes of radii within a factor 2, each with cells at
    least twice its slab thick, :func:`_cell_grid`); for each contact only the cells the slab crosses
    are visited (:func:`_crossed_cells`). Every face passing the test lies in a visited cell; the same
    exact test then decides. Work: the visited cells and the faces in them, not faces x contacts."""
    fs: list[np.ndarray] = []
    bs: list[np.ndarray] = []
    ns: list[np.ndarray] = []
    base = max(float(face_rad.min(initial=0.0)), 1e-9)
    cls = np.floor(np.log2(np.maximum(face_rad, base) / base)).astype(np.int64)
    for c in np.unique(cls):
        grid = _cell_grid(cent, slab_tol, lat_tol, np.flatnonzero(cls == c))
        for s in range(0, len(cu), _SLAB_CONTACTS):
            f, b = _crossed_cells(grid, cu, axu, np.arange(s, min(len(cu), s + _SLAB_CONTACTS)))
            d = cent[f] - cu[b]
            xs = np.einsum("ki,ki->k", d, axu[b])
            nx = np.einsum("ki,ki->k", fn[f], axu[b])
            near = (np.abs(xs) <= slab_tol[f]) & (np.einsum("ki,ki->k", d, d) - xs * xs <= lat_tol[f]) & \
                ((nx < 0) if j == 0 else (nx > 0))
            fs.append(f[near])
            bs.append(b[near])
            ns.append(nx[near])
    if not fs:
        z = np.zeros(0, dtype=np.int64)
        return z, z, np.zeros(0)
    f, b, nx = np.concatenate(fs), np.concatenate(bs), np.concatenate(ns)
    o = np.lexsort((b, f))
    return f[o], b[o], nx[o]
