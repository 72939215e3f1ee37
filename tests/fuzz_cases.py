"""Deterministic generator of malformed mesh inputs for the fuzz suite (issue 14).

Every case is a :class:`MeshCase`: a name, a CLI command (``candidates`` or ``grasps``), extra
options, and how to materialise PART in a scratch folder (file bytes, a folder, a FIFO, a
missing file, a very long name...). Cases come from :func:`mesh_cases` with a seeded
``numpy.random.Generator``, so the same seed gives byte-identical cases on every machine.

Used by ``tests/test_fuzz_mesh.py``; the full run is documented in ``docs/fuzz.md``.
"""
from __future__ import annotations

import os
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: the seed of the suite's cases (``GRASPLAN_FUZZ_SEED`` overrides it)
DEFAULT_SEED = 14


@dataclass(frozen=True)
class MeshCase:
    """One fuzz case. ``make(folder) -> PART path`` creates the input inside ``folder``."""

    name: str
    family: str
    make: Callable[[Path], Path] = field(repr=False, compare=False)
    command: str = "candidates"
    options: tuple[str, ...] = ()

    def args(self, part: Path, out: Path) -> list[str]:
        """The CLI arguments (``grasplan <args>``)."""
        return [self.command, str(part), "-o", str(out), *self.options]


# -- geometry helpers (plain NumPy so the cases do not depend on the code under test) ----------

def _box(ex=(30.0, 20.0, 10.0)) -> tuple[np.ndarray, np.ndarray]:
    """A closed box, vertices (8, 3) centred at 0 and faces (12, 3) wound outwards."""
    ex = np.asarray(ex, dtype=np.float64) / 2
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64) * ex
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return v, f


def _cylinder(r=10.0, h=25.0, n=16) -> tuple[np.ndarray, np.ndarray]:
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring = np.c_[r * np.cos(a), r * np.sin(a)]
    v = np.vstack([np.c_[ring, np.zeros(n)], np.c_[ring, np.full(n, h)], [[0, 0, 0], [0, 0, h]]])
    i = np.arange(n)
    j = (i + 1) % n
    f = np.vstack([np.c_[i, 2 * n + np.zeros(n, int), j], np.c_[n + i, n + j, np.full(n, 2 * n + 1)],
                   np.c_[i, j, n + j], np.c_[i, n + j, n + i]])
    return v, f


def binary_stl(v: np.ndarray, f: np.ndarray, *, header: bytes = b"grasplan fuzz") -> bytes:
    tri = np.asarray(v, dtype=np.float64)[np.asarray(f)]
    rec = np.zeros(len(tri), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = tri
    return header.ljust(80, b" ")[:80] + struct.pack("<I", len(tri)) + rec.tobytes()


def ascii_stl(v: np.ndarray, f: np.ndarray, *, fmt: Callable[[float], str] = repr) -> bytes:
    lines = ["solid fuzz"]
    for t in np.asarray(v, dtype=np.float64)[np.asarray(f)]:
        lines += ["  facet normal 0 0 0", "    outer loop"]
        lines += [f"      vertex {fmt(float(p[0]))} {fmt(float(p[1]))} {fmt(float(p[2]))}" for p in t]
        lines += ["    endloop", "  endfacet"]
    lines.append("endsolid fuzz")
    return ("\n".join(lines) + "\n").encode()


def obj_text(v: np.ndarray, f: np.ndarray) -> bytes:
    return ("".join(f"v {a!r} {b!r} {c!r}\n" for a, b, c in np.asarray(v, float).tolist())
            + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in np.asarray(f).tolist())).encode()


def ply_ascii(v: np.ndarray, f: np.ndarray) -> bytes:
    head = (f"ply\nformat ascii 1.0\nelement vertex {len(v)}\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    return (head + "".join(f"{a!r} {b!r} {c!r}\n" for a, b, c in np.asarray(v, float).tolist())
            + "".join(f"3 {a} {b} {c}\n" for a, b, c in np.asarray(f).tolist())).encode()


def ply_binary(v: np.ndarray, f: np.ndarray) -> bytes:
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\nproperty float x\n"
            f"property float y\nproperty float z\nelement face {len(f)}\n"
            f"property list uchar int vertex_indices\nend_header\n").encode()
    fr = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", 3)])
    fr["n"], fr["i"] = 3, f
    return head + np.asarray(v, "<f4").tobytes() + fr.tobytes()


