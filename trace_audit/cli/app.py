"""The ``trace-audit`` typer app, its shared options, and the one place errors become exit codes.

Exit codes (documented in the README and in ``--help``):
  0 ok · 1 findings (verify failed, a metric under its threshold) · 2 usage (bad option,
  t outside the log, unknown action) · 3 unreadable input (missing, not MCAP, truncated,
  not a TRACE log, empty).
"""

from __future__ import annotations

import copy
import re
import sys
from collections.abc import Callable, Sequence
from typing import Annotated, Any, NoReturn, TypeVar

import typer
from typer.core import TyperCommand, TyperGroup
from typer.main import get_group
from typer.models import CommandFunctionType, CommandInfo

from trace_runtime.errors import TimeOutOfRangeError, TraceError, UsageError

T = TypeVar("T")

EXIT_OK = 0
EXIT_FINDINGS = 1
EXIT_USAGE = 2
EXIT_UNREADABLE = 3


# Rich markup written in help texts ("[bold]Examples[/bold]:"): the help is drawn by click's
# plain formatter (below), so the tags are taken out rather than printed. Only style tags:
# "[0, 1]" or "[default: 600]" are text.
_MARKUP_TAG = re.compile(r"\[/?(?:bold|italic|dim|underline|b|i|u)\]|\[/\]")


def _plain(text: str | None) -> str | None:
    return None if text is None else _MARKUP_TAG.sub("", text)


class _Group(TyperGroup):
    """typer's group, with a ``--help`` flag that starts as ``False`` rather than unset.

    typer (0.29) builds a pydantic ``TypeAdapter`` to coerce every parameter that has no
    value yet, the group's own ``--help`` among them, so ``trace-audit COMMAND --help``
    imported pydantic (~60 ms) before it printed a word; a ``bool`` is left alone."""

    def __init__(self, *args: Any, help: str | None = None, **kwargs: Any) -> None:
        super().__init__(*args, help=_plain(help), **kwargs)

    def get_help_option(self, ctx: Any) -> Any:
        option = super().get_help_option(ctx)
        if option is not None and option.default is None:
            option.default = False
        return option


class _Command(TyperCommand):
    """A command whose help text may carry rich markup; click's formatter prints it plain.

    The command list shows a command's whole first paragraph (click would cut it at ~45
    characters with "..."), as typer's rich help did."""

    def __init__(
        self,
        *args: Any,
        help: str | None = None,
        short_help: str | None = None,
        **kwargs: Any,
    ) -> None:
        help = _plain(help)
        if short_help is None and help:
            short_help = " ".join(help.strip().split("\n\n")[0].split())
        super().__init__(*args, help=help, short_help=short_help, **kwargs)

    def collect_usage_pieces(self, ctx: Any) -> list[str]:
        # "explain [OPTIONS] LOG", as click and every Unix tool write it; typer 0.29 writes
        # a required argument as "{log}", which reads like a template placeholder.
        pieces = [self.options_metavar] if self.options_metavar else []
        for param in self.get_params(ctx):
            if param.param_type_name == "argument":
                name = _argument_name(param)
                pieces.append(name if param.required else f"[{name}]")
        return pieces

    def format_options(self, ctx: Any, formatter: Any) -> None:
        # typer 0.29 names a value by its Python type ("--evidence <list[Path]>", "log
        # <path>"); the usage line's names ("LOG", "--evidence PATH") read as click's do.
        sections: dict[str, list[tuple[str, str]]] = {"argument": [], "option": []}
        for param in self.get_params(ctx):
            record = param.get_help_record(ctx)
            if record is None or param.param_type_name not in sections:
                continue
            first, text = record
            if param.param_type_name == "argument":
                first = _argument_name(param)
            else:
                first = _VALUE_TYPE.sub(lambda m: _VALUE_WORDS.get(m[1], m[1].upper()), first)
            sections[param.param_type_name].append((first, text))
        for title, kind in (("Arguments", "argument"), ("Options", "option")):
            if sections[kind]:
                with formatter.section(title):
                    formatter.write_dl(sections[kind])


_VALUE_TYPE = re.compile(r"<([^<>]+)>")
_VALUE_WORDS = {
    "str": "TEXT",
    "list[str]": "TEXT",
    "path": "PATH",
    "list[Path]": "PATH",
    "int": "INTEGER",
    "int range": "INTEGER",
    "float": "NUMBER",
    "float range": "NUMBER",
}
"""How an option's value is named in help, by the type name typer gives it."""


def _argument_name(param: Any) -> str:
    name = str(param.metavar or param.name or "ARG").upper()
    return name + "..." if param.nargs != 1 else name


