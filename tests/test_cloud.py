"""Point clouds (grasplan.piles.cloud): PLY / PCD / NPY readers checked against each other and NumPy,
and the octree obstacle against the points it was built from."""
from __future__ import annotations

import os

import numpy as np
import pytest

from grasplan.piles.cloud import cloud_octree, read_cloud
from grasplan.errors import InputError

RNG = np.random.default_rng(7)
PTS = RNG.uniform(-0.2, 0.4, (257, 3))


def _ply_ascii(path, pts, extra_first=False):
    head = ["ply", "format ascii 1.0", f"element vertex {len(pts)}", "property float x", "property float y",
            "property float z", "property uchar red", "end_header"]
    path.write_text("\n".join(head) + "\n" + "\n".join(f"{x!r} {y!r} {z!r} 7" for x, y, z in pts.tolist()) + "\n")


def _ply_binary(path, pts, order="<"):
    fmt = "binary_little_endian" if order == "<" else "binary_big_endian"
    dt = np.dtype([("nx", order + "f4"), ("x", order + "f8"), ("y", order + "f8"), ("z", order + "f8")])
    rec = np.zeros(len(pts), dtype=dt)
    rec["x"], rec["y"], rec["z"] = pts.T
    # a face element before the vertices, without list properties: skipped by its fixed size
    pre = np.zeros(3, dtype=np.dtype([("a", order + "i4")]))
    head = (f"ply\nformat {fmt} 1.0\nelement camera 3\nproperty int a\nelement vertex {len(pts)}\n"
            "property float nx\nproperty double x\nproperty double y\nproperty double z\nend_header\n")
    path.write_bytes(head.encode() + pre.tobytes() + rec.tobytes())


def _pcd(path, pts, binary):
    head = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\n"
            f"WIDTH {len(pts)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(pts)}\n"
            f"DATA {'binary' if binary else 'ascii'}\n")
    if binary:
        rec = np.zeros(len(pts), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
        rec["x"], rec["y"], rec["z"] = pts.T
        path.write_bytes(head.encode() + rec.tobytes())
    else:
        path.write_text(head + "\n".join(f"{x!r} {y!r} {z!r} 0" for x, y, z in pts.astype(np.float32).tolist()) + "\n")


@pytest.mark.parametrize("kind", ["ply_ascii", "ply_le", "ply_be", "pcd_ascii", "pcd_binary", "npy"])
def test_readers_agree(tmp_path, kind):
    p = tmp_path / ("c.npy" if kind == "npy" else "c.pcd" if kind.startswith("pcd") else "c.ply")
    if kind == "ply_ascii":
        _ply_ascii(p, PTS)
    elif kind == "ply_le":
        _ply_binary(p, PTS, "<")
    elif kind == "ply_be":
        _ply_binary(p, PTS, ">")
    elif kind.startswith("pcd"):
        _pcd(p, PTS, kind == "pcd_binary")
    else:
        np.save(p, PTS)
    c = read_cloud(p)
    tol = 1e-6 if kind.startswith("pcd") or kind == "ply_ascii" else 0.0
    np.testing.assert_allclose(c.points, PTS, atol=tol)
    assert c.points.dtype == np.float64 and c.dropped == 0


def test_non_finite_points_dropped_and_counted(tmp_path):
    pts = PTS.copy()
    pts[[3, 9]] = np.nan
    np.save(tmp_path / "c.npy", pts)
    c = read_cloud(tmp_path / "c.npy")
    assert c.dropped == 2 and len(c.points) == len(PTS) - 2


@pytest.mark.parametrize("make, match", [
    (lambda p: p.with_suffix(".xyz").write_text("1 2 3\n"), "unknown suffix"),
    (lambda p: np.save(p.with_suffix(".npy"), PTS * 1000), "millimetres"),
    (lambda p: np.save(p.with_suffix(".npy"), np.zeros((4, 2))), r"\(N, 3\)"),
    (lambda p: p.with_suffix(".ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 10\n"
                                                  b"property float x\nproperty float y\nproperty float z\n"
                                                  b"end_header\n" + b"\0" * 12), "truncated"),
    (lambda p: p.with_suffix(".pcd").write_text("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\n"
                                                 "DATA binary_compressed\n"), "binary_compressed"),
    (lambda p: np.save(p.with_suffix(".npy"), np.full((3, 3), np.nan)), "no point with finite"),
])
def test_bad_clouds_refused(tmp_path, make, match):
    base = tmp_path / "c"
    make(base)
    path = next(tmp_path.iterdir())
    with pytest.raises(InputError, match=match):
        read_cloud(path)


def test_fifo_refused_without_blocking(tmp_path):
    p = tmp_path / "scan.ply"
    os.mkfifo(p)
    with pytest.raises(InputError, match="FIFO"):
        read_cloud(p)


def test_octree_occupies_the_points_and_nothing_far():
    import coal

    pts = np.array([[0.40, 0.0, 0.05], [0.41, 0.0, 0.05]])
    tree = cloud_octree(pts, 0.005)
    req, box = coal.CollisionRequest(), coal.Box(0.004, 0.004, 0.004)

    def hits(p):
        res = coal.CollisionResult()
        return coal.collide(tree, coal.Transform3s(), box, coal.Transform3s(np.eye(3), np.asarray(p, float)), req, res) > 0

    assert hits(pts[0]) and hits(pts[1])
    assert not hits([0.40, 0.0, 0.08]) and not hits([0.30, 0.1, 0.05])
    with pytest.raises(InputError, match="leaf size"):
        cloud_octree(pts, 1e-5)
