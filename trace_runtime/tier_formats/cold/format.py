"""The trace-cold-v1 format's constants and its one error: topics, schemas, block header
codes, and the guard that turns whatever a damaged block trips over into that error.

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
from collections.abc import Iterator
from typing import Any

import orjson
import zstandard

from trace_runtime.errors import TraceError
from trace_runtime.records import TOPIC_CHECKPOINT
from trace_runtime.tier_formats.shapes import ShapeError

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
MAX_BLOCK_BYTES = 1 << 31

# column codecs, as a block's header names them
CONST, INT, DEC, F64, BOOL, STR, DIGEST, JSON = "c", "i", "d", "f", "b", "s", "h", "j"
NULLABLE = "n"

LENGTHS = -1
"""Last path element of a vector's lengths column (element columns end in the index)."""
FLAT = -2
"""Last path element of a vector's flat column: every element of every row, in row order."""

ColumnKey = tuple[int, tuple[Any, ...]]
"""A column of a block: (topic id in the block, leaf path)."""


class ColdFormatError(TraceError, ValueError):
    """A cold block is malformed (wrapped into ``LogReadError`` by callers). A ``TraceError``
    so that one that escapes still maps to an exit code; a ``ValueError`` because it is one."""


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
