"""The two meanings of "a number" in untrusted JSON, each pinned: ``as_float`` (a bool is not
a number) and ``as_number_or_flag`` (a bool counts as 0.0 or 1.0); neither ever raises."""

from __future__ import annotations

import math
from typing import Any

from hypothesis import given
from hypothesis import strategies as st

from trace_audit.causal.distances import entity_distances
from trace_audit.causal.lenient import as_float, as_number_or_flag, mappings

numbers = st.integers() | st.floats(allow_nan=False)
not_numbers = st.none() | st.text() | st.lists(st.integers()) | st.dictionaries(st.text(), numbers)
json_values = st.recursive(
    st.none() | st.booleans() | numbers | st.text(),
    lambda inner: st.lists(inner) | st.dictionaries(st.text(), inner),
    max_leaves=10,
)


@given(numbers)
def test_a_json_number_reads_as_its_float_in_both_meanings(value: int | float) -> None:
    for read in (as_float, as_number_or_flag):
        got = read(value)
        assert type(got) is float
        assert got == float(value)


@given(st.booleans())
def test_a_bool_is_not_a_number_for_as_float_and_zero_or_one_for_as_number_or_flag(
    value: bool,
) -> None:
    assert as_float(value) is None
    got = as_number_or_flag(value)
    assert type(got) is float
    assert got == (1.0 if value else 0.0)


@given(not_numbers)
def test_anything_else_reads_as_absent_in_both_meanings(value: Any) -> None:
    assert as_float(value) is None
    assert as_number_or_flag(value) is None


@given(json_values)
def test_the_meanings_differ_only_on_bools(value: Any) -> None:
    if isinstance(value, bool):
        assert as_float(value) is None
        assert as_number_or_flag(value) == float(value)
    else:
        assert as_float(value) == as_number_or_flag(value)


def test_nan_and_infinities_are_numbers() -> None:
    for read in (as_float, as_number_or_flag):
        assert math.isnan(read(float("nan")) or 0.0)
        assert read(float("inf")) == math.inf
        assert read(-(2**70)) == float(-(2**70))


def test_subclasses_of_int_and_float_are_numbers_in_both_meanings() -> None:
    """Decoded JSON never holds them, but a value built in Python may (an ``IntEnum``)."""

    class Level(int):
        pass

    class Metres(float):
        pass

    for read in (as_float, as_number_or_flag):
        assert read(Level(3)) == 3.0
        assert type(read(Metres(1.5))) is float


@given(json_values)
def test_mappings_keeps_the_objects_of_a_list_and_nothing_else(value: Any) -> None:
    got = list(mappings(value))
    expected = [v for v in value if isinstance(v, dict)] if isinstance(value, list) else []
    assert got == expected


def test_a_boolean_distance_counts_as_a_flag_in_the_fleet_index() -> None:
    """The fleet index's distances read a bool as 0/1, as its numeric columns do."""
    belief = {
        "nodes": [
            {"id": "p1.distance", "kind": "state", "unit": "m", "value": True},
            {"id": "p2.distance", "kind": "state", "unit": "m", "value": "far"},
        ],
        "edges": [
            {"parent": "p1", "child": "p1.distance"},
            {"parent": "p2", "child": "p2.distance"},
        ],
    }
    assert entity_distances(belief) == {"p1": 1.0}
