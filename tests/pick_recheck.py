"""An INDEPENDENT python-fcl re-check of planned picks (a helper module: no tests in it).

Built on :mod:`tests.fcl_recheck` (URDF links from the URDF, gripper shapes, the cell's table
half-space and obstacles, the part static or attached, all in python-fcl; Pinocchio only for
forward kinematics). The pile is added as obstacles written here from the scene: every other
instance present when the pick was planned as a python-fcl BVH of its mesh at its pose, and every
point of the cloud as the cube of its octree leaf (``floor(p / resolution)`` cells). The rules:

* transit and approach (jaws at the pick's opening, the instance static): robot links and gripper
  against table, bin, obstacles, the instance, every other instance and the cloud; self-collision;
* lift (jaws at the contact width, the instance attached by ``T_tcp_part``): the same, plus the
  carried instance against table, bin, every other instance, the cloud and the links not on the
  tool joint. Within the first ``lift_contact`` metres of TCP travel from the grasp (FK) the carried
  instance may touch the table, the bin or a neighbour (it rests on them); beyond it, it may touch
  a neighbour only when the two interpenetrate by at most ``lift_depth`` (+ :data:`DEPTH_SLACK` for
  the sampling) more than they do at rest (the pick's ``T_world_part``; counted up to ``rest_cap``,
  the planner's ``overlap_tol``; 0: the absolute depth), measured here independently of grasplan
  (:func:`mesh_depth`: trimesh's random surface samples and vertices, a generalised winding number
  for inside, trimesh's exact closest point on the triangles for the distance); nothing else may
  touch. The lift is the motion's own ``lift`` segment, whatever its direction. A neighbour the pick
  says its lift raises (``pick.carries``, ``lift_carry``) may be touched by the carried instance
  (not by the robot or the gripper) when :func:`rises_freely` finds it lying on it, free to rise.
"""
from __future__ import annotations

from dataclasses import replace

import fcl
import numpy as np

from fcl_recheck import FclWorld, Report, densify

from grasplan.cell.model import Obstacle


#: the planner and this check sample the surfaces differently: depths may differ by about this (m)
DEPTH_SLACK = 0.0003


def _winding(V: np.ndarray, F: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Generalised winding number of each point (k,) (van Oosterom-Strackee solid angles)."""
    out = np.zeros(len(pts))
    tri = V[F]
    for c in range(0, len(pts), 256):
        p = pts[c:c + 256]
        a, b, d = (tri[None, :, i, :] - p[:, None, :] for i in range(3))
        la, lb, ld = (np.linalg.norm(x, axis=2) for x in (a, b, d))
        num = np.einsum("kfi,kfi->kf", a, np.cross(b, d))
        den = la * lb * ld + np.einsum("kfi,kfi->kf", a, b) * ld + np.einsum("kfi,kfi->kf", a, d) * lb \
            + np.einsum("kfi,kfi->kf", b, d) * la
        out[c:c + 256] = (2.0 * np.arctan2(num, den)).sum(axis=1) / (4.0 * np.pi)
    return out


def _depth_one_way(ma, Ta, mb, Tb, n_samples: int) -> float:
    import trimesh

    Va, Fa = np.asarray(ma.vertices, dtype=np.float64), np.asarray(ma.faces)
    Vb, Fb = np.asarray(mb.vertices, dtype=np.float64), np.asarray(mb.faces)
    pts, _ = trimesh.sample.sample_surface(trimesh.Trimesh(Va, Fa, process=False), n_samples, seed=1)
    pts = np.vstack([Va, pts])
    T = np.linalg.inv(Tb) @ Ta
    local = pts @ T[:3, :3].T + T[:3, 3]
    local = local[np.all((local >= Vb.min(axis=0)) & (local <= Vb.max(axis=0)), axis=1)]
    if not len(local):
        return 0.0
    inside = local[_winding(Vb, Fb, local) > 0.5]
    best = 0.0
    tri = Vb[Fb]
    for c in range(0, len(inside), 64):
        p = inside[c:c + 64]
        cp = trimesh.triangles.closest_point(np.repeat(tri[None], len(p), axis=0).reshape(-1, 3, 3),
                                             np.repeat(p, len(tri), axis=0))
        d = np.linalg.norm(cp - np.repeat(p, len(tri), axis=0), axis=1).reshape(len(p), len(tri)).min(axis=1)
        best = max(best, float(d.max()))
    return best


def mesh_depth(ma, Ta, mb, Tb, *, n_samples: int = 20_000) -> float:
    """Penetration depth (m) of mesh ``ma`` at ``Ta`` and ``mb`` at ``Tb``: the largest distance to the
    other's surface of a surface point of either inside the other (written independently of
    grasplan.pick.depth)."""
    return max(_depth_one_way(ma, Ta, mb, Tb, n_samples), _depth_one_way(mb, Tb, ma, Ta, n_samples))


def pile_obstacles(instances, meshes, *, exclude: str, cloud=None, resolution: float = 0.005) -> list[Obstacle]:
    """Obstacles for every instance but ``exclude`` (mesh at its pose) and the cloud's leaf cubes."""
    out = []
    for inst in instances:
        if inst.id == exclude:
            continue
        m = meshes[inst.part]
        out.append(Obstacle(f"instance_{inst.id}", "mesh", np.asarray(inst.T_world_part),
                            vertices=np.asarray(m.vertices), faces=np.asarray(m.faces)))
    if cloud is not None:
        cells = np.unique(np.floor(np.asarray(cloud) / resolution).astype(np.int64), axis=0)
        for k, c in enumerate(cells):
            T = np.eye(4)
            T[:3, 3] = (c + 0.5) * resolution
            out.append(Obstacle(f"cloud_{k}", "box", T, size=(resolution,) * 3))
    return out


