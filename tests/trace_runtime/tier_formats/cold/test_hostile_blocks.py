"""Cold blocks an attacker prepared: a block is refused before it is inflated past what
``ReadLimits`` allows for its compressed size, and nothing a block declares inside (a
vector's length, a constant repeated for every row) makes the decoder build more than the
limits allow.

The files are made from the outside: a small log root compacted to cold, then one block's
message data replaced with the plain ``mcap`` library (``hostile.rewrite``), and the real
``trace-audit`` run on it as a process (``hostile.run_cli``: wall time, peak RSS).
"""

from __future__ import annotations

import functools
import shutil
import struct
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import orjson
import pytest
import zstandard

from tests.trace_runtime import hostile
from tests.trace_runtime.tier_logs import make_root
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.errors import ColdFormatError
from trace_runtime.read_limits import ReadLimits
from trace_runtime.tier_formats.cold import BLOCK_TOPIC, BlockCache, BlockEncoder, PartialBlock
from trace_runtime.tier_formats.cold.columns import pack_i64
from trace_runtime.tier_formats.cold.format import MAGIC
from trace_runtime.tier_formats.shapes import Shape
from trace_runtime.tiers import ColdOptions, compact

MAX_SECONDS = 5.0
MAX_RSS_MB = 150.0
TWO_GIB = 1 << 31


def _frame_declaring(content_size: int, payload: bytes = b"{}") -> bytes:
    """A zstd frame whose header declares ``content_size`` but which holds ``payload``."""
    frame = bytearray(zstandard.ZstdCompressor(level=1).compress(payload))
    # A small frame has a 1-byte content size field (single segment, FCS flag 0); widen it
    # to 4 bytes (FCS flag 2), the window descriptor stays absent.
    assert frame[4] & 0xC0 == 0 and frame[4] & 0x20
    frame[4] = (frame[4] & 0x3F) | 0x80
    return bytes(frame[:5] + struct.pack("<I", content_size) + frame[6:])


BLOCKS: dict[str, Callable[[], bytes]] = {
    # a real frame of 2 GiB of zeros, ~64 KB, its content size in its header
    "declares-2GiB": lambda: MAGIC + hostile.zstd_zeros(TWO_GIB),
    # the same frame without a content size: it declares nothing and inflates to 2 GiB
    "inflates-2GiB-undeclared": lambda: MAGIC + hostile.zstd_zeros(TWO_GIB, content_size=False),
    # a frame that declares 16 bytes and holds 2 GiB of zeros
    "declares-16-inflates-2GiB": lambda: MAGIC + _lying_bomb(),
}


@functools.cache
def _block(name: str) -> bytes:
    return BLOCKS[name]()


def _lying_bomb() -> bytes:
    frame = hostile.zstd_zeros(TWO_GIB)
    # header: magic, descriptor (FCS flag 2: a 4-byte content size after the window byte)
    assert frame[4] >> 6 == 2 and not frame[4] & 0x20
    return frame[:6] + struct.pack("<I", 16) + frame[10:]


@pytest.fixture(scope="module")
def cold_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = make_root(tmp_path_factory.mktemp("cold") / "log", cycles=60)
    compact(root, "cold", older_than_ns=0, cold=ColdOptions(block_cycles=16))
    assert list((root / "cold").glob("*.mcap"))
    return root


def _with_block(root: Path, target: Path, block: bytes) -> Path:
    """A copy of ``root`` whose first cold block is ``block`` (a valid MCAP file still)."""
    shutil.copytree(root, target)
    segment = next((target / "cold").glob("*.mcap"))
    replaced: list[int] = []

    def change(topic: str, _sequence: int, data: bytes) -> bytes:
        if topic == BLOCK_TOPIC and not replaced:
            replaced.append(1)
            return block
        return data

    rewritten = hostile.rewrite(segment, segment.with_suffix(".tmp"), change)
    rewritten.replace(segment)
    assert replaced
    return target


