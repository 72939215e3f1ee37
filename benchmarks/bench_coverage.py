"""Coverage of the emitted grasps against an independent dense ground truth (issue 10).

    .venv/bin/python benchmarks/bench_coverage.py [--method regions] [--parts NAME ...] [--points 4000]

Per part (every paper part in ../shared/parts/paper/ or $GRASPLAN_PAPER_PARTS, SileaneGear in its
stable pose 1; every part in examples/parts/; the 60 x 45 x 14 mm box as 12 triangles and
subdivided to 1.5 mm and 0.5 mm) it runs ``compute_grasps`` with ``CandidateParams(method=...)`` and
thinning off (``GraspParams(thin_spacing=0)``), in a fresh process (seconds and peak RSS are that
process's), and measures it against a ground truth that shares no code with the candidate search or
the collision filter:

* 4000 points sampled on the surface (area-weighted, seeded); for each point p with normal n every
  exit point q of the inward ray p - t n (trimesh's ray tracer) whose face normal is anti-parallel
  to n within 2 deg and with |p - q| <= max opening makes a pair (jaws may close across bores);
* a pair is feasible when the gripper's shapes (body, and each finger swept from the pre-grasp
  opening min(max_opening, w + 10 mm) to w + 2 mm), at some roll about the closing axis in 15 deg
  steps, hit neither the part in its resting pose (python-fcl, own BVH) nor the table (z <= table_z);
* recall = share of feasible pairs with an emitted collision-free grasp whose midpoint lies within
  3 mm and whose closing axis lies within 10 deg (sign-free);
* violations = emitted collision-free grasps that the independent check finds in collision (at
  most --check of them, seeded sample).

Targets (docs/candidates.md): recall >= 95 % everywhere, 0 violations, the three boxes within 10 %
of each other's candidate count, ``grasplan candidates`` < 2 s and peak RSS < 1.5 GB up to 250k
triangles.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

PAPER_DIR = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
EXAMPLES = ROOT / "examples" / "parts"
SUFFIXES = (".stl", ".obj", ".ply")
BOX_MM = (60.0, 45.0, 14.0)
BOXES = {"box_12tri": None, "box_1.5mm": 1.5, "box_0.5mm": 0.5}
POSE_INDEX = {"SileaneGear": 1}
ANTI_DEG, MID_TOL, AXIS_DEG, ROLL_DEG = 2.0, 0.003, 10.0, 15.0
PREGRASP, CLOSE = 0.010, 0.002     # the sweep: pre-grasp opening w + 10 mm (capped) -> w + 2 mm


# ------------------------------------------------------------------ parts
def part_list(names=None):
    out = []
    if PAPER_DIR.is_dir():
        out += [(p.stem, p, "auto") for p in sorted(PAPER_DIR.iterdir()) if p.suffix.lower() in SUFFIXES]
    out += [(p.stem, p, "mm") for p in sorted(EXAMPLES.iterdir()) if p.suffix.lower() in SUFFIXES]
    out += [(k, None, "mm") for k in BOXES]
    if names:
        out = [o for o in out if o[0] in names]
    return out


def box_mesh(name):
    import trimesh

    box = trimesh.creation.box(extents=BOX_MM)
    if BOXES[name] is None:
        return box
    V, F = trimesh.remesh.subdivide_to_size(box.vertices, box.faces, BOXES[name])
    return trimesh.Trimesh(V, F)


# ------------------------------------------------------------------ independent ground truth
def ray_hits(tri, origins, dirs, length, chunk=64):
    """All hits of segments ``origins + t dirs``, ``0 < t <= length``, with triangles ``tri`` (m, 3, 3):
    (ray index, triangle index, t). Moeller-Trumbore in NumPy; rays in spatially sorted chunks, each
    against the triangles whose bounding boxes meet the chunk's."""
    lo_t, hi_t = tri.min(axis=1), tri.max(axis=1)
    key = np.lexsort(np.floor(origins / max(length, 1e-9)).T[::-1])
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    out_r, out_f, out_t = [], [], []
    for s in range(0, len(origins), chunk):
        rr = key[s:s + chunk]
        o, d = origins[rr], dirs[rr]
        ends = o + length * d
        lo = np.minimum(o, ends).min(axis=0) - 1e-12
        hi = np.maximum(o, ends).max(axis=0) + 1e-12
        f = np.flatnonzero(((lo_t <= hi) & (hi_t >= lo)).all(axis=1))
        if len(f) == 0:
            continue
        E1, E2, T0 = e1[f][None], e2[f][None], tri[f, 0][None]
        D = d[:, None]
        pv = np.cross(D, E2)
        det = np.einsum("rfk,rfk->rf", E1, pv)
        inv = 1.0 / np.where(np.abs(det) > 1e-300, det, np.inf)
        tv = o[:, None] - T0
        u = np.einsum("rfk,rfk->rf", tv, pv) * inv
        qv = np.cross(tv, E1)
        v = np.einsum("rfk,rfk->rf", D, qv) * inv
        t = np.einsum("rfk,rfk->rf", E2, qv) * inv
        hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t <= length) & (det != 0)
        ri, fi = np.nonzero(hit)
        out_r.append(rr[ri])
        out_f.append(f[fi])
        out_t.append(t[ri, fi])
    if not out_r:
        z = np.zeros(0, dtype=np.int64)
        return z, z, np.zeros(0)
    return np.concatenate(out_r), np.concatenate(out_f), np.concatenate(out_t)


