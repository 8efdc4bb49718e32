"""``trace-audit tail``: each decision change with its reason as it is written.

Parses its arguments, iterates ``trace_audit.tail.tail`` and prints each event as it comes:
a line for people, or one JSON object a line with ``--json`` (like ``journalctl -o json``).
Ctrl-C (SIGINT) or SIGTERM ends a followed tail cleanly, with exit code 0.
"""

from __future__ import annotations

import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from trace_audit.cli.app import app, guarded, help_text
from trace_audit.cli.options import JsonOption, PlainOption, RobotsOption

if TYPE_CHECKING:  # the library is imported inside the command: start-up stays light
    from collections.abc import Sequence
    from types import FrameType

    from trace_audit.cli.output import JsonValue
    from trace_audit.foxglove.live import LiveView
    from trace_audit.tail import TailEvent

__all__ = ["event_json", "event_line", "tail_command"]

_TAIL_HELP = """Each decision change with its reason, as the robot writes it.

Reads each robot's newest segment of a log root (the one being written) and prints every
cycle whose command differs from the robot's previous cycle's: its time, the change, the
leading factor and the rationale. A segment being written is shown as live (its writer holds
its lock), one whose writer died as recovered. --follow keeps watching, following the logger
to its next segment when it rotates, until Ctrl-C or SIGTERM (exit 0), and waits for a root
or robot that has not appeared yet (like tail -F); without it, tail prints the changes
written so far and exits. --json prints one JSON object a line. Each poll reads only what
the logger appended since the last one.

--foxglove also serves the robot live to Foxglove (the export's channels: scene, pose,
decision changes, factor and actuator plots, the /trace and sensor channels) over the
Foxglove WebSocket protocol, on 127.0.0.1 (--host) and port 8765 (--port; 0: any free port),
and prints the address on stderr; in Foxglove, Open connection, Foxglove WebSocket, that
address. It implies --follow and shows one robot (--robot, or the root's only one); it needs
the look extra. docs/foxglove.md.

[bold]Examples[/bold]:

  trace-audit tail logs/ --follow

  trace-audit tail logs/ --robot amr-7 --follow --json

  trace-audit tail logs/ --robot amr-7 --foxglove --port 8765
"""


@app.command("tail", help=help_text(_TAIL_HELP))
def tail_command(  # noqa: PLR0917 - typer maps each parameter to an option
    root: Annotated[
        Path,
        typer.Argument(help="A log root (the folder a robot logs into).", show_default=False),
    ],
    follow: Annotated[
        bool, typer.Option("--follow", "-f", help="Keep watching for new changes until Ctrl-C.")
    ] = False,
    robot: RobotsOption = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,  # the lines are plain text already; accepted like elsewhere
    foxglove: Annotated[
        bool,
        typer.Option(
            "--foxglove",
            help="Also serve the robot live to Foxglove over WebSocket (implies --follow).",
        ),
    ] = False,
    host: Annotated[
        str, typer.Option("--host", help="--foxglove: the address to listen on.")
    ] = "127.0.0.1",
    port: Annotated[
        int,
        typer.Option("--port", min=0, max=65535, help="--foxglove: the port (0: any free one)."),
    ] = 8765,
) -> None:
    live = (host, port) if foxglove else None
    guarded(lambda: _run(root, robot or (), follow=follow, json_out=json_out, live=live))


def _run(
    root: Path,
    robots: Sequence[str],
    *,
    follow: bool,
    json_out: bool,
    live: tuple[str, int] | None = None,
) -> None:
    """Print each event as it comes; SIGINT or SIGTERM sets the stop flag the poll waits on, so the
    loop ends between reads, never with a traceback. ``live``: (host, port) of the Foxglove
    view to serve while following."""
    import threading

    from trace_audit.tail import tail

    view = None
    if live is not None:
        view = _serve(root, tuple(robots), *live)
        follow = True
    stop = threading.Event()

    def interrupted(_signum: int, _frame: FrameType | None) -> None:
        stop.set()

    # A followed tail runs under a service manager as often as in a terminal: SIGTERM is
    # its Ctrl-C, and both end it between reads with exit 0.
    previous = {sig: signal.signal(sig, interrupted) for sig in (signal.SIGINT, signal.SIGTERM)}
    on_cycle = view.cycle if view is not None else None
    if follow and not root.exists():
        sys.stderr.write(f"trace-audit: {root} does not exist yet; waiting for it (Ctrl-C stops)\n")
        sys.stderr.flush()
    try:
        for event in tail(root, robots=robots, follow=follow, stop=stop, on_cycle=on_cycle):
            if stop.is_set():
                break
            _print(_json_line(event_json(event)) if json_out else event_line(event))
    except BrokenPipeError:  # `tail ... | head`: the reader went away, nothing more to say
        sys.stderr.close()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if view is not None:
            view.close()


def _serve(root: Path, robots: tuple[str, ...], host: str, port: int) -> LiveView:
    """Start the live Foxglove view and say on stderr where it listens (a root that does not
    exist yet is waited for by tail, its first robot shown)."""
    from trace_audit.foxglove.live import LiveView, live_robot

    robot = live_robot(root, robots) if root.is_dir() else None
    view = LiveView(robot=robot, host=host, port=port)
    shown = robot or "the first robot to log"
    sys.stderr.write(
        f"trace-audit: Foxglove live view of {shown} on {view.url} "
        "(Foxglove: Open connection, Foxglove WebSocket)\n"
    )
    sys.stderr.flush()
    return view


def _print(line: str) -> None:
    sys.stdout.write(line + "\n")
    sys.stdout.flush()


def _json_line(data: dict[str, JsonValue]) -> str:
    import orjson

    return orjson.dumps(data).decode()


def event_line(event: TailEvent) -> str:
    """One event as a line for people."""
    from trace_audit.cli.doc import fmt_duration
    from trace_audit.tail import LogGap, SegmentState

    if isinstance(event, LogGap):
        return (
            f"{event.shown_t}  {event.robot}  cycle {event.cycle}  GAP of "
            f"{fmt_duration(event.gap_ns)} after cycle {event.after_cycle}: {event.not_logged}"
        )
    if isinstance(event, SegmentState):
        said = {
            "live": "live (being written)",
            "finished": "finished",
            "recovered": "recovered (no footer, its writer is gone)",
        }[event.status.value]
        return f"-- {event.robot}: {event.segment} {said}"
    change = f"{event.previous} -> {event.command}" if event.previous else f"{event.command}"
    parts = [f"{event.shown_t}  {event.robot}  cycle {event.cycle}  {change}"]
    if event.leading is not None:
        parts.append(f"leading {event.leading.label} = {event.leading.shown}")
    if event.rationale:
        parts.append(f"because {event.rationale}")
    return "; ".join(parts)


def event_json(event: TailEvent) -> dict[str, JsonValue]:
    """One event as JSON data; a change carries its time as shown (``t``) beside ``t_ns``."""
    from trace_audit.jsonout import to_jsonable
    from trace_audit.tail import DecisionChange, LogGap

    data: dict[str, JsonValue] = to_jsonable(event)
    if isinstance(event, DecisionChange | LogGap):
        del data["clock"]
        data["t"] = event.shown_t
    if isinstance(event, LogGap):
        data["not_logged"] = event.not_logged
    return data
