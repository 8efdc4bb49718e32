"""The segment check reads a segment's chunks once: the checkpoints come from the cycle scan's
own read, equal to a read of their own (``iter_checkpoints``) on an honest file, one with a
damaged chunk, and one whose chunk trips a read limit (where a read of their own is made,
and its finding reported first, as when it came before the scan)."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest
from mcap.reader import make_reader

from tests.trace_runtime.verification.test_tamper import write_signed_log
from trace_runtime import open_segment
from trace_runtime.chain import digest
from trace_runtime.errors import LogReadError
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.tlog.checkpoints import decode_checkpoint, iter_checkpoints
from trace_runtime.tlog.keys import Ed25519Signer
from trace_runtime.verification.segment_check import SegmentCheck
from trace_runtime.verification.sink import FindingSink


def _chunks(path: Path) -> list[tuple[int, int]]:
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return [(c.chunk_start_offset, c.chunk_length) for c in summary.chunk_indexes]


def _decay(path: Path) -> None:
    """Flip bytes in the middle of a chunk's compressed data: it fails its CRC."""
    offset, length = _chunks(path)[len(_chunks(path)) // 2]
    data = bytearray(path.read_bytes())
    at = offset + length // 2
    data[at : at + 8] = bytes(b ^ 0x5A for b in data[at : at + 8])
    path.write_bytes(bytes(data))


def _bomb(path: Path) -> None:
    """A chunk declaring 1 TiB decompressed: a read limit refuses it (LogLimitError)."""
    offset, _length = _chunks(path)[len(_chunks(path)) // 3]
    with path.open("r+b") as f:
        f.seek(offset + 9 + 16)  # opcode, record length, start and end times
        f.write(struct.pack("<Q", 1 << 40))


def _expected(path: Path) -> tuple[list[tuple[int, int, object]], bool]:
    """The checkpoints a read of their own gives, and whether it stopped at an error."""
    found = []
    try:
        for m in iter_checkpoints(open_segment(path)):
            found.append((m.log_time_ns, m.sequence, decode_checkpoint(m.data)))
    except LogReadError:
        return found, True
    return found, False


@pytest.mark.parametrize("damage", ["none", "decayed", "bomb"])
def test_checkpoints_and_heads_from_the_scan_equal_a_read_of_their_own(
    tmp_path: Path, damage: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = write_signed_log(tmp_path / "run.mcap", Ed25519Signer.generate(), 120, interval_s=0.5)
    if damage == "decayed":
        _decay(path)
    elif damage == "bomb":
        _bomb(path)
    expected, stopped = _expected(path)
    assert len(expected) > 5 and stopped == (damage == "bomb")

    segment = open_segment(path)
    decodes: list[int] = []
    real = segment._chunk_reader.decoder.decode

    def counted(data: object, offset: int, *args: object) -> object:
        decodes.append(offset)
        return real(data, offset, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(segment._chunk_reader.decoder, "decode", counted)
    sink = FindingSink()
    check = SegmentCheck(segment, None, None, None, sink)
    check.run()

    assert check.checkpoints == expected
    sealed: dict[int, list[str]] = {}
    try:
        for cycle in open_segment(path).iter_cycles():
            if TOPIC_SEAL in cycle.payloads:
                sealed.setdefault(cycle.cycle, []).append(digest(cycle.payloads[TOPIC_SEAL]))
    except LogReadError:  # the bomb: the cycles before it (the check reads on after it)
        assert damage == "bomb"
    named = {c.cycle for _t, _s, c in expected if c is not None}
    heads = check.scan.heads
    assert set(heads) <= named and {n: heads[n] for n in sealed if n in named} == {
        n: sealed[n] for n in named if n in sealed
    }
    if damage == "bomb":
        assert sink.findings[0].message.startswith("cannot read the segment's checkpoints")
    else:  # one read: each chunk decoded once, the checkpoints taken on the way
        assert sorted(decodes) == sorted(set(decodes)) and len(decodes) == len(_chunks(path))
