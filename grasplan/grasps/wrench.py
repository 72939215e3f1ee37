"""Wrench metrics of a parallel-jaw grasp: gravity margin and Ferrari-Canny epsilon.

For ``M`` grasps (TCP frames ``T_part_tcp`` (M, 4, 4), contacts ``(M, 2, 3)`` with outward unit
normals, widths ``(M,)``, patch areas ``(M, 2)`` from :func:`grasplan.grasps.patches.contact_patches`;
metres, part frame): :func:`gravity_margin` (below 1 the part slips under the lift and shake of
:data:`LOAD`) and :func:`epsilon_dedup` (the Ferrari-Canny L1 quality). Both model soft-finger
contacts (:func:`torsion_length`), each pressed with ``grip_force / CONTACTS_PER_GRIP``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..part.mass import MassProperties
from .epsilon_kernels import facet_pairs
from .quality_kernels import margin_of_loads, margin_summary

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
#: standard gravity, m/s^2
G = 9.81
#: the gripper's ``grip_force`` (gripper YAML, N) is the datasheet gripping force, which Schunk (and
#: most makers of parallel grippers) define as the arithmetic sum of the forces of the jaws: each of
#: the two contacts is pressed with the normal force ``F = grip_force / CONTACTS_PER_GRIP`` (70 N for
#: the EGP-C 40's 140 N)
CONTACTS_PER_GRIP = 2


def patch_radius(area: np.ndarray) -> np.ndarray:
    """Soft-finger disc radius ``max(sqrt(area / pi), MIN_PATCH_RADIUS)`` (m) of patch areas (m^2)."""
    return np.maximum(np.sqrt(np.maximum(area, 0.0) / math.pi), MIN_PATCH_RADIUS)


#: soft-finger torsion: the largest friction torque about a contact normal is ``mu * N * SOFT_FINGER
#: * radius`` (uniform pressure on a disc of that radius: the integral of ``r dF`` gives 2/3)
SOFT_FINGER = 2.0 / 3.0


def torsion_length(area: np.ndarray) -> np.ndarray:
    """Torsional friction per unit ``mu`` and newton of normal force (m) of patches of ``area``
    (m^2): ``SOFT_FINGER * patch_radius(area)``: a soft-finger contact resists a torque about its
    normal of up to ``mu F SOFT_FINGER a`` (uniform pressure on a disc of radius ``a = sqrt(area /
    pi)``, at least ``MIN_PATCH_RADIUS``). The one definition used by :func:`gravity_margin`,
    epsilon and the MuJoCo check (:mod:`grasplan.sim.simulate`)."""
    return SOFT_FINGER * patch_radius(area)


@dataclass(frozen=True)
class LoadModel:
    """The lift and shake a grasp must survive: one definition for :func:`gravity_margin` and the
    MuJoCo check (:mod:`grasplan.sim.simulate` runs exactly this profile).

    After closing, the gripper lifts ``lift_height`` in ``lift_s`` (cosine profile: vertical
    acceleration ``+-lift_accel``, up first), then shakes ``+-shake_accel`` (sine at ``shake_hz``)
    along world x for ``shake_s / 2`` and along world y for ``shake_s / 2``. The jaws must supply
    ``m (a - g)`` for every gripper acceleration ``a`` of :meth:`accelerations`: the lift's two
    extremes and the shake's peak in ``shake_directions`` horizontal directions (x and y, the
    simulation's, among them; the margin does not depend on how the part happens to be turned about
    the vertical). Peak load: ``m sqrt(g^2 + shake_accel^2)`` = 1.12 g tilted 27 deg while shaking,
    ``m (g + lift_accel)`` = 1.20 g while lifting."""

    lift_height: float = 0.10      #: m
    lift_s: float = 0.5            #: s
    shake_accel: float = 5.0       #: m/s^2, amplitude
    shake_s: float = 1.0           #: s, half along world x then half along world y
    shake_hz: float = 4.0          #: Hz
    shake_directions: int = 8      #: horizontal directions the margin checks (multiple of 4: includes +-x, +-y)

    @property
    def lift_accel(self) -> float:
        """Peak vertical acceleration of the cosine lift profile, m/s^2."""
        return 0.5 * self.lift_height * (math.pi / self.lift_s) ** 2

    def accelerations(self) -> np.ndarray:
        """(K, 3) gripper accelerations in the world (m/s^2) whose loads the margin checks: lift up,
        lift braking, and the shake's peak in ``shake_directions`` horizontal directions."""
        th = 2.0 * math.pi * np.arange(self.shake_directions) / self.shake_directions
        shake = self.shake_accel * np.column_stack([np.cos(th), np.sin(th), np.zeros_like(th)])
        lift = np.array([[0.0, 0.0, self.lift_accel], [0.0, 0.0, -self.lift_accel]])
        return np.vstack([lift, shake])


    def peak_g(self) -> float:
        """The largest load of :meth:`accelerations`, in g (gravity included)."""
        return float(np.linalg.norm(np.array([0.0, 0.0, G]) + self.accelerations(), axis=1).max() / G)


