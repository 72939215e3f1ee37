"""``grasplan candidates``: exact JSON layout of the issue, summary, exit code 3 on bad input."""
from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from grasplan.cli import main
from grasplan.io import sha256_file

TOP = {"schema", "part", "params", "counts", "timing_s", "candidates"}
PART = {"path", "sha256", "scale_to_m", "triangles"}
COUNTS = {"triangles_in", "triangles_blm", "convex_faces", "candidates"}
TIMING = {"load", "blm", "convexity", "antipodal"}
CANDS = {"contacts", "normals", "width", "faces", "region"}
PARAMS = {"blm", "alpha", "gamma_deg", "d_shift", "epsilon", "max_opening", "beta_deg", "mu", "method", "spacing"}


def run(args):
    return CliRunner().invoke(main, ["candidates", *args], catch_exceptions=False)


def test_json_layout_and_values(tmp_path, example_part):
    part = example_part("bracket.stl")
    out = tmp_path / "c.json"
    r = run([str(part), "-o", str(out), "--units", "mm", "--epsilon", "4mm", "--beta", "1.5"])
    assert r.exit_code == 0, r.output
    d = json.loads(out.read_text())
    assert set(d) == TOP and d["schema"] == "grasplan.candidates/1"
    assert set(d["part"]) == PART and set(d["counts"]) == COUNTS and set(d["timing_s"]) == TIMING
    assert set(d["candidates"]) == CANDS and PARAMS <= set(d["params"])
    assert d["part"]["sha256"] == sha256_file(part) and d["part"]["scale_to_m"] == 1e-3
    assert d["params"]["epsilon"] == pytest.approx(0.004) and d["params"]["beta_deg"] == 1.5
    assert d["params"]["alpha"] == pytest.approx(1e-4) and d["params"]["max_opening"] == pytest.approx(0.05)
    n = d["counts"]["candidates"]
    assert n > 0 and d["counts"]["triangles_blm"] > d["counts"]["triangles_in"] == d["part"]["triangles"]
    c = d["candidates"]
    contacts, normals = np.array(c["contacts"]), np.array(c["normals"])
    assert contacts.shape == (n, 2, 3) and normals.shape == (n, 2, 3) and len(c["width"]) == n
    assert np.array(c["faces"]).shape == (n, 2)
    # the default method samples contact regions: every candidate names its region
    assert d["params"]["method"] == "regions" and np.min(c["region"]) >= 0
    assert np.allclose(np.linalg.norm(contacts[:, 1] - contacts[:, 0], axis=1), c["width"])
    assert np.allclose(np.linalg.norm(normals, axis=2), 1.0)
    assert np.abs(contacts).max() < 0.1          # metres, not millimetres
    assert all(v >= 0 for v in d["timing_s"].values())
    # summary on stdout
    for word in ("triangles in", "triangles after BLM", "convex faces", "candidates", "blm (s)", "units mm"):
        assert word in r.output


def test_no_blm(tmp_path, example_part):
    out = tmp_path / "c.json"
    r = run([str(example_part("gear.stl")), "-o", str(out), "--no-blm", "--units", "mm"])
    assert r.exit_code == 0, r.output
    d = json.loads(out.read_text())
    assert d["counts"]["triangles_blm"] is None and d["params"]["blm"] is False
    assert d["timing_s"]["blm"] == 0.0


def test_bad_values_are_exit_3(tmp_path, example_part):
    out = tmp_path / "out.json"
    for args in (["--mu", "-1"], ["--gamma", "80"], ["--beta", "95"]):
        r = CliRunner().invoke(main, ["candidates", str(example_part("box.stl")), "-o", str(out), *args])
        assert r.exit_code == 3, (args, r.output)
        assert not out.exists()
    # malformed lengths are rejected by the option type itself (click usage error, exit 2)
    r = CliRunner().invoke(main, ["candidates", str(example_part("box.stl")), "-o", str(out), "--max-opening", "0"])
    assert r.exit_code == 2 and not out.exists()
    r = CliRunner().invoke(main, ["candidates", str(tmp_path / "missing.stl"), "-o", str(out)])
    assert r.exit_code == 3 and "no such file" in r.output and not out.exists()
    empty = tmp_path / "empty.stl"
    empty.write_bytes(b"")
    r = CliRunner().invoke(main, ["candidates", str(empty), "-o", str(out)])
    assert r.exit_code == 3 and "empty" in r.output and not out.exists()
    nan = tmp_path / "nan.obj"
    nan.write_text("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n")
    r = CliRunner().invoke(main, ["candidates", str(nan), "-o", str(out)])
    assert r.exit_code == 3 and not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty.stl", "nan.obj"]   # no temp files left


def test_help_documents_every_option():
    r = run(["--help"])
    for opt in ("--no-blm", "--alpha", "--gamma", "--d-shift", "--epsilon", "--max-opening", "--mu", "--beta", "--units",
                "--method", "--spacing", "-o"):
        assert opt in r.output


def test_nothing_found_is_exit_4_and_file_still_written(tmp_path, example_part):
    """The box is 10 x 20 x 30 mm: no contact pair fits a 5 mm opening. Exit 4, empty result written."""
    out = tmp_path / "c.json"
    r = CliRunner().invoke(main, ["candidates", str(example_part("box.stl")), "--units", "mm", "--max-opening", "5mm",
                                  "-o", str(out)])
    assert r.exit_code == 4, r.output
    assert "no antipodal candidate" in r.output
    d = json.loads(out.read_text())
    assert d["counts"]["candidates"] == 0 and d["candidates"]["width"] == []
    assert d["params"]["max_opening"] == pytest.approx(0.005)


@pytest.mark.parametrize("command", ["blm", "candidates"])
def test_alpha_in_metres_by_mistake_is_refused(example_part, tmp_path, command):
    """A bare number is metres: '--alpha 0.1' on a 40 mm part is a units mistake, refused with the fix."""
    from click.testing import CliRunner

    from grasplan.cli import main

    out = tmp_path / ("out.stl" if command == "blm" else "out.json")
    r = CliRunner().invoke(main, [command, str(example_part("bracket.stl")), "--alpha", "0.1", "-o", str(out)])
    assert r.exit_code == 3 and "did you mean 0.1mm" in r.output and not out.exists()
    r = CliRunner().invoke(main, [command, str(example_part("bracket.stl")), "--alpha", "0.1mm", "-o", str(out)])
    assert r.exit_code == 0 and out.exists()
