"""Partial decoding: building only the messages of a block that one cycle depends on, for a
seek (``ColdAssembler.cycle_at``) that wants one cycle and not the whole block."""

from __future__ import annotations

from collections.abc import Sequence
from itertools import accumulate
from typing import Any

import orjson

from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.errors import ColdFormatError
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.tier_formats.cold.columns import counters, decode_column, plan
from trace_runtime.tier_formats.cold.decode import BlockStreams, fitting, hex_of
from trace_runtime.tier_formats.cold.format import (
    CONST,
    FLAT,
    LENGTHS,
    REFERENCES,
    BuildBudget,
    ColumnKey,
)
from trace_runtime.tier_formats.cold.sensors import DERIVED, SensorCovers
from trace_runtime.tier_formats.shapes import ShapeCache


class PartialBlock:
    """A block opened for building only some of its messages (a seek wants one cycle).

    The message streams and the column table are read at once; a column is decoded the
    first time a message that needs it is built, and a shape group's rows are cut from
    its columns the first time one of them is needed. A message's digest references are
    followed back first, so building a cycle builds just the messages its bytes depend
    on: its own, the sensor readings its evidence names, and the seals (with their
    cycles) back to the nearest seal whose ``prev`` the block stores as a literal (the
    encoder writes one every ``SEAL_ANCHOR_CYCLES`` cycles; a block without such anchors
    is built back to its start, correctly, only more slowly).

    What the block builds, over all the seeks into it, is charged to one ``BuildBudget``:
    the messages it keeps and the repetitions of its constants.
    """

    def __init__(self, body: bytes, cache: ShapeCache, budget: BuildBudget | None = None) -> None:
        """Open the decompressed ``body`` of a block; its shapes are looked up in ``cache``;
        what it builds is charged to ``budget`` (by default, what the default limits allow)."""
        budget = budget if budget is not None else BuildBudget.within()
        streams = BlockStreams.read(body, cache)
        header, pos, raw_lens, raw_body = (
            streams.header,
            streams.columns_at,
            streams.raw_lens,
            streams.raw_body,
        )
        self.n = n = streams.n
        self.tier = str(header["tier"])
        self.plain = [int(p) for p in header.get("plain", [])]
        self.topic_names = streams.topic_names
        self.topic_ids = streams.topic_ids
        self.shape_ids = streams.shape_ids
        self.times = streams.times
        self.sequences = streams.sequences
        self.shapes = streams.shapes

        self._body = body
        self._budget = budget
        self._specs: dict[ColumnKey, tuple[str, Any, int, int]] = {}
        self._constants: dict[ColumnKey, Any] = {}
        self._digest_keys: set[ColumnKey] = set()
        for topic_id, path, codec, size, param in header["cols"]:
            key = (int(topic_id), tuple(path))
            fitting(pos, size, len(body))
            if codec == CONST:
                self._constants[key] = param
            else:
                self._specs[key] = (codec, param, pos, size)
            if codec in REFERENCES:
                self._digest_keys.add(key)
            pos += size
        self._covers: SensorCovers | None = None
        self._values: dict[ColumnKey, list[Any]] = {}

        # each message's row within its shape group
        counts = [0] * (len(self.shapes) + 1)
        self.row_of: list[int] = []
        for group in self.shape_ids:
            if group > len(self.shapes):
                raise ColdFormatError("a message names a shape the block does not have")
            self.row_of.append(counts[group])
            counts[group] += 1
        self.datas: list[bytes | None] = [None] * n
        raw_at = 0
        raw_positions = [i for i, group in enumerate(self.shape_ids) if group == 0]
        for index, size in zip(raw_positions, raw_lens, strict=True):
            self.datas[index] = raw_body[raw_at : raw_at + size]
            raw_at += size
        budget.spend(len(raw_body))
        self._counts = counts
        self._layout = self._lay_out(counts)
        self._by_path: dict[ColumnKey, list[tuple[int, int]]] | None = None
        self._flat_starts: dict[ColumnKey, list[int]] = {}
        self._rows: dict[int, list[Sequence[Any]]] = {}
        self._digest_slots: dict[int, list[int]] = {}

    def _slots_of_digests(self, group: int) -> list[int]:
        """The slots of a group whose column holds digest back-references."""
        slots = self._digest_slots.get(group)
        if slots is None:
            topic_id, shape = self.shapes[group - 1]
            keys = plan(shape, topic_id)[0]
            slots = [i for i, key in enumerate(keys) if key in self._digest_keys]
            self._digest_slots[group] = slots
        return slots

    def _column(self, key: ColumnKey) -> list[Any]:
        values = self._values.get(key)
        if values is None:
            codec, param, pos, size = self._specs[key]
            data = self._body[pos : pos + size]
            values = self._values[key] = decode_column(codec, param, data)
        return values

    def _cut(self, key: ColumnKey, start: int, count: int) -> list[Any]:
        if key in self._constants:
            return self._budget.repeat(self._constants[key], count)
        values = self._column(key)
        if start + count > len(values):
            raise ColdFormatError("a column is shorter than its shapes need")
        return values[start : start + count]

    def _lay_out(self, counts: list[int]) -> list[list[int]]:
        """Where each shape group's slots start in their columns: groups take their rows
        from the columns in group order, as the encoder put them there. A vector slot
        counts its rows in its lengths column (a scalar leaf of the same path, where the
        array was null, has a column of its own)."""
        taken: dict[ColumnKey, int] = {}
        get = taken.get
        layout: list[list[int]] = []
        for group, (topic_id, shape) in enumerate(self.shapes, start=1):
            count = counts[group]
            keys = counters(shape, topic_id)
            starts = [get(key, 0) for key in keys]
            taken.update(zip(keys, [start + count for start in starts], strict=True))
            layout.append(starts)
        self._rows_per_column = taken  # vectors counted in their lengths column
        return layout

    def _slot_groups(self) -> dict[ColumnKey, list[tuple[int, int]]]:
        """Per leaf path: (group, first row) of every group with a slot on it, in group
        order (a vector's first row is in its lengths column). Built only when asked."""
        if self._by_path is None:
            self._by_path = {}
            for group, (topic_id, shape) in enumerate(self.shapes, start=1):
                keys = plan(shape, topic_id)[0]
                for key, start in zip(keys, self._layout[group - 1], strict=True):
                    self._by_path.setdefault(key, []).append((group, start))
        return self._by_path

    def _shared_start(self, key: ColumnKey, group: int) -> int:
        """Where ``group`` starts in column ``key`` = (..., i), a column that scalar leaves
        (an array holding an object) and the i-th elements of vectors (an array of scalars
        elsewhere) may share: every earlier take of either kind, in group order."""
        topic_id, path = key
        index, parent = path[-1], (topic_id, path[:-1])
        length_key = (topic_id, (*path[:-1], LENGTHS))
        by_path = self._slot_groups()
        start = 0
        for earlier, _first in by_path.get(key, ()):
            if earlier < group and not self._is_vector_slot(earlier, key):
                start += self._counts[earlier]
        for earlier, first in by_path.get(parent, ()):
            wide_enough = earlier < group and self._is_vector_slot(earlier, parent)
            if wide_enough and self._cut(length_key, first, 1)[0] > index:
                start += self._counts[earlier]
        return start

    def _is_vector_slot(self, group: int, key: ColumnKey) -> bool:
        _topic_id, shape = self.shapes[group - 1]
        return shape.paths.index(key[1]) in shape.vectors

    def _vectors(self, key: ColumnKey, start: int, count: int, group: int) -> list[Any]:
        topic_id, path = key
        length_key = (topic_id, (*path, LENGTHS))
        lengths = self._cut(length_key, start, count)
        flat_key = (topic_id, (*path, FLAT))
        if flat_key in self._specs or flat_key in self._constants:
            before = self._flat_starts.get(length_key)
            if before is None:
                every = self._cut(length_key, 0, self._total(length_key))
                before = self._flat_starts[length_key] = [0, *accumulate(every)]
            flat = self._cut(flat_key, before[start], sum(lengths))
            ends = list(accumulate(lengths))
            return [flat[end - k : end] for k, end in zip(lengths, ends, strict=True)]
        width = lengths[0] if lengths else 0
        if lengths.count(width) != len(lengths):
            raise ColdFormatError("vectors of different lengths without a flat column")
        if width == 0:
            return [[] for _ in lengths]
        elements = []
        for i in range(width):
            element_key = (topic_id, (*path, i))
            # shared with scalar leaves (their takes counted apart) only if any exist
            shared = self._rows_per_column.get(element_key) and element_key not in self._constants
            at = self._shared_start(element_key, group) if shared else start
            elements.append(self._cut(element_key, at, count))
        return list(map(list, zip(*elements, strict=True)))

    def _total(self, key: ColumnKey) -> int:
        """Rows in a lengths column (a constant one has one per row of its groups)."""
        if key in self._constants:
            return self._rows_per_column.get(key, 0)
        return len(self._column(key))

    def _group_rows(self, group: int) -> list[Sequence[Any]]:
        rows = self._rows.get(group)
        if rows is not None:
            return rows
        count = self._counts[group]
        _topic_id, shape = self.shapes[group - 1]
        vectors = shape.vectors
        columns = []
        topic_id = self.shapes[group - 1][0]
        keys = plan(shape, topic_id)[0]
        for slot, (key, start) in enumerate(zip(keys, self._layout[group - 1], strict=True)):
            if slot in vectors:
                columns.append(self._vectors(key, start, count, group))
            else:
                # shared with vector elements only if the column holds more than the leaves
                shared = key in self._specs and len(self._column(key)) != self._rows_per_column[key]
                at = self._shared_start(key, group) if shared else start
                columns.append(self._cut(key, at, count))
        rows = self._rows[group] = list(zip(*columns, strict=True)) if columns else [()] * count
        return rows

    def messages(self, first: int, last: int) -> list[RawMessage]:
        """Messages ``first`` to ``last`` (positions in the block, inclusive), byte for byte."""
        if not 0 <= first <= last < self.n:
            raise ColdFormatError("a message range outside the block")
        needed = bytearray(self.n)
        needed[first : last + 1] = b"\x01" * (last + 1 - first)
        shape_ids, row_of, datas = self.shape_ids, self.row_of, self.datas
        # Digest references point back only: walking down from the end marks every
        # message the range depends on before any of them is built.
        for index in range(last, -1, -1):
            group = shape_ids[index]
            if not needed[index] or not group or datas[index] is not None:
                continue
            slots = self._slots_of_digests(group)
            if slots:
                row = self._group_rows(group)[row_of[index]]
                for slot in slots:
                    back = row[slot]
                    if type(back) is int:
                        if not 0 < back <= index:
                            raise ColdFormatError("a digest reference points outside the block")
                        needed[index - back] = 1
                    elif back is DERIVED:
                        for at in self._sensor_covers().readings(index):
                            needed[at] = 1
        dumps = orjson.dumps
        hexes: dict[int, str] = {}
        built: list[bytes] = datas  # type: ignore[assignment]  # refs only reach built ones
        for index in range(last + 1):
            if not needed[index] or datas[index] is not None:
                continue
            group = shape_ids[index]
            _topic_id, shape = self.shapes[group - 1]
            row = self._group_rows(group)[row_of[index]]
            slots = self._slots_of_digests(group)
            if slots:
                row = list(row)
                for slot in slots:
                    back = row[slot]
                    if type(back) is int:
                        row[slot] = hex_of(built, hexes, index - back)
                    elif back is DERIVED:
                        row[slot] = self._sensor_covers().cover(
                            index, lambda at: hex_of(built, hexes, at), self._budget.spend
                        )
            build = shape.build if shape.compiled else shape.build_uncompiled
            data = datas[index] = dumps(build(row))
            self._budget.spend(len(data))
        names = self.topic_names
        return [
            RawMessage(names[self.topic_ids[i]], self.sequences[i], self.times[i], built[i])
            for i in range(first, last + 1)
        ]

    def _sensor_covers(self) -> SensorCovers:
        if self._covers is None:
            self._covers = SensorCovers(
                self.topic_names, self.topic_ids, self.sequences, self.times
            )
        return self._covers

    def _seals(self) -> list[int]:
        seal_id = self.topic_names.index(TOPIC_SEAL) if TOPIC_SEAL in self.topic_names else -1
        return [i for i, topic_id in enumerate(self.topic_ids) if topic_id == seal_id]

    @property
    def ends_sealed(self) -> bool:
        """Whether the block's last message is a seal: else an unsealed cycle ends it, whose
        time only assembling it tells (a seek then decodes the block whole)."""
        return self.n == 0 or self.topic_names[self.topic_ids[-1]] == TOPIC_SEAL

    def sealed_cycle_at(self, t_ns: int) -> tuple[int, int] | None:
        """The message range of the block's last sealed cycle at or before ``t_ns`` (its
        seal's log time), or None if there is none."""
        seals = self._seals()
        found = None
        for k, at in enumerate(seals):
            if self.times[at] <= t_ns:
                found = k
        if found is None:
            return None
        return (seals[found - 1] + 1 if found else 0), seals[found]
