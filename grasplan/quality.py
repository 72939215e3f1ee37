"""Physical grasp quality: contact patches, gravity margin and Ferrari-Canny epsilon (issue 11).

For ``M`` parallel-jaw grasps of a part (TCP frames ``T_part_tcp`` (M, 4, 4), contacts
``(M, 2, 3)`` with outward unit normals, widths ``(M,)``; metres, part frame):

**Contact patch** (per jaw). The finger pad is the inner face of the gripper's own finger
geometry (``Gripper.finger``: the points of its shape on its inner face ``x = 0``, bounded by their
y/z extent), placed on the plane through the contact, perpendicular to the closing axis. The patch
is the part surface inside the pad rectangle and within ``CONTACT_DEPTH`` (0.1 mm, the pad's
compliance) of that plane, facing the pad: every such triangle is clipped exactly to the
box ``|x - x_contact| <= depth`` x pad rectangle (vectorised Sutherland-Hodgman) and its
projection on the pad is integrated (area, first and second moments). ``area`` is m^2; ``type``
is ``surface`` when the part faces parallel to the pad (within ``FLAT_DEG``) cover a patch at least
``MIN_SIDE`` (2 mm) wide in every direction, else ``line`` when the patch is at least ``MIN_SIDE``
long and ``LINE_ASPECT`` (2) times longer than wide, else ``point``. Widths are those of the uniform rectangle with the same second moments.
Triangles are paired with grasps through a KD-tree of face centroids (radius: pad reach + the
largest face radius) and processed in chunks of at most ``MAX_PAIRS`` pairs: memory stays bounded.

**Grip force.** ``grip_force`` (gripper YAML, N) is the datasheet gripping force, which Schunk (and
most makers of parallel grippers) define as the arithmetic sum of the forces of the jaws: each of
the two contacts is pressed with the normal force ``F = grip_force / 2`` (70 N for the EGP-C 40's
140 N). ``CONTACTS_PER_GRIP`` is that 2.

**Gravity margin** (soft-finger model). Each contact is pressed with ``F`` (N, above). A contact
resists a tangential force ``|t| <= mu F`` and a torque about the closing axis
``|tau| <= (2/3) mu F a`` (uniform pressure on a disc of radius ``a = sqrt(area / pi)``, at least
``MIN_PATCH_RADIUS``), combined elliptically: ``(|t| / (mu F))^2 + (tau / tau_max)^2 <= 1``. The
load is the part's weight plus a 1 g acceleration in the worst direction: ``f = m g (g_hat + u)``
for unit ``u`` (``N_DIRECTIONS`` Fibonacci directions and ``u = g_hat``), applied at the centre of
mass, whose offset from the contact axis is the lever arm. Forces along the closing axis are held
by the jaws' mechanism; tangential force is shared equally; the torque about the closing axis is
held by torsional friction (shared by capacity); the torque perpendicular to it by a couple of
opposite tangential forces ``|tau_perp| / width`` at the two contacts. ``gravity_margin`` =
1 / (largest utilisation over both contacts and every direction): below 1 the part slips.

**Epsilon** (Ferrari-Canny L1). Two soft-finger contacts, unit normal force each: the friction
cone linearised with ``CONE_EDGES`` (8) edges ``nu + mu (cos k t1 + sin k t2)`` plus the pure normal
force with torsion ``+-(2/3) mu a nu``; torques about the centre of mass divided by the part's
radius ``rho`` (largest distance of the part's vertices from the centre of mass), so wrenches are
in newtons. ``epsilon`` is the radius of the largest origin-centred ball inside the convex hull
(scipy ConvexHull, Qhull) of the 20 wrenches; 0 when the origin is outside or the hull is flat.
For speed the torsion radius of epsilon is rounded down to a 5 % geometric grid
(``RADIUS_STEP``), so the rolls of one candidate (same contacts) share one hull computation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import ConvexHull, QhullError

from .errors import ConfigError, InputError
from .gripper import Gripper
from .mass import MassProperties
from .scoring import (  # noqa: F401
    DEFAULT_SCORING,
    SCORING_FILE,
    ScoringConfig,
    load_score_weights,
    load_scoring,
)
from .transforms import check_transform

#: part surface within this distance of the pad plane touches the pad, m (pad compliance)
CONTACT_DEPTH = 1e-4
#: part faces within this angle of the pad's plane count as flat contact, degrees
FLAT_DEG = 1.0
#: a patch narrower than this in every direction is a point, in one direction a line, m
MIN_SIDE = 2e-3
#: a non-flat patch at least this many times longer than wide (and MIN_SIDE long) is a line
LINE_ASPECT = 2.0
#: torsional friction radius of a point or line contact on a compliant pad, m
MIN_PATCH_RADIUS = 5e-4
#: epsilon: patch radii are rounded down to a geometric grid of this relative step (shared Qhull calls)
RADIUS_STEP = 0.05
#: Qhull options of epsilon: joggled input (simplicial facets; ~40 % faster on these symmetric wrench
#: sets, facet offsets within 1e-10 of the exact hull; deterministic), no precision warnings
QHULL_OPTIONS = "QJ Pp"
#: epsilon below this (N per N) is 0: the joggle's size, wrench sets that are flat or touch the origin
EPSILON_TOL = 1e-9
#: edges of the linearised friction cone
CONE_EDGES = 8
#: load directions sampled for the worst-case 1 g acceleration
N_DIRECTIONS = 64
#: standard gravity, m/s^2
G = 9.81
#: largest (grasp, face) pairs held at once by the patch computation
MAX_PAIRS = 400_000
#: the gripper's ``grip_force`` is the sum over its jaws: each contact gets grip_force / this
CONTACTS_PER_GRIP = 2
#: contact type codes of ``Quality.contact_type``
CONTACT_TYPES = ("point", "line", "surface")


@dataclass(frozen=True)
class Quality:
    """Quality of ``M`` grasps.

    Attributes
    ----------
    contact_area : (M, 2) float64
        Patch area per jaw (jaw 0 touches contact 0, on the TCP's -x side), m^2.
    contact_type : (M, 2) int8
        Index into ``CONTACT_TYPES`` ("point", "line", "surface").
    contact_width : (M, 2, 2) float64
        Equivalent (min, max) widths of each patch, m.
    gravity_margin : (M,) float64
        Friction available / friction needed under gravity + 1 g worst case; < 1 slips.
    epsilon : (M,) float64
        Ferrari-Canny L1 quality (wrench units: N per N of normal force), >= 0.
    grip_force : float
        The gripping force used, N (sum of both jaws; each contact is pressed with half of it).
    mu : float
        Friction coefficient used.
    """

    contact_area: np.ndarray
    contact_type: np.ndarray
    contact_width: np.ndarray
    gravity_margin: np.ndarray
    epsilon: np.ndarray
    grip_force: float
    mu: float

    def __len__(self) -> int:
        return len(self.epsilon)

    def to_json(self, i: int, *, score: float | None = None) -> dict:
        """The ``quality`` object of grasp ``i`` (areas m^2; ``score`` added when given)."""
        out = {
            "contact": [{"area_m2": float(self.contact_area[i, j]),
                         "type": CONTACT_TYPES[int(self.contact_type[i, j])]}
                        for j in range(2)],
            "gravity_margin": float(self.gravity_margin[i]),
            "epsilon": float(self.epsilon[i]),
        }
        if score is not None:
            out["score"] = float(score)
        return out


# ------------------------------------------------------------------------------------------------
# finger pad
# ------------------------------------------------------------------------------------------------
def pad_rectangle(gripper: Gripper) -> np.ndarray:
    """The +x jaw's pad in the TCP frame at opening 0: ``[[y0, y1], [z0, z1]]`` (m), the y/z extent
    of the finger's points on its inner face (x = 0). The -x jaw's pad is ``[[-y1, -y0], [z0, z1]]``."""
    pts = np.asarray(gripper.finger.corners(), dtype=np.float64)
    tol = 1e-6 + 1e-3 * float(np.ptp(pts[:, 0]))
    face = pts[pts[:, 0] <= pts[:, 0].min() + tol]
    rect = np.array([[face[:, 1].min(), face[:, 1].max()], [face[:, 2].min(), face[:, 2].max()]])
    if np.any(rect[:, 1] - rect[:, 0] <= 0):
        raise ConfigError(f"gripper {gripper.name}: the finger has no flat inner face on x = 0 to grip with "
                          "(give a finger whose inner face is a plane)")
    return rect


# ------------------------------------------------------------------------------------------------
# polygon clipping and moments, vectorised over polygons
# ------------------------------------------------------------------------------------------------
def _gather(P: np.ndarray, idx: np.ndarray) -> np.ndarray:
    return np.take_along_axis(P, idx[..., None].repeat(P.shape[-1], axis=-1), axis=1)


def clip_polygons(P: np.ndarray, n: np.ndarray, axis: int, bound: np.ndarray, keep_below: bool):
    """Clip convex polygons to a half-space (Sutherland-Hodgman, all polygons at once).

    ``P`` (K, N, d) vertices (the first ``n[k]`` valid, in order), ``n`` (K,) counts; keeps
    ``p[axis] <= bound`` (``keep_below``) or ``p[axis] >= bound``, ``bound`` (K,). Returns the
    clipped ``(P', n')`` with ``P'`` (K, N', d)."""
    K, N, _ = P.shape
    if K == 0 or N == 0:
        return P, n
    sgn = 1.0 if keep_below else -1.0
    # only polygons with a vertex outside the half-space change (most lie inside the pad's box)
    valid = np.arange(N)[None, :] < n[:, None]
    need = np.any(valid & (sgn * (P[..., axis] - bound[:, None]) > 0), axis=1)
    if not need.all():
        if not need.any():
            return P, n
        Pc, nc = _clip_all(P[need], n[need], axis, bound[need], sgn)
        out = np.zeros((K, max(N, Pc.shape[1]), P.shape[2]))
        out[~need, :N] = P[~need]
        out[need, :Pc.shape[1]] = Pc
        n_out = n.copy()
        n_out[need] = nc
        return out, n_out
    return _clip_all(P, n, axis, bound, sgn)


def _clip_all(P: np.ndarray, n: np.ndarray, axis: int, bound: np.ndarray, sgn: float):
    K, N, _ = P.shape
    i = np.arange(N)
    valid = i[None, :] < n[:, None]
    nxt = (i[None, :] + 1) % np.maximum(n[:, None], 1)
    Q = _gather(P, nxt)
    dp = sgn * (P[..., axis] - bound[:, None])
    dq = sgn * (Q[..., axis] - bound[:, None])
    in_p = dp <= 0
    cross = valid & (in_p != (dq <= 0))
    t = np.divide(dp, dp - dq, out=np.zeros_like(dp), where=cross)
    X = P + t[..., None] * (Q - P)
    out = np.stack([P, X], axis=2).reshape(K, 2 * N, -1)
    keep = np.stack([valid & in_p, cross], axis=2).reshape(K, 2 * N)
    order = np.argsort(~keep, axis=1, kind="stable")
    n_new = keep.sum(axis=1)
    m = int(n_new.max())
    return _gather(out, order[:, :m]), n_new


def polygon_moments(Y: np.ndarray, Z: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Area integrals of polygons in the (y, z) plane: ``(K, 6)`` = unsigned ``[A, int y, int z,
    int y^2, int z^2, int yz]``. ``Y``, ``Z`` (K, N), the first ``n[k]`` vertices valid."""
    K, N = Y.shape
    out = np.zeros((K, 6))
    if K == 0 or N == 0:
        return out
    i = np.arange(N)
    valid = i[None, :] < n[:, None]
    nxt = (i[None, :] + 1) % np.maximum(n[:, None], 1)
    Y1, Z1 = np.take_along_axis(Y, nxt, 1), np.take_along_axis(Z, nxt, 1)
    c = np.where(valid, Y * Z1 - Y1 * Z, 0.0)
    A = 0.5 * c.sum(1)
    out[:, 0] = A
    out[:, 1] = ((Y + Y1) * c).sum(1) / 6.0
    out[:, 2] = ((Z + Z1) * c).sum(1) / 6.0
    out[:, 3] = ((Y * Y + Y * Y1 + Y1 * Y1) * c).sum(1) / 12.0
    out[:, 4] = ((Z * Z + Z * Z1 + Z1 * Z1) * c).sum(1) / 12.0
    out[:, 5] = ((Y * Z1 + 2 * Y * Z + 2 * Y1 * Z1 + Y1 * Z) * c).sum(1) / 24.0
    return out * np.sign(A)[:, None]