def recheck_pick(robot, gripper, cell, pick, instances, meshes, *, cloud=None, resolution: float = 0.005,
                 lift_contact: float = 0.002, lift_depth: float = 0.0, rest_cap: float = 0.0,
                 step: float = 0.01) -> Report:
    """Re-check one :class:`grasplan.pick.Pick` against the pile ``instances`` present when it was planned."""
    obstacles = pile_obstacles(instances, meshes, exclude=pick.instance, cloud=cloud, resolution=resolution)
    world = FclWorld(robot, gripper, replace(cell, obstacles=tuple(cell.obstacles) + tuple(obstacles)),
                     meshes[pick.part])
    m = pick.motion
    path = np.asarray(m.path)
    g0, g1 = m.segment("approach")
    l0, l1 = m.segment("lift")
    T_tcp_part = np.asarray(m.T_tcp_part)
    rep = Report()
    rep.lift_depths = []  # type: ignore[attr-defined]  # depths of the accepted and refused lift contacts
    by_id = {i.id: i for i in instances if i.id != pick.instance}
    rest: dict[str, float] = {}  # resting depth per neighbour touched
    carried = set(getattr(pick, "carries", ()))
    for iid in sorted(carried):
        why = rises_freely(by_id[iid], instances, meshes, up=np.asarray(cell.retreat_direction, dtype=np.float64),
                           dist=float(cell.retreat_distance), lift_contact=lift_contact, lift_depth=lift_depth,
                           rest_cap=rest_cap)
        if why:
            rep.problems.append(f"lift raises {iid}, which is not free to rise: {why}")

    def at_rest(iid: str) -> float:
        if iid not in rest:
            rest[iid] = 0.0 if rest_cap <= 0 else min(rest_cap, mesh_depth(
                meshes[pick.part], pick.T_world_part, meshes[by_id[iid].part], by_id[iid].T_world_part))
        return rest[iid]
    from fcl_recheck import RobotLinks

    tcp = RobotLinks(robot, gripper.T_flange_tcp)
    T_grasp = tcp.fk_tcp(path[l0])
    states = [(0, g1, pick.opening, "static", pick.T_world_part), (l0, l1, pick.width, "attached", T_tcp_part)]
    if m.segment("transfer") is not None:  # carried to the place, lowered, released, retreat
        d1 = m.segment("descend")[1]
        r0, r1 = m.segment("retreat")
        states += [(l1, d1, pick.width, "attached", T_tcp_part),
                   (r0, r1, pick.opening, "static", np.asarray(m.T_world_part_place))]
    for k, (s, e, opening, mode, T) in enumerate(states):
        qs, _ = densify(path[s:e + 1], step)
        for q in qs:
            rep.configs += 1
            hits = world.check(q, opening, mode, T)
            if mode == "attached":
                here = tcp.fk_tcp(q)[:3, 3]
                travel = float(np.linalg.norm(here - T_grasp[:3, 3]))
                if k == 1 and travel <= lift_contact + 1e-9:
                    hits = [h for h in hits if not (h.startswith("part (attached) vs ")
                                                    and (h.endswith("vs table") or " vs obstacle:" in h))]
                elif k == 1 and lift_depth > 0:  # shallow contacts with neighbours, by an independent depth
                    T_part = tcp.fk_tcp(q) @ T_tcp_part
                    keep = []
                    for h in hits:
                        iid = h[len("part (attached) vs obstacle:instance_"):]
                        if h.startswith("part (attached) vs obstacle:instance_") and iid in carried:
                            continue
                        if h.startswith("part (attached) vs obstacle:instance_") and iid in by_id:
                            d = mesh_depth(meshes[pick.part], T_part, meshes[by_id[iid].part],
                                           by_id[iid].T_world_part) - at_rest(iid)
                            rep.lift_depths.append(d)
                            if d <= lift_depth + DEPTH_SLACK:
                                continue
                            h += f" ({1e3 * d:.2f} mm deeper than at rest)"
                        keep.append(h)
                    hits = keep
            if hits:
                rep.problems.append(f"{mode} q={np.round(q, 4).tolist()}: " + ", ".join(hits[:3]))
                break
    return rep


