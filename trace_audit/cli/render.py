"""A small document model for command output, rendered with rich or as plain text.

Commands build a ``Doc`` of titles, headings, label/value fields, tables, trees and lines;
``show`` prints it with rich (colour, box drawing) on a terminal, or as plain ASCII text with
``--plain`` or when stdout is not a terminal, so the same output reads well in a pager, a CI
log or a grep. Meaning never rests on colour alone: every styled span carries its own words
or markers (``[ok]``, ``MISSING``, ``=>``), and the plain renderer may swap in an ASCII form.
Both fit the terminal width (80 columns when it is unknown).
"""

from __future__ import annotations

import os
import shutil
import sys
import textwrap
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Literal

from trace_audit.cli.app import print_json

__all__ = [
    "Column",
    "Doc",
    "Item",
    "Seg",
    "fmt_duration",
    "fmt_t",
    "setup_logging",
    "show",
    "use_plain",
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


def _segs(line: Line) -> list[Seg]:
    if isinstance(line, str):
        return [Seg(line)]
    if isinstance(line, Seg):
        return [line]
    return [Seg(s) if isinstance(s, str) else s for s in line]


def _plain(line: Line) -> str:
    return "".join(s.plain() for s in _segs(line))


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


@dataclass(slots=True)
class _Block:
    kind: str
    data: Any


@dataclass(slots=True)
class Doc:
    """What a command prints, in order."""

    blocks: list[_Block] = field(default_factory=list)

    def title(self, line: Line) -> None:
        self.blocks.append(_Block("title", line))

    def heading(self, text: str) -> None:
        self.blocks.append(_Block("heading", text))

    def fields(self, rows: Iterable[tuple[str, Line]]) -> None:
        self.blocks.append(_Block("fields", list(rows)))

    def table(self, columns: Sequence[Column], rows: Iterable[Sequence[Line]]) -> None:
        self.blocks.append(_Block("table", (list(columns), [list(r) for r in rows])))

    def tree(self, root: Item) -> None:
        self.blocks.append(_Block("tree", root))

    def line(self, line: Line, indent: int = 0) -> None:
        self.blocks.append(_Block("line", (line, indent)))


# --- formatting helpers ------------------------------------------------------------------------


def fmt_t(t_ns: int) -> str:
    """A log time in seconds with millisecond precision."""
    return f"{t_ns / 1e9:.3f} s"


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


def use_plain(plain: bool) -> bool:
    """Plain text when asked, or when stdout is not a terminal."""
    return plain or not sys.stdout.isatty()


def _width() -> int:
    columns = os.environ.get("COLUMNS", "")
    if columns.isdigit() and int(columns) >= 40:
        return int(columns)
    return max(40, shutil.get_terminal_size((80, 24)).columns)


_HANDLER_NAME = "trace-audit stderr line"


def setup_logging() -> None:
    """Library warnings (e.g. a recovered segment) as one ``trace-audit: warning:`` line."""
    import logging  # here, not at the top: ``--help`` never logs (start-up budget)

    class StderrLine(logging.Handler):
        """One ``trace-audit: warning: ...`` line on whatever ``sys.stderr`` is at the time."""

        def emit(self, record: logging.LogRecord) -> None:
            try:
                sys.stderr.write(
                    f"trace-audit: {record.levelname.lower()}: {record.getMessage()}\n"
                )
            except (OSError, ValueError):  # stderr closed or unable to encode the message
                self.handleError(record)

    logger = logging.getLogger("trace_runtime")
    # With a handler here Python's last-resort printer stays quiet; propagation is left on
    # so an application (or pytest) that configured the root logger still sees the record.
    if not any(h.get_name() == _HANDLER_NAME for h in logger.handlers):
        handler = StderrLine(logging.WARNING)
        handler.set_name(_HANDLER_NAME)
        logger.addHandler(handler)
    if logger.level == logging.NOTSET:
        logger.setLevel(logging.WARNING)


@contextmanager
def progress_bar(description: str, *, visible: bool = True) -> Iterator[Any]:
    """A transient rich progress bar on stderr (counts, bar, time left), for long library
    calls that report progress; the caller decides whether to show one at all."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    with Progress(
        "[progress.description]{task.description}",
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=True,
    ) as bar:
        bar.add_task(description, total=None, visible=visible)
        yield bar


# --- rendering -----------------------------------------------------------------------------------


def show(doc: Doc, *, plain: bool) -> None:
    """Print ``doc`` on stdout: rich on a terminal, plain text otherwise (or when asked)."""
    if use_plain(plain):
        sys.stdout.write(render_plain(doc, _width()))
    else:
        _render_rich(doc)


def emit(result: Any, to_doc: Callable[[Any], Doc], *, json_out: bool, plain: bool) -> None:
    """A command's output: ``result`` as JSON for scripts, or its document for people."""
    if json_out:
        print_json(result)
    else:
        show(to_doc(result), plain=plain)


def render_plain(doc: Doc, width: int = 80) -> str:
    """``doc`` as plain ASCII-marked text no wider than ``width`` (long words excepted)."""
    out: list[str] = []
    for block in doc.blocks:
        kind, data = block.kind, block.data
        if kind == "title":
            text = _plain(data)
            out += [text, "=" * min(len(text), width)]
        elif kind == "heading":
            out += ["", data, "-" * min(len(data), width)]
        elif kind == "fields":
            out += _plain_fields(data, width)
        elif kind == "table":
            out += _plain_table(data[0], data[1], width)
        elif kind == "tree":
            out += _plain_tree(data, width)
        elif kind == "line":
            line, indent = data
            pad = " " * indent
            out += _wrap(_plain(line), width, pad, pad + "  ")
    return "\n".join(out) + "\n"


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
        out += _wrap(_plain(value), width, first, " " * (label_w + 2))
    return out


def _plain_table(columns: list[Column], rows: list[list[Line]], width: int) -> list[str]:
    cells = [[_plain(c) for c in row] for row in rows]
    n = len(columns)
    widths = [len(c.header) for c in columns]
    for row in cells:
        for i, text in enumerate(row[:n]):
            widths[i] = max(widths[i], len(text))
    wrap_at = next((i for i, c in enumerate(columns) if c.wrap), None)
    gap = 2
    if wrap_at is not None:
        others = sum(w for i, w in enumerate(widths) if i != wrap_at) + gap * (n - 1)
        widths[wrap_at] = max(16, min(widths[wrap_at], width - others))

    def fmt(row: list[str]) -> list[str]:
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
            lines.append("  " + (" " * gap).join(pieces).rstrip())
        return lines

    out = fmt([c.header for c in columns])
    out.append("  " + (" " * gap).join("-" * w for w in widths))
    for row in cells:
        out += fmt(row)
    return out


def _plain_tree(root: Item, width: int) -> list[str]:
    out: list[str] = []

    def walk(item: Item, prefix: str, child_prefix: str) -> None:
        out.extend(_wrap(_plain(item.line), width, prefix, child_prefix + "    "))
        for i, child in enumerate(item.children):
            last = i == len(item.children) - 1
            walk(
                child,
                child_prefix + ("`-- " if last else "|-- "),
                child_prefix + ("    " if last else "|   "),
            )

    walk(root, "  ", "  ")
    return out


def _rich_text(line: Line) -> Any:
    from rich.text import Text

    text = Text()
    for seg in _segs(line):
        text.append(seg.text, style=seg.style or "")
    return text


def _render_rich(doc: Doc) -> None:
    from rich import box
    from rich.console import Console
    from rich.table import Table
    from rich.tree import Tree

    console = Console(highlight=False, emoji=False)
    for block in doc.blocks:
        kind, data = block.kind, block.data
        if kind == "title":
            text = _rich_text(data)
            text.stylize("bold")
            console.print(text)
        elif kind == "heading":
            console.print()
            console.print(f"[bold cyan]{_escape(data)}[/]")
        elif kind == "fields":
            grid = Table.grid(padding=(0, 2))
            grid.add_column(style="bold", no_wrap=True)
            grid.add_column(overflow="fold")
            for label, value in data:
                grid.add_row(label, _rich_text(value))
            console.print(grid)
        elif kind == "table":
            columns, rows = data
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
            console.print(table)
        elif kind == "tree":
            tree = Tree(_rich_text(data.line), guide_style="dim")

            def add(node: Any, item: Item) -> None:
                for child in item.children:
                    add(node.add(_rich_text(child.line)), child)

            add(tree, data)
            console.print(tree)
        elif kind == "line":
            line, indent = data
            text = _rich_text(line)
            if indent:
                from rich.padding import Padding

                console.print(Padding(text, (0, 0, 0, indent)))
            else:
                console.print(text)


def _escape(text: str) -> str:
    from rich.markup import escape

    return escape(text)
