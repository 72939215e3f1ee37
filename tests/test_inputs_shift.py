"""Inputs that were accepted but wrong, and robot meshes without limits: each test
states the rule and fails on the code before it was enforced.

- KRL/RAPID program names: reserved words and the programs' own names are refused, from ``-o``'s
  stem and from ``program_name``, with a name that passes;
- picks files: every number checked as a plan's (finite, joint limits, FK-consistent);
- plan and picks files: a key written twice is refused;
- ASCII STL whatever its solid name, binary STL whose header says "solid"; OBJ vertex numbering;
  PLY element counts;
- robot meshes: refused from their header counts before Pinocchio loads them.
"""
from __future__ import annotations

import json
import re
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

sys.path.insert(0, str(Path(__file__).parent))
from fuzz_cases import ascii_stl, binary_stl, obj_text, ply_ascii, ply_binary  # noqa: E402
from shift_inputs import huge_stl, picks_file, plan_file, plan_result, robot_yaml, tetra  # noqa: E402

import grasplan  # noqa: E402
from grasplan.cli import main  # noqa: E402
from grasplan.errors import ConfigError, InputError, MeshError  # noqa: E402
from grasplan.part.meshfile import ReadLimits, read_mesh  # noqa: E402
from grasplan.results.program_names import program_name_problem, suggest_program_name  # noqa: E402

LIMITS = ReadLimits(1_000_000, 1 << 30)


def run(*argv: str):
    return CliRunner().invoke(main, [str(a) for a in argv])


# -- program names ---------------------------------------------------------------------------------

@pytest.mark.parametrize("fmt, ext", [("krl", ".src"), ("rapid", ".mod")])
@pytest.mark.parametrize("word", ["END", "DEF", "IF", "MODULE", "PROC", "ENDMODULE"])
def test_reserved_word_as_output_stem_is_refused(tmp_path_factory, tmp_path, fmt, ext, word):
    """``-o END.src``: exit 3 naming the word and a file name that passes; nothing written."""
    out = tmp_path / f"{word}{ext}"
    r = run("export", plan_file(tmp_path_factory), "--format", fmt, "-o", out)
    assert r.exit_code == 3, r.output
    assert f"'{word}' is a reserved word of" in r.output and f"{word}_1{ext}" in r.output
    assert not out.exists() and not out.with_suffix(".dat").exists()
    good = tmp_path / f"{word}_1{ext}"
    r = run("export", plan_file(tmp_path_factory), "--format", fmt, "-o", good)
    assert r.exit_code == 0, r.output
    assert (f"DEF {word}_1( )" if fmt == "krl" else f"MODULE {word}_1") in good.read_text()


@pytest.mark.parametrize("fmt", ["krl", "rapid"])
def test_reserved_word_as_program_name_option_is_refused(tmp_path_factory, fmt):
    """The ``program_name`` of the Python API (and of the service's /export): InputError naming the
    word, in any case, and a name that passes."""
    res = plan_result(tmp_path_factory)
    for word in ("endmodule", "Proc", "END"):
        with pytest.raises(InputError, match=f"program_name: '{word}' is a reserved word.*use e.g. '{word}_1'"):
            grasplan.export.render(res, fmt, program_name=word)
    assert "PROC pick_1_main()" in grasplan.export.render(res, "rapid", program_name="pick_1")[".mod"]


def _identifiers(code: str, comment: str) -> set[str]:
    """Identifiers of a program's code (comments and strings removed)."""
    text = "\n".join(line.split(comment, 1)[0] for line in code.splitlines())
    text = re.sub(r'"[^"]*"', "", text)
    return set(re.findall(r"(?<![\w$#.])[A-Za-z_][A-Za-z0-9_]*", text))


