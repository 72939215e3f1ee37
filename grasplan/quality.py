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

**Gravity margin** (soft-finger model). Each jaw presses with ``grip_force`` ``F`` (N). A contact
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
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
import yaml
from scipy.spatial import ConvexHull, QhullError, cKDTree

from .config_files import config_number, packaged_file
from .errors import ConfigError, InputError
from .gripper import Gripper
from .mass import MassProperties
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
#: edges of the linearised friction cone
CONE_EDGES = 8
#: load directions sampled for the worst-case 1 g acceleration
N_DIRECTIONS = 64
#: standard gravity, m/s^2
G = 9.81
#: largest (grasp, face) pairs held at once by the patch computation
MAX_PAIRS = 400_000
#: contact type codes of ``Quality.contact_type``
CONTACT_TYPES = ("point", "line", "surface")
#: scoring configuration shipped with grasplan
SCORING_FILE = packaged_file("configs", "scoring.yaml")


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
        N per jaw used.
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
            "contact": [{"area": float(self.contact_area[i, j]), "type": CONTACT_TYPES[int(self.contact_type[i, j])]}
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
    # faces no larger than the pad are found by a KD-tree of centroids; larger ones (few on a CAD
    # mesh: big planar facets) are paired with every grasp
    small = np.flatnonzero(face_rad <= pad_reach)
    big = np.flatnonzero(face_rad > pad_reach)
    reach = pad_reach + (float(face_rad[small].max()) if len(small) else 0.0)
    tree = cKDTree(cent[small]) if len(small) else None
    cos_flat = math.cos(math.radians(flat_deg))
    # moments: [grasp, jaw, (all, flat), 6]
    mom = np.zeros((M, 2, 2, 6))
    R = T[:, :3, :3]
    o = T[:, :3, 3]
    for j in range(2):
        ysgn = -1.0 if j == 0 else 1.0
        y_lo, y_hi = sorted(ysgn * rect[0])
        z_lo, z_hi = rect[1]
        x_c = np.einsum("mi,mi->m", C[:, j] - o, R[:, :, 0])  # contact's x in the TCP frame
        counts = len(big) + (tree.query_ball_point(C[:, j], reach, return_length=True) if tree is not None and M
                             else np.zeros(M, dtype=np.int64))
        start = 0
        while start < M:
            stop = start + max(1, int(np.searchsorted(np.cumsum(counts[start:]), max_pairs, side="right")))
            lists = tree.query_ball_point(C[start:stop, j], reach) if tree is not None else [[]] * (stop - start)
            lens = np.array([len(x) for x in lists], dtype=np.int64)  # one entry per grasp
            g = np.concatenate([np.repeat(np.arange(start, stop), lens), np.repeat(np.arange(start, stop), len(big))])
            f = np.concatenate([small[np.concatenate([np.asarray(x, dtype=np.int64) for x in lists])] if lens.sum() else
                                np.zeros(0, dtype=np.int64), np.tile(big, stop - start)])
            start = stop
            if len(f) == 0:
                continue
            nx = np.einsum("ki,ki->k", fn[f], R[g, :, 0])
            facing = nx < 0 if j == 0 else nx > 0
            g, f, nx = g[facing], f[facing], nx[facing]
            # cull on the contact slab first (x only), then bring the survivors into the TCP frame
            x = np.einsum("kvi,ki->kv", tris[f] - o[g][:, None], R[g, :, 0])
            xc = x_c[g]
            near = (x.min(axis=1) <= xc + depth) & (x.max(axis=1) >= xc - depth)
            g, f, nx, xc = g[near], f[near], nx[near], xc[near]
            P = np.einsum("kvi,kij->kvj", tris[f] - o[g][:, None], R[g])  # v_tcp = R^T (v - o)
            box_lo = np.stack([xc - depth, np.full(len(f), y_lo), np.full(len(f), z_lo)], axis=1)
            box_hi = np.stack([xc + depth, np.full(len(f), y_hi), np.full(len(f), z_hi)], axis=1)
            meets = np.all((P.min(axis=1) <= box_hi) & (P.max(axis=1) >= box_lo), axis=1)  # cull before clipping
            P, g, nx, box_lo, box_hi = P[meets], g[meets], nx[meets], box_lo[meets], box_hi[meets]
            n = np.full(len(P), 3)
            for axis in range(3):
                P, n = clip_polygons(P, n, axis, box_lo[:, axis], keep_below=False)
                P, n = clip_polygons(P, n, axis, box_hi[:, axis], keep_below=True)
            if len(P) == 0 or P.shape[1] == 0:
                continue
            m6 = polygon_moments(P[..., 1], P[..., 2], n)
            flat = np.abs(nx) >= cos_flat
            for k in range(6):
                mom[:, j, 0, k] += np.bincount(g, weights=m6[:, k], minlength=M)
                mom[:, j, 1, k] += np.bincount(g, weights=m6[:, k] * flat, minlength=M)
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
                   width: np.ndarray, area: np.ndarray, *, mu: float, grip_force: float,
                   accel_g: float = 1.0) -> np.ndarray:
    """(M,) friction available / needed to hold the part under gravity plus ``accel_g`` g in the
    worst direction (module docstring). ``area`` (M, 2) m^2, ``width`` (M,) m, ``grip_force`` N."""
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
    t_max = mu * grip_force
    if t_max <= 0:  # no friction: nothing holds the part against a tangential load
        return np.zeros(len(T))
    tors_max = (2.0 / 3.0) * mu * grip_force * patch_radius(area).sum(axis=1)  # both contacts
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
            eq = ConvexHull(W[m]).equations
        except QhullError:
            continue
        d = -eq[:, -1]  # unit facet normals: n . x + b <= 0 inside
        out[m] = max(0.0, float(d.min()))
    return out


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
        Its finger gives the pad; its ``grip_force`` (N per jaw) is used unless ``grip_force``.
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
        N per jaw; default ``gripper.grip_force``.
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
    area, kind, widths = contact_patches(part_mesh, gripper, T, C)
    margin = gravity_margin(mass_props, Twp, T, w, area, mu=mu, grip_force=F)
    rho = max(part_radius(part_mesh, mass_props.com), 1e-9)
    torsion = (2.0 / 3.0) * mu * patch_radius(area)
    eps = ferrari_canny(contact_wrenches(C, N, mass_props.com, rho, mu, torsion)) if M else np.zeros(0)
    return Quality(contact_area=area, contact_type=kind, contact_width=widths, gravity_margin=margin,
                   epsilon=eps, grip_force=F, mu=float(mu))


