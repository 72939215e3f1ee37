"""Length/angle parsing and atomic output."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

from grasplan.errors import InputError
from grasplan.io import read_json, write_json
from grasplan.tolerance import Tolerance
from grasplan.units import parse_angle_deg, parse_length


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