def test_the_programs_own_names_are_refused(tmp_path_factory):
    """Every identifier a KRL or RAPID export writes (keywords, its targets, data, routines, the
    KUKA BAS call) is refused as a program name, so a program can never be named like one of them."""
    res = plan_result(tmp_path_factory)
    krl = grasplan.export.render(res, "krl", program_name="prog")
    rapid = grasplan.export.render(res, "rapid", program_name="prog")
    names = (_identifiers(krl[".src"] + krl[".dat"], ";") | _identifiers(rapid[".mod"], "!"))
    names -= {"prog", "prog_main", "prog_tool", "prog_wobj", "RVP", "ACCESS", "REL"}  # ours; &ACCESS/&REL headers
    # keywords of a target's components and the literal parts are not names a program could clash with
    names -= {n for n in names if re.fullmatch(r"(A[1-6]|E[1-6]|[XYZABC]|TRUE|FALSE)", n, re.I)}
    accepted = sorted(n for n in names if program_name_problem(n) is None)
    assert not accepted, f"names the exported programs use but program_name accepts: {accepted}"


def test_program_name_suggestions_pass():
    for name in ["END", "endmodule", "XP12", "jt_3", "BAS", "a" * 30, "1abc", "my-prog", "", "x" * 23 + "Y"]:
        good = suggest_program_name(name)
        assert program_name_problem(good) is None, (name, good)
    assert suggest_program_name("END") == "END_1" and suggest_program_name("my-prog") == "my_prog"


def test_program_name_length_and_characters():
    """KRL names: at most 24 characters, a letter first, letters, digits and _ (RAPID's 32 leave
    room for the _main/_tool/_wobj suffixes)."""
    assert program_name_problem("a" * 24) is None
    for bad in ("a" * 25, "1abc", "_abc", "a-b", "a b", "é", "$tool", 5):
        assert program_name_problem(bad) is not None, bad


# -- picks files -----------------------------------------------------------------------------------

def _tampered(tmp_path: Path, src: Path, edit) -> Path:
    d = json.loads(src.read_text())
    edit(d["picks"][0])
    out = tmp_path / "tampered_picks.json"
    out.write_text(json.dumps(d))
    return out


def test_picks_q_grasp_1e300_is_refused(tmp_path_factory, tmp_path):
    """The issue's case: exit 0 before (q_grasp was not read), now exit 3 naming the field; the
    untampered file still exports."""
    good = tmp_path / "pick_a.src"
    r = run("export", picks_file(tmp_path_factory), "--format", "krl", "-o", good)
    assert r.exit_code == 0 and good.exists(), r.output

    def edit(p):
        p["q_grasp"][0] = 1e300
    bad = _tampered(tmp_path, picks_file(tmp_path_factory), edit)
    r = run("export", bad, "--format", "urscript", "-o", tmp_path / "pick.script")
    assert r.exit_code == 3, r.output
    assert "q_grasp" in r.output and "joint limits" in r.output
    assert not (tmp_path / "pick.script").exists()


@pytest.mark.parametrize("field, where, value, words", [
    ("T_world_pregrasp", (0, 3), 0.005, "T_world_pregrasp is 5 mm"),
    ("T_world_lifted", (2, 3), -0.01, "T_world_lifted is 10 mm"),
    ("T_world_tcp", (1, 3), 0.003, "T_world_tcp is 3 mm"),
    ("contacts", (0, 0), 0.02, "contact lies"),
    ("normals", (0, 0), 5.0, "normals"),
    ("score", None, 7.5, "score = 7.5"),
    ("opening", None, 0.2, "opening"),
    ("q_pregrasp", (0,), 0.01, "differs from q_pregrasp"),
])
def test_picks_numbers_are_checked_like_a_plan(tmp_path_factory, tmp_path, field, where, value, words):
    """A pick's poses agree with each other, the scene and FK; its numbers lie in their ranges."""
    def edit(p):
        if where is None:
            p[field] = value
        else:
            target = p[field]
            for k in where[:-1]:
                target = target[k]
            target[where[-1]] += value
    bad = _tampered(tmp_path, picks_file(tmp_path_factory), edit)
    r = run("export", bad, "--format", "csv", "-o", tmp_path / "g.csv")
    assert r.exit_code == 3, r.output
    assert words in r.output
    assert "Traceback" not in r.output and not (tmp_path / "g.csv").exists()


