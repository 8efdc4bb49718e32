"""``catalog_rows`` reads a catalog's rows one at a time: the same rows a whole-file JSON parse
gives, whatever the strings hold (braces, escaped quotes), and None for an element the format
does not put in a catalog."""

from __future__ import annotations

import json
from pathlib import Path

import msgspec
import pytest

from trace_runtime.errors import LogReadError
from trace_runtime.reading.catalog_rows import CATALOG_FORMAT, CATALOG_NAME, read_catalog_file


class _Row(msgspec.Struct):
    path: str
    segment: int


def _write(root: Path, text: str) -> None:
    (root / CATALOG_NAME).write_text(text, encoding="utf-8")


@pytest.mark.parametrize("indent", [None, 2])
def test_rows_are_those_of_a_whole_parse_whatever_the_strings_hold(
    tmp_path: Path, indent: int | None
) -> None:
    paths = ["hot/a}b.mcap", 'hot/q"}".mcap', "hot/back\\}slash.mcap", "hot/{[x]}", "hot/é"]
    rows = [{"path": p, "extra": "}}", "segment": n} for n, p in enumerate(paths)]
    body = {"problems": ["x: }", "y"], "segments": rows, "format": CATALOG_FORMAT}
    _write(tmp_path, json.dumps(body, indent=indent))
    stored = read_catalog_file(tmp_path)
    assert stored is not None
    assert stored.rows(_Row) == [_Row(p, n) for n, p in enumerate(paths)]
    assert stored.rows(_Row, lambda r: r.segment % 2 == 0) == [
        _Row(p, n) for n, p in enumerate(paths) if n % 2 == 0
    ]
    assert stored.rows(_Row, limit=4) is None and stored.rows(_Row, limit=5) is not None
    assert stored.problems_listed(10) == ["x: }", "y"] and stored.problems_listed(1) == ["x: }"]
    assert not stored.lists_no_problem()


@pytest.mark.parametrize(
    "element",
    ['{"path": "a", "segment": 1, "n": {"x": 1}}', "0", '"hot/a"', '{"path": "a"}', "[]", "{}"],
)
def test_an_element_that_is_not_a_row_makes_no_rows(tmp_path: Path, element: str) -> None:
    good = '{"path": "b}", "segment": 2}'
    _write(tmp_path, f'{{"format": "{CATALOG_FORMAT}", "segments": [{good}, {element}, {good}]}}')
    stored = read_catalog_file(tmp_path)
    assert stored is not None and stored.lists_no_problem()
    assert stored.rows(_Row) is None


def test_another_format_is_none_and_other_json_a_read_error(tmp_path: Path) -> None:
    assert read_catalog_file(tmp_path) is None
    _write(tmp_path, '{"format": "trace-catalog-v0", "segments": []}')
    assert read_catalog_file(tmp_path) is None
    for text in ('{"format": "x"', "[]", '{"format": 1, "segments": []}', "[" * 100_000):
        _write(tmp_path, text)
        with pytest.raises(LogReadError):
            read_catalog_file(tmp_path)