def surface_pairs(mesh, n_points, max_opening, seed):
    """(k, 2, 3) contact pairs of the dense ground truth (part frame)."""
    import trimesh

    pts, fid = trimesh.sample.sample_surface(mesh, n_points, seed=seed)
    nrm = np.asarray(mesh.face_normals)[fid]
    scale = float(np.linalg.norm(mesh.extents))
    origins = pts - 1e-7 * scale * nrm
    ri, ti, t = ray_hits(np.asarray(mesh.triangles), origins, -nrm, max_opening)
    anti = np.einsum("ij,ij->i", np.asarray(mesh.face_normals)[ti], nrm[ri]) <= -np.cos(np.radians(ANTI_DEG))
    q = origins[ri] - t[:, None] * nrm[ri]
    d = np.linalg.norm(q - pts[ri], axis=1)
    ok = anti & (d <= max_opening) & (d > 1e-6 * scale)
    return np.stack([pts[ri[ok]], q[ok]], axis=1)


def tcp_frames(pairs, roll_deg):
    """(k, r, 4, 4) TCP frames: origin at the midpoint, x the closing axis, z rolled about x."""
    x = pairs[:, 1] - pairs[:, 0]
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    h = np.where(np.abs(x[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    u = np.cross(x, h)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(x, u)
    ang = np.radians(np.arange(0.0, 360.0, roll_deg))
    z = np.cos(ang)[None, :, None] * u[:, None] + np.sin(ang)[None, :, None] * v[:, None]
    xx = np.broadcast_to(x[:, None], z.shape)
    T = np.zeros(z.shape[:2] + (4, 4))
    T[..., :3, 0], T[..., :3, 2] = xx, z
    T[..., :3, 1] = np.cross(z, xx)
    T[..., :3, 3] = pairs.mean(axis=1)[:, None]
    T[..., 3, 3] = 1.0
    return T


class Checker:
    """Gripper shapes vs the part (python-fcl) and the table half-space; no grasplan collision code."""

    def __init__(self, part_mesh, T_world_part, gripper, table_z):
        import fcl

        self.fcl = fcl
        self.T_wp = T_world_part
        self.table_z = table_z
        self.g = gripper
        V = np.asarray(part_mesh.vertices, dtype=np.float64) @ T_world_part[:3, :3].T + T_world_part[:3, 3]
        bvh = fcl.BVHModel()
        bvh.beginModel(len(V), len(part_mesh.faces))
        bvh.addSubModel(V, np.asarray(part_mesh.faces, dtype=np.int64))
        bvh.endModel()
        self.part = fcl.CollisionObject(bvh, fcl.Transform())
        self.req = fcl.CollisionRequest()

    def _shapes(self, width):
        """[(kind, geometry, T_tcp_shape)] of the body and both swept fingers (TCP frame)."""
        from grasplan.gripper.model import Box

        out = [(s.extents, s.T_tcp_box) if isinstance(s, Box) else (s.vertices, s.faces) for s in self.g.body]
        f = self.g.finger
        pre = min(self.g.max_opening, width + PREGRASP)
        lo, hi = sorted((min(width + CLOSE, pre), pre))
        if isinstance(f, Box):
            ext = np.array(f.extents, dtype=np.float64)
            x0, x1 = f.T_tcp_box[0, 3] - ext[0] / 2 + lo / 2, f.T_tcp_box[0, 3] + ext[0] / 2 + hi / 2
            T = f.T_tcp_box.copy()
            ext[0], T[0, 3] = x1 - x0, 0.5 * (x0 + x1)
            M = np.diag([-1.0, -1.0, 1.0, 1.0])
            out += [(ext, T), (ext, M @ T)]
        else:
            import trimesh

            pts = np.vstack([f.vertices + [o / 2, 0, 0] for o in (lo, hi)])
            hull = trimesh.convex.convex_hull(pts)
            V = np.asarray(hull.vertices)
            out += [(V, np.asarray(hull.faces)), (V * [-1, -1, 1], np.asarray(hull.faces)[:, ::-1])]
        return out

    def free(self, T_world_tcp, width):
        """True when no shape hits the part or the table."""
        fcl = self.fcl
        for geom, extra in self._shapes(width):
            if extra.ndim == 2 and extra.shape == (4, 4):           # box: extents, T_tcp_box
                T = T_world_tcp @ extra
                s = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)]) * (0.5 * geom)
                if (s @ T[:3, :3].T + T[:3, 3])[:, 2].min() < self.table_z - 1e-9:
                    return False
                obj = fcl.CollisionObject(fcl.Box(*geom), fcl.Transform(T[:3, :3], T[:3, 3]))
            else:                                                   # mesh: vertices, faces (TCP frame)
                V = geom @ T_world_tcp[:3, :3].T + T_world_tcp[:3, 3]
                if V[:, 2].min() < self.table_z - 1e-9:
                    return False
                m = fcl.BVHModel()
                m.beginModel(len(V), len(extra))
                m.addSubModel(V, np.asarray(extra, dtype=np.int64))
                m.endModel()
                obj = fcl.CollisionObject(m, fcl.Transform())
            if fcl.collide(obj, self.part, self.req, fcl.CollisionResult()):
                return False
        return True