def off_text(v: np.ndarray, f: np.ndarray) -> bytes:
    return (f"OFF\n{len(v)} {len(f)} 0\n" + "".join(f"{a!r} {b!r} {c!r}\n" for a, b, c in np.asarray(v, float).tolist())
            + "".join(f"3 {a} {b} {c}\n" for a, b, c in np.asarray(f).tolist())).encode()


def _file(name: str, data: bytes) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        p = folder / name
        p.write_bytes(data)
        return p
    return make


# -- the families ------------------------------------------------------------------------------

def _truncated(rng, out):
    shapes = {"box": _box(), "cyl": _cylinder()}
    for sname, (v, f) in shapes.items():
        data = binary_stl(v, f)
        cuts = sorted(set(int(c) for c in rng.integers(1, len(data) - 1, 40)) | {1, 80, 83, 84, 85, 133})
        for c in cuts:
            out.append(MeshCase(f"trunc-bin-{sname}-{c}", "truncated_binary_stl", _file("part.stl", data[:c])))
        text = ascii_stl(v, f)
        for c in sorted(set(int(c) for c in rng.integers(5, len(text) - 1, 15))):
            out.append(MeshCase(f"trunc-ascii-{sname}-{c}", "truncated_ascii_stl", _file("part.stl", text[:c])))


def _garbled(rng, out):
    v, f = _box()
    data = bytearray(binary_stl(v, f))
    for k in range(60):
        d = bytearray(data)
        mode = k % 4
        if mode == 0:  # wrong triangle count
            d[80:84] = struct.pack("<I", int(rng.integers(0, 2**32)))
        elif mode == 1:  # random bytes in the records
            idx = rng.integers(84, len(d), int(rng.integers(1, 40)))
            d_arr = np.frombuffer(bytes(d), np.uint8).copy()
            d_arr[idx] = rng.integers(0, 256, len(idx))
            d = bytearray(d_arr.tobytes())
        elif mode == 2:  # extra trailing bytes
            d += rng.bytes(int(rng.integers(1, 120)))
        else:  # a header that says "solid" on a binary body
            d[:5] = b"solid"
            if k % 8 == 3:
                d = d[: len(d) - int(rng.integers(1, 40))]
        out.append(MeshCase(f"garbled-bin-{k}", "garbled_binary_stl", _file("part.stl", bytes(d))))
    for k in range(30):
        n = int(rng.integers(1, 3000))
        out.append(MeshCase(f"random-bytes-{k}", "random_bytes", _file("part.stl", rng.bytes(n))))
    for k in range(20):
        body = rng.bytes(int(rng.integers(0, 2000)))
        out.append(MeshCase(f"solid-random-{k}", "random_bytes", _file("part.stl", b"solid " + body)))


_BAD_NUMBERS = ["abc", "1e999", "-1e999", "nan", "NaN", "inf", "-inf", "1.2.3", "0x10", "-", "+", "1e", "e5",
                "1,5", "１", "1e308", "-1e308", "9" * 400, "1_000", "", "\x00", "1e-400", "Infinity", "--1"]


def _ascii_bad(rng, out):
    v, f = _box()
    base = ascii_stl(v, f).decode()
    lines = base.split("\n")
    vlines = [i for i, line in enumerate(lines) if line.strip().startswith("vertex")]
    for k, tok in enumerate(_BAD_NUMBERS * 3):
        li = list(lines)
        i = vlines[int(rng.integers(len(vlines)))]
        parts = li[i].split()
        parts[1 + int(rng.integers(3))] = tok
        li[i] = "      " + " ".join(parts)
        out.append(MeshCase(f"ascii-number-{k}", "ascii_bad_number", _file("part.stl", "\n".join(li).encode())))
    for k in range(30):
        li = list(lines)
        kind = k % 5
        if kind == 0:  # drop a vertex line
            del li[vlines[int(rng.integers(len(vlines)))]]
        elif kind == 1:  # a vertex with 2 or 4 numbers
            i = vlines[int(rng.integers(len(vlines)))]
            li[i] += " 1.0" if k % 2 else ""
            li[i] = li[i] if k % 2 else " ".join(li[i].split()[:-1])
        elif kind == 2:  # keywords only
            li = [line for line in li if "vertex" not in line]
        elif kind == 3:  # shuffled lines
            li = [li[j] for j in rng.permutation(len(li))]
        else:  # binary junk in the middle
            li.insert(int(rng.integers(1, len(li))), rng.bytes(30).decode("latin-1"))
        out.append(MeshCase(f"ascii-struct-{k}", "ascii_bad_structure",
                            _file("part.stl", "\n".join(li).encode("utf-8", "surrogateescape"))))


