"""What every figure of the report shares: matplotlib's style, SVG safe to inline, the
command colours and the bands of the command in force.

``to_svg`` returns one ``<svg>`` element as text, ready to inline in the page: no XML
prolog, no metadata, no namespace URLs, glyphs as paths (no font is fetched or needed) and
every ``id`` prefixed with the figure's name so several figures share one page without their
clip paths colliding. Text from the log reaches the SVG only through matplotlib, which
escapes it, and as glyph outlines. The figures themselves are drawn in ``time_figures``,
``scene`` and ``graph_figures``, laid out with networkx where they are graphs.
"""

from __future__ import annotations

import io
import re
import textwrap
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING

from trace_audit.incident.data import ReportData

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "BROKEN",
    "COMMAND_COLOURS",
    "MARKED",
    "MAX_ENTITIES",
    "MAX_FACTORS",
    "MAX_GRAPH_NODES",
    "as_seconds",
    "command_bands",
    "command_colour",
    "command_legend",
    "figure_style",
    "new_figure",
    "time_axis_label",
    "to_svg",
    "wrap_label",
]

COMMAND_COLOURS = {
    "STOP": "#d62728",
    "SLOW": "#ff9f1c",
    "CONTINUE": "#2ca02c",
    "REROUTE": "#1f77b4",
}
# A log may hold anything (docs/integrity.md, hostile files): the figures draw at most this
# much, and the page says what was left out; explain --json has all of it.
MAX_FACTORS = 8
MAX_ENTITIES = 60
MAX_GRAPH_NODES = 150

_OTHER_COLOURS = ("#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")
MARKED = "#222222"
BROKEN = "#c0392b"
_WRAP = 24


def command_colour(command: str | None) -> str:
    """A stable colour per command: the usual ones fixed, others by a stable hash."""
    if command is None:
        return "#bbbbbb"
    known = COMMAND_COLOURS.get(command.upper())
    if known is not None:
        return known
    return _OTHER_COLOURS[sum(command.encode()) % len(_OTHER_COLOURS)]


# --- SVG plumbing ------------------------------------------------------------------------


@contextmanager
def figure_style() -> Iterator[None]:
    """The figures' style, and the text of the log drawn as the text it is.

    A name or a rationale may hold ``$`` (matplotlib would read ``$...$`` as mathtext, and
    fail on a bad one) or glyphs DejaVu Sans lacks (matplotlib warns, naming its own source
    file, and draws a box): mathtext is off, and matplotlib's warnings stay inside the
    figure code; the page has the text itself in its tables."""
    import matplotlib

    with (
        warnings.catch_warnings(),
        matplotlib.rc_context(
            {
                "text.parse_math": False,
                "svg.fonttype": "path",  # glyph outlines: the page needs no font
                "svg.hashsalt": "trace-report",  # ids stable from run to run
                "font.family": "DejaVu Sans",
                "font.size": 9,
                "axes.spines.top": False,
                "axes.spines.right": False,
                "axes.titlesize": 10,
                "axes.titleweight": "bold",
            }
        ),
    ):
        # matplotlib attributes a glyph's warning to the caller's line (``to_svg``), not to
        # itself: every UserWarning of the drawing is matplotlib's, and stays here.
        warnings.simplefilter("ignore", UserWarning)
        yield


def new_figure(width_in: float, height_in: float) -> Figure:
    from matplotlib.figure import Figure

    return Figure(figsize=(width_in, height_in), layout="constrained")


_PROLOG = re.compile(r"^.*?(?=<svg)", re.S)
_METADATA = re.compile(r"<metadata>.*?</metadata>\s*", re.S)
_NAMESPACES = re.compile(r'\s+xmlns(:\w+)?="[^"]*"')
_SIZE = re.compile(r'(<svg[^>]*?)\s+width="[^"]*"\s+height="[^"]*"')


def to_svg(fig: Figure, name: str, title: str) -> str:
    """``fig`` as an inline ``<svg>``, ids prefixed with ``name``, titled for screen readers."""
    buffer = io.StringIO()
    fig.savefig(buffer, format="svg", metadata={"Date": None, "Creator": None})
    text = _METADATA.sub("", _PROLOG.sub("", buffer.getvalue(), count=1))
    text = _NAMESPACES.sub("", text)
    text = _SIZE.sub(r"\1", text, count=1)
    text = re.sub(r'\bid="([^"]+)"', rf'id="{name}-\1"', text)
    text = re.sub(r'href="#([^"]+)"', rf'href="#{name}-\1"', text)
    text = re.sub(r"url\(#([^)]+)\)", rf"url(#{name}-\1)", text)
    from html import escape

    label = escape(title, quote=True)
    return text.replace("<svg ", f'<svg role="img" aria-label="{label}" class="figure" ', 1)


def as_seconds(data: ReportData, t_ns: int) -> float:
    """A time on a figure's axis: seconds in the log's clock, or, on a wall clock, seconds
    from the log's start (raw seconds since 1970 would print as an offset like +1.78e9)."""
    clock = data.explanation.log_clock
    return (t_ns - clock.start_ns) / 1e9 if clock.wall else t_ns / 1e9


def time_axis_label(data: ReportData) -> str:
    """What a figure's time axis counts, in the words of ``as_seconds``."""
    clock = data.explanation.log_clock
    if not clock.wall:
        return "log time (s)"
    return f"seconds from the log's start, {clock.iso(clock.start_ns, digits=3)}"


def wrap_label(text: str, width: int = _WRAP, lines: int = 4) -> str:
    wrapped = textwrap.wrap(text, width) or [""]
    if len(wrapped) > lines:
        wrapped = [*wrapped[: lines - 1], wrapped[lines - 1][: width - 1] + "…"]
    return "\n".join(wrapped)


def command_bands(ax: Axes, data: ReportData) -> None:
    """The command in force as coloured bands behind a time plot; gaps hatched."""
    for row in data.timeline.rows:
        ax.axvspan(
            as_seconds(data, row.t_ns),
            as_seconds(data, row.t_ns + row.held_ns),
            color=command_colour(row.command),
            alpha=0.13,
            lw=0,
        )
    for gap in data.timeline.gaps:
        ax.axvspan(
            as_seconds(data, gap.after_t_ns + gap.period_ns),
            as_seconds(data, gap.before_t_ns),
            facecolor="none",
            edgecolor="#555555",
            hatch="////",
            lw=0,
        )
    ax.axvline(as_seconds(data, data.explanation.t_ns), color=MARKED, lw=1.2, ls="-")


def command_legend(fig: Figure, data: ReportData, extra: Sequence[Artist] = ()) -> None:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    commands = dict.fromkeys(row.command for row in data.timeline.rows)
    handles: list[Artist] = [
        Patch(color=command_colour(c), alpha=0.35, label=c or "no action") for c in commands
    ]
    handles.append(Line2D([], [], color=MARKED, lw=1.2, label="decision explained"))
    if data.timeline.gaps:
        handles.append(
            Patch(facecolor="none", edgecolor="#555555", hatch="////", label="gap (no seal)")
        )
    handles += extra
    fig.legend(
        handles=handles, loc="outside upper center", ncols=min(len(handles), 5), frameon=False
    )
