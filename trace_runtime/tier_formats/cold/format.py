"""The trace-cold-v1 format's constants and its one error: topics, schemas, block header
codes, the guard that turns whatever a damaged block trips over into that error, and the
``BuildBudget`` that bounds what decoding one block may build.

A cold segment holds, per block of ``block_cycles`` whole cycles, one MCAP chunk: the
block's signed checkpoints as plain messages, the block itself on ``/trace/cold/block``
(message encoding ``trace-cold-v1``, log time = the earliest log time in the block) and a
small JSON index entry on ``/trace/cold/index`` (log time = the latest), so the chunk index
spans exactly the time the block covers and a seek to t decodes one block. See
``docs/storage.md`` for the byte layout inside a block.
"""

from __future__ import annotations

import contextlib
import gc
import struct
from collections.abc import Callable, Iterator
from typing import Any

import orjson
import zstandard

from trace_runtime.errors import ColdFormatError, ShapeError
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits
from trace_runtime.records import TOPIC_CHECKPOINT
from trace_runtime.tier_formats.shapes import Shape

CODEC = "trace-cold-v1"
BLOCK_TOPIC = "/trace/cold/block"
INDEX_TOPIC = "/trace/cold/index"
BLOCK_SCHEMA = ("trace.ColdBlock", "", b"")
INDEX_SCHEMA = (
    "trace.ColdIndex",
    "jsonschema",
    b'{"type":"object","title":"Cold block index entry","properties":{'
    b'"messages":{"type":"integer"},"cycles":{"type":"integer"},'
    b'"first_cycle":{"type":["integer","null"]},"last_cycle":{"type":["integer","null"]},'
    b'"first_seal":{"type":["string","null"]},"last_seal":{"type":["string","null"]}}}',
)
PLAIN_TOPICS = frozenset({TOPIC_CHECKPOINT})
"""Topics kept out of blocks, as ordinary MCAP messages in the block's chunk: signed chain
heads stay readable by any MCAP tool without decoding. The block records where they were."""
DEFAULT_BLOCK_CYCLES = 256
DEFAULT_LEVEL = 11
MAGIC = b"TCB\x01"

# column codecs, as a block's header names them
CONST, INT, DEC, F64, BOOL, STR, DIGEST, JSON = "c", "i", "d", "f", "b", "s", "h", "j"
NULLABLE = "n"
SENSORS = "r"
"""Seals' sensors digests, each derived from the block's readings or a literal (a block
using it is refused by decoders that predate it: an unknown codec)."""
REFERENCES = frozenset({DIGEST, SENSORS})
"""Codecs whose values are resolved from other messages of the block as it is built."""

LENGTHS = -1
"""Last path element of a vector's lengths column (element columns end in the index)."""
FLAT = -2
"""Last path element of a vector's flat column: every element of every row, in row order."""

ColumnKey = tuple[int, tuple[Any, ...]]
"""A column of a block: (topic id in the block, leaf path)."""


COMPILE_BYTES = 256
"""What compiling a shape is charged per byte of its descriptor: compiling a shape of
60,000 leaves (650 KB) takes ~0.4 s and ~200 MB at its peak, ~300 bytes a byte."""


class BuildBudget:
    """What decoding one block may still build: the bytes of the messages it rebuilds, a
    pointer's 8 bytes for every value a constant column is repeated for, and
    ``COMPILE_BYTES`` a descriptor byte for every shape it compiles. A block stores a value
    (or a shape) once and rebuilds it for every row, so what it declares (a vector's length,
    a row count, its shapes) is charged here before the decoder allocates for it, and a
    block that would build more than ``ReadLimits.max_chunk_bytes`` (what one chunk may
    inflate to) is refused while it is built, not after."""

    __slots__ = ("left", "most")

    def __init__(self, most: int) -> None:
        self.most = most
        self.left = most

    @classmethod
    def within(cls, limits: ReadLimits = DEFAULT_LIMITS) -> BuildBudget:
        """What one block may build within ``limits``."""
        return cls(limits.max_chunk_bytes)

    def spend(self, size: int) -> None:
        self.left -= size
        if self.left < 0:
            raise ColdFormatError(
                f"cold block builds more than the limit of {self.most} bytes (a bomb, not a log)"
            )

    def compiled(self, shape: Shape) -> Callable[[Any], Any]:
        """``shape.build``, its compiling charged first (once: a compiled shape is kept)."""
        if not shape.compiled:
            self.spend(COMPILE_BYTES * len(shape.key))
        return shape.build

    def repeat(self, value: Any, count: int) -> list[Any]:
        """``[value] * count``, charged first."""
        if count < 0:
            raise ColdFormatError("a column declares a negative number of values")
        self.spend(8 * count)
        return [value] * count


@contextlib.contextmanager
def gc_paused() -> Iterator[None]:
    """Pause the cyclic GC while a block is taken apart or put together.

    A block makes and keeps hundreds of thousands of small acyclic objects (parsed messages,
    rows, columns); the collector would walk them again and again for nothing, a large
    share of the time. Reference counting still frees everything as usual.
    """
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


@contextlib.contextmanager
def malformed_as_format_error() -> Iterator[None]:
    """Whatever a damaged block makes the decoder trip over becomes one ``ColdFormatError``."""
    try:
        yield
    except ColdFormatError:
        raise
    except (zstandard.ZstdError, orjson.JSONDecodeError, struct.error) as err:
        raise ColdFormatError(f"corrupt cold block ({err})") from err
    except (KeyError, IndexError, TypeError, ValueError, ShapeError) as err:
        raise ColdFormatError(f"malformed cold block ({type(err).__name__}: {err})") from err
