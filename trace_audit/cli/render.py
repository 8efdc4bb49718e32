"""Drawing the document model of ``trace_audit.cli.doc``: a ``Doc`` as plain ASCII text
(flow blocks only) or onto a rich console (every block; boxed tables in ASCII when the
console's colour is off).

Plain text fits the width it is given (long words excepted); rich fits the console's. This
module decides layout only: which stream, which console and which of the two layouts is
``trace_audit.cli.output.show``'s.
"""

from __future__ import annotations

import textwrap
from typing import TYPE_CHECKING

from trace_audit.cli.doc import (
    BoxBlock,
    BoxTable,
    Column,
    ConsoleBlock,
    Doc,
    FieldsBlock,
    FlowBlock,
    HeadingBlock,
    Item,
    Line,
    LineBlock,
    MarkupBlock,
    TableBlock,
    TitleBlock,
    TreeBlock,
    VerbatimBlock,
    plain_text,
    segs,
)

if TYPE_CHECKING:  # rich is imported where a document is drawn, not to build one
    from rich.console import Console, RenderableType
    from rich.table import Table
    from rich.text import Text
    from rich.tree import Tree

__all__ = ["draw_rich", "render_plain"]


# --- plain text -------------------------------------------------------------------------------


def render_plain(doc: Doc, width: int = 80) -> str:
    """``doc`` as plain ASCII-marked text no wider than ``width`` (long words excepted).

    Its blocks are flow blocks: rich lays out the others (``Doc.console_layout``)."""
    out: list[str] = []
    for block in doc.blocks:
        if isinstance(block, ConsoleBlock):
            raise ValueError(f"a {_KIND[type(block)]} block is drawn by rich only (draw_rich)")
        out += _plain_block(block, width)
    return "\n".join(out) + "\n"


_KIND = {MarkupBlock: "markup", VerbatimBlock: "verbatim", BoxBlock: "box"}
"""A console block's name in the error ``render_plain`` raises."""


def _plain_block(block: FlowBlock, width: int) -> list[str]:
    if isinstance(block, TitleBlock):
        text = plain_text(block.line)
        return [text, "=" * min(len(text), width)]
    if isinstance(block, HeadingBlock):
        return ["", block.text, "-" * min(len(block.text), width)]
    if isinstance(block, FieldsBlock):
        return _plain_fields(block.rows, width)
    if isinstance(block, TableBlock):
        return _plain_table(block.columns, block.rows, width)
    if isinstance(block, TreeBlock):
        return _plain_tree(block.root, width)
    pad = " " * block.indent
    return _wrap(plain_text(block.line), width, pad, pad + "  ")


def _wrap(text: str, width: int, first: str, rest: str) -> list[str]:
    if not text:
        return [first.rstrip()]
    lines = textwrap.wrap(
        text,
        width=max(20, width),
        initial_indent=first,
        subsequent_indent=rest,
        break_long_words=False,
        break_on_hyphens=False,
    )
    return lines or [first.rstrip()]


def _plain_fields(rows: list[tuple[str, Line]], width: int) -> list[str]:
    if not rows:
        return []
    label_w = min(max(len(label) for label, _ in rows), 18)
    out: list[str] = []
    for label, value in rows:
        first = f"{label:<{label_w}}  "
        out += _wrap(plain_text(value), width, first, " " * (label_w + 2))
    return out


_GAP = 2
"""Spaces between the columns of a plain table."""


_MIN_WRAP = 32
"""A wrapping column left fewer characters than this (an 80-column terminal, wide cells
beside it) reads a word or two a line: its text goes under its row instead, full width."""


def _plain_table(columns: list[Column], rows: list[list[Line]], width: int) -> list[str]:
    cells = [[plain_text(c) for c in row] for row in rows]
    below = _wrap_below(columns, cells, width)
    if below is not None:
        return _plain_table_below(columns, cells, width, below)
    widths = _column_widths(columns, cells, width)
    out = _plain_row(columns, widths, [c.header for c in columns])
    out.append("  " + (" " * _GAP).join("-" * w for w in widths))
    for row in cells:
        out += _plain_row(columns, widths, row)
    return out


