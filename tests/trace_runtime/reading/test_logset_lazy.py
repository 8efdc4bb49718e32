"""A lazily opened log (``open_log(root, lazy=True)``): a catalogued root's segments are
opened only when a query reaches them, and the answers are those of a log opened in full."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import msgspec
import orjson
import pytest

from trace_runtime import AuditLogger, LoggerConfig
from trace_runtime.errors import TimeOutOfRangeError
from trace_runtime.reading import catalogued, logset
from trace_runtime.reading.catalog_rows import CATALOG_NAME
from trace_runtime.reading.logset import Log, open_log
from trace_runtime.reading.reader import Segment
from trace_runtime.tiers import compact, load_catalog, refresh_catalog

CYCLES = 60


@pytest.fixture
def root(tmp_path: Path, log_writer: Callable[..., AuditLogger]) -> Path:
    """A catalogued root of six one-second segments (10 cycles each)."""
    root = tmp_path / "root"
    log_writer(root, CYCLES, config=LoggerConfig(threaded=False, max_segment_s=1.0))
    refresh_catalog(root)
    return root


@pytest.fixture
def opened(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[str]]:
    """The names of the segment files the log set opens, in order."""
    names: list[str] = []

    class CountedSegment(Segment):
        def __init__(self, path: str | Path, *args: object, **kwargs: object) -> None:
            names.append(Path(path).name)
            super().__init__(path, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(logset, "Segment", CountedSegment)
    monkeypatch.setattr(catalogued, "Segment", CountedSegment)
    yield names


def _is_lazy(log: Log) -> bool:
    return not any(isinstance(slot, Segment) for slot in log._slots)


def test_a_seek_opens_only_the_segment_holding_t(root: Path, opened: list[str]) -> None:
    lazy = open_log(root, lazy=True)
    assert opened == [] and _is_lazy(lazy)
    full = open_log(root)
    assert len(full.segments) == 6
    opened.clear()
    for t in (full.start_ns, 25 * 10**8 + 1, 39 * 10**8, full.end_ns):
        assert lazy.cycle_at(t).payloads == full.cycle_at(t).payloads
    assert len(opened) == 4 and len(set(opened)) == 4  # each opened once, the others never
    # Past the last cycle, whether t is still within a period of it takes every segment's
    # period, as a log opened in full has them.
    late = full.end_ns + 10**6
    assert lazy.cycle_at(late).payloads == full.cycle_at(late).payloads
    assert sorted(opened) == sorted(s.path.name for s in full.segments)
    assert (lazy.start_ns, lazy.end_ns, lazy.recovered) == (
        full.start_ns,
        full.end_ns,
        full.recovered,
    )
    assert lazy.first_robot == full.segments[0].session.robot_id


def test_a_walk_back_across_a_boundary_opens_the_previous_segment(
    root: Path, opened: list[str]
) -> None:
    lazy, full = open_log(root, lazy=True), open_log(root)
    opened.clear()
    start, end = 18 * 10**8, 23 * 10**8
    walked = [c.cycle for c in lazy.iter_cycles(start, end, reverse=True)]
    assert walked == [c.cycle for c in full.iter_cycles(start, end, reverse=True)]
    assert walked == list(range(23, 17, -1)) and len(opened) == 2


def test_every_segment_is_opened_when_all_are_asked_for(root: Path) -> None:
    lazy, full = open_log(root, lazy=True), open_log(root)
    assert [c.cycle for c in lazy.iter_cycles()] == list(range(CYCLES))
    assert [s.path for s in lazy.segments] == [s.path for s in full.segments]
    assert [(s.start_ns, s.end_ns) for s in lazy.segments] == [
        (s.start_ns, s.end_ns) for s in full.segments
    ]
    assert lazy.period_ns == full.period_ns and lazy.problems == full.problems == []
    assert lazy.holds_cycle_messages() and full.holds_cycle_messages()


def test_a_time_outside_the_log_is_refused_alike(root: Path) -> None:
    lazy, full = open_log(root, lazy=True), open_log(root)
    for t in (full.start_ns - 1, full.end_ns + full.period_ns + 1):
        with pytest.raises(TimeOutOfRangeError) as lazy_err:
            lazy.cycle_at(t)
        with pytest.raises(TimeOutOfRangeError) as full_err:
            full.cycle_at(t)
        assert str(lazy_err.value) == str(full_err.value)


def test_without_a_catalog_every_segment_is_opened(root: Path, opened: list[str]) -> None:
    (root / "catalog.json").unlink()
    log = open_log(root, lazy=True)
    assert len(opened) == 6 and not _is_lazy(log)


def test_a_file_changed_since_the_catalog_opens_everything(root: Path) -> None:
    first = sorted((root / "hot").glob("*.mcap"))[0]
    stat = first.stat()
    os.utime(first, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1))
    assert not _is_lazy(open_log(root, lazy=True))


def test_a_file_the_catalog_does_not_list_opens_everything(root: Path) -> None:
    """An unreadable file must still be reported in ``problems``, as without ``lazy``."""
    (root / "hot" / "amr-1_000099.mcap").write_bytes(b"")
    log = open_log(root, lazy=True)
    assert not _is_lazy(log)
    assert [p.path.name for p in log.problems] == ["amr-1_000099.mcap"]


def test_a_segment_in_two_tiers_opens_everything(root: Path, tmp_path: Path) -> None:
    """Which copy is read is decided on the opened files (``preferred_copies``)."""
    compact(root, "cold", older_than_ns=0, retention_ns=None)
    shutil.copy2(sorted((root / "cold").glob("*.mcap"))[0], root / "hot")
    refresh_catalog(root)
    log = open_log(root, lazy=True)
    assert not _is_lazy(log) and log.shadowed


def test_a_compacted_root_is_read_lazily(root: Path) -> None:
    full = [(c.cycle, c.payloads) for c in open_log(root).iter_cycles()]
    compact(root, "cold", older_than_ns=0, retention_ns=None)
    lazy = open_log(root, lazy=True)
    assert _is_lazy(lazy)
    assert [(c.cycle, c.payloads) for c in lazy.iter_cycles()] == full


def test_the_catalog_is_read_as_the_catalog_module_reads_it(root: Path) -> None:
    """``catalogued`` reads ``catalog.json`` itself (the tiers package would import the writer
    and the ``mcap`` library); its rows must be ``load_catalog``'s entries."""
    catalog = load_catalog(root)
    assert catalog is not None
    rows = catalogued._catalog_rows(root, len(catalog.entries))
    assert rows is not None
    fields = catalogued.CatalogRow.__struct_fields__
    assert [msgspec.structs.asdict(row) for row in rows] == [
        {name: getattr(entry, name) for name in fields} for entry in catalog.entries
    ]
    assert catalogued._catalog_rows(root, len(catalog.entries) - 1) is None


