"""The HTML pieces every section of the report is built from: tables, figures, badges.

Values handed to ``html_fields`` and ``html_table`` are HTML already (escape them when
building); headings, captions and problem texts are escaped here.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from html import escape

from trace_audit.incident.drawing import command_colour

__all__ = [
    "command_badge",
    "html_fields",
    "html_figure",
    "html_problems",
    "html_table",
    "seconds",
]


def seconds(t_ns: int | None) -> str:
    """A time in the log's clock as people read it: ``12.300 s`` (``?`` unknown)."""
    return "?" if t_ns is None else f"{t_ns / 1e9:.3f} s"


def html_fields(rows: Iterable[tuple[str, str]]) -> str:
    """A two-column table; values are HTML already (escape them when building)."""
    cells = "".join(f"<tr><th>{escape(k)}</th><td>{v}</td></tr>" for k, v in rows)
    return f'<table class="fields">{cells}</table>'


def html_table(headers: Sequence[str], rows: Iterable[Sequence[str]], numeric: set[int]) -> str:
    """A table with a header row; the columns in ``numeric`` are right-aligned."""
    head = "".join(f"<th>{escape(h)}</th>" for h in headers)
    body = "".join(
        "<tr>"
        + "".join(
            f'<td class="num">{cell}</td>' if i in numeric else f"<td>{cell}</td>"
            for i, cell in enumerate(row)
        )
        + "</tr>"
        for row in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def command_badge(command: str | None) -> str:
    """A command in its colour (the colour every figure uses for it)."""
    colour = command_colour(command)
    return f'<span class="command" style="background:{colour}">{escape(command or "none")}</span>'


def html_figure(svg: str, caption: str) -> str:
    """An inline SVG figure with its caption."""
    return f"<figure>{svg}<figcaption>{escape(caption)}</figcaption></figure>"


def html_problems(items: Iterable[str]) -> str:
    """A list of problems in the colour of a failure (nothing when there is none)."""
    listed = "".join(f"<li>{escape(p)}</li>" for p in items)
    return f'<ul class="problems">{listed}</ul>' if listed else ""