# -- duplicate keys --------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["plan", "picks"])
def test_duplicate_keys_are_refused(tmp_path_factory, tmp_path, kind):
    src = plan_file(tmp_path_factory) if kind == "plan" else picks_file(tmp_path_factory)
    text = src.read_text()
    i = text.index('"schema"')
    bad = tmp_path / f"dup_{kind}.json"
    bad.write_text(text[:i] + '"schema": "nonsense", ' + text[i:])  # the last value is the right one
    r = run("export", bad, "--format", "csv", "-o", tmp_path / "g.csv")
    assert r.exit_code == 3, r.output
    assert 'duplicate key "schema"' in r.output
    with pytest.raises(InputError, match='duplicate key "schema"'):
        grasplan.load_result(bad) if kind == "plan" else grasplan.load_picks(bad)


# -- meshes ----------------------------------------------------------------------------------------

def _named_ascii(name: str) -> bytes:
    v, f = tetra()
    body = ascii_stl(v, f).decode().split("\n")
    return ("\n".join([f"solid {name}".rstrip()] + body[1:-2] + [f"endsolid {name}".rstrip(), ""])).encode()


def test_every_valid_stl_loads(tmp_path):
    """ASCII STL whatever its solid name (before: the word "vertex" in it, as in "Vertex-Bracket",
    made a valid file "damaged"), and a binary STL whose 80-byte header starts with "solid" (as
    SolidWorks writes it) read as binary (its size is 84 + 50 n)."""
    v, f = tetra()
    for name in ["Vertex-Bracket", "", "vertex 1 2 3", "my part no. 2", "vertex", "facet normal 0 0 1"]:
        path = tmp_path / "part.stl"
        path.write_bytes(_named_ascii(name))
        got_v, got_f, _ = read_mesh(path, LIMITS)
        assert len(got_f) == 4 and np.allclose(got_v.max(axis=0), [20, 20, 20]), name
    path = tmp_path / "sw.stl"
    path.write_bytes(binary_stl(v, f, header=b"solid SolidWorks binary export, vertex 1 2 3"))
    got_v, got_f, _ = read_mesh(path, LIMITS)
    assert len(got_f) == 4 and np.allclose(got_v.reshape(-1, 3, 3), v[f])


def test_obj_face_number_zero_is_exit_3_naming_the_line(tmp_path):
    """Before: loaded as a wrong mesh (trimesh took 0 as -1) and ended with exit 4."""
    v, f = tetra()
    path = tmp_path / "part.obj"
    path.write_bytes(obj_text(v, f).replace(b"f 1 3 2", b"f 0 3 2"))
    with pytest.raises(MeshError, match=r"OBJ line 5: 'f 0 3 2': vertex 0 does not exist: OBJ numbers vertices from 1"):
        read_mesh(path, LIMITS)
    r = run("candidates", path, "-o", tmp_path / "c.json")
    assert r.exit_code == 3 and "OBJ line 5" in r.output, r.output


def test_obj_negative_numbers_count_back_from_the_face(tmp_path):
    """Two objects each written with relative (negative) numbers: each face uses its own object's
    vertices (before: both used the last object's, as if counted from the end of the file)."""
    v, f = tetra()
    text = ""
    for shift in (0.0, 100.0):
        text += "".join(f"v {x + shift} {y} {z}\n" for x, y, z in v)
        text += "".join(f"f {a - 4} {b - 4} {c - 4}\n" for a, b, c in f)
    path = tmp_path / "two.obj"
    path.write_text(text)
    got_v, got_f, _ = read_mesh(path, LIMITS)
    tris = got_v[got_f]
    assert np.allclose(tris[:4], v[f]) and np.allclose(tris[4:], v[f] + [100.0, 0, 0])