class _App(typer.Typer):
    """The typer app, whose commands are ``_Command`` unless one asks for another class.

    A command module registers as before (``@app.command("name", help=...)`` in a module
    imported by ``trace_audit/cli/__init__.py``); nothing in it has to change."""

    def command(
        self, name: str | None = None, *, cls: type[TyperCommand] | None = None, **kwargs: Any
    ) -> Callable[[CommandFunctionType], CommandFunctionType]:
        return super().command(name, cls=cls or _Command, **kwargs)

    def runner_for(self, args: Sequence[str]) -> Callable[..., Any]:
        """What runs this command line: when it names a command first, a group holding that
        command alone; else the whole app.

        typer builds every registered command (the signature and type hints of its function,
        ~1.3 ms each, ~20 ms for all) before it reads the arguments, though one runs. A
        command's parsing, errors and help name no other command, so they come out the same;
        anything else (no command, ``--help``, an unknown or misspelt name) meets them all."""
        name = args[0] if args else None
        if self.registered_groups or self.registered_callback:
            return self
        if list(args) in ([], ["--help"]):
            return get_group(self._listing())
        chosen = [info for info in self.registered_commands if info.name == name]
        if len(chosen) != 1:
            return self
        alone = copy.copy(self)
        alone.registered_commands = chosen
        # As a group, as the whole app is: typer would run an app of one command as that
        # command (its usage line would lose the command's name).
        return get_group(alone)

    def _listing(self) -> _App:
        """The app as its own help lists it: each command's name and help, none of its
        parameters (the list shows no parameter; building them all is most of the time
        ``trace-audit --help`` took)."""
        listing = copy.copy(self)
        listing.registered_commands = [_without_parameters(i) for i in self.registered_commands]
        return listing


def _without_parameters(info: CommandInfo) -> CommandInfo:
    shown = copy.copy(info)
    # typer takes a command's help from its function's docstring when none was given
    shown.help = info.help if info.help is not None else getattr(info.callback, "__doc__", None)
    shown.callback = _no_parameters
    return shown


def _no_parameters() -> None:
    pass


# The help is drawn by click's plain formatter (``rich_markup_mode=None``), not typer's rich
# panels: typer's rich help imports rich, markdown-it and pygments (~90 ms), which put every
# ``--help`` at 7x a bare interpreter against a budget of 4x (docs/performance.md, CLI start-up).
app = _App(
    name="trace-audit",
    cls=_Group,
    help=(
        "Investigate TRACE robot decision logs: explain a decision, find why the robot "
        "stopped, measure auditability, verify integrity, compact storage tiers.\n\n"
        "Exit codes: 0 ok, 1 findings, 2 usage error, 3 unreadable input."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    # As wide as the terminal up to 100 columns (click's default stops at 80); commands inherit it.
    context_settings={"max_content_width": 100},
)

JsonOption = Annotated[bool, typer.Option("--json", help="Print machine-readable JSON on stdout.")]
PlainOption = Annotated[
    bool, typer.Option("--plain", help="No colour or box drawing (for logs and CI).")
]


def help_text(text: str) -> str:
    """Help with each prose paragraph on one line, so typer re-wraps it to the terminal;
    indented paragraphs (the examples) keep their lines."""
    return "\n\n".join(
        para if para.startswith("  ") else " ".join(line.strip() for line in para.splitlines())
        for para in text.strip().split("\n\n")
    )


def fail(message: str, code: int) -> NoReturn:
    """Print one line on stderr and exit with ``code``."""
    sys.stderr.write(f"trace-audit: {message}\n")
    raise typer.Exit(code)


def exit_code_for(err: TraceError) -> int:
    """The documented exit code of an error raised by the library: the one place they are
    mapped. Every error the library raises on purpose is a ``TraceError`` (third-party
    errors are wrapped where they arise), so nothing here knows zstd, struct or orjson."""
    if isinstance(err, TimeOutOfRangeError | UsageError):
        return EXIT_USAGE
    # LogReadError (and its LogLimitError, PayloadError, NotTraceLogError) and every other
    # TraceError describe the input: unreadable, not a TRACE log, over a read limit.
    return EXIT_UNREADABLE


def guarded(call: Callable[[], T]) -> T:
    """Run a library call; turn its ``TraceError`` into one stderr line and an exit code.

    Library warnings (a recovered segment, a skipped damaged chunk) go to stderr as one
    ``trace-audit: warning:`` line each, whichever command runs."""
    from trace_audit.cli.render import setup_logging

    setup_logging()
    try:
        return call()
    except TraceError as err:
        fail(str(err), exit_code_for(err))
    except KeyboardInterrupt:
        fail("interrupted", 130)


def print_json(value: Any) -> None:
    """Write ``value`` (pydantic model, dataclass tree or plain data) as JSON on stdout."""
    import json  # here, not at the top: start-up (``--help``) does not need it

    from trace_audit.jsonout import to_jsonable

    sys.stdout.write(json.dumps(to_jsonable(value), indent=2, ensure_ascii=False) + "\n")


def console(plain: bool = False) -> Any:
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
