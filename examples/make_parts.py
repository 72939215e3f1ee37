"""Build the example parts that ship in ``examples/parts/`` (run: ``python examples/make_parts.py``).

Every part is an extruded 2D profile, written as binary STL in millimetres (like most CAD exports):

- ``bracket.stl``: a 40 x 30 x 20 mm block with a 10 mm wide, 8 mm deep notch across its top.
- ``gear.stl``: a 20-tooth spur gear, 40 mm tip diameter, 10 mm thick, flat tooth tips.
- ``box.stl``: a 30 x 20 x 10 mm box.

The script is deterministic: running it again gives byte-identical files.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import trimesh

HERE = Path(__file__).resolve().parent / "parts"


def _signed_area(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def ear_clip(poly: np.ndarray) -> np.ndarray:
    """Triangulate a simple counter-clockwise polygon ``(n, 2)``; returns ``(n - 2, 3)`` indices."""
    idx = list(range(len(poly)))
    tris = []

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    guard = 0
    while len(idx) > 3:
        guard += 1
        if guard > 10 * len(poly) ** 2:
            raise ValueError("ear clipping failed: is the polygon simple and counter-clockwise?")
        for k in range(len(idx)):
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
            a, b, c = poly[i0], poly[i1], poly[i2]
            if cross(a, b, c) <= 1e-12:  # reflex or collinear: not an ear
                continue
            inside = False
            for j in idx:
                if j in (i0, i1, i2):
                    continue
                p = poly[j]
                if cross(a, b, p) >= 0 and cross(b, c, p) >= 0 and cross(c, a, p) >= 0:
                    inside = True
                    break
            if inside:
                continue
            tris.append((i0, i1, i2))
            idx.pop(k)
            break
    tris.append(tuple(idx))
    return np.asarray(tris, dtype=np.int64)


def extrude(profile: np.ndarray, height: float, *, axis: str = "z") -> trimesh.Trimesh:
    """Extrude a simple polygon ``(n, 2)`` by ``height`` into a watertight, outward-wound mesh."""
    poly = np.asarray(profile, dtype=np.float64)
    if _signed_area(poly) < 0:
        poly = poly[::-1]
    n = len(poly)
    cap = ear_clip(poly)
    bottom = np.column_stack([poly, np.zeros(n)])
    top = np.column_stack([poly, np.full(n, height)])
    vertices = np.vstack([bottom, top])
    faces = [cap[:, ::-1], cap + n]  # bottom faces down, top faces up
    i = np.arange(n)
    j = (i + 1) % n
    faces.append(np.column_stack([i, j, j + n]))
    faces.append(np.column_stack([i, j + n, i + n]))
    mesh = trimesh.Trimesh(vertices, np.vstack(faces), process=True)
    if axis == "y":  # profile in the x-z plane, extruded along +y
        mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
        mesh.apply_translation([0, height, 0])
    assert mesh.is_watertight and mesh.volume > 0
    return mesh


def bracket() -> trimesh.Trimesh:
    """40 (x) x 30 (y) x 20 (z) mm block, notch 10 mm wide and 8 mm deep across the top."""
    profile = np.array([(0, 0), (40, 0), (40, 20), (25, 20), (25, 12), (15, 12), (15, 20), (0, 20)], dtype=float)
    m = extrude(profile, 30.0, axis="y")
    m.apply_translation([-20.0, -15.0, 0.0])
    return m


def gear(teeth: int = 20, r_tip: float = 20.0, r_root: float = 16.5, thickness: float = 10.0) -> trimesh.Trimesh:
    """Spur gear with trapezoidal teeth and flat tips, centred on the z axis."""
    pts = []
    pitch = 2 * np.pi / teeth
    for k in range(teeth):
        a = k * pitch
        # root land, flank up, flat tip, flank down (fractions of one pitch)
        for frac, r in ((0.00, r_root), (0.20, r_root), (0.35, r_tip), (0.65, r_tip), (0.80, r_root)):
            pts.append((r * np.cos(a + frac * pitch), r * np.sin(a + frac * pitch)))
    return extrude(np.asarray(pts), thickness)


def box() -> trimesh.Trimesh:
    return trimesh.creation.box(extents=(30.0, 20.0, 10.0))


PARTS = {"bracket": bracket, "gear": gear, "box": box}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=HERE, help="output folder (default: examples/parts)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for name, build in PARTS.items():
        mesh = build()
        path = args.out / f"{name}.stl"
        path.write_bytes(trimesh.exchange.stl.export_stl(mesh))
        print(f"{path}: {len(mesh.faces)} triangles, extents {np.round(mesh.extents, 3).tolist()} mm")


if __name__ == "__main__":
    main()