def _other_formats(rng, out):
    v, f = _cylinder()
    good = {".obj": obj_text(v, f), ".ply": ply_ascii(v, f), ".off": off_text(v, f)}
    good_bin_ply = ply_binary(v, f)
    for k in range(25):  # OBJ garbage
        text = good[".obj"].decode().split("\n")
        mode = k % 5
        if mode == 0:
            text.append(f"f 1 2 {int(rng.integers(100, 10**6))}")
        elif mode == 1:
            text.append("f -1 -2 -999")
        elif mode == 2:
            text = [line for line in text if not line.startswith("f")]
        elif mode == 3:
            text.insert(int(rng.integers(len(text))), "v 1 two 3")
        else:
            text = [line.replace("v ", "v nan ", 1) if rng.random() < 0.2 else line for line in text]
        out.append(MeshCase(f"obj-{k}", "obj_garbage", _file("part.obj", "\n".join(text).encode())))
    for k in range(10):
        out.append(MeshCase(f"obj-random-{k}", "obj_garbage", _file("part.obj", rng.bytes(int(rng.integers(1, 800))))))
    for k in range(25):  # PLY garbage
        data = good[".ply"] if k % 2 else good_bin_ply
        mode = k % 5
        if mode == 0:
            data = data[: int(rng.integers(1, len(data)))]
        elif mode == 1:
            data = data.replace(b"element vertex", b"element vertex 999999 ", 1)
        elif mode == 2:
            data = data.replace(b"property float y\n", b"", 1)
        elif mode == 3:
            data = data.replace(b"element face", b"element face 4000000000 ", 1)
        else:
            data = b"ply\n" + rng.bytes(200)
        out.append(MeshCase(f"ply-{k}", "ply_garbage", _file("part.ply", data)))
    for k in range(12):  # OFF garbage
        data = good[".off"]
        data = data[: int(rng.integers(3, len(data)))] if k % 2 else data.replace(b"OFF\n", b"OFF\n-3 ", 1)
        out.append(MeshCase(f"off-{k}", "off_garbage", _file("part.off", data)))
    for k in range(8):
        out.append(MeshCase(f"glb-{k}", "gltf_garbage", _file("part.glb", b"glTF" + rng.bytes(int(rng.integers(0, 300))))))
        out.append(MeshCase(f"gltf-{k}", "gltf_garbage",
                            _file("part.gltf", b'{"asset": {"version": "2.0"}, "buffers": [{"uri": "missing.bin"}]'
                                  if k % 2 else rng.bytes(50))))


def _non_finite(rng, out):
    v, f = _box()
    for k in range(40):
        w = v.copy()
        val = [np.nan, np.inf, -np.inf, 1e308, -1e308, 3e38, 1e300, 1e200][k % 8]
        w[int(rng.integers(len(w))), int(rng.integers(3))] = val
        if k % 2 and abs(val) < 3.5e38 or not np.isfinite(val):
            data = binary_stl(w, f)
            name = "part.stl"
        else:
            data = ascii_stl(w, f) if k % 3 else obj_text(w, f)
            name = "part.stl" if k % 3 else "part.obj"
        out.append(MeshCase(f"nonfinite-{k}", "non_finite", _file(name, data)))
    for k in range(10):  # far from the origin
        w = v + float(10.0 ** rng.integers(5, 300))
        out.append(MeshCase(f"offset-{k}", "far_offset", _file("part.stl", ascii_stl(w, f))))


