"""Honest rewrites of an MCAP file in every layout the MCAP specification allows.

A ``Variant`` names one layout: chunked or not, the compression, which summary records and
indexes are written, whether schemas and channels are repeated in the summary, padding at
the end of records (readers must skip bytes they do not know), and whether attachments are
copied. ``rewrite`` copies a file's schemas, channels, messages, attachments and metadata in
file order with the reference ``mcap`` Writer, the way the official CLI's ``compress``,
``decompress`` and ``filter`` do (attachments included, byte for byte: a TRACE log's own
``trace.chunk_columns`` then describes the chunks of the file it came from, not this one).

The Writer has no option for padding, so ``padding`` pads the records it frames through its
``RecordBuilder`` (the records outside chunks but Message, whose data is the rest of the
record, and the Footer, which readers find at a fixed distance from the end). Records inside
chunks stay unpadded: the reference Python reader does not skip padding there.
"""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import Iterator
from dataclasses import dataclass, fields
from pathlib import Path

import mcap.data_stream
import mcap.writer
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, DataEnd, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, IndexType, Writer

_COMPRESSION = {"": CompressionType.NONE, "lz4": CompressionType.LZ4, "zstd": CompressionType.ZSTD}
_UNPADDED = {Opcode.MESSAGE, Opcode.FOOTER}


@dataclass(frozen=True)
class Variant:
    """One layout of the same content. The default is what the reference Writer writes."""

    chunked: bool = True
    compression: str = "zstd"
    chunk_size: int = 1 << 20
    statistics: bool = True
    summary_offsets: bool = True
    chunk_index: bool = True
    message_index: bool = True
    attachment_index: bool = True
    metadata_index: bool = True
    repeat: bool = True
    padding: int = 0
    attachments: bool = True

    @property
    def name(self) -> str:
        default = Variant()
        parts = [
            f"{f.name}={getattr(self, f.name)!r}"
            for f in fields(self)
            if getattr(self, f.name) != getattr(default, f.name)
        ]
        return ",".join(parts) or "reference"

    @property
    def _index_types(self) -> IndexType:
        chosen = IndexType.NONE
        for wanted, kind in (
            (self.chunk_index, IndexType.CHUNK),
            (self.message_index, IndexType.MESSAGE),
            (self.attachment_index, IndexType.ATTACHMENT),
            (self.metadata_index, IndexType.METADATA),
        ):
            if wanted:
                chosen |= kind
        return chosen


def single_changes() -> list[Variant]:
    """The reference layout and each option changed on its own."""
    out = [Variant()]
    for f in fields(Variant):
        value = getattr(Variant(), f.name)
        if isinstance(value, bool):
            out.append(Variant(**{f.name: not value}))
    out += [Variant(compression=""), Variant(compression="lz4"), Variant(padding=7)]
    out += [Variant(chunk_size=4096), Variant(chunk_size=300)]
    return out


def every_layout() -> list[Variant]:
    """Every combination of the options that change where a reader must look."""
    return list(_layouts())


def _layouts() -> Iterator[Variant]:
    for (
        chunked,
        statistics,
        offsets,
        chunk_index,
        message_index,
        repeat,
        padding,
    ) in itertools.product((True, False), repeat=7):
        if not chunked and (not chunk_index or not message_index):
            continue  # chunk options mean nothing without chunks
        yield Variant(
            chunked=chunked,
            statistics=statistics,
            summary_offsets=offsets,
            chunk_index=chunk_index,
            message_index=message_index,
            metadata_index=repeat,
            attachment_index=not repeat,
            repeat=repeat,
            padding=5 if padding else 0,
            compression=("zstd", "lz4", "")[(chunked + statistics + offsets) % 3],
            chunk_size=4096 if message_index else 1 << 20,
        )


def rewrite(src: Path, dst: Path, variant: Variant) -> Path:
    """Copy ``src`` to ``dst`` in the layout ``variant`` names; the content stays the same."""
    with src.open("rb") as f_in, dst.open("wb") as f_out, _padded(variant.padding):
        writer = Writer(
            f_out,
            chunk_size=variant.chunk_size,
            compression=_COMPRESSION[variant.compression],
            index_types=variant._index_types,
            repeat_channels=variant.repeat,
            repeat_schemas=variant.repeat,
            use_chunking=variant.chunked,
            use_statistics=variant.statistics,
            use_summary_offsets=variant.summary_offsets,
        )
        header = None
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for record in StreamReader(f_in, skip_magic=False).records:
            if header is None and hasattr(record, "profile"):
                header = record
                writer.start(profile=record.profile, library=record.library)
            elif isinstance(record, Schema) and record.id not in schemas:
                schemas[record.id] = writer.register_schema(
                    record.name, record.encoding, record.data
                )
            elif isinstance(record, Channel) and record.id not in channels:
                channels[record.id] = writer.register_channel(
                    record.topic,
                    record.message_encoding,
                    schemas.get(record.schema_id, 0),
                    record.metadata,
                )
            elif isinstance(record, Message):
                writer.add_message(
                    channels[record.channel_id],
                    record.log_time,
                    record.data,
                    record.publish_time,
                    record.sequence,
                )
            elif isinstance(record, Attachment) and variant.attachments:
                writer.add_attachment(
                    record.create_time, record.log_time, record.name, record.media_type, record.data
                )
            elif isinstance(record, Metadata):
                writer.add_metadata(record.name, record.metadata)
            elif isinstance(record, DataEnd):
                break
        writer.finish()  # type: ignore[no-untyped-call]
    return dst


@contextlib.contextmanager
def _padded(padding: int) -> Iterator[None]:
    """While writing, every record the Writer frames outside chunks (but Message and Footer) ends in
    ``padding`` zero bytes, counted in its length as the specification allows."""
    if not padding:
        yield
        return
    original = mcap.data_stream.RecordBuilder

    class PaddedBuilder(original):  # type: ignore[misc, valid-type]
        def start_record(self, opcode: Opcode) -> None:
            self._padding_opcode = opcode
            super().start_record(opcode)

        def finish_record(self) -> None:
            if self._padding_opcode not in _UNPADDED:
                self._buffer.write(b"\0" * padding)
            super().finish_record()

    mcap.writer.RecordBuilder = PaddedBuilder  # type: ignore[misc]
    try:
        yield
    finally:
        mcap.writer.RecordBuilder = original  # type: ignore[misc]