# ------------------------------------------------------------------------------------------------
# scoring configuration
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ScoringConfig:
    """``configs/scoring.yaml``: ``weights`` ((term, weight), ...) and the normalisation references."""

    weights: tuple[tuple[str, float], ...]
    gravity_margin_ref: float
    epsilon_ref: float


def load_scoring(path: str | Path | None = None) -> ScoringConfig:
    """Read a scoring YAML (default: the packaged ``configs/scoring.yaml``); ConfigError naming the field."""
    p = Path(path) if path is not None else SCORING_FILE
    try:
        data = yaml.safe_load(p.read_text())
    except OSError as exc:
        raise ConfigError(f"scoring file {p}: cannot read it ({exc.strerror}); give an existing YAML file") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"scoring file {p}: not valid YAML: {exc}") from None
    if not isinstance(data, dict) or not isinstance(data.get("weights"), dict) or not data["weights"]:
        raise ConfigError(f"scoring file {p}: expected a mapping with 'weights: {{term: weight, ...}}'")
    unknown = set(data) - {"weights", "normalisation"}
    if unknown:
        raise ConfigError(f"scoring file {p}: unknown fields {sorted(unknown)}; allowed: weights, normalisation")
    weights = tuple((str(k), config_number(v, f"{p}: weights.{k}", nonneg=True)) for k, v in data["weights"].items())
    if sum(w for _, w in weights) <= 0:
        raise ConfigError(f"scoring file {p}: weights: at least one weight must be > 0")
    norm = data.get("normalisation") or {}
    if not isinstance(norm, dict) or set(norm) - {"gravity_margin_ref", "epsilon_ref"}:
        raise ConfigError(f"scoring file {p}: normalisation: allowed keys gravity_margin_ref, epsilon_ref")
    gm = config_number(norm.get("gravity_margin_ref", 10.0), f"{p}: normalisation.gravity_margin_ref", positive=True)
    if gm <= 1:
        raise ConfigError(f"scoring file {p}: normalisation.gravity_margin_ref must be > 1, got {gm:g}")
    eps = config_number(norm.get("epsilon_ref", 0.1), f"{p}: normalisation.epsilon_ref", positive=True)
    return ScoringConfig(weights=weights, gravity_margin_ref=gm, epsilon_ref=eps)


def load_score_weights(path: str | Path | None = None) -> tuple[tuple[str, float], ...]:
    """``((term, weight), ...)`` from a scoring YAML (default the packaged ``configs/scoring.yaml``)."""
    return load_scoring(path).weights


def score_quality_terms(quality: Quality, config: ScoringConfig | None = None) -> dict[str, np.ndarray]:
    """Normalised quality terms, each (M,) in [0, 1], higher is better:

    ``gravity_margin = clip(log(margin) / log(gravity_margin_ref), 0, 1)`` (0 when it slips, 1 at
    the reference margin and above); ``epsilon = clip(epsilon / epsilon_ref, 0, 1)``."""
    cfg = config if config is not None else load_scoring()
    gm = np.clip(np.log(np.maximum(quality.gravity_margin, 1e-300)) / math.log(cfg.gravity_margin_ref), 0.0, 1.0)
    eps = np.clip(quality.epsilon / cfg.epsilon_ref, 0.0, 1.0)
    return {"gravity_margin": gm, "epsilon": eps}