@pytest.fixture(scope="module")
def hostile_roots(cold_root: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("hostile-cold")
    return {name: _with_block(cold_root, base / name, _block(name)) for name in BLOCKS}


def _args(command: str, root: Path) -> list[str]:
    if command == "explain":
        return [command, str(root), "--t", "+0.5", "--plain"]
    return [command, str(root), "--plain"]


@pytest.mark.parametrize("command", ["info", "explain", "metrics", "verify"])
@pytest.mark.parametrize("name", list(BLOCKS))
def test_a_cold_block_bomb_is_refused_in_bounded_time_and_memory(
    name: str, command: str, hostile_roots: dict[str, Path]
) -> None:
    run = hostile.run_cli(_args(command, hostile_roots[name]))
    assert "Traceback" not in run.stderr, run.stderr
    assert run.seconds < MAX_SECONDS, run
    assert run.rss_mb < MAX_RSS_MB, run
    if command == "verify":  # a block that does not read is damage the verdict reports
        assert run.code == 1, run
        assert "damaged" in run.stdout, run.stdout
        assert not run.stderr.strip(), run.stderr
        return
    assert run.code == 3, run
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("trace-audit: "), run.stderr
    assert "cold block 0" in lines[0], lines[0]


def test_the_untouched_root_reads(cold_root: Path, tmp_path: Path) -> None:
    """The crafting alone (a rewrite with the plain mcap library) leaves a root that reads."""
    same = _with_block(cold_root, tmp_path / "same", _first_block(cold_root))
    run = hostile.run_cli(["verify", str(same), "--plain"])
    assert run.code == 0 and "CLEAN" in run.stdout, run


def _first_block(root: Path) -> bytes:
    from trace_runtime import open_segment

    segment = open_segment(next((root / "cold").glob("*.mcap")))
    return next(m.data for m in segment.iter_messages() if m.topic == BLOCK_TOPIC)


# --- in process: the bounds themselves ----------------------------------------------------------


def _peak_mb(run: Callable[[], object]) -> float:
    tracemalloc.start()
    try:
        with pytest.raises(ColdFormatError):
            run()
        return tracemalloc.get_traced_memory()[1] / (1 << 20)
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("name", list(BLOCKS))
def test_a_bomb_is_refused_before_it_inflates(name: str) -> None:
    block = _block(name)
    assert _peak_mb(lambda: BlockCache(0).body(block)) < 4


def test_a_frame_declaring_more_than_it_holds_is_refused_without_the_allocation() -> None:
    block = MAGIC + _frame_declaring(TWO_GIB - 1)
    with pytest.raises(ColdFormatError, match="over the limit"):
        BlockCache(0).body(block)


def test_the_body_limit_scales_with_the_compressed_size() -> None:
    """A block of an idle robot (2,000 identical messages: its messages ~50 times its body,
    its body ~400 times the block) decodes within the default limits; a tighter inflation
    limit refuses it."""
    messages = [RawMessage("/t", i, i, b'{"a":1}') for i in range(2000)]
    block = BlockEncoder(level=1).encode(messages, "hot")
    assert BlockCache(0).decode(block).messages == messages
    tight = ReadLimits(max_inflation=1, small_chunk_bytes=1)
    with pytest.raises(ColdFormatError, match="over the limit"):
        BlockCache(0, limits=tight).decode(block)


def _reblocked(block: bytes, edit: Callable[[dict[str, object], bytearray], bytes]) -> bytes:
    """``block`` with its header edited (``edit`` gets the header and the rest of the body
    and returns the new rest), compressed again."""
    body = BlockCache(0).body(block)
    (head_len,) = struct.unpack_from("<I", body, 0)
    header = orjson.loads(body[4 : 4 + head_len])
    rest = edit(header, bytearray(body[4 + head_len :]))
    head = orjson.dumps(header)
    new_body = struct.pack("<I", len(head)) + head + rest
    return MAGIC + zstandard.ZstdCompressor(level=1).compress(new_body)


def _vector_block(count: int = 50) -> bytes:
    """``count`` messages of a constant string and a vector whose lengths vary and whose
    elements are all 0 (a lengths column and a constant flat column)."""
    messages = [
        RawMessage("/t", i, 1000 + i, orjson.dumps({"s": "x", "v": [0] * (1 + i % 5)}))
        for i in range(count)
    ]
    return BlockEncoder(level=1).encode(messages, "hot")


def _huge_lengths(header: dict[str, object], rest: bytearray) -> bytes:
    """Every vector 2**26 long: a constant flat column repeated 3.3 billion times."""
    cols = header["cols"]
    assert isinstance(cols, list)
    at = sum(header["msg"][2:])  # type: ignore[index]
    for _topic, path, codec, size, _param in cols:
        if path[-1] == -1:
            assert codec == "i"
            new = pack_i64([1 << 26] * 50, delta=True)
            assert new is not None and len(new) == size
            rest[at : at + size] = new
        at += size
    return bytes(rest)


def test_a_vector_that_declares_billions_of_constant_elements_is_refused() -> None:
    block = _reblocked(_vector_block(), _huge_lengths)
    assert _peak_mb(lambda: BlockCache(0).decode(block)) < 70


def test_a_seek_into_that_vector_is_refused_too() -> None:
    block = _reblocked(_vector_block(), _huge_lengths)

    def seek() -> None:
        partial = BlockCache(0).open(block)
        assert isinstance(partial, PartialBlock)
        partial.messages(10, 12)

    assert _peak_mb(seek) < 70


def _big_constant(header: dict[str, object], rest: bytearray) -> bytes:
    """The constant string of every message made 60,000 bytes (the body stays within what
    any block may inflate to): 500 messages, 30 MB to build."""
    cols = header["cols"]
    assert isinstance(cols, list)
    for col in cols:
        if col[1] == ["s"]:
            col[4] = "x" * 60_000
    return bytes(rest)


def test_a_constant_repeated_past_the_limit_is_refused_while_building() -> None:
    block = _reblocked(_vector_block(500), _big_constant)
    assert len(BlockCache(0).decode(block).messages) == 500  # 30 MB: within the defaults
    small = ReadLimits(max_chunk_bytes=1 << 20)
    with pytest.raises(ColdFormatError, match="builds more than the limit"):
        BlockCache(0, limits=small).decode(block)
    # (tracemalloc counts what orjson reserves for a message, ~8x what it keeps for one
    # that is a long string: the whole block, built, would count ~260 MB)
    assert _peak_mb(lambda: BlockCache(0, limits=small).decode(block)) < 16

    def seek() -> None:
        partial = BlockCache(0, limits=small).open(block)
        assert isinstance(partial, PartialBlock)
        partial.messages(0, 499)

    assert _peak_mb(seek) < 16


def _many_big_shapes(header: dict[str, object], rest: bytearray) -> bytes:
    """20 shapes of 20,000 constant leaves each (200 KB of descriptor apiece) that no
    message uses: compiling them all takes seconds and hundreds of MB."""
    names = [f"k{i}" for i in range(20_000)]
    shapes, cols = header["shapes"], header["cols"]
    assert isinstance(shapes, list) and isinstance(cols, list)
    for i in range(20):
        shapes.append([0, orjson.dumps(dict.fromkeys(names[i:] + names[:i], 0)).decode()])
    cols += [[0, [name], "c", 0, 0] for name in names]
    return bytes(rest)


def test_compiling_the_shapes_a_block_declares_is_charged(monkeypatch: pytest.MonkeyPatch) -> None:
    block = _reblocked(_vector_block(), _many_big_shapes)
    assert len(block) < 64_000
    compiled: list[int] = []
    real = Shape._compile

    def counting(shape: Shape) -> None:
        compiled.append(len(shape.paths))
        real(shape)

    monkeypatch.setattr(Shape, "_compile", counting)
    for most, compiles in ((8 << 20, 1), (512 << 20, 11)):  # 2 MiB of descriptors at 512 MiB
        compiled.clear()
        cache = BlockCache(0, limits=ReadLimits(max_chunk_bytes=most))
        with pytest.raises(ColdFormatError, match="builds more than the limit"):
            cache.decode(block)
        assert sum(n > 100 for n in compiled) <= compiles