def rises_freely(inst, instances, meshes, *, up: np.ndarray, dist: float, lift_contact: float, lift_depth: float,
                 rest_cap: float, step: float = 0.002) -> str:
    """"" (it is free) or the first problem: instance ``inst`` moved alone along ``up`` by
    ``lift_contact`` .. ``dist`` (every ``step``) against every other instance (python-fcl meshes),
    a contact allowed only within ``lift_depth`` (+ :data:`DEPTH_SLACK`) beyond the resting depth
    (:func:`mesh_depth`, counted up to ``rest_cap``)."""

    def bvh(m):
        b = fcl.BVHModel()
        b.beginModel(len(m.vertices), len(m.faces))
        b.addSubModel(np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int32))
        b.endModel()
        return b
    u = up / np.linalg.norm(up)
    me = fcl.CollisionObject(bvh(meshes[inst.part]), fcl.Transform(inst.T_world_part[:3, :3], inst.T_world_part[:3, 3]))
    for o in instances:
        if o.id == inst.id:
            continue
        other = fcl.CollisionObject(bvh(meshes[o.part]), fcl.Transform(o.T_world_part[:3, :3], o.T_world_part[:3, 3]))
        rest = None
        for t in np.arange(lift_contact, dist + 1e-12, step):
            T = np.array(inst.T_world_part, dtype=np.float64)
            T[:3, 3] += t * u
            me.setTransform(fcl.Transform(T[:3, :3], T[:3, 3]))
            if not fcl.collide(me, other, fcl.CollisionRequest(), fcl.CollisionResult()):
                continue
            if rest is None:
                rest = 0.0 if rest_cap <= 0 else min(rest_cap, mesh_depth(meshes[inst.part], inst.T_world_part,
                                                                          meshes[o.part], o.T_world_part))
            d = mesh_depth(meshes[inst.part], T, meshes[o.part], o.T_world_part) - rest
            if lift_depth <= 0 or d > lift_depth + DEPTH_SLACK:
                return f"{1e3 * t:.0f} mm up it is {1e3 * d:.2f} mm deeper in {o.id} than at rest"
    return ""
