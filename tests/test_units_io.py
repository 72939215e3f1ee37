"""Length/angle parsing and atomic output."""
from __future__ import annotations

import os

import numpy as np
import pytest

from grasplan.errors import InputError
from grasplan.io import read_json, write_json
from grasplan.geometry.tolerance import Tolerance
from grasplan.geometry.units import parse_angle_deg, parse_length


@pytest.mark.parametrize(
    "text, metres",
    [("0.1mm", 1e-4), ("5cm", 0.05), ("0.05", 0.05), ("2 in", 0.0508), ("1e-3m", 1e-3), (".5mm", 5e-4), (0.2, 0.2)],
)
def test_parse_length(text, metres):
    assert parse_length(text) == pytest.approx(metres)


@pytest.mark.parametrize("text", ["abc", "1 parsec", "-1mm", "0", "nan", "inf mm", "1..2mm"])
def test_parse_length_rejects(text):
    with pytest.raises(InputError, match="alpha"):
        parse_length(text, name="alpha")


def test_parse_angle():
    assert parse_angle_deg("15") == 15.0
    assert parse_angle_deg("15deg") == 15.0
    assert parse_angle_deg(f"{np.pi}rad") == pytest.approx(180.0)
    with pytest.raises(InputError):
        parse_angle_deg("fifteen")


def test_write_json_is_atomic_and_refuses_nan(tmp_path):
    out = tmp_path / "sub" / "x.json"
    write_json(out, {"a": np.arange(3), "b": np.float64(1.5)})
    assert read_json(out) == {"a": [0, 1, 2], "b": 1.5}
    with pytest.raises(ValueError):
        write_json(out, {"a": float("nan")})
    assert read_json(out) == {"a": [0, 1, 2], "b": 1.5}  # the old file is intact
    assert [p.name for p in out.parent.iterdir()] == ["x.json"]  # no temporary left behind
    umask = os.umask(0)
    os.umask(umask)
    assert out.stat().st_mode & 0o777 == 0o666 & ~umask  # like open(), not mkstemp's 0600


def test_tolerance_scales_with_part():
    small, big = Tolerance.for_scale(0.01), Tolerance.for_scale(1.0)
    assert big.distance == pytest.approx(100 * small.distance)
    assert big.merge < big.distance
    with pytest.raises(ValueError):
        Tolerance.for_scale(0.0)


def test_zero_lengths_only_where_zero_means_off():
    assert parse_length("0", name="--thin", allow_zero=True) == 0.0
    assert parse_length("3mm", name="--thin", allow_zero=True) == pytest.approx(0.003)
    with pytest.raises(InputError, match=">= 0"):
        parse_length("-1mm", name="--thin", allow_zero=True)
    with pytest.raises(InputError, match="positive"):
        parse_length("0", name="--alpha")


@pytest.mark.parametrize("command", ["grasps", "plan"])
def test_thin_option_accepts_zero_and_refuses_negative(tmp_path, example_part, command):
    from click.testing import CliRunner

    from grasplan.cli import main

    out = tmp_path / "out.json"
    base = [command, str(example_part("gear.stl")), "-o", str(out)] + (["--robot", "ur5"] if command == "plan" else [])
    r = CliRunner().invoke(main, base + ["--thin", "-1mm"])
    assert r.exit_code == 2 and "--thin" in r.output and ">= 0" in r.output and not out.exists()
    if command == "grasps":
        posed = {}
        for thin in ("3mm", "0"):
            r = CliRunner().invoke(main, base + ["--roll-step", "120", "--thin", thin])
            assert r.exit_code == 0, r.output
            doc = read_json(out)
            posed[thin] = doc["counts"]["posed_candidates"]
            assert doc["params"]["thin_spacing"] == (0.003 if thin == "3mm" else 0.0)
        assert 0 < posed["3mm"] < posed["0"]


# -- issue 14: outputs that cannot or must not be written are refused before any work -----------