def _natural_widths(columns: list[Column], cells: list[list[str]]) -> list[int]:
    """Each column as wide as its header and its widest cell."""
    widths = [len(c.header) for c in columns]
    for row in cells:
        for i, text in enumerate(row[: len(columns)]):
            widths[i] = max(widths[i], len(text))
    return widths


def _column_widths(columns: list[Column], cells: list[list[str]], width: int) -> list[int]:
    """Each column as wide as its widest cell; the wrapping one takes what is left."""
    widths = _natural_widths(columns, cells)
    wrap_at = _wrap_column(columns)
    if wrap_at is not None:
        others = sum(w for i, w in enumerate(widths) if i != wrap_at) + _GAP * (len(columns) - 1)
        widths[wrap_at] = max(16, min(widths[wrap_at], width - others))
    return widths


def _wrap_below(columns: list[Column], cells: list[list[str]], width: int) -> int | None:
    """The wrapping column, when its text goes under each row (``_MIN_WRAP``); else None."""
    wrap_at = _wrap_column(columns)
    if wrap_at is None:
        return None
    widths = _natural_widths(columns, cells)
    others = sum(w for i, w in enumerate(widths) if i != wrap_at) + _GAP * len(columns)
    return wrap_at if width - others < min(_MIN_WRAP, widths[wrap_at]) else None


def _plain_table_below(
    columns: list[Column], cells: list[list[str]], width: int, below: int
) -> list[str]:
    """The table without column ``below``, each row followed by that column's text wrapped
    to the whole width, indented under the row."""
    kept = [c for i, c in enumerate(columns) if i != below]
    rows = [[t for i, t in enumerate(row) if i != below] for row in cells]
    widths = _natural_widths(kept, rows)
    if 2 + sum(widths) + _GAP * (len(widths) - 1) > width:  # still too wide: the widest wraps
        widest = widths.index(max(widths))
        kept[widest] = Column(kept[widest].header, kept[widest].justify, wrap=True)
        widths = _column_widths(kept, rows, width - 2)  # the rows' indent
    out = _plain_row(kept, widths, [c.header for c in kept])
    out.append("  " + (" " * _GAP).join("-" * w for w in widths))
    for row, full in zip(rows, cells, strict=True):
        out += _plain_row(kept, widths, row)
        text = full[below] if below < len(full) else ""
        if text:
            out += _wrap(text, width, "      ", "      ")
    return out


def _wrap_column(columns: list[Column]) -> int | None:
    return next((i for i, c in enumerate(columns) if c.wrap), None)


def _plain_row(columns: list[Column], widths: list[int], row: list[str]) -> list[str]:
    """One table row as text lines: the wrapping column may take several."""
    n = len(columns)
    wrap_at = _wrap_column(columns)
    parts: list[list[str]] = []
    for i in range(n):
        text = row[i] if i < len(row) else ""
        if i == wrap_at:
            parts.append(textwrap.wrap(text, widths[i], break_long_words=False) or [""])
        else:
            parts.append([text])
    height = max(len(p) for p in parts)
    lines = []
    for k in range(height):
        pieces = []
        for i, col in enumerate(columns):
            text = parts[i][k] if k < len(parts[i]) else ""
            last = i == n - 1
            if col.justify == "right":
                pieces.append(text.rjust(widths[i]))
            else:
                pieces.append(text if last else text.ljust(widths[i]))
        lines.append("  " + (" " * _GAP).join(pieces).rstrip())
    return lines


def _plain_tree(root: Item, width: int) -> list[str]:
    out: list[str] = []

    def walk(item: Item, prefix: str, child_prefix: str) -> None:
        out.extend(_wrap(plain_text(item.line), width, prefix, child_prefix + "    "))
        for i, child in enumerate(item.children):
            last = i == len(item.children) - 1
            walk(
                child,
                child_prefix + ("`-- " if last else "|-- "),
                child_prefix + ("    " if last else "|   "),
            )

    walk(root, "  ", "  ")
    return out