#: the load model of the margin and the simulation
LOAD = LoadModel()
#: pad-pressure moment: a flat patch pressed with ``F`` carries a moment perpendicular to the
#: closing axis of up to ``F * PRESSURE_ARM * w`` by shifting its centre of pressure (``w``: the
#: patch's smaller equivalent width): 1/2, the pressure at the patch's edge (tipping, the limit of
#: rigid bodies, which the simulation reaches: its contact points sit on the patch's corners). A
#: pressure centre shifted by ``e`` bears on the effective patch ``1 - 2 e / w`` of the area
#: (Meyerhof's effective width), which scales the patch's torsion radius by ``sqrt(1 - 2 e / w)``.
PRESSURE_ARM = 0.5


def pressure_widths(contact_type: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """(M, 2) width (m) of each jaw's pad-pressure moment (:data:`PRESSURE_ARM`): the smaller
    equivalent width of a surface patch (``contact_type`` 2, ``widths`` (M, 2, 2) sorted, from
    :func:`grasplan.grasps.patches.contact_patches`); 0 for point and line contacts."""
    return np.where(np.asarray(contact_type) == 2, np.asarray(widths, dtype=np.float64)[..., 0], 0.0)


#: the margin is found by bisection in log scale between these load factors (iterations: relative
#: precision ``log(hi / lo) / 2^iterations``, 3e-10); a margin above the bracket is reported as its top
MARGIN_BRACKET, MARGIN_ITERATIONS = (1e-4, 1e4), 36


def gravity_margin(mass_props: MassProperties, T_world_part: np.ndarray, T_part_tcp: np.ndarray,
                   width: np.ndarray, area: np.ndarray, *, mu: float, normal_force: float,
                   patch_width: np.ndarray | None = None, load: LoadModel = LOAD) -> np.ndarray:
    """(M,) the largest factor ``s`` by which the loads of ``load`` can be scaled and still be held:
    below 1 the part slips. ``area`` (M, 2) m^2, ``width`` (M,) m,
    ``normal_force``: N pressing each contact (``grip_force / CONTACTS_PER_GRIP``); ``patch_width``
    (M, 2) m: each patch's smaller equivalent width (its pad-pressure moment, :data:`PRESSURE_ARM`;
    ``None``: none).

    At a load ``s f`` (TCP frame, at the centre of mass) the jaws press with ``F -+ s f_x / 2``
    (contact 0 on the -x side; the centric jaws share the load along the closing axis); the
    tangential load is shared equally; the moment perpendicular to the
    closing axis goes first to the pads' pressure (``PRESSURE_ARM * (N0 w0 + N1 w1)``), the rest to a
    couple of opposite tangential forces over the width; each contact's tangential utilisation
    ``u = |t| / (mu N)`` must stay <= 1 and the twist about the closing axis is held by the two
    patches' torsional friction, each on its soft-finger ellipse: ``|s tau_x| <= sum_j mu N_j L_j
    sqrt(1 - u_j^2)`` (``L_j``: :func:`torsion_length`, times ``sqrt(1 - p)`` when the pressure
    moment is a share ``p`` of its capacity (effective patch), at least the point contact's), the
    pad model of the MuJoCo check. Homogeneous: the margin grows in proportion to ``normal_force``.
    The bisection on the scale is compiled (:func:`grasplan.grasps.quality_kernels.margin_of_loads`).

    The loads are those of the lift and shake the MuJoCo check applies (:class:`LoadModel`,
    :data:`LOAD`): ``f = m (g - a)`` for the gripper accelerations ``a`` of
    :meth:`LoadModel.accelerations` (the lift's +-1.97 m/s^2, the shake's +-5 m/s^2 in 8 horizontal
    directions), applied at the centre of mass, whose offset from the contact axis is the lever arm.
    The simulation's pads are this model (:mod:`grasplan.sim.simulate`: one torsional resistance per
    pad)."""
    args = _margin_args(mass_props, T_world_part, T_part_tcp, width, area, mu=mu, normal_force=normal_force,
                        patch_width=patch_width, load=load)
    return margin_of_loads(*args) if args is not None else np.zeros(len(np.asarray(T_part_tcp).reshape(-1, 16)))


def margin_summary_of(mass_props: MassProperties, T_world_part: np.ndarray, T_part_tcp: np.ndarray,
                      width: np.ndarray, area: np.ndarray, *, mu: float, normal_force: float,
                      patch_width: np.ndarray | None = None, load: LoadModel = LOAD) -> tuple[int, float]:
    """``(grasps whose gravity_margin is >= 1, the largest gravity_margin)`` (0 and 0.0 for no grasp):
    the two numbers of :func:`gravity_margin`'s margins (same arguments), bisecting only the grasps
    that could change them (:func:`grasplan.grasps.quality_kernels.margin_summary`)."""
    args = _margin_args(mass_props, T_world_part, T_part_tcp, width, area, mu=mu, normal_force=normal_force,
                        patch_width=patch_width, load=load)
    if args is None:
        return 0, 0.0
    n, best = margin_summary(*args)
    return int(n), float(best)


def _margin_args(mass_props: MassProperties, T_world_part: np.ndarray, T_part_tcp: np.ndarray, width: np.ndarray,
                 area: np.ndarray, *, mu: float, normal_force: float, patch_width: np.ndarray | None,
                 load: LoadModel) -> tuple[Any, ...] | None:
    """The arguments of the margin kernels, or None when nothing can hold (no grasp, no friction)."""
    T = np.asarray(T_part_tcp, dtype=np.float64).reshape(-1, 4, 4)
    M = len(T)
    if not (mu * normal_force > 0) or M == 0:  # no friction: nothing holds the part against a tangential load
        return None
    # load on the part that the jaws must hold, world: m (g - a); in the part frame (the kernel turns
    # it and the centre of mass into each TCP frame)
    f_world = mass_props.mass * (np.array([0.0, 0.0, -G])[None] - load.accelerations())  # (D, 3)
    f_part = f_world @ np.asarray(T_world_part, dtype=np.float64)[:3, :3]               # rows: R_wp^T f
    pw = np.zeros((M, 2)) if patch_width is None else np.maximum(np.asarray(patch_width, dtype=np.float64), 0.0)
    L = torsion_length(np.asarray(area, dtype=np.float64))
    c = np.ascontiguousarray
    return (c(T[:, :3, :3]), c(T[:, :3, 3]), c(mass_props.com, dtype=np.float64), c(f_part),
            c(PRESSURE_ARM * pw[:, 0]), c(PRESSURE_ARM * pw[:, 1]),
            c(1.0 / np.maximum(np.asarray(width, dtype=np.float64), 1e-9)), c(L[:, 0]), c(L[:, 1]),
            float(normal_force), float(mu), SOFT_FINGER * MIN_PATCH_RADIUS,
            math.log(MARGIN_BRACKET[0]), math.log(MARGIN_BRACKET[1]), MARGIN_ITERATIONS)


def _tangent_basis(nu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.where(np.abs(nu[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    t1 = np.cross(nu, a)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    return t1, np.cross(nu, t1)


def contact_wrenches(contacts: np.ndarray, normals: np.ndarray, com: np.ndarray, rho: float, mu: float,
                     torsion: np.ndarray) -> np.ndarray:
    """(M, 2 * (CONE_EDGES + 2), 6) primitive wrenches (force N, torque / ``rho``) of two soft-finger
    contacts with unit normal force: the cone edges and the normal force with +-torsion.
    ``torsion`` (M, 2): torsional friction per newton of normal force, m.

    The friction cone is linearised with ``CONE_EDGES`` (8) edges ``nu + mu (cos k t1 + sin k t2)``,
    plus the pure normal force with torsion ``+-(2/3) mu a nu``; torques about the centre of mass are
    divided by the part's radius ``rho`` (largest distance of the part's vertices from the centre of
    mass), so wrenches are in newtons."""
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
    from scipy.spatial import ConvexHull, QhullError  # SciPy loads with the first quality computed

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


#: exact epsilon: relative tolerance of the support test of a candidate facet (value units: 1 = on the plane)
FACET_TOL = 1e-10
#: exact epsilon: grasps processed at once (memory: ~ chunk x 304 candidates x 6 floats)
EPS_CHUNK = 1024


def _bipyramid_dirs(mu: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local facet families of a contact's wrench bipyramid at unit torsion radius (coordinates
    (alpha, beta, gamma, s): force ``alpha nu + beta t1 + gamma t2`` and torsion ``s``; every
    primitive wrench has alpha = 1). Returns the triangle directions (16, 4), the edge direction
    pairs (24, 2, 4) and the 10 local points (10, 4). For torsion radius ``tau`` the triangles'
    ``s`` column and the edges' first direction's ``s`` column scale by ``1 / tau``, the points'
    ``s`` column by ``tau`` (:func:`grasplan.grasps.epsilon_kernels.facet_pairs` applies it)."""
    E = CONE_EDGES
    th = 2.0 * math.pi * np.arange(E) / E
    c = np.stack([np.cos(th), np.sin(th)], 1)  # (E, 2) cone directions
    half = math.pi / E
    m = np.stack([np.cos(th + half), np.sin(th + half)], 1) / math.cos(half)  # m . c_e = m . c_{e+1} = 1
    tri = np.zeros((2 * E, 4))
    tri[:, 0] = -1.0
    tri[:, 1:3] = np.tile(m / mu, (2, 1))
    tri[:, 3] = np.concatenate([np.ones(E), -np.ones(E)])
    edge = np.zeros((3 * E, 2, 4))
    edge[:E, 0, 0] = -1.0  # octagon edges (e, e+1): lambda (-1, m/mu, 0) + sigma e_s
    edge[:E, 0, 1:3] = m / mu
    edge[:E, 1, 3] = 1.0
    for k, sgn in enumerate((1.0, -1.0)):  # apex edges (apex +-, c_e): lambda (-1, c/mu, +-1/tau) + sigma c_perp
        sl = slice(E * (k + 1), E * (k + 2))
        edge[sl, 0, 0] = -1.0
        edge[sl, 0, 1:3] = c / mu
        edge[sl, 0, 3] = sgn
        edge[sl, 1, 1] = -c[:, 1]
        edge[sl, 1, 2] = c[:, 0]
    pts = np.zeros((E + 2, 4))
    pts[:, 0] = 1.0
    pts[:E, 1:3] = mu * c
    pts[E, 3] = 1.0
    pts[E + 1, 3] = -1.0
    return tri, edge, pts


def ferrari_canny_pair(contacts: np.ndarray, normals: np.ndarray, com: np.ndarray, rho: float, mu: float,
                       torsion: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact Ferrari-Canny L1 epsilon of two soft-finger contacts without Qhull: the level-set maps
    vectorised over grasps (an SVD per grasp), the candidate facets compiled, one grasp at a time
    (:func:`grasplan.grasps.epsilon_kernels.facet_pairs`).

    Each contact's primitive wrenches (:func:`contact_wrenches`) are a linear image of one
    bipyramid (the 8-gon of cone edges plus the two torsion points), so every facet of the hull of
    both sets is spanned by a face of each: (triangle, triangle), (edge, whole set) or (whole set,
    edge), 304 candidate hyperplanes. On the level set ``u . w = 1`` each candidate is a 2 x 2
    linear solve in closed form; it is a facet (origin inside) when every primitive wrench has
    ``u . w <= 1`` and it separates the origin when every one has ``u . w >= 1`` (epsilon 0).
    epsilon = min over facets of ``1 / |u|``. Returns ``(epsilon (M,), exact (M,) bool)``: rows with
    ``exact`` False (degenerate: flat wrench set, the origin on a candidate's plane) need
    :func:`ferrari_canny`."""
    C = np.asarray(contacts, dtype=np.float64)
    M = len(C)
    out = np.zeros(M)
    exact = np.zeros(M, dtype=bool)
    if M == 0 or not mu > 0:
        return out, exact
    nu = -np.asarray(normals, dtype=np.float64)
    nu = nu / np.linalg.norm(nu, axis=-1, keepdims=True)
    t1, t2 = _tangent_basis(nu)
    r = C - com
    tors = np.asarray(torsion, dtype=np.float64).reshape(M, 2)
    bipyramid = _bipyramid_dirs(mu)
    for s0 in range(0, M, EPS_CHUNK):
        sl = slice(s0, min(M, s0 + EPS_CHUNK))
        out[sl], exact[sl] = _fc_pair_chunk(nu[sl], t1[sl], t2[sl], r[sl], rho, tors[sl], bipyramid)
    return out, exact


def _fc_pair_chunk(nu: np.ndarray, t1: np.ndarray, t2: np.ndarray, r: np.ndarray, rho: float, tors: np.ndarray,
                   bipyramid: tuple[np.ndarray, np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    B = len(nu)
    # phi_k = L_k^T u: (a + b x r_k / rho, b . nu_k / rho); Lt (B, 8, 6) stacks both contacts
    Lt = np.zeros((B, 8, 6))
    for k in range(2):
        Lt[:, 4 * k:4 * k + 3, :3] = np.eye(3)
        rx = r[:, k] / rho
        # (b x r) = -[r]x b: the rows of -[r]x
        Lt[:, 4 * k, 3:] = np.stack([np.zeros(B), rx[:, 2], -rx[:, 1]], 1)
        Lt[:, 4 * k + 1, 3:] = np.stack([-rx[:, 2], np.zeros(B), rx[:, 0]], 1)
        Lt[:, 4 * k + 2, 3:] = np.stack([rx[:, 1], -rx[:, 0], np.zeros(B)], 1)
        Lt[:, 4 * k + 3, 3:] = nu[:, k] / rho
    U, S, _ = np.linalg.svd(Lt)
    ok = S[:, -1] > 1e-9 * S[:, 0]  # full rank: the wrench set spans R^6
    N = U[:, :, 6:]  # (B, 8, 2): (phi1, phi2) is an image iff N^T phi = 0
    G = np.swapaxes(U[:, :, :6], 1, 2) / np.where(S > 0, S, 1.0)[..., None]  # |u| = |G phi| (u = V G phi)
    Ek = np.zeros((B, 2, 4, 4))  # local (alpha, beta, gamma, s) -> q = (f, s)
    Ek[:, :, :3, 0], Ek[:, :, :3, 1], Ek[:, :, :3, 2] = nu, t1, t2
    Ek[:, :, 3, 3] = 1.0
    A = [np.matmul(np.swapaxes(N[:, 4 * k:4 * k + 4], 1, 2), Ek[:, k]) for k in range(2)]  # (B, 2, 4)
    GE = [np.matmul(G[:, :, 4 * k:4 * k + 4], Ek[:, k]) for k in range(2)]  # (B, 6, 4)
    h = A[0][:, :, 0] + A[1][:, :, 0]
    g0 = GE[0][:, :, 0] + GE[1][:, :, 0]
    tri, edge, pts = bipyramid
    best = np.empty(B)
    outside = np.empty(B, dtype=bool)
    singular = np.empty(B, dtype=bool)
    facet_pairs(np.ascontiguousarray(np.stack(A, 1)), np.ascontiguousarray(np.stack(GE, 1)),
                np.ascontiguousarray(h), np.ascontiguousarray(g0), tri, edge, pts,
                np.ascontiguousarray(tors, dtype=np.float64), FACET_TOL, best, outside, singular)
    eps = np.where(outside | ~np.isfinite(best), 0.0, best)
    eps = np.where(eps > EPSILON_TOL, eps, 0.0)
    exact = ok & ~singular & (np.isfinite(best) | outside)
    return eps, exact


def quantised_patch_radius(area: np.ndarray) -> np.ndarray:
    """:func:`patch_radius` rounded down to the geometric grid ``MIN_PATCH_RADIUS * (1 +
    RADIUS_STEP)^k`` (conservative: less torsion, a 5 % geometric grid), so that grasps with the same
    contacts (the rolls of one candidate) share one epsilon hull computation (:func:`epsilon_dedup`)."""
    r = patch_radius(area)
    k = np.floor(np.log(r / MIN_PATCH_RADIUS) / math.log1p(RADIUS_STEP) + 1e-9)
    return MIN_PATCH_RADIUS * np.exp(np.maximum(k, 0.0) * math.log1p(RADIUS_STEP))


def epsilon_dedup(contacts: np.ndarray, normals: np.ndarray, area: np.ndarray, com: np.ndarray, rho: float,
                  mu: float) -> np.ndarray:
    """(M,) Ferrari-Canny epsilon, once per distinct wrench set (the rolls of one candidate share
    contacts and normals, and their patch radii are quantised (:func:`quantised_patch_radius`)):
    :func:`ferrari_canny_pair` (closed form, compiled), Qhull (:func:`ferrari_canny`) only for the
    degenerate sets it does not decide.

    Epsilon (Ferrari-Canny L1) of two soft-finger contacts, unit normal force each
    (:func:`contact_wrenches`): the radius of the largest origin-centred ball inside the convex hull
    of the 20 wrenches; 0 when the origin is outside or the hull is flat. The closed form (each
    contact's wrenches are a linear image of one bipyramid, so the hull's facets come from 304 face
    pairs, each a 2 x 2 solve; ~25 us per distinct wrench set, half of it the SVD, instead of
    ~0.6 ms per Qhull call) leaves the rare degenerate sets (flat, origin on a candidate plane) to
    Qhull (scipy ConvexHull). The two agree within 1e-9 relative or 1e-10 absolute (Qhull's joggle),
    tests/test_quality_fast.py."""
    M = len(contacts)
    if M == 0:
        return np.zeros(0)
    rq = quantised_patch_radius(area)
    key = np.concatenate([np.asarray(contacts, dtype=np.float64).reshape(M, 6),
                          np.asarray(normals, dtype=np.float64).reshape(M, 6), rq], axis=1)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    u = first
    Cu, Nu, tors = np.asarray(contacts)[u], np.asarray(normals)[u], SOFT_FINGER * mu * rq[u]
    eps, exact = ferrari_canny_pair(Cu, Nu, com, rho, mu, tors)
    if not exact.all():  # degenerate wrench sets: Qhull
        bad = np.flatnonzero(~exact)
        eps[bad] = ferrari_canny(contact_wrenches(Cu[bad], Nu[bad], com, rho, mu, tors[bad]))
    return eps[inverse.reshape(-1)]