def _degenerate(rng, out):
    n = 12
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ngon = np.vstack([np.c_[20 * np.cos(a), 20 * np.sin(a), np.zeros(n)], [[0, 0, 0]]])
    flat = {
        "single-triangle": (np.array([[0, 0, 0], [30, 0, 0], [0, 20, 0.0]]), np.array([[0, 1, 2]])),
        "plane": (np.array([[0, 0, 0], [50, 0, 0], [50, 30, 0], [0, 30, 0.0]]), np.array([[0, 1, 2], [0, 2, 3]])),
        "bow-tie": (np.array([[0, 0, 0], [50, 0, 0], [25, 12.5, 0], [0, 25, 0], [50, 25, 0.0]]),
                    np.array([[0, 1, 2], [2, 4, 3]])),
        "n-gon": (ngon, np.array([[i, (i + 1) % n, n] for i in range(n)])),
        "flattened-box": (_box((30, 20, 0.0))[0], _box()[1]),
        "thin-box": (_box((30, 20, 1e-9))[0], _box()[1]),
        "collinear": (np.array([[0, 0, 0], [10, 0, 0], [20, 0, 0], [30, 0, 0.0]]), np.array([[0, 1, 2], [1, 2, 3]])),
        "point": (np.zeros((3, 3)), np.array([[0, 1, 2]])),
        "repeated-index": (_box()[0], np.array([[0, 0, 1], [2, 2, 2]])),
        "bad-index": (_box()[0], np.array([[0, 1, 2], [3, 4, 2**20]])),
    }
    for name, (v, f) in flat.items():
        for cmd in ("candidates", "grasps"):
            fv = v.copy()
            if rng.random() < 0.5:  # tilt some of them
                c, s = np.cos(0.3), np.sin(0.3)
                fv = fv @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]]).T
            try:
                data = binary_stl(fv, f)
            except IndexError:  # bad-index: only representable in OBJ
                data = None
            opts = ("--roll-step", "90") if cmd == "grasps" else ()
            if data is not None:
                out.append(MeshCase(f"degenerate-{name}-{cmd}", "degenerate", _file("part.stl", data), cmd, opts))
            out.append(MeshCase(f"degenerate-{name}-{cmd}-obj", "degenerate", _file("part.obj", obj_text(fv, f)),
                                cmd, opts))
    for k in range(20):  # random triangle soups, some coplanar
        m = int(rng.integers(1, 12))
        v = rng.normal(size=(3 * m, 3)) * 10
        if k % 2:
            v[:, 2] = 0.0
        out.append(MeshCase(f"soup-{k}", "degenerate", _file("part.stl", binary_stl(v, np.arange(3 * m).reshape(-1, 3))),
                            "grasps" if k % 4 == 1 else "candidates", ("--roll-step", "90") if k % 4 == 1 else ()))


def _scales(rng, out):
    v, f = _box()
    for k, e in enumerate(range(-14, 15, 2)):
        for units in ("auto", "mm", "m", "in"):
            out.append(MeshCase(f"scale-1e{e}-{units}", "scale", _file("part.stl", binary_stl(v * 10.0 ** e, f)),
                                options=("--units", units)))
    inch = _box((40 / 25.4, 30 / 25.4, 20 / 25.4))
    out.append(MeshCase("inch-part-auto", "scale", _file("part.stl", binary_stl(*inch))))
    out.append(MeshCase("metre-part-as-mm", "scale", _file("part.stl", binary_stl(v / 1000, f)), options=("--units", "mm")))


def _extensions(rng, out):
    v, f = _box()
    payloads = {"stl": binary_stl(v, f), "astl": ascii_stl(v, f), "obj": obj_text(v, f), "ply": ply_ascii(v, f)}
    for pname, data in payloads.items():
        for ext in (".stl", ".obj", ".ply", ".off", ".glb", ".txt", ".step", "", ".STL", ".stl.gz"):
            out.append(MeshCase(f"ext-{pname}-as{ext or '-none'}", "wrong_extension", _file(f"part{ext}", data)))