# --- rich -------------------------------------------------------------------------------------


def _rich_text(line: Line) -> Text:
    from rich.text import Text

    text = Text()
    for seg in segs(line):
        text.append(seg.text, style=seg.style or "")
    return text


def draw_rich(doc: Doc, console: Console) -> None:
    """Print ``doc`` on a rich ``console``: colour and box drawing (ASCII boxes when the
    console's colour is off)."""
    from rich.markup import escape

    for block in doc.blocks:
        if isinstance(block, HeadingBlock):
            console.print()
            console.print(f"[bold cyan]{escape(block.text)}[/]")
        elif isinstance(block, MarkupBlock):
            console.print(block.text)
        elif isinstance(block, VerbatimBlock):
            console.print(block.text, markup=False, soft_wrap=True)
        elif isinstance(block, BoxBlock):
            console.print(_box_table(block.table, plain=console.no_color))
        else:
            console.print(_rich_block(block, console.width))


def _rich_block(
    block: TitleBlock | FieldsBlock | TableBlock | TreeBlock | LineBlock, width: int
) -> RenderableType:
    """A flow block other than a heading as one rich renderable."""
    if isinstance(block, TitleBlock):
        text = _rich_text(block.line)
        text.stylize("bold")
        return text
    if isinstance(block, FieldsBlock):
        return _rich_fields(block.rows)
    if isinstance(block, TableBlock):
        return _rich_table(block.columns, block.rows, width)
    if isinstance(block, TreeBlock):
        return _rich_tree(block.root)
    text = _rich_text(block.line)
    indent = block.indent
    if indent:
        from rich.padding import Padding

        return Padding(text, (0, 0, 0, indent))
    return text


def _rich_fields(rows: list[tuple[str, Line]]) -> Table:
    from rich.table import Table

    grid = Table.grid(padding=(0, 2))
    grid.add_column(style="bold", no_wrap=True)
    grid.add_column(overflow="fold")
    for label, value in rows:
        grid.add_row(label, _rich_text(value))
    return grid


def _rich_table(columns: list[Column], rows: list[list[Line]], width: int) -> RenderableType:
    from rich import box
    from rich.table import Table
    from rich.text import Text

    cells = [[plain_text(c) for c in row] for row in rows]
    below = _wrap_below(columns, cells, width)
    if below is not None:  # rich cannot span a cell across a row: the plain layout, bold head
        lines = _plain_table_below(columns, cells, width, below)
        text = Text("\n".join(lines), no_wrap=True, overflow="ignore")  # laid out already
        text.stylize("bold", 0, len(lines[0]))
        return text

    table = Table(box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False, header_style="bold")
    for col in columns:
        table.add_column(
            col.header,
            justify=col.justify,
            no_wrap=not col.wrap,
            overflow="fold" if col.wrap else "ellipsis",
            ratio=1 if col.wrap else None,
        )
    for row in rows:
        table.add_row(*(_rich_text(c) for c in row))
    return table


def _rich_tree(root: Item) -> Tree:
    from rich.tree import Tree

    tree = Tree(_rich_text(root.line), guide_style="dim")

    def add(node: Tree, item: Item) -> None:
        for child in item.children:
            add(node.add(_rich_text(child.line)), child)

    add(tree, root)
    return tree


# --- boxed tables ----------------------------------------------------------------------------


def _box_table(spec: BoxTable, *, plain: bool) -> Table:
    from rich import box
    from rich.table import Table

    table = Table(  # what is not asked for keeps rich's default (centred title, padded edges)
        box=box.ASCII if plain else box.SIMPLE_HEAVY,
        show_edge=False,
        title=spec.title,
        title_justify="left" if spec.flush else "center",
        pad_edge=not spec.flush,
        collapse_padding=spec.collapse_plain and not plain,
    )
    for col in spec.columns:
        table.add_column(col.header, justify=col.justify, no_wrap=col.no_wrap)
        if col.min_width is not None:
            table.columns[-1].min_width = col.min_width
    for row in spec.rows:
        table.add_row(*row)
    return table
