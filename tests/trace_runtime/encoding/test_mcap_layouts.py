"""Every layout the MCAP specification allows reads as the same log (PROFILE §5).

A clean TRACE log is rewritten by the reference ``mcap`` Writer in every combination of
chunked or not, Statistics, Summary Offsets, Chunk Index, Message Index, repeated schemas
and channels, record padding, and attachments kept or dropped (``tests/mcap_variants``).
Kept attachments include the log's own ``trace.chunk_columns``, copied byte for byte, as the
official ``mcap`` CLI does in ``compress``, ``decompress`` and ``filter``: it then describes
the chunks of another file. Each rewrite must read as the same cycles, verify CLEAN and score
the same metrics; small non-TRACE files must give the same messages as the reference reader.
"""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import NonSeekingReader
from mcap.writer import Writer

from tests.mcap_variants import Variant, every_layout, rewrite, single_changes
from tests.trace_audit.conftest import write_log
from tests.trace_runtime.tier_logs import cycle_key
from trace_audit.jsonout import to_jsonable
from trace_audit.metrics import compute_metrics
from trace_runtime import open_log, open_segment
from trace_runtime.encoding.mcap_file import McapFile
from trace_runtime.encoding.mcap_records import CHUNK_TABLE_ATTACHMENT
from trace_runtime.verification import verify


@pytest.fixture(scope="module")
def clean(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_log(tmp_path_factory.mktemp("clean") / "log.mcap")


@pytest.fixture(scope="module")
def clean_cycles(clean: Path) -> list[tuple[object, ...]]:
    return [cycle_key(c) for c in open_log(clean).iter_cycles()]


def _overall(path: Path) -> object:
    report = to_jsonable(compute_metrics([path]))
    return {k: report[k] for k in ("overall", "groups", "failures_total", "gaps_total")}


@pytest.mark.parametrize("variant", every_layout(), ids=lambda v: v.name)
def test_every_layout_reads_as_the_same_cycles(
    variant: Variant,
    clean: Path,
    clean_cycles: list[tuple[object, ...]],
    tmp_path: Path,
    caplog: pytest.LogCaptureFixture,
) -> None:
    copy = rewrite(clean, tmp_path / "copy.mcap", variant)
    with caplog.at_level(logging.WARNING, logger="trace_runtime"):
        log = open_log(copy)
        assert [cycle_key(c) for c in log.iter_cycles()] == clean_cycles
    # a finished file is never a crashed one, whatever indexes its writer chose to write
    assert not log.recovered and log.segments[0].finished
    assert "no footer" not in caplog.text


@pytest.mark.parametrize("variant", single_changes(), ids=lambda v: v.name)
def test_every_rewrite_verifies_clean_and_scores_the_same(
    variant: Variant, clean: Path, tmp_path: Path
) -> None:
    copy = rewrite(clean, tmp_path / "copy.mcap", variant)
    report = verify(open_log(copy))
    assert report.ok, [f.message for f in report.findings]
    assert report.cycles == report.cycles_valid == 100
    assert _overall(copy) == _overall(clean)


@pytest.mark.parametrize("compression", ["zstd", "lz4", ""])
def test_a_copied_chunk_table_attachment_is_noted_and_not_used(
    compression: str, clean: Path, tmp_path: Path
) -> None:
    """``mcap compress``/``decompress`` keep our attachment; it names the old offsets."""
    copy = rewrite(clean, tmp_path / "copy.mcap", Variant(compression=compression))
    segment = open_segment(copy)
    assert CHUNK_TABLE_ATTACHMENT in _attachment_names(copy)
    assert len(list(segment.iter_cycles())) == 100
    assert not segment.skipped_chunks  # an honest log is never called damaged
    assert any(CHUNK_TABLE_ATTACHMENT in note for note in segment.notes)


def test_the_writers_own_chunk_table_is_used_when_it_agrees(clean: Path) -> None:
    segment = open_segment(clean)
    assert len(segment.chunk_table()[0]) > 1
    assert segment.notes == []


def test_a_scanned_file_of_loose_messages_starts_at_its_first_message(
    clean: Path, tmp_path: Path
) -> None:
    """No placeholder 0 enters the time range of a file read by linear scan."""
    copy = rewrite(clean, tmp_path / "loose.mcap", Variant(chunked=False))
    cut = tmp_path / "cut.mcap"
    data = copy.read_bytes()
    cut.write_bytes(data[: data.rindex(b"\x0f", 0, len(data) - 200)])  # crash before DataEnd
    segment = open_segment(cut)
    first = min(m.log_time_ns for m in McapFile(copy).iter_messages())
    assert not segment.finished
    assert segment.info.start_ns == segment.start_ns == first > 0


def _attachment_names(path: Path) -> list[str]:
    with path.open("rb") as f:
        return [a.name for a in NonSeekingReader(f).iter_attachments()]


# --- any MCAP, against the reference reader -----------------------------------------------

_MESSAGES = st.lists(
    st.tuples(
        st.integers(0, 2),
        st.integers(0, 10**12),
        st.binary(max_size=40),
    ),
    min_size=0,
    max_size=60,
)


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(messages=_MESSAGES, layout=st.sampled_from([*every_layout(), *single_changes()]))
def test_any_mcap_reads_the_messages_the_reference_reader_reads(
    messages: list[tuple[int, int, bytes]], layout: Variant, tmp_path: Path
) -> None:
    source = tmp_path / "source.mcap"
    with source.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="", library="tests")
        schema = writer.register_schema("Blob", "", b"")
        channels = [writer.register_channel(f"/t{i}", "raw", schema) for i in range(3)]
        writer.add_metadata("robot", {"name": "any"})
        for n, (channel, t, data) in enumerate(messages):
            writer.add_message(channels[channel], t, data, t, sequence=n)
        writer.finish()  # type: ignore[no-untyped-call]
    copy = rewrite(source, tmp_path / "copy.mcap", layout)
    with copy.open("rb") as f:
        expected = [
            (channel.topic, m.sequence, m.log_time, m.data)
            for _schema, channel, m in NonSeekingReader(f).iter_messages()
        ]
    ours = McapFile(copy)
    got = [(m.topic, m.sequence, m.log_time_ns, bytes(m.data)) for m in ours.iter_messages()]
    assert sorted(got) == sorted(expected)  # by time per chunk; the same messages
    assert ours.metadata == {"robot": {"name": "any"}}
    assert ours.finished
