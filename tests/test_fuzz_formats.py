"""Fuzz classes for inputs that were accepted but wrong, one per defect (docs/fuzz.md):

- ``program_names``: every KRL/RAPID reserved word and every name the exported programs use, in
  three spellings, through ``-o NAME.src|.mod`` and through ``program_name``: refused (exit 3 /
  InputError) naming the word and a name that passes, nothing written;
- ``picks_numbers``: a picks file's numbers tampered (1e300, -1e300, NaN, outside the joint limits,
  FK-inconsistent) through every export format: exit 3, one line, nothing written;
- ``stl_names``: ASCII STL solid names (spaces, hyphens, digits, unicode, keywords, empty, CRLF,
  one-line files) and binary STL headers starting with "solid": all load, as the right mesh;
- ``obj_numbers``: OBJ face numbers (0, past the vertices, negative past the vertices defined so
  far, valid relative and v/t/n forms): the right mesh or one MeshError naming the line;
- ``ply_counts``: PLY element counts (negative, absurd, off by one, not numbers) in ASCII and
  binary files: one MeshError naming the header line;
- ``robot_meshes``: robot collision/visual meshes over the limits in every counted format (the
  count read from the header or streamed, never loaded): a ConfigError naming the file, its count
  and the limit, in well under a second.

Deterministic. The default run takes a representative subset; ``GRASPLAN_FUZZ_FULL=1`` runs every
case.
"""
from __future__ import annotations

import json
import os
import random
import re
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

sys.path.insert(0, str(Path(__file__).parent))
from fuzz_cases import ascii_stl, binary_stl, obj_text, ply_ascii, ply_binary  # noqa: E402
from shift_inputs import FORMATS, huge_stl, picks_file, plan_file, plan_result, robot_yaml, tetra  # noqa: E402

import grasplan  # noqa: E402
from grasplan.cli import main  # noqa: E402
from grasplan.errors import ConfigError, InputError, MeshError  # noqa: E402
from grasplan.part.meshfile import ReadLimits, read_mesh  # noqa: E402
from grasplan.results.program_names import (
    KRL_PROGRAM_NAMES, KRL_RESERVED, RAPID_PROGRAM_NAMES, RAPID_RESERVED, program_name_problem
)

FULL = os.environ.get("GRASPLAN_FUZZ_FULL", "") not in ("", "0")
LIMITS = ReadLimits(1_000_000, 1 << 30)
LEAKS = re.compile(r"Traceback|KeyError|IndexError|ValueError|TypeError|AttributeError|OverflowError|"
                   r"RuntimeWarning|could not be read to its end|out of bounds|internal error")