def test_check_output_path_refuses_what_cannot_be_written(tmp_path):
    from grasplan.io import check_output_path

    (tmp_path / "file").write_text("x")
    mesh = tmp_path / "part.stl"
    mesh.write_text("solid")
    cases = {
        "": "empty",
        "   ": "empty",
        "/proc/x.json": "under /proc",
        "/sys/x.json": "under /sys",
        "/dev/null": "under /dev",
        str(tmp_path): "is a folder",
        str(tmp_path / "file" / "x.json"): "is a file, not a folder",
        str(tmp_path / "missing" / "x.json"): "does not exist",
        str(tmp_path / ("y" * 300 + ".json")): "at most 255",
        "a\x00b.json": "NUL",
    }
    for out, message in cases.items():
        with pytest.raises(InputError, match=message):
            check_output_path(out)
    with pytest.raises(InputError, match="also an input"):
        check_output_path(tmp_path / "." / "part.stl", inputs=[mesh])
    (tmp_path / "link.stl").symlink_to(mesh)
    with pytest.raises(InputError, match="also an input"):
        check_output_path(tmp_path / "link.stl", inputs=[str(mesh)])
    assert check_output_path(tmp_path / "new.json", inputs=[mesh]) == tmp_path / "new.json"
    assert check_output_path(tmp_path / "a" / "b.json", create_parents=True) == tmp_path / "a" / "b.json"


def test_check_output_path_refuses_a_read_only_folder(tmp_path):
    from grasplan.io import check_output_path

    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        if os.access(ro, os.W_OK):
            pytest.skip("running as root: a read-only folder is still writable")
        with pytest.raises(InputError, match="not writable"):
            check_output_path(ro / "x.json")
    finally:
        ro.chmod(0o700)


def test_write_error_is_an_input_error_and_leaves_nothing(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match="cannot write"):
        write_json(tmp_path / "file" / "x.json", {"a": 1})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_long_output_name_still_gets_a_temporary_file(tmp_path):
    out = tmp_path / ("z" * 250 + ".json")
    write_json(out, {"a": 1})
    assert read_json(out) == {"a": 1}


_SIGTERM_WRITER = r"""
import os, signal, sys
from pathlib import Path
import grasplan.io as gio

out = Path(sys.argv[1])
real_fsync = os.fsync

def slow_fsync(fd):
    print("writing", flush=True)      # the temporary file exists now
    signal.pause() if sys.argv[2] == "pause" else None
    real_fsync(fd)

gio.os.fsync = slow_fsync
gio.write_atomic_bytes(out, b"new content")
"""


@pytest.mark.parametrize("previous", ["default", "python"])
def test_sigterm_during_a_write_removes_the_temporary_file(tmp_path, previous):
    import signal
    import subprocess
    import sys

    out = tmp_path / "out.json"
    out.write_text("old")
    script = _SIGTERM_WRITER
    if previous == "python":  # a handler of the caller's is restored and still called
        script = ("import signal, sys\nsignal.signal(signal.SIGTERM, lambda s, f: (print('caller handler', "
                  "flush=True), sys.exit(7)))\n") + script
    proc = subprocess.Popen([sys.executable, "-c", script, str(out), "pause"], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "writing"
        assert len(list(tmp_path.glob(".out.json.*.tmp"))) == 1
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    rest = proc.stdout.read()
    if previous == "default":
        assert rc == -signal.SIGTERM  # the process still ends the way SIGTERM ends it
    else:
        assert rc == 7 and "caller handler" in rest
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]  # no temporary file left
    assert out.read_text() == "old"  # the existing output is intact


def test_sigterm_handler_is_restored_after_a_write(tmp_path):
    import signal

    before = signal.getsignal(signal.SIGTERM)
    write_json(tmp_path / "x.json", {"a": 1})
    assert signal.getsignal(signal.SIGTERM) is before