def _equivalent_widths(mom: np.ndarray) -> np.ndarray:
    """(..., 2) sorted widths of the uniform rectangle with the moments ``mom`` (..., 6)."""
    A = np.maximum(mom[..., 0], 1e-300)
    my, mz = mom[..., 1] / A, mom[..., 2] / A
    cyy = mom[..., 3] / A - my * my
    czz = mom[..., 4] / A - mz * mz
    cyz = mom[..., 5] / A - my * mz
    C = np.stack([np.stack([cyy, cyz], -1), np.stack([cyz, czz], -1)], -2)
    lam = np.linalg.eigvalsh(C)
    w = np.sqrt(12.0 * np.maximum(lam, 0.0))
    return np.where(mom[..., :1] > 0, w, 0.0)


# ------------------------------------------------------------------------------------------------
# contact patches
# ------------------------------------------------------------------------------------------------
def _accumulate(mom, j, tri, nx, o, R, xc, g, depth, rect, cos_flat, M) -> None:
    """Clip the triangles ``tri`` (K, 3, 3) (part frame) paired with grasps ``g`` (K,) (TCP origin
    ``o``, rotation ``R``, contact at TCP x ``xc``) to jaw ``j``'s pad box and add their moments."""
    y_lo, y_hi, z_lo, z_hi = rect
    P = np.einsum("kvi,kij->kvj", tri - o[:, None], R)  # v_tcp = R^T (v - o)
    K = len(P)
    box_lo = np.stack([xc - depth, np.full(K, y_lo), np.full(K, z_lo)], axis=1)
    box_hi = np.stack([xc + depth, np.full(K, y_hi), np.full(K, z_hi)], axis=1)
    meets = np.all((P.min(axis=1) <= box_hi) & (P.max(axis=1) >= box_lo), axis=1)  # cull before clipping
    P, g, nx, box_lo, box_hi = P[meets], g[meets], nx[meets], box_lo[meets], box_hi[meets]
    n = np.full(len(P), 3)
    for axis in range(3):
        P, n = clip_polygons(P, n, axis, box_lo[:, axis], keep_below=False)
        P, n = clip_polygons(P, n, axis, box_hi[:, axis], keep_below=True)
    if len(P) == 0 or P.shape[1] == 0:
        return
    m6 = polygon_moments(P[..., 1], P[..., 2], n)
    flat = np.abs(nx) >= cos_flat
    for k in range(6):
        mom[:, j, 0, k] += np.bincount(g, weights=m6[:, k], minlength=M)
        mom[:, j, 1, k] += np.bincount(g, weights=m6[:, k] * flat, minlength=M)