@pytest.mark.parametrize(
    "damage",
    [
        lambda body: body.update(format="trace-catalog-v0"),
        lambda body: body.update(problems=["hot/x.mcap: empty file"]),
        lambda body: body["segments"][0].update(start_ns="0"),
        lambda body: body["segments"][0].pop("mtime_ns"),
        lambda body: body.update(segments={}),
    ],
)
def test_a_catalog_not_whole_and_clean_is_not_used(
    root: Path, damage: Callable[[dict[str, Any]], None]
) -> None:
    body = orjson.loads((root / CATALOG_NAME).read_bytes())
    damage(body)
    (root / CATALOG_NAME).write_bytes(orjson.dumps(body))
    log = open_log(root, lazy=True)
    assert not _is_lazy(log) and [c.cycle for c in log.iter_cycles()] == list(range(CYCLES))


def test_a_lazy_open_imports_neither_the_writer_nor_mcap(root: Path) -> None:
    code = (
        "import sys\n"
        "from trace_runtime.reading.logset import open_log\n"
        f"log = open_log({str(root)!r}, lazy=True)\n"
        "log.cycle_at(log.start_ns)\n"
        "heavy = {'mcap', 'trace_runtime.logger.segment_writer', 'trace_runtime.tiers.catalog'}\n"
        "loaded = heavy & set(sys.modules)\n"
        "assert not loaded, loaded\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)