def pick(cases: list, n: int, seed: int) -> list:
    """All ``cases`` in the full run, else ``n`` of them chosen with ``seed`` (the first ones kept:
    they are the issue's own)."""
    if FULL or len(cases) <= n:
        return cases
    head = cases[: n // 3]
    return head + random.Random(seed).sample(cases[n // 3:], n - len(head))


def run(*argv) -> object:
    return CliRunner().invoke(main, [str(a) for a in argv])


# -- program_names ---------------------------------------------------------------------------------

WORDS = ["END", "DEF", "IF", "MODULE", "PROC", "ENDMODULE"]
WORDS += sorted((KRL_RESERVED | RAPID_RESERVED | KRL_PROGRAM_NAMES | RAPID_PROGRAM_NAMES | {"XP1", "XP12", "JT_7"})
                - set(WORDS))
NAME_CASES = [(w, spell, fmt, route) for w in WORDS for spell in ("upper", "lower", "title")
              for fmt in ("krl", "rapid") for route in ("stem", "option")]
NAME_CASES = pick(NAME_CASES, 40, 1)


@pytest.mark.parametrize("word, spell, fmt, route", NAME_CASES,
                         ids=[f"{w}-{s}-{f}-{r}" for w, s, f, r in NAME_CASES])
def test_fuzz_program_names(tmp_path_factory, tmp_path, word, spell, fmt, route):
    name = {"upper": word.upper(), "lower": word.lower(), "title": word.title()}[spell]
    ext = ".src" if fmt == "krl" else ".mod"
    if route == "stem":
        out = tmp_path / f"{name}{ext}"
        r = run("export", plan_file(tmp_path_factory), "--format", fmt, "-o", out)
        assert r.exit_code == 3, r.output
        msg = r.output.strip().splitlines()[-1]
        assert msg.startswith("grasplan: error: ") and not LEAKS.search(r.output), r.output
        assert not out.exists() and not out.with_suffix(".dat").exists()
        good = re.search(r"write it as (\S+)" + re.escape(ext) + "$", msg)
    else:
        with pytest.raises(InputError) as err:
            grasplan.export.render(plan_result(tmp_path_factory), fmt, program_name=name)
        msg = str(err.value)
        good = re.search(r"use e\.g\. '([^']+)'", msg)
    assert f"'{name}'" in msg and ("reserved word" in msg or "itself declares" in msg), msg
    assert msg.count("\n") == 0 and not LEAKS.search(msg)
    assert good is not None and program_name_problem(good.group(1)) is None, msg


# -- picks_numbers ---------------------------------------------------------------------------------

#: (field path in a pick, tamperings that must be refused)
PICK_FIELDS = [
    (("q_grasp", 0), ("1e300", "-1e300", "nan", "limit", "fk")),
    (("q_pregrasp", 2), ("1e300", "-1e300", "nan", "limit", "fk")),
    (("path", 0, 0), ("1e300", "-1e300", "nan", "limit", "fk")),
    (("path", 5, 1), ("1e300", "-1e300", "nan", "limit")),  # a row inside the approach: FK-checked on export only
    (("path", -1, 5), ("1e300", "-1e300", "nan", "limit", "fk")),
    (("T_world_part", 0, 3), ("1e300", "-1e300", "nan", "fk")),
    (("T_part_tcp", 1, 3), ("1e300", "-1e300", "nan", "fk")),
    (("T_part_tcp", 0, 0), ("1e300", "-1e300", "nan", "fk")),
    (("T_world_tcp", 2, 3), ("1e300", "-1e300", "nan", "fk")),
    (("T_world_pregrasp", 0, 3), ("1e300", "-1e300", "nan", "fk")),
    (("T_world_lifted", 2, 3), ("1e300", "-1e300", "nan", "fk")),
    (("T_tcp_part", 0, 3), ("1e300", "-1e300", "nan", "fk")),
    (("contacts", 0, 0), ("1e300", "-1e300", "nan", "fk")),
    (("normals", 1, 2), ("1e300", "-1e300", "nan", "fk")),
    (("width",), ("1e300", "-1e300", "nan")),
    (("opening",), ("1e300", "-1e300", "nan", "fk")),
    (("score",), ("1e300", "-1e300", "nan")),
    (("rank",), ("1e300", "-1e300", "nan")),
    (("quality", "epsilon"), ("-1e300", "nan")),
    (("gripper", 0, "width"), ("1e300", "-1e300", "nan")),
]
PICK_CASES = [(f, kind, fmt) for f, kinds in PICK_FIELDS for kind in kinds for fmt in sorted(FORMATS)]
PICK_CASES = pick(PICK_CASES, 50, 2)


def _tamper(doc: dict, field: tuple, kind: str) -> None:
    from grasplan.robot.description import robot_from_json

    d = doc["picks"][0]
    for k in field[:-1]:
        d = d[k]
    old = d[field[-1]]
    if kind == "limit":  # just outside the joint's upper limit
        d[field[-1]] = float(robot_from_json(doc["robot"]).upper[field[-1]]) + 0.01
    elif kind == "fk":  # a small, plausible-looking edit: 0.05 rad, 0.05 on a unit normal, else 5 mm
        d[field[-1]] = old + (0.05 if field[0] in ("q_grasp", "q_pregrasp", "path", "normals") else 0.005)
    else:
        d[field[-1]] = float(kind)


@pytest.mark.parametrize("field, kind, fmt", PICK_CASES,
                         ids=[f"{'.'.join(map(str, f))}-{k}-{fmt}" for f, k, fmt in PICK_CASES])
def test_fuzz_picks_numbers(tmp_path_factory, tmp_path, field, kind, fmt):
    doc = json.loads(picks_file(tmp_path_factory).read_text())
    _tamper(doc, field, kind)
    src = tmp_path / "picks.json"
    src.write_text(json.dumps(doc))  # NaN is written as the NaN literal Python's JSON reads back
    out = tmp_path / FORMATS[fmt]
    r = run("export", src, "--format", fmt, "-o", out)
    assert r.exit_code == 3, r.output
    msg = r.output.strip().splitlines()[-1]
    assert msg.startswith("grasplan: error: ") and not LEAKS.search(r.output), r.output
    assert sorted(os.listdir(tmp_path)) == ["picks.json"]  # nothing written, no temporary file left


# -- stl_names -------------------------------------------------------------------------------------

STL_NAMES = ["Vertex-Bracket", "vertex", "VERTEX 1 2 3", "my part 2", "", "solid", "endsolid", "facet normal 0 0 1",
             "outer loop vertex 0 0 0", "Würfel 40×30", "部品", "x" * 500, "a\tb", "1e5", "-", "endloop endfacet",
             "vertex 1e999 nan inf", "#;!\"'<>", "solid solid vertex"]
STL_CASES = [(n, layout) for n in STL_NAMES for layout in ("lf", "crlf", "one-line", "bom")
             # on one line, a name holding STL keywords is ambiguous: the name ends at 'facet normal'
             if not (layout == "one-line" and re.search(r"facet|vertex|endloop", n, re.I))]
STL_CASES += [(n, "binary-header") for n in STL_NAMES if len(n.encode()) <= 70]
STL_CASES = pick(STL_CASES, 30, 3)


def _ascii_named(name: str, layout: str) -> bytes:
    v, f = tetra()
    lines = ascii_stl(v, f).decode().split("\n")[1:-2]
    text = "\n".join([f"solid {name}"] + lines + [f"endsolid {name}", ""])
    if layout == "crlf":
        text = text.replace("\n", "\r\n")
    elif layout == "one-line":
        text = " ".join(t.strip() for t in text.split("\n")) + "\n"
    data = text.encode("utf-8")
    return b"\xef\xbb\xbf" + data if layout == "bom" else data


@pytest.mark.parametrize("name, layout", STL_CASES, ids=[f"{i}-{lay}" for i, (_, lay) in enumerate(STL_CASES)])
def test_fuzz_stl_names(tmp_path, name, layout):
    v, f = tetra()
    path = tmp_path / "part.stl"
    if layout == "binary-header":
        path.write_bytes(binary_stl(v, f, header=f"solid {name}".encode()[:80]))
    else:
        path.write_bytes(_ascii_named(name, layout))
    got_v, got_f, _ = read_mesh(path, LIMITS)
    assert np.allclose(got_v[got_f], v[f]), (name, layout)


# -- obj_numbers -----------------------------------------------------------------------------------

def _obj_cases() -> list[tuple[str, str, object]]:
    """(case id, OBJ text, the triangles' vertex coordinates expected or the error's regex)."""
    v, f = tetra()
    vs = "".join(f"v {x} {y} {z}\n" for x, y, z in v)
    tris = v[f]
    out: list[tuple[str, str, object]] = []
    for face in range(4):
        for pos in range(3):
            for bad, why in (("0", "vertex 0 does not exist"), ("5", "vertex 5 does not exist"),
                             ("9999999", "vertex 9999999 does not exist"), ("-5", "vertex -5 counts back"),
                             ("x", "'x' is not a vertex number"), ("1.5", "'1.5' is not a vertex number"),
                             ("99999999999999999999", "is not a vertex number"), ("--1", "is not a vertex number")):
                rows = [[str(i + 1) for i in fr] for fr in f]
                rows[face][pos] = bad
                text = vs + "".join("f " + " ".join(r) + "\n" for r in rows)
                out.append((f"f{face}p{pos}-{bad[:6]}", text, rf"OBJ line {5 + face}: .*{re.escape(why)}"))
    rel = "".join(f"f {a - 4} {b - 4} {c - 4}\n" for a, b, c in f)
    out.append(("relative", vs + rel, tris))
    out.append(("relative-interleaved", vs + rel + "".join(f"v {x + 50} {y} {z}\n" for x, y, z in v) + rel,
                np.concatenate([tris, tris + [50, 0, 0]])))
    out.append(("relative-too-early", "v 0 0 0\nv 20 0 0\nf -1 -2 -3\nv 0 20 0\n", r"OBJ line 3: .*counts back"))
    out.append(("vtn", vs + "vt 0 0\nvn 0 0 1\n" + "".join(f"f {a + 1}/1/1 {b + 1}//1 {c + 1}/1\n" for a, b, c in f),
                tris))
    out.append(("comments-groups", "# a part\no p\n" + vs + "g g1\nusemtl m\ns off\n"
                + "".join(f"f {a + 1} {b + 1} {c + 1} # face\n" for a, b, c in f), tris))
    out.append(("quad", "v 0 0 0\nv 20 0 0\nv 20 20 0\nv 0 20 0\nv 0 0 20\nf 1 4 3 2\nf 1 2 5\nf 2 3 5\nf 3 4 5\nf 4 1 5\n",
                np.array([[0, 0, 0], [20, 20, 0], [20, 0, 0]], dtype=float)))
    out.append(("two-vertices", vs + "f 1 2\n", r"OBJ line 5: 'f 1 2': a face needs at least 3 vertices"))
    out.append(("no-faces", vs, r"holds no faces"))
    out.append(("bad-vertex", vs + "v 1 two 3\nf 1 2 3\n", r"OBJ line 5: cannot read 'v 1 two 3'"))
    out.append(("crlf", (vs + "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n").replace("\n", "\r\n"), tris))
    out.append(("continued", vs + "f 1 3 \\\n 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n", tris))
    return out


OBJ_CASES = pick(_obj_cases(), 30, 4)


@pytest.mark.parametrize("name, text, want", OBJ_CASES, ids=[c[0] for c in OBJ_CASES])
def test_fuzz_obj_numbers(tmp_path, name, text, want):
    path = tmp_path / "part.obj"
    path.write_text(text)
    if isinstance(want, str):
        with pytest.raises(MeshError, match=want) as err:
            read_mesh(path, LIMITS)
        assert not LEAKS.search(str(err.value)) and "index" not in str(err.value)
        return
    v, f, _ = read_mesh(path, LIMITS)
    if name == "quad":  # a polygon as a triangle fan from its first vertex: 6 triangles in all
        assert len(f) == 6 and np.allclose(v[f[1]], want) and f[0].tolist() == [0, 3, 2]
    else:
        assert np.allclose(v[f], want), name


def test_fuzz_obj_number_zero_exit_3(tmp_path):
    """Through the CLI: exit 3 (was 4) with one line naming the OBJ line."""
    v, f = tetra()
    path = tmp_path / "part.obj"
    path.write_bytes(obj_text(v, f).replace(b"f 1 2 4", b"f 1 0 4"))
    r = run("candidates", path, "-o", tmp_path / "c.json")
    assert r.exit_code == 3 and "OBJ line 6" in r.output and not LEAKS.search(r.output), r.output


# -- ply_counts ------------------------------------------------------------------------------------

def _ply_cases() -> list[tuple[str, bytes, str | None]]:
    v, f = tetra()
    out: list[tuple[str, bytes, str | None]] = []
    for fmt, data in (("ascii", ply_ascii(v, f)), ("binary", ply_binary(v, f))):
        out.append((f"{fmt}-valid", data, None))
        for elem, n in (("vertex", 4), ("face", 4)):
            line = f"element {elem} {n}".encode()
            assert line in data
            for bad, why in (("-12", "a whole number >= 0"), ("-1", "a whole number >= 0"), ("abc", "a whole number"),
                             ("4.0", "a whole number"), ("", "a name and a count"), ("4 4", "a name and a count"),
                             ("99999999999", "more than grasplan handles"), ("4000000000", "more than grasplan handles"),
                             ("999999999999999999999999", "a whole number"), (str(n + 1), None), (str(n - 1), None),
                             (str(n + 1000), None), ("0", None)):
                why = why or ("element lines" if fmt == "ascii" else "bytes")
                edited = data.replace(line, f"element {elem} {bad}".strip().encode(), 1)
                out.append((f"{fmt}-{elem}-{bad[:8] or 'none'}", edited, why))
    return out


PLY_CASES = pick(_ply_cases(), 24, 5)


@pytest.mark.parametrize("name, data, why", PLY_CASES, ids=[c[0] for c in PLY_CASES])
def test_fuzz_ply_counts(tmp_path, name, data, why):
    path = tmp_path / "part.ply"
    path.write_bytes(data)
    if why is None:
        _, f, _ = read_mesh(path, LIMITS)
        assert len(f) == 4
        return
    with pytest.raises(MeshError) as err:
        read_mesh(path, LIMITS)
    msg = str(err.value)
    assert re.search(r"PLY header line \d+ 'element (vertex|face)", msg) and why in msg, msg
    assert not LEAKS.search(msg)


# -- robot_meshes ----------------------------------------------------------------------------------

def _mesh_file(folder: Path, fmt: str, triangles: int) -> Path:
    """A mesh file of ``fmt`` whose triangle count (as grasplan counts it without loading) is
    ``triangles``: declared in the header (binary STL in a sparse file, PLY, OFF, Collada) or
    written out (ASCII STL facets, OBJ faces; kept small by the caller)."""
    path = folder / f"m_{fmt}_{triangles}.{fmt.split('-')[0]}"
    if fmt == "stl":
        return huge_stl(path, triangles)
    if fmt == "stl-ascii":  # counted by its facets' ends (kept short: the count is what is tested)
        path = folder / f"m_ascii_{triangles}.stl"
        path.write_bytes(b"solid x\n" + b"endfacet\n" * triangles + b"endsolid x\n")
    elif fmt == "obj":
        path.write_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\n" + b"f 1 2 3\n" * triangles)
    elif fmt == "ply":
        path.write_bytes(f"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                         f"property float z\nelement face {triangles}\nproperty list uchar int vertex_indices\n"
                         f"end_header\n".encode())
    elif fmt == "off":
        path.write_bytes(f"OFF\n3 {triangles} 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n".encode())
    elif fmt == "dae":
        half = triangles // 2
        path.write_bytes(f'<?xml version="1.0"?><COLLADA><library_geometries><geometry><mesh>'
                         f'<triangles material="a" count="{half}"><p>0 1 2</p></triangles>'
                         f'<polylist count="{triangles - half}"><vcount>3</vcount><p>0 1 2</p></polylist>'
                         f'</mesh></geometry></library_geometries></COLLADA>'.encode())
    return path


ROBOT_FORMATS = ["stl", "stl-ascii", "obj", "ply", "off", "dae"]
ROBOT_CASES = [(fmt, kind, scale) for fmt in ROBOT_FORMATS for kind in ("collision", "visual")
               for scale in ("limit", "2M")]
ROBOT_CASES += [("missing", "collision", "-"), ("unsupported", "collision", "-"), ("folder", "collision", "-"),
                ("budget", "collision", "-"), ("budget", "visual", "-")]
ROBOT_CASES = pick(ROBOT_CASES, 14, 6)


@pytest.mark.parametrize("fmt, kind, scale", ROBOT_CASES, ids=[f"{a}-{b}-{c}" for a, b, c in ROBOT_CASES])
def test_fuzz_robot_meshes(tmp_path, monkeypatch, fmt, kind, scale):
    import grasplan.part.mesh
    import grasplan.robot.files

    v, f = tetra()
    ok = tmp_path / "ok.stl"
    ok.write_bytes(binary_stl(v * 1e-3, f))
    n = 2_000_000 if scale == "2M" else 50
    if fmt in ("stl-ascii", "obj") and scale == "2M":
        n = 1_000_001 if FULL else 50  # streamed, ~9 MB in the full run; the default run lowers the limit
        if not FULL:
            scale = "limit"
    if scale == "limit":
        monkeypatch.setattr(grasplan.part.mesh, "MAX_TRIANGLES", 40)  # the constant is read when the robot is built
    if fmt == "missing":
        bad, want = "nowhere/gone.stl", r"'nowhere/gone.stl': not found"
    elif fmt == "unsupported":
        (tmp_path / "m.3ds").write_bytes(b"\0" * 100)
        bad, want = "m.3ds", r"unsupported file type '\.3ds'"
    elif fmt == "folder":
        (tmp_path / "dir.stl").mkdir()
        bad, want = "dir.stl", r"is a folder"
    elif fmt == "budget":
        monkeypatch.setattr(grasplan.robot.files, "MAX_ROBOT_TRIANGLES", 7)
        bad, want = "ok.stl", f"{kind} meshes hold 8 triangles in all"
    else:
        path = _mesh_file(tmp_path, fmt, n)
        bad, want = path.name, rf"{re.escape(path.name)}: (PLY header line \d+ '[^']*': )?{n:,} (triangles|faces) is more than"
    meshes = {"l1": "ok.stl", "l2": bad}
    y = robot_yaml(tmp_path, meshes if kind == "collision" else {"l1": "ok.stl"},
                   visual=meshes if kind == "visual" else None, name=f"r_{fmt}_{kind}_{scale}")
    t0 = time.process_time()
    with pytest.raises(ConfigError) as err:
        robot = grasplan.load_robot(y)
        robot.visual_model
    assert time.process_time() - t0 < 2.0
    msg = str(err.value)
    assert re.search(want, msg), msg
    assert f"{kind} mesh" in msg and not LEAKS.search(msg)