def contact_patches(part_mesh: trimesh.Trimesh, gripper: Gripper, T_part_tcp: np.ndarray, contacts: np.ndarray,
                    *, depth: float = CONTACT_DEPTH, flat_deg: float = FLAT_DEG, max_pairs: int = MAX_PAIRS):
    """Patch between each finger pad and the part (see the module docstring).

    Returns ``area`` (M, 2) m^2, ``type`` (M, 2) int8 into ``CONTACT_TYPES``, ``widths`` (M, 2, 2) m
    (sorted equivalent widths of the whole patch)."""
    T = np.asarray(T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    C = np.asarray(contacts, dtype=np.float64).reshape(-1, 2, 3)
    M = len(T)
    rect = pad_rectangle(gripper)
    tris = np.asarray(part_mesh.triangles, dtype=np.float64)
    fn = np.asarray(part_mesh.face_normals, dtype=np.float64)
    cent = tris.mean(axis=1)
    face_rad = np.linalg.norm(tris - cent[:, None], axis=2).max(axis=1) if len(tris) else np.zeros(0)
    pad_reach = math.hypot(np.abs(rect[0]).max(), np.abs(rect[1]).max()) + depth
    F = len(tris)
    cent_sq = np.einsum("fi,fi->f", cent, cent)
    slab_tol = face_rad + depth  # a face meeting the slab has its centroid this close to the contact plane
    lat_tol = (pad_reach + face_rad) ** 2  # ... and this close (squared) to the contact, laterally
    cos_flat = math.cos(math.radians(flat_deg))
    # moments: [grasp, jaw, (all, flat), 6]
    mom = np.zeros((M, 2, 2, 6))
    R = T[:, :3, :3]
    o = T[:, :3, 3]
    for j in range(2):
        ysgn = -1.0 if j == 0 else 1.0
        y_lo, y_hi = sorted(ysgn * rect[0])
        z_lo, z_hi = rect[1]
        # the rolls of one candidate share the contact and the closing axis: the face search and the
        # slab cull (roll-independent) run once per distinct (contact, closing axis)
        key = np.concatenate([C[:, j], R[:, :, 0], np.einsum("mi,mi->m", C[:, j] - o, R[:, :, 0])[:, None]], axis=1)
        _, rep, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
        inv = inv.reshape(-1)
        U = len(rep)
        members = np.argsort(inv, kind="stable")
        gsize = np.bincount(inv, minlength=U)
        gstart = np.cumsum(gsize) - gsize
        cu, axu = C[rep, j], R[rep, :, 0]
        x_cu = np.einsum("mi,mi->m", cu - o[rep], axu)  # contact's x in the TCP frame
        # faces near each contact's pad: a dense (faces x contacts) test on centroids, chunked so
        # that at most max_pairs (face, contact) pairs exist at once
        step = max(1, max_pairs // max(F, 1))
        for start in range(0, U if F else 0, step):
            stop = min(U, start + step)
            ax, c = axu[start:stop], cu[start:stop]
            xs = cent @ ax.T - np.einsum("bi,bi->b", c, ax)  # (F, b) centroid height over the contact plane
            nx_all = fn @ ax.T
            d2 = cent_sq[:, None] - 2.0 * (cent @ c.T) + np.einsum("bi,bi->b", c, c)  # squared distance
            near = (np.abs(xs) <= slab_tol[:, None]) & (d2 - xs * xs <= lat_tol[:, None]) & \
                ((nx_all < 0) if j == 0 else (nx_all > 0))
            f, b = np.nonzero(near)
            if len(f) == 0:
                continue
            gu = start + b
            nx = nx_all[f, b]
            # exact cull on the contact slab (x only, the same for every roll)
            x = np.einsum("kvi,ki->kv", tris[f] - cu[gu][:, None], axu[gu])  # x - x_contact
            keep = (x.min(axis=1) <= depth) & (x.max(axis=1) >= -depth)
            gu, f, nx = gu[keep], f[keep], nx[keep]
            # expand the survivors to every roll of their contact, in bounded sub-chunks
            nrep = gsize[gu]
            ends = np.cumsum(nrep)
            s0 = 0
            while s0 < len(gu):
                s1 = s0 + max(1, int(np.searchsorted(ends[s0:] - (ends[s0 - 1] if s0 else 0), max_pairs, side="right")))
                r = nrep[s0:s1]
                pu = np.repeat(np.arange(s0, s1), r)
                within = np.arange(len(pu)) - np.repeat(np.cumsum(r) - r, r)
                g = members[gstart[gu[pu]] + within]
                _accumulate(mom, j, tris[f[pu]], nx[pu], o[g], R[g], x_cu[gu[pu]], g, depth,
                            (y_lo, y_hi, z_lo, z_hi), cos_flat, M)
                s0 = s1
    area = mom[:, :, 0, 0]
    widths = _equivalent_widths(mom[:, :, 0])
    flat_widths = _equivalent_widths(mom[:, :, 1])
    line = (widths[..., 1] >= MIN_SIDE) & (widths[..., 1] >= LINE_ASPECT * widths[..., 0])
    kind = np.where(flat_widths[..., 0] >= MIN_SIDE, 2, np.where(line, 1, 0)).astype(np.int8)
    return area, kind, widths


# ------------------------------------------------------------------------------------------------
# gravity margin and epsilon
# ------------------------------------------------------------------------------------------------
def fibonacci_directions(n: int) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere (deterministic)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = k * math.pi * (3.0 - math.sqrt(5.0))
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def patch_radius(area: np.ndarray) -> np.ndarray:
    """Soft-finger disc radius ``max(sqrt(area / pi), MIN_PATCH_RADIUS)`` (m) of patch areas (m^2)."""
    return np.maximum(np.sqrt(np.maximum(area, 0.0) / math.pi), MIN_PATCH_RADIUS)


def gravity_margin(mass_props: MassProperties, T_world_part: np.ndarray, T_part_tcp: np.ndarray,
                   width: np.ndarray, area: np.ndarray, *, mu: float, normal_force: float,
                   accel_g: float = 1.0) -> np.ndarray:
    """(M,) friction available / needed to hold the part under gravity plus ``accel_g`` g in the
    worst direction (module docstring). ``area`` (M, 2) m^2, ``width`` (M,) m, ``normal_force``: N
    pressing each contact (``grip_force / CONTACTS_PER_GRIP``)."""
    T = np.asarray(T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    R = T[:, :3, :3]
    g_hat = np.einsum("mji,j->mi", R, T_world_part[:3, :3].T @ np.array([0.0, 0.0, -1.0]))  # in TCP
    com = np.einsum("mji,mj->mi", R, mass_props.com - T[:, :3, 3])  # centre of mass in TCP
    u = np.concatenate([g_hat[:, None], np.broadcast_to(fibonacci_directions(N_DIRECTIONS), (len(T), N_DIRECTIONS, 3))], 1)
    f = mass_props.mass * G * (g_hat[:, None] + accel_g * u)  # (M, D, 3) load on the part, TCP frame
    tau = np.cross(com[:, None], f)
    f_t = f.copy()
    f_t[..., 0] = 0.0
    tau_perp = tau.copy()
    tau_perp[..., 0] = 0.0
    x = np.array([1.0, 0.0, 0.0])
    h = np.cross(tau_perp, x) / np.maximum(np.asarray(width, dtype=np.float64), 1e-9)[:, None, None]
    t_max = mu * normal_force
    if t_max <= 0:  # no friction: nothing holds the part against a tangential load
        return np.zeros(len(T))
    tors_max = (2.0 / 3.0) * mu * normal_force * patch_radius(area).sum(axis=1)  # both contacts
    r_tors = np.abs(tau[..., 0]) / tors_max[:, None]
    r0 = np.hypot(np.linalg.norm(0.5 * f_t - h, axis=2) / t_max, r_tors)
    r1 = np.hypot(np.linalg.norm(0.5 * f_t + h, axis=2) / t_max, r_tors)
    demand = np.maximum(r0, r1).max(axis=1)
    return 1.0 / np.maximum(demand, 1e-12)


def _tangent_basis(nu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.where(np.abs(nu[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    t1 = np.cross(nu, a)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    return t1, np.cross(nu, t1)


def contact_wrenches(contacts: np.ndarray, normals: np.ndarray, com: np.ndarray, rho: float, mu: float,
                     torsion: np.ndarray) -> np.ndarray:
    """(M, 2 * (CONE_EDGES + 2), 6) primitive wrenches (force N, torque / ``rho``) of two soft-finger
    contacts with unit normal force: the cone edges and the normal force with +-torsion.
    ``torsion`` (M, 2): torsional friction per newton of normal force, m."""
    nu = -np.asarray(normals, dtype=np.float64)
    nu = nu / np.linalg.norm(nu, axis=-1, keepdims=True)
    t1, t2 = _tangent_basis(nu)
    th = 2.0 * math.pi * np.arange(CONE_EDGES) / CONE_EDGES
    edges = nu[:, :, None] + mu * (np.cos(th)[:, None] * t1[:, :, None] + np.sin(th)[:, None] * t2[:, :, None])
    F = np.concatenate([edges, np.repeat(nu[:, :, None], 2, axis=2)], axis=2)  # (M, 2, E + 2, 3)
    r = (np.asarray(contacts, dtype=np.float64) - com)[:, :, None]
    tq = np.cross(r, F)
    tq[:, :, CONE_EDGES] += torsion[..., None] * nu
    tq[:, :, CONE_EDGES + 1] -= torsion[..., None] * nu
    W = np.concatenate([F, tq / rho], axis=3)
    return W.reshape(len(W), -1, 6)


def ferrari_canny(W: np.ndarray) -> np.ndarray:
    """(M,) L1 epsilon: distance from the origin to the hull of each wrench set ``W`` (M, k, 6);
    0 when the origin is not strictly inside or the hull is degenerate. One Qhull call per grasp."""
    out = np.zeros(len(W))
    for m in range(len(W)):
        try:
            eq = ConvexHull(W[m], qhull_options=QHULL_OPTIONS).equations
        except QhullError:
            continue
        d = -eq[:, -1]  # unit facet normals: n . x + b <= 0 inside
        e = float(d.min())
        out[m] = e if e > EPSILON_TOL else 0.0  # below the joggle: the origin is on the boundary (flat set)
    return out


def quantised_patch_radius(area: np.ndarray) -> np.ndarray:
    """:func:`patch_radius` rounded down to the geometric grid ``MIN_PATCH_RADIUS * (1 +
    RADIUS_STEP)^k`` (conservative: less torsion), so that grasps with the same contacts share one
    epsilon."""
    r = patch_radius(area)
    k = np.floor(np.log(r / MIN_PATCH_RADIUS) / math.log1p(RADIUS_STEP) + 1e-9)
    return MIN_PATCH_RADIUS * np.exp(np.maximum(k, 0.0) * math.log1p(RADIUS_STEP))


def epsilon_dedup(contacts: np.ndarray, normals: np.ndarray, area: np.ndarray, com: np.ndarray, rho: float,
                  mu: float) -> np.ndarray:
    """(M,) Ferrari-Canny epsilon, one Qhull call per distinct wrench set: the rolls of one
    candidate share contacts and normals, and their patch radii are quantised
    (:func:`quantised_patch_radius`), so most of them are computed once."""
    M = len(contacts)
    if M == 0:
        return np.zeros(0)
    rq = quantised_patch_radius(area)
    key = np.concatenate([np.asarray(contacts, dtype=np.float64).reshape(M, 6),
                          np.asarray(normals, dtype=np.float64).reshape(M, 6), rq], axis=1)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    u = first
    W = contact_wrenches(np.asarray(contacts)[u], np.asarray(normals)[u], com, rho, mu, (2.0 / 3.0) * mu * rq[u])
    return ferrari_canny(W)[inverse.reshape(-1)]


def part_radius(part_mesh: trimesh.Trimesh, com: np.ndarray) -> float:
    """Largest distance of the part's (hull) vertices from ``com``, m: the torque scale of epsilon."""
    v = np.asarray(part_mesh.convex_hull.vertices if len(part_mesh.vertices) > 64 else part_mesh.vertices)
    return float(np.linalg.norm(v - com, axis=1).max())


def grasp_quality(part_mesh: trimesh.Trimesh, mass_props: MassProperties, gripper: Gripper,
                  T_part_tcp: np.ndarray, contacts: np.ndarray, normals: np.ndarray, width: np.ndarray, *,
                  T_world_part: np.ndarray, mu: float, grip_force: float | None = None) -> Quality:
    """Contact patches, gravity margin and epsilon of ``M`` grasps (module docstring).

    Parameters
    ----------
    part_mesh : trimesh.Trimesh
        Part frame, metres.
    mass_props : MassProperties
        From :func:`grasplan.mass.mass_properties`.
    gripper : Gripper
        Its finger gives the pad; its ``grip_force`` (N, sum of both jaws) is used unless ``grip_force``.
    T_part_tcp : (M, 4, 4)
    contacts, normals : (M, 2, 3)
        Contact points (m) and outward unit surface normals, part frame; contact 0 on the TCP's -x side.
    width : (M,)
        Contact distance, m.
    T_world_part : (4, 4)
        The part's pose (gives the direction of gravity).
    mu : float
        Friction coefficient (>= 0).
    grip_force : float, optional
        Gripping force, N (sum of both jaws: each contact is pressed with half); default
        ``gripper.grip_force``.
    """
    T = check_transform(T_part_tcp, "T_part_tcp", batch=True) if len(np.shape(T_part_tcp)) == 3 else \
        check_transform(T_part_tcp, "T_part_tcp")[None]
    Twp = check_transform(T_world_part, "T_world_part")
    M = len(T)
    C = np.asarray(contacts, dtype=np.float64)
    N = np.asarray(normals, dtype=np.float64)
    w = np.asarray(width, dtype=np.float64).reshape(-1)
    if C.shape != (M, 2, 3) or N.shape != (M, 2, 3) or w.shape != (M,):
        raise InputError(f"grasp quality: expected contacts and normals (M, 2, 3) and width (M,) for M = {M} "
                         f"grasps, got {C.shape}, {N.shape}, {w.shape}")
    if not (np.all(np.isfinite(C)) and np.all(np.isfinite(N)) and np.all(np.isfinite(w))):
        raise InputError("grasp quality: contacts, normals or widths hold NaN or infinite values")
    if not (math.isfinite(mu) and mu >= 0):
        raise InputError(f"grasp quality: mu must be a finite number >= 0, got {mu!r}")
    F = float(gripper.grip_force if grip_force is None else grip_force)
    if not (math.isfinite(F) and F > 0):
        raise InputError(f"grasp quality: grip_force must be > 0 N, got {grip_force!r} (gripper YAML grip_force)")
    if M == 0:
        z2 = np.zeros((0, 2))
        return Quality(contact_area=z2, contact_type=np.zeros((0, 2), dtype=np.int8), contact_width=np.zeros((0, 2, 2)),
                       gravity_margin=np.zeros(0), epsilon=np.zeros(0), grip_force=F, mu=float(mu))
    area, kind, widths = contact_patches(part_mesh, gripper, T, C)
    margin = gravity_margin(mass_props, Twp, T, w, area, mu=mu, normal_force=F / CONTACTS_PER_GRIP)
    eps = epsilon_dedup(C, N, area, mass_props.com, max(part_radius(part_mesh, mass_props.com), 1e-9), mu)
    return Quality(contact_area=area, contact_type=kind, contact_width=widths, gravity_margin=margin,
                   epsilon=eps, grip_force=F, mu=float(mu))


# ------------------------------------------------------------------------------------------------
# scoring configuration
# ------------------------------------------------------------------------------------------------
def quality_columns(quality: Quality, rows: np.ndarray, M: int) -> dict:
    """Per-pose arrays of :class:`grasplan.result.GraspTable` for ``M`` poses whose rows ``rows``
    have ``quality`` (the others NaN, type -1): contact_area (M, 2), contact_type (M, 2) int8,
    gravity_margin (M,), epsilon (M,)."""
    rows = np.asarray(rows, dtype=np.int64)
    area = np.full((M, 2), np.nan)
    kind = np.full((M, 2), -1, dtype=np.int8)
    gm = np.full(M, np.nan)
    eps = np.full(M, np.nan)
    area[rows], kind[rows], gm[rows], eps[rows] = quality.contact_area, quality.contact_type, \
        quality.gravity_margin, quality.epsilon
    return {"contact_area": area, "contact_type": kind, "gravity_margin": gm, "epsilon": eps}


def quality_and_score(part_mesh: trimesh.Trimesh, gripper: Gripper, T_world_part: np.ndarray, T_part_tcp: np.ndarray,
                      candidate: np.ndarray, candidates, status: np.ndarray, mu: float, params):
    """The grasp stage's quality step: mass properties at ``params.density`` / ``params.mass``, the
    quality of the ``ok`` poses and the score of every pose (NaN where not ``ok``) with the weights
    ``params.score_weights`` / ``params.score_refs`` (a :class:`grasplan.params.GraspParams`).

    Returns ``(Quality of the ok rows, MassProperties, score (M,), note)``. A part without volume
    (flat, degenerate: no mass properties) has no quality: ``(None, None, score, note)`` with the
    score of the other terms and ``note`` saying why; ``note`` is "" otherwise."""
    from .mass import mass_properties
    from .scoring import PHYSICAL_TERMS, ScoringConfig, score_grasps

    T = np.asarray(T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    M = len(T)
    ok = np.flatnonzero(np.asarray(status).astype(str) == "ok")
    ci = np.asarray(candidate, dtype=np.int64)[ok]
    width = np.asarray(candidates.width, dtype=np.float64)[ci]
    cfg = ScoringConfig.from_params(params.score_weights, params.score_refs)
    try:
        mp = mass_properties(part_mesh, density=params.density, mass=params.mass)
    except InputError as exc:
        if params.mass is not None or params.density != type(params)().density:
            raise  # the user asked for a mass: say why there is none
        note = f"no grasp quality: {exc}; the score uses only the other terms"
        weights = tuple((n, w) for n, w in cfg.weights if n not in PHYSICAL_TERMS)
        score = np.full(M, np.nan)
        if len(ok) and sum(w for _, w in weights) > 0:
            score[ok] = score_grasps(part_mesh, T_world_part, T[ok], width, float(gripper.max_opening), weights,
                                     scoring=cfg)
        return None, None, score, note
    q = grasp_quality(part_mesh, mp, gripper, T[ok], candidates.contacts[ci], candidates.normals[ci], width,
                      T_world_part=T_world_part, mu=mu)
    score = np.full(M, np.nan)
    if len(ok):
        score[ok] = score_grasps(part_mesh, T_world_part, T[ok], width, float(gripper.max_opening), cfg.weights,
                                 quality=q, scoring=cfg, com=mp.com)
    return q, mp, score, ""


def score_quality_terms(quality: Quality, config: ScoringConfig | None = None) -> dict[str, np.ndarray]:
    """Normalised quality terms, each (M,) in [0, 1], higher is better:

    ``gravity_margin = clip(log(margin) / log(gravity_margin_ref), 0, 1)`` (0 when it slips, 1 at
    the reference margin and above); ``epsilon = clip(epsilon / epsilon_ref, 0, 1)``."""
    cfg = config if config is not None else DEFAULT_SCORING
    gm = np.clip(np.log(np.maximum(quality.gravity_margin, 1e-300)) / math.log(cfg.gravity_margin_ref), 0.0, 1.0)
    eps = np.clip(quality.epsilon / cfg.epsilon_ref, 0.0, 1.0)
    return {"gravity_margin": gm, "epsilon": eps}


# ------------------------------------------------------------------------------------------------
# JSON of a grasp table's quality and simulation columns (grasplan.result)
# ------------------------------------------------------------------------------------------------
def quality_entries(table, ids: np.ndarray) -> list | None:
    """The ``quality`` object per grasp row ``ids`` of a :class:`grasplan.result.GraspTable`
    (``{score, gravity_margin, epsilon, contact: [{area_m2, type}] * 2}``, None for grasps without
    quality), or None when the table has no quality columns."""
    if table.gravity_margin is None:
        return None
    ids = np.asarray(ids, dtype=np.int64)
    gm = table.gravity_margin[ids]
    has = np.isfinite(gm)
    area = np.round(table.contact_area[ids], 12).tolist()
    kind = table.contact_type[ids].tolist()
    score = table.score[ids].tolist()
    gml, eps = gm.tolist(), table.epsilon[ids].tolist()
    return [{"score": None if score[k] != score[k] else score[k], "gravity_margin": gml[k], "epsilon": eps[k],
             "contact": [{"area_m2": area[k][j], "type": CONTACT_TYPES[kind[k][j]]} for j in range(2)]}
            if has[k] else None for k in range(len(ids))]


def sim_entries(table, ids: np.ndarray) -> list | None:
    """The ``sim`` object ``{success, slip_m, turn_deg}`` per grasp row (None: not simulated), or
    None when the table has no simulation columns."""
    if table.sim_success is None:
        return None
    ids = np.asarray(ids, dtype=np.int64)
    ok, slip, turn = table.sim_success[ids].tolist(), table.sim_slip_m[ids].tolist(), table.sim_turn_deg[ids].tolist()
    return [{"success": bool(ok[k]), "slip_m": slip[k], "turn_deg": turn[k]} if ok[k] >= 0 else None
            for k in range(len(ids))]


def _bad(where: str, i: int, g, what: str) -> InputError:
    gid = g.get("id") if isinstance(g, dict) else None
    return InputError(f"{where}: grasps[{i}] (id {str(gid)[:20]}): {what}")


def parse_quality_sim(grasps: list, where: str) -> dict:
    """GraspTable quality / sim columns from the grasp dicts of a file (keys absent: no columns);
    InputError naming the grasp for a malformed ``quality`` or ``sim`` object."""
    M = len(grasps)
    out: dict = {}
    qs = [g.get("quality") if isinstance(g, dict) else None for g in grasps]
    if any(q is not None for q in qs):
        cols = {"contact_area": np.full((M, 2), np.nan), "contact_type": np.full((M, 2), -1, dtype=np.int8),
                "gravity_margin": np.full(M, np.nan), "epsilon": np.full(M, np.nan)}
        for i, q in enumerate(qs):
            if q is None:
                continue
            try:
                gm, eps = float(q["gravity_margin"]), float(q["epsilon"])
                con = q["contact"]
                area = [float(c["area_m2"]) for c in con]
                kind = [CONTACT_TYPES.index(c["type"]) for c in con]
                ok = (len(con) == 2 and math.isfinite(gm) and gm >= 0 and math.isfinite(eps) and eps >= 0
                      and all(math.isfinite(a) and a >= 0 for a in area)
                      and not any(isinstance(v, bool) for v in (q["gravity_margin"], q["epsilon"])))
            except (KeyError, TypeError, ValueError, OverflowError, AttributeError):
                ok = False
            if not ok:
                raise _bad(where, i, grasps[i], "'quality' malformed; expected {score, gravity_margin >= 0, "
                           "epsilon >= 0, contact: [{area_m2 >= 0, type: point|line|surface}] x 2} or null")
            cols["gravity_margin"][i], cols["epsilon"][i] = gm, eps
            cols["contact_area"][i], cols["contact_type"][i] = area, kind
        out.update(cols)
    ss = [g.get("sim") if isinstance(g, dict) else None for g in grasps]
    if any(x is not None for x in ss):
        succ, slip, turn = np.full(M, -1, dtype=np.int8), np.full(M, np.nan), np.full(M, np.nan)
        for i, x in enumerate(ss):
            if x is None:
                continue
            try:
                ok = isinstance(x["success"], bool) and all(
                    not isinstance(x[k], bool) and math.isfinite(float(x[k])) and float(x[k]) >= 0
                    for k in ("slip_m", "turn_deg"))
            except (KeyError, TypeError, ValueError, OverflowError):
                ok = False
            if not ok:
                raise _bad(where, i, grasps[i], "'sim' malformed; expected {success: bool, slip_m >= 0, "
                           "turn_deg >= 0} or null")
            succ[i], slip[i], turn[i] = int(x["success"]), float(x["slip_m"]), float(x["turn_deg"])
        out.update(sim_success=succ, sim_slip_m=slip, sim_turn_deg=turn)
    return out


def parse_mass_record(part: dict, where: str) -> dict | None:
    """The ``part`` mass record (``mass_kg``, ``com``, ``density``, ``mass_from``) of a file, None
    when absent; InputError when malformed."""
    if not isinstance(part, dict) or "mass_kg" not in part:
        return None
    try:
        m, d = float(part["mass_kg"]), float(part.get("density", "nan"))
        com = np.asarray(part["com"], dtype=np.float64)
        ok = m > 0 and math.isfinite(m) and com.shape == (3,) and np.all(np.isfinite(com))
    except (KeyError, TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise InputError(f"{where}: part.mass_kg must be a positive number and part.com three finite numbers (m)")
    return {"mass_kg": m, "com": com.tolist(), "density": d, "mass_from": str(part.get("mass_from", "mesh"))}
