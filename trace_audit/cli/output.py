"""Where a command's output goes: stdout as JSON or as a document, stderr for warnings and
progress.

``emit`` is the one choice between "JSON for scripts" and "a document for people" (rich on
a terminal, plain text with ``--plain`` or when stdout is not a terminal); ``console``
makes the rich console every document is drawn on; ``setup_logging`` turns library
warnings into one stderr line each. The heavy imports (rich, json, logging) happen inside
the functions: ``--help`` needs none of them.
"""

from __future__ import annotations

import os
import shutil
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, TypeAlias, TypeVar

from trace_audit.cli.doc import Doc
from trace_audit.cli.render import draw_rich, render_plain

if TYPE_CHECKING:  # rich is imported where a document is drawn: ``--help`` needs none of it
    from rich.console import Console
    from rich.progress import Progress

    from trace_audit.selection import PerRobot

__all__ = [
    "JsonValue",
    "console",
    "console_width",
    "emit",
    "per_robot_value",
    "print_json",
    "progress_bar",
    "setup_logging",
    "show",
    "use_plain",
]

R = TypeVar("R")

JsonValue: TypeAlias = "str | int | float | bool | list[JsonValue] | dict[str, JsonValue] | None"
"""Plain JSON data, as a command builds the JSON it prints when that is not a result itself."""


def print_json(value: object) -> None:
    """Write ``value`` (pydantic model, dataclass tree or plain data) as JSON on stdout.

    ``object``: ``to_jsonable`` takes any value (what it does not convert, ``json`` writes or
    refuses)."""
    import json  # here, not at the top: start-up (``--help``) does not need it

    from trace_audit.jsonout import to_jsonable

    sys.stdout.write(json.dumps(to_jsonable(value), indent=2, ensure_ascii=False) + "\n")


def console(plain: bool = False) -> Console:
    """A rich console; plain (no colour, ASCII boxes) when asked or when stdout is not a tty."""
    from rich.console import Console

    if plain:
        # No escape codes at all (colour or bold): logs, CI and files read it as text.
        return Console(
            color_system=None,
            no_color=True,  # renderers read this to choose ASCII boxes
            highlight=False,
            emoji=False,
            soft_wrap=False,
            width=100,
        )
    return Console(highlight=False)


def console_width(plain: bool) -> int:
    """The width a document of console blocks is drawn at: what ``console(plain)`` has."""
    return console(plain).width


def use_plain(plain: bool) -> bool:
    """Plain text when asked, or when stdout is not a terminal."""
    return plain or not sys.stdout.isatty()


def _width() -> int:
    columns = os.environ.get("COLUMNS", "")
    if columns.isdigit() and int(columns) >= 40:
        return int(columns)
    return max(40, shutil.get_terminal_size((80, 24)).columns)


def show(doc: Doc, *, plain: bool) -> None:
    """Print a document on stdout: the one choice of its layout.

    Flow blocks only: rich on a terminal, plain text otherwise (or when asked), at the
    terminal's width (80 columns when it is unknown). With console blocks
    (``Doc.console_layout``): rich either way, without colour and with ASCII boxes when
    plain."""
    if doc.console_layout:
        draw_rich(doc, console(plain))
    elif use_plain(plain):
        sys.stdout.write(render_plain(doc, _width()))
    else:
        from rich.console import Console

        draw_rich(doc, Console(highlight=False, emoji=False))


def emit(
    result: R,
    to_doc: Callable[[R], Doc],
    *,
    json_out: bool,
    plain: bool,
    to_json: Callable[[R], object] | None = None,
) -> None:
    """A command's output: ``result`` as JSON for scripts (``to_json(result)`` when the JSON
    is not the result itself), or its document for people."""
    if json_out:
        print_json(result if to_json is None else to_json(result))
    else:
        show(to_doc(result), plain=plain)


def emit_per_robot(
    path: str,
    answers: Sequence[R],
    to_doc: Callable[[R], Doc],
    *,
    json_out: bool,
    plain: bool,
) -> None:
    """A question's answers for each robot of a log (``selection.per_robot``): one answer
    printed as on a one-robot log; several as one document, robot after robot, or as
    ``{"path": ..., "robots": [...]}`` (``selection.PerRobot``)."""
    if len(answers) == 1:
        emit(answers[0], to_doc, json_out=json_out, plain=plain)
        return
    from trace_audit.selection import PerRobot

    def each(fleet: PerRobot[R]) -> Doc:
        return Doc([block for answer in fleet.robots for block in to_doc(answer).blocks])

    emit(PerRobot(path, tuple(answers)), each, json_out=json_out, plain=plain)


def per_robot_value(path: str, answers: Sequence[R]) -> R | PerRobot[R]:
    """What ``emit_per_robot`` prints as JSON: the one answer, or every robot's
    (``selection.PerRobot``); the assistant's answers carry the same."""
    if len(answers) == 1:
        return answers[0]
    from trace_audit.selection import PerRobot

    return PerRobot(path, tuple(answers))


_HANDLER_NAME = "trace-audit stderr line"
_SAID_AT_MOST = 10_000
"""Distinct warning lines remembered to print each once (past this, repeats print again)."""


def setup_logging() -> None:
    """Library warnings (e.g. a recovered segment) as one ``trace-audit: warning:`` line."""
    import logging  # here, not at the top: ``--help`` never logs (start-up budget)

    class StderrLine(logging.Handler):
        """One ``trace-audit: warning: ...`` line on whatever ``sys.stderr`` is at the time,
        each line once: a command that opens a segment twice (verify, then the witness
        comparison) says once that it was recovered."""

        def __init__(self, level: int) -> None:
            super().__init__(level)
            self.said: set[str] = set()

        def emit(self, record: logging.LogRecord) -> None:
            line = f"trace-audit: {record.levelname.lower()}: {record.getMessage()}\n"
            if line in self.said:
                return
            if len(self.said) < _SAID_AT_MOST:
                self.said.add(line)
            try:
                sys.stderr.write(line)
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
def progress_bar(description: str, *, visible: bool = True) -> Iterator[Progress]:
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