def _special_paths(rng, out):
    v, f = _box()
    data = binary_stl(v, f)

    def folder(p: Path) -> Path:
        d = p / "folder.stl"
        d.mkdir()
        return d

    def fifo(p: Path) -> Path:
        q = p / "pipe.stl"
        os.mkfifo(q)
        return q

    def missing(p: Path) -> Path:
        return p / "missing.stl"

    def long_name(p: Path) -> Path:
        return p / ("x" * 300 + ".stl")

    def long_path(p: Path) -> Path:
        return p.joinpath(*["d" * 200] * 30, "part.stl")

    def unreadable(p: Path) -> Path:
        q = _file("locked.stl", data)(p)
        q.chmod(0)
        return q

    def symlink_loop(p: Path) -> Path:
        q = p / "loop.stl"
        q.symlink_to(q)
        return q

    specials = {"folder": folder, "fifo": fifo, "missing": missing, "long-name": long_name, "long-path": long_path,
                "unreadable": unreadable, "symlink-loop": symlink_loop, "dev-null": lambda p: Path("/dev/null"),
                "empty": _file("empty.stl", b""), "newline-name": _file("evil\n  popup(\"x\")\n#.stl", data),
                "unicode-name": _file("teil\u2028ü.stl", data), "space-name": _file(" part .stl", data),
                "dash-name": _file("-part.stl", data), "nul-bytes": _file("zeros.stl", b"\0" * 84)}
    for name, make in specials.items():
        for cmd in ("candidates", "grasps"):
            out.append(MeshCase(f"path-{name}-{cmd}", "special_path", make, cmd,
                                ("--roll-step", "90") if cmd == "grasps" else ()))


FAMILIES = (_truncated, _garbled, _ascii_bad, _other_formats, _non_finite, _degenerate, _scales, _extensions,
            _special_paths)


def mesh_cases(seed: int = DEFAULT_SEED) -> list[MeshCase]:
    """All malformed-mesh cases for ``seed`` (deterministic; names are unique)."""
    rng = np.random.default_rng(seed)
    out: list[MeshCase] = []
    for family in FAMILIES:
        family(rng, out)
    names = [c.name for c in out]
    assert len(names) == len(set(names)), "duplicate fuzz case names"
    return out


def representative(cases: list[MeshCase], per_family: int, seed: int = DEFAULT_SEED) -> list[MeshCase]:
    """A deterministic subset: every ``special_path``, ``degenerate`` and ``scale`` case named in
    the issue, plus up to ``per_family`` cases of every family, spread evenly over it."""
    keep: dict[str, MeshCase] = {}
    must = ("path-", "degenerate-", "inch-part", "metre-part")
    by_family: dict[str, list[MeshCase]] = {}
    for c in cases:
        by_family.setdefault(c.family, []).append(c)
    for fam, cs in by_family.items():
        step = max(1, len(cs) // per_family)
        for c in cs[::step][:per_family]:
            keep[c.name] = c
    for c in cases:
        if c.name.startswith(must) and (c.command == "grasps" or "grasps" not in c.name) and \
                (c.family != "degenerate" or not c.name.endswith("-obj")):
            keep[c.name] = c
    return [c for c in cases if c.name in keep]


def uv_sphere(n_target: int, radius: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (in the units of ``radius``) and outward faces of a UV sphere of about ``n_target`` triangles (plain NumPy)."""
    nlat = int(round((n_target / 4) ** 0.5))
    nlon = 2 * nlat
    th = np.linspace(0, np.pi, nlat + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, nlon, endpoint=False)
    T, P = np.meshgrid(th, ph, indexing="ij")
    v = radius * np.c_[np.sin(T).ravel() * np.cos(P).ravel(), np.sin(T).ravel() * np.sin(P).ravel(), np.cos(T).ravel()]
    v = np.vstack([v, [[0, 0, radius], [0, 0, -radius]]])
    top, bot = len(v) - 2, len(v) - 1
    idx = np.arange((nlat - 1) * nlon).reshape(nlat - 1, nlon)
    nxt = np.roll(idx, -1, axis=1)
    f = np.vstack([np.c_[np.full(nlon, top), idx[0], nxt[0]], np.c_[np.full(nlon, bot), nxt[-1], idx[-1]],
                   np.c_[idx[:-1].ravel(), idx[1:].ravel(), nxt[:-1].ravel()],
                   np.c_[nxt[:-1].ravel(), idx[1:].ravel(), nxt[1:].ravel()]])
    return v, f
