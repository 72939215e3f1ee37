"""The strict JSON reader: duplicate keys refused at any depth, everything else as json.loads."""
from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from grasplan.config.jsontext import DuplicateKeyError, loads_strict

_json = st.recursive(
    st.none() | st.booleans() | st.integers(-10**6, 10**6) | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=20)


@given(_json)
@settings(max_examples=200, deadline=None)
def test_same_as_json_loads_without_duplicates(doc):
    text = json.dumps(doc)
    assert loads_strict(text) == json.loads(text)


@pytest.mark.parametrize("text,key", [
    ('{"a": 1, "a": 2}', "a"),
    ('{"x": {"T": [1], "T": [2]}}', "T"),
    ('[{"id": 0}, {"id": 1, "pose": 0, "id": 2}]', "id"),
    ('{"a": {"b": {"c": {"d": 1, "d": 1}}}}', "d"),
    ('{"\\u0061": 1, "a": 2}', "a"),  # the same key spelled two ways
])
def test_duplicate_keys_refused_at_any_depth(text, key):
    with pytest.raises(DuplicateKeyError) as exc:
        loads_strict(text)
    assert exc.value.key == key
    assert json.dumps(key) in str(exc.value)
    json.loads(text)  # the plain parser accepts it: the reason this reader exists


def test_number_hooks_pass_through():
    seen = []
    assert loads_strict('{"a": 1.5}', parse_float=lambda s: seen.append(s) or 0.0) == {"a": 0.0}
    assert seen == ["1.5"]
