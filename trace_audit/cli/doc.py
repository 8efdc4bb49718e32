"""What a command prints for people, as data: the document model and the formats of times.

A ``Doc`` is a list of blocks, in order. The flow blocks (titles, headings, label/value
fields, tables, trees and lines) are laid out by ``trace_audit.cli.render`` with rich on a
terminal or as plain ASCII text. Meaning never rests on colour alone: every styled span
carries its own words or markers (``[ok]``, ``MISSING``, ``=>``), and the plain layout may
swap in an ASCII form.

The console blocks (lines of rich markup, verbatim lines, boxed tables: the layout of
``metrics``, ``compact`` and ``catalog``) are rich's own layout, so a document that holds any
is drawn by rich in both modes, without colour and with ASCII boxes when plain. Building a
document imports nothing heavy; only drawing it imports rich.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal, TypeAlias

if TYPE_CHECKING:
    from trace_audit.log_time import LogClock

__all__ = [
    "Block",
    "BoxBlock",
    "BoxColumn",
    "BoxTable",
    "Column",
    "ConsoleBlock",
    "Doc",
    "FieldsBlock",
    "FlowBlock",
    "HeadingBlock",
    "Item",
    "Line",
    "LineBlock",
    "MarkupBlock",
    "Seg",
    "TableBlock",
    "TitleBlock",
    "TreeBlock",
    "VerbatimBlock",
    "fmt_duration",
    "fmt_t",
    "fmt_value",
    "plain_text",
    "segs",
]


@dataclass(frozen=True, slots=True)
class Seg:
    """A span of text with a rich style; ``ascii`` replaces it in plain output."""

    text: str
    style: str = ""
    ascii: str | None = None

    def plain(self) -> str:
        return self.text if self.ascii is None else self.ascii


Line = str | Seg | Sequence["str | Seg"]


def segs(line: Line) -> list[Seg]:
    """The spans of a line, each a ``Seg``."""
    if isinstance(line, str):
        return [Seg(line)]
    if isinstance(line, Seg):
        return [line]
    return [Seg(s) if isinstance(s, str) else s for s in line]


def plain_text(line: Line) -> str:
    """A line as plain text: each span's ASCII form where it has one."""
    return "".join(s.plain() for s in segs(line))


@dataclass(frozen=True, slots=True)
class Column:
    header: str
    justify: Literal["left", "right"] = "left"
    wrap: bool = False
    """This column takes the width left over and wraps (at most one per table)."""


@dataclass(slots=True)
class Item:
    """A node of a tree: its line and its children."""

    line: Line
    children: list[Item] = field(default_factory=list)

    def add(self, line: Line) -> Item:
        child = Item(line)
        self.children.append(child)
        return child


@dataclass(frozen=True, slots=True)
class BoxColumn:
    header: str
    justify: Literal["left", "right"] = "left"
    min_width: int | None = None
    no_wrap: bool = False


@dataclass(frozen=True, slots=True)
class BoxTable:
    """A boxed table: heavy lines on a colour terminal, ASCII ones when colour is off."""

    columns: tuple[BoxColumn, ...]
    rows: tuple[tuple[str, ...], ...]
    title: str | None = None
    flush: bool = False
    """A left-aligned title and no padding at the table's left and right edges."""
    collapse_plain: bool = False
    """The padding between columns collapses when colour is off."""


# --- blocks: one class each, so that a renderer gets the type it draws --------------------


@dataclass(frozen=True, slots=True)
class TitleBlock:
    line: Line


@dataclass(frozen=True, slots=True)
class HeadingBlock:
    text: str


@dataclass(frozen=True, slots=True)
class FieldsBlock:
    """Label/value rows."""

    rows: list[tuple[str, Line]]


@dataclass(frozen=True, slots=True)
class TableBlock:
    columns: list[Column]
    rows: list[list[Line]]


@dataclass(frozen=True, slots=True)
class TreeBlock:
    root: Item


@dataclass(frozen=True, slots=True)
class LineBlock:
    line: Line
    indent: int = 0


@dataclass(frozen=True, slots=True)
class MarkupBlock:
    """A console line of rich markup."""

    text: str


@dataclass(frozen=True, slots=True)
class VerbatimBlock:
    """A console line printed as it is (no markup), not wrapped at the width."""

    text: str


@dataclass(frozen=True, slots=True)
class BoxBlock:
    table: BoxTable


FlowBlock: TypeAlias = TitleBlock | HeadingBlock | FieldsBlock | TableBlock | TreeBlock | LineBlock
"""The blocks laid out as plain text or by rich."""
ConsoleBlock: TypeAlias = MarkupBlock | VerbatimBlock | BoxBlock
"""The blocks only rich lays out: a document holding one is drawn by rich in both modes."""
Block: TypeAlias = FlowBlock | ConsoleBlock


@dataclass(slots=True)
class Doc:
    """What a command prints, in order."""

    blocks: list[Block] = field(default_factory=list)

    @property
    def console_layout(self) -> bool:
        """Whether rich draws this document in both modes (it holds a console block)."""
        return any(isinstance(block, ConsoleBlock) for block in self.blocks)

    def title(self, line: Line) -> None:
        self.blocks.append(TitleBlock(line))

    def heading(self, text: str) -> None:
        self.blocks.append(HeadingBlock(text))

    def fields(self, rows: Iterable[tuple[str, Line]]) -> None:
        self.blocks.append(FieldsBlock(list(rows)))

    def table(self, columns: Sequence[Column], rows: Iterable[Sequence[Line]]) -> None:
        self.blocks.append(TableBlock(list(columns), [list(r) for r in rows]))

    def tree(self, root: Item) -> None:
        self.blocks.append(TreeBlock(root))

    def line(self, line: Line, indent: int = 0) -> None:
        self.blocks.append(LineBlock(line, indent))

    def markup(self, text: str) -> None:
        """A console line of rich markup."""
        self.blocks.append(MarkupBlock(text))

    def verbatim(self, text: str) -> None:
        """A console line printed as it is (no markup), not wrapped at the width."""
        self.blocks.append(VerbatimBlock(text))

    def box(self, table: BoxTable) -> None:
        """A boxed table."""
        self.blocks.append(BoxBlock(table))


# --- formats ---------------------------------------------------------------------------------


def fmt_t(t_ns: int, clock: LogClock | None = None) -> str:
    """A log time to the millisecond: in seconds, or as ``clock`` shows it (ISO UTC and
    seconds since the log's start on a wall clock)."""
    return clock.show(t_ns) if clock is not None else f"{t_ns / 1e9:.3f} s"


def fmt_duration(ns: int) -> str:
    """A duration as people say it: 850 ms, 12.3 s, 4 min 10 s, 2 h 05 min."""
    ns = abs(ns)
    if ns < 1_000_000_000:
        return f"{ns / 1e6:.0f} ms"
    s = ns / 1e9
    if s < 60:
        return f"{s:.1f} s"
    if s < 3600:
        return f"{int(s // 60)} min {int(s % 60):02d} s"
    return f"{int(s // 3600)} h {int(s % 3600 // 60):02d} min"


def fmt_value(value: object, unit: str | None = None) -> str:
    """A logged value as the investigator writes it everywhere (``trace_audit.causal``):
    any value (``object``), what is not a number, bool or None written as ``str`` writes it."""
    from trace_audit.causal import format_value  # the library: not needed for ``--help``

    return format_value(value, unit)