# ------------------------------------------------------------------ one part (child process)
def run_one(name, path, units, method, n_points, n_check, seed):
    from dataclasses import replace

    from grasplan.grasps.pipeline import compute_grasps
    from grasplan.part.mesh import load_part, part_from_trimesh
    from grasplan.config.params import PAPER_GRIPPER, CandidateParams, GraspParams

    t0 = time.perf_counter()
    part = load_part(path, units=units) if path else part_from_trimesh(box_mesh(name), units="mm", path=name)
    gp = GraspParams(thin_spacing=0)
    if name in POSE_INDEX:
        gp = replace(gp, pose_index=POSE_INDEX[name])
    res = compute_grasps(part, candidates=CandidateParams(method=method), gripper=PAPER_GRIPPER, grasps=gp)
    seconds = time.perf_counter() - t0
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    t_cand = res.timing_s.get("candidates", float("nan"))

    g = res.gripper
    mesh = part.mesh
    ok = np.flatnonzero(res.status == "ok")
    T_pt = res.frames.T_part_tcp[ok]
    widths = res.width[ok]
    checker = Checker(mesh, res.T_world_part, g, float(res.cell.table_z))
    # ground truth
    pairs = surface_pairs(mesh, n_points, g.max_opening, seed)
    T = tcp_frames(pairs, ROLL_DEG)
    w = np.linalg.norm(pairs[:, 1] - pairs[:, 0], axis=1)
    feasible = np.zeros(len(pairs), dtype=bool)
    for k in range(len(pairs)):
        for r in range(T.shape[1]):
            if checker.free(res.T_world_part @ T[k, r], float(w[k])):
                feasible[k] = True
                break
    fp = pairs[feasible]
    # recall: an emitted ok grasp within 3 mm (midpoint) and 10 deg (sign-free axis)
    covered = 0
    if len(fp) and len(ok):
        from scipy.spatial import cKDTree

        mid = T_pt[:, :3, 3]
        ax = T_pt[:, :3, 0]
        tree = cKDTree(mid)
        gm = fp.mean(axis=1)
        ga = fp[:, 1] - fp[:, 0]
        ga /= np.linalg.norm(ga, axis=1, keepdims=True)
        cos_a = np.cos(np.radians(AXIS_DEG))
        for k, near in enumerate(tree.query_ball_point(gm, MID_TOL)):
            if near and (np.abs(ax[near] @ ga[k]) >= cos_a).any():
                covered += 1
    # independent check of emitted collision-free grasps
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(ok), size=min(n_check, len(ok)), replace=False) if len(ok) else np.zeros(0, int)
    viol = sum(not checker.free(res.T_world_part @ T_pt[k], float(widths[k])) for k in pick)
    return {"part": name, "triangles": int(part.triangles), "candidates": len(res.cand.candidates),
            "regions": len(np.unique(res.cand.candidates.region)), "gt_pairs": len(pairs),
            "feasible": int(feasible.sum()), "covered": int(covered),
            "recall": covered / max(int(feasible.sum()), 1), "emitted_ok": len(ok),
            "checked": len(pick), "violations": int(viol), "seconds": seconds, "candidates_s": t_cand,
            "peak_rss_mb": rss_mb}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--method", default="regions", choices=("regions", "paper"))
    ap.add_argument("--parts", nargs="*", help="part names (file stems or box_12tri, box_1.5mm, box_0.5mm)")
    ap.add_argument("--points", type=int, default=4000)
    ap.add_argument("--check", type=int, default=2000, help="emitted ok grasps re-checked per part")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--one", nargs=3, metavar=("NAME", "PATH", "UNITS"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        name, path, units = args.one
        print(json.dumps(run_one(name, None if path == "-" else Path(path), units, args.method, args.points,
                                 args.check, args.seed)))
        return 0
    from grasplan.cli.common import table

    rows, bad = [], False
    for name, path, units in part_list(args.parts):
        cmd = [sys.executable, __file__, "--method", args.method, "--points", str(args.points), "--check",
               str(args.check), "--seed", str(args.seed), "--one", name, str(path) if path else "-", units]
        p = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if p.returncode != 0:
            print(f"{name}: failed\n{p.stderr[-2000:]}")
            bad = True
            continue
        r = json.loads(p.stdout.strip().splitlines()[-1])
        bad |= r["recall"] < 0.95 or r["violations"] > 0
        rows.append((r["part"], r["triangles"], r["candidates"], r["feasible"], f"{100 * r['recall']:.1f}",
                     r["emitted_ok"], f"{r['violations']}/{r['checked']}", f"{r['candidates_s']:.2f}",
                     f"{r['seconds']:.2f}", f"{r['peak_rss_mb']:.0f}"))
        print(table(rows[-1:], header=("part", "triangles", "candidates", "feasible pairs", "recall %",
                                       "emitted ok", "violations", "candidates s", "grasps s", "peak RSS MB")),
              flush=True)
    print(f"\nmethod={args.method}, thinning off; {args.points} surface points per part")
    print(table(rows, header=("part", "triangles", "candidates", "feasible pairs", "recall %", "emitted ok",
                              "violations", "candidates s", "grasps s", "peak RSS MB")))
    print("targets " + ("MISSED" if bad else "met") + " (recall >= 95 %, 0 violations)")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