def test_ply_negative_face_count_is_refused_naming_the_header_line(tmp_path):
    """Before: ``element face -12`` loaded (or failed with a message naming nothing)."""
    v, f = tetra()
    data = ply_ascii(v, f)
    path = tmp_path / "part.ply"
    path.write_bytes(data.replace(b"element face 4", b"element face -12"))
    with pytest.raises(MeshError, match=r"PLY header line \d+ 'element face -12'"):
        read_mesh(path, LIMITS)
    path.write_bytes(data.replace(b"element face 4", b"element face 3"))  # one face line too many
    with pytest.raises(MeshError, match=r"'element face 3': the header declares 7 element lines"):
        read_mesh(path, LIMITS)
    path.write_bytes(ply_binary(v, f).replace(b"element face 4", b"element face 2"))  # extra data
    with pytest.raises(MeshError, match=r"'element face 2': the elements the header declares take"):
        read_mesh(path, LIMITS)


# -- robot meshes ----------------------------------------------------------------------------------

def test_robot_mesh_over_the_triangle_limit_is_refused_from_its_header(tmp_path):
    """A URDF naming a 2M-triangle mesh: refused in well under a second, naming the file, its
    count and the limit (before: Pinocchio loaded it, minutes per export)."""
    (tmp_path / "meshes").mkdir()
    huge_stl(tmp_path / "meshes" / "upper.stl", 2_000_000)
    v, f = tetra()
    (tmp_path / "meshes" / "small.stl").write_bytes(binary_stl(v * 1e-3, f))
    y = robot_yaml(tmp_path, {"base": "meshes/small.stl", "l1": "meshes/upper.stl"})
    t0 = time.process_time()
    with pytest.raises(ConfigError) as err:
        grasplan.load_robot(y)
    assert time.process_time() - t0 < 5
    msg = str(err.value)
    assert "upper.stl" in msg and "2,000,000 triangles" in msg and "grasplan.part.mesh.MAX_TRIANGLES" in msg
    assert "link 'l1' collision mesh" in msg


def test_robot_mesh_limit_follows_grasplan_mesh_max_triangles(tmp_path, monkeypatch):
    """The limit is the part limit, read when the robot is built (never a copy of its value)."""
    import grasplan.part.mesh

    v, f = tetra()
    (tmp_path / "m.stl").write_bytes(binary_stl(v * 1e-3, f))
    y = robot_yaml(tmp_path, {"l1": "m.stl"}, name="tiny")
    monkeypatch.setattr(grasplan.part.mesh, "MAX_TRIANGLES", 3)
    with pytest.raises(ConfigError, match="4 triangles is more than grasplan handles"):
        grasplan.load_robot(y)


def test_robot_meshes_total_budget_and_visual_meshes(tmp_path, monkeypatch):
    import grasplan.robot.files

    v, f = tetra()
    for n in ("a", "b", "c"):
        (tmp_path / f"{n}.stl").write_bytes(binary_stl(v * 1e-3, f))
    huge_stl(tmp_path / "v.stl", 5_000_000)
    y = robot_yaml(tmp_path, {"l1": "a.stl", "l2": "b.stl", "base": "c.stl"}, visual={"l1": "v.stl"}, name="budget")
    monkeypatch.setattr(grasplan.robot.files, "MAX_ROBOT_TRIANGLES", 10)
    with pytest.raises(ConfigError, match="collision meshes hold 12 triangles in all"):
        grasplan.load_robot(y)
    monkeypatch.setattr(grasplan.robot.files, "MAX_ROBOT_TRIANGLES", 1_000_000)
    robot = grasplan.load_robot(y)  # the collision meshes load; the visual ones only when asked for
    with pytest.raises(ConfigError, match=r"link 'l1' visual mesh: .*v\.stl: 5,000,000 triangles"):
        robot.visual_model


def test_shipped_robots_pass_the_mesh_checks():
    from grasplan.robot.description import available_robots
    from grasplan.robot.files import check_robot_meshes

    for name in available_robots():
        r = grasplan.load_robot(name)
        for kind in ("collision", "visual"):
            assert 0 < check_robot_meshes(r.urdf_path, r.package_dirs, kind, name) <= 200_000
