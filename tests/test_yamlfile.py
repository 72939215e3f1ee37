"""The one YAML reader (grasplan.config.yamlfile): bounded in time and memory, every problem an InputError
naming the file and the field."""
from __future__ import annotations

import os
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from grasplan.errors import InputError
from grasplan.config.yamlfile import MAX_EXPANDED_NODES, load_yaml_text, read_yaml_file


def _bomb(levels: int, width: int = 9, field: str = "retreat") -> str:
    lines = [f"l0: &l0 [{', '.join(['x'] * width)}]"]
    for k in range(1, levels):
        lines.append(f"l{k}: &l{k} [{', '.join([f'*l{k - 1}'] * width)}]")
    lines.append(f"{field}: *l{levels - 1}")
    return "\n".join(lines) + "\n"


def test_alias_bomb_refused_fast():
    text = _bomb(9)
    assert len(text) < 1500
    t = time.perf_counter()
    with pytest.raises(InputError, match="alias"):
        load_yaml_text(text, "cell bomb.yaml")
    assert time.perf_counter() - t < 2.0


def test_aliases_below_the_limit_are_fine():
    doc = load_yaml_text(_bomb(3, width=3), "x")
    assert doc["retreat"] == [[["x"] * 3] * 3] * 3


@pytest.mark.parametrize("text, field", [
    ("table_z: !!float abc\n", "table_z"),
    ("a: {b: !!bool maybe}\n", "a.b"),
    ("a: [1, !!timestamp x]\n", "a[1]"),
    ("n: " + "9" * 5000 + "\n", "n"),
    ("x: !!python/object/apply:os.system [ls]\n", "x"),
])
def test_unconstructible_values_name_the_field(text, field):
    with pytest.raises(InputError) as e:
        load_yaml_text(text, "cell c.yaml")
    msg = str(e.value)
    assert msg.startswith("cell c.yaml: ") and f" {field} (line" in msg


def test_dates_stay_strings():
    assert load_yaml_text("table_z: 2001-13-45\nd: 2020-01-01\n", "x") == {"table_z": "2001-13-45", "d": "2020-01-01"}


def test_duplicate_keys_refused_naming_the_key():
    with pytest.raises(InputError, match=r"duplicate key 'wall'.*bin\.wall"):
        load_yaml_text("bin:\n  wall: 0.01\n  wall: 0.02\n", "cell c.yaml")


def test_deep_nesting_and_syntax_errors():
    with pytest.raises(InputError, match="nested deeper"):
        load_yaml_text("[" * 3000 + "]" * 3000, "x")
    with pytest.raises(InputError, match=r"line 2, column 1"):
        load_yaml_text("a: [1, 2\n", "x")


def test_file_reader_refuses_fifo_and_size(tmp_path):
    fifo = tmp_path / "pipe.yaml"
    os.mkfifo(fifo)
    t = time.perf_counter()
    with pytest.raises(InputError, match="FIFO"):
        read_yaml_file(fifo, what="scoring")
    assert time.perf_counter() - t < 1.0
    big = tmp_path / "big.yaml"
    big.write_text("a: " + "1" * 2000 + "\n")
    with pytest.raises(InputError, match="larger than the limit"):
        read_yaml_file(big, what="cell", max_bytes=1000)
    with pytest.raises(InputError, match="is a character device"):
        read_yaml_file("/dev/zero", what="scoring")


@settings(max_examples=60, deadline=None)
@given(st.recursive(st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6),
                              st.floats(allow_nan=False, allow_infinity=False, width=32),
                              st.text(alphabet="abcxyz _-", max_size=8)),
                    lambda c: st.one_of(st.lists(c, max_size=4),
                                        st.dictionaries(st.text(alphabet="abc", min_size=1, max_size=3), c,
                                                        max_size=4)),
                    max_leaves=20))
def test_round_trip_of_plain_documents(doc):
    """What yaml.safe_dump writes, the reader reads back equal (no alias, no date, no tag)."""
    import yaml

    assert load_yaml_text(yaml.safe_dump({"v": doc}), "x") == {"v": doc}


def test_limit_constant_is_the_one_enforced():
    assert MAX_EXPANDED_NODES >= 100_000
