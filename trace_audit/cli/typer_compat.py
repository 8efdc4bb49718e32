"""Where the CLI reaches into typer's internals: every subclass or override of a typer (and
its bundled click) class that shapes help, usage lines or usage errors.

Written against typer 0.29 (the range pinned in ``pyproject.toml``); each override names the
behaviour of that version it replaces. That version carries its own copy of click
(``typer._click``): its classes, not the ``click`` package's, are what the overrides receive.
Nothing else in ``trace_audit/cli`` imports ``typer._click``, ``typer.core``, ``typer.main``,
``typer.models`` or ``typer.exceptions`` (``OptionInfo`` is re-exported for ``options``).
"""

from __future__ import annotations

import copy
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, get_args, get_origin

import typer
from typer._click import Context, HelpFormatter, Parameter
from typer._coercion import RuntimeParam, TypeDescriptor, build_runtime_param
from typer._param_types import coerce_cli_path
from typer.core import TyperCommand, TyperGroup, TyperOption, _TyperParameter
from typer.exceptions import TyperException
from typer.main import get_group, solve_typer_info_defaults
from typer.models import CommandFunctionType, CommandInfo, OptionInfo, TyperInfo

__all__ = [
    "App",
    "Command",
    "Group",
    "OptionInfo",
    "TyperException",
    "help_without_command",
    "usage_error_line",
]

# Rich markup written in help texts ("[bold]Examples[/bold]:"): the help is drawn by click's
# plain formatter (below), so the tags are taken out rather than printed. Only style tags:
# "[0, 1]" or "[default: 600]" are text.
_MARKUP_TAG = re.compile(r"\[/?(?:bold|italic|dim|underline|b|i|u)\]|\[/\]")


def _plain(text: str | None) -> str | None:
    return None if text is None else _MARKUP_TAG.sub("", text)


def _summary(help: str | None) -> str | None:
    """A command's line in a listing: its help's whole first paragraph (click would cut it
    at ~45 characters with "...")."""
    return " ".join(help.strip().split("\n\n")[0].split()) if help else None


class Group(TyperGroup):
    """typer's group, with a ``--help`` flag that starts as ``False`` rather than unset.

    typer (0.29) builds a pydantic ``TypeAdapter`` to coerce every parameter that has no
    value yet, the group's own ``--help`` among them, so ``trace-audit COMMAND --help``
    would import pydantic (~60 ms) before it printed a word; a ``bool`` is left alone."""

    def __init__(
        self,
        *args: Any,
        help: str | None = None,
        short_help: str | None = None,
        **kwargs: Any,
    ) -> None:
        # Any: whatever typer (0.29) builds a group with, passed on to it unread.
        help = _plain(help)
        super().__init__(*args, help=help, short_help=short_help or _summary(help), **kwargs)

    def get_help_option(self, ctx: Context) -> TyperOption | None:
        option = super().get_help_option(ctx)
        if option is not None and option.default is None:
            option.default = False
        return option

    def format_commands(self, ctx: Context, formatter: HelpFormatter) -> None:
        """The commands under "Commands:", in sections by their ``rich_help_panel`` (what a
        user does with them) when they name one: each section in the order its first command
        is listed, its heading at the margin and its commands indented, as ``git help``
        lists its commands. The names are aligned across sections.

        typer 0.29 draws the panels only in its rich help, which this app does not use
        (start-up); its plain help would list every command in one block."""
        shown = [(name, self.get_command(ctx, name)) for name in self.list_commands(ctx)]
        commands = [(name, cmd) for name, cmd in shown if cmd is not None and not cmd.hidden]
        if not any(getattr(cmd, "rich_help_panel", None) for _name, cmd in commands):
            super().format_commands(ctx, formatter)
            return
        width = max(len(name) for name, _cmd in commands)
        limit = formatter.width - 6 - width  # as click's: three times its column spacing
        sections: dict[str, list[tuple[str, str]]] = {}
        for name, cmd in commands:
            rows = sections.setdefault(getattr(cmd, "rich_help_panel", None) or "Other", [])
            rows.append((name.ljust(width), cmd.get_short_help_str(limit)))
        formatter.write_paragraph()
        formatter.write_heading("Commands")
        for title, rows in sections.items():
            with formatter.section(title):
                formatter.write_dl(rows)


class Command(TyperCommand):
    """A command whose help text may carry rich markup; click's formatter prints it plain.

    The command list shows a command's whole first paragraph (click would cut it at ~45
    characters with "..."), as typer's rich help does."""

    def __init__(
        self,
        *args: Any,
        help: str | None = None,
        short_help: str | None = None,
        **kwargs: Any,
    ) -> None:
        # Any: whatever typer (0.29) builds a command with, passed on to it unread.
        help = _plain(help)
        super().__init__(*args, help=help, short_help=short_help or _summary(help), **kwargs)

    def get_params(self, ctx: Context) -> list[Parameter]:
        params = super().get_params(ctx)
        for param in params:  # the help option too: typer coerces its unset value
            _coerce_plainly(param)
        return params

    def collect_usage_pieces(self, ctx: Context) -> list[str]:
        # "explain [OPTIONS] LOG", as click and every Unix tool write it; typer 0.29 writes
        # a required argument as "{log}", which reads like a template placeholder.
        pieces = [self.options_metavar] if self.options_metavar else []
        for param in self.get_params(ctx):
            if param.param_type_name == "argument":
                name = _argument_name(param)
                pieces.append(name if param.required else f"[{name}]")
        return pieces

    def format_options(self, ctx: Context, formatter: HelpFormatter) -> None:
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


def _argument_name(param: Parameter) -> str:
    name = str(param.metavar or param.name or "ARG").upper()
    return name + "..." if param.nargs != 1 else name


class App(typer.Typer):
    """The typer app, whose commands are ``Command`` unless one asks for another class.

    A command module needs nothing beyond ``@app.command("name", help=...)`` in a module
    imported by ``trace_audit/cli/__init__.py``."""

    def command(
        self, name: str | None = None, *, cls: type[TyperCommand] | None = None, **kwargs: Any
    ) -> Callable[[CommandFunctionType], CommandFunctionType]:
        # Any: typer.Typer.command's own keywords, passed on to it unread.
        return super().command(name, cls=cls or Command, **kwargs)

    def runner_for(self, args: Sequence[str]) -> typer.Typer | TyperGroup:
        """What runs this command line: when it names a command (or a sub-command group)
        first, a group holding that one alone; else the whole app.

        typer builds every registered command (the signature and type hints of its function,
        ~1.3 ms each, ~20 ms for all) before it reads the arguments, though one runs. A
        command's parsing, errors and help name no other command, so they come out the same;
        anything else (no command, ``--help``, an unknown or misspelt name) meets them all."""
        name = args[0] if args else None
        if self.registered_callback:
            return self
        if list(args) in ([], ["--help"]):
            return get_group(self._listing())
        commands = [info for info in self.registered_commands if info.name == name]
        groups = [info for info in self.registered_groups if _group_name(info) == name]
        if len(commands) + len(groups) != 1:
            return self
        alone = copy.copy(self)
        alone.registered_commands = commands
        alone.registered_groups = groups
        # As a group, as the whole app is: typer would run an app of one command as that
        # command (its usage line would lose the command's name).
        return get_group(alone)

    def _listing(self) -> App:
        """The app as its own help lists it: each command's (and sub-command group's) name
        and help, none of its parameters or sub-commands (the list shows none; building them
        all is most of the time ``trace-audit --help`` takes)."""
        listing = copy.copy(self)
        listing.registered_commands = [
            *(_without_parameters(i) for i in self.registered_commands),
            *(_as_listed(i) for i in self.registered_groups),
        ]
        listing.registered_groups = []
        return listing


def _group_name(info: TyperInfo) -> str | None:
    """A sub-command group's name: given to ``add_typer``, else its app's own."""
    return solve_typer_info_defaults(info).name


def _as_listed(info: TyperInfo) -> CommandInfo:
    """A sub-command group as the listing shows it: a line like a command's."""
    solved = solve_typer_info_defaults(info)
    return CommandInfo(
        name=solved.name,
        cls=Command,
        help=solved.help,
        rich_help_panel=solved.rich_help_panel,
        callback=_no_parameters,
    )


def _without_parameters(info: CommandInfo) -> CommandInfo:
    shown = copy.copy(info)
    # typer takes a command's help from its function's docstring when none was given
    shown.help = info.help if info.help is not None else getattr(info.callback, "__doc__", None)
    shown.callback = _no_parameters
    return shown


def _no_parameters() -> None:
    pass


def help_without_command(err: TyperException) -> str | None:
    """The help a group prints when run without a sub-command (typer 0.29's click raises it
    as ``NoArgsIsHelpError``, a usage error whose message is the help), for stdout; None
    for any other error."""
    from typer._click.exceptions import NoArgsIsHelpError

    if not isinstance(err, NoArgsIsHelpError):
        return None
    return err.format_message().rstrip("\n") + "\n"


def usage_error_line(err: TyperException, program: str) -> str | None:
    """The one stderr line for a command line's own error (an unknown option, a bad value),
    naming the command's ``--help``; None when there is nothing to say (no arguments at
    all: the help was shown instead)."""
    ctx = getattr(err, "ctx", None)
    command = ctx.command_path if ctx is not None else program
    message = err.format_message() if hasattr(err, "format_message") else str(err)
    if not message.strip():
        return None
    return f"{program}: {message} (see '{command} --help')\n"


@dataclass(frozen=True)
class _PlainParam(RuntimeParam):
    """A parameter's value as typer 0.29 would give it, without pydantic for text and paths.

    typer 0.29 builds a pydantic ``TypeAdapter`` for every parameter of the command that
    runs, set or not, before it reads a value: importing pydantic and building them is
    ~70 ms of every command (a third of an honest ``query``). Text and paths are what its
    adapters make of them (``str``; ``Path`` through typer's own ``coerce_cli_path``, which
    also applies ``exists=`` and the like); anything else (a number, a choice, a parser)
    goes to typer's adapter, built then, so its checks and messages stay typer's."""

    descriptor: TypeDescriptor

    def _coerce_value(self, value: Any, param: Any, ctx: Context) -> Any:
        info, kind = self.parameter_info, self.annotation
        # typer 0.29 types an annotation as ParamSpec-or-type; a list[...] is one at runtime
        many: bool = get_origin(kind) is list  # type: ignore[comparison-overlap]
        item = get_args(kind)[0] if many else kind
        values = value if many and isinstance(value, tuple | list) else (value,)
        if info.parser is None and all(isinstance(v, str) for v in values):
            if item is str:
                return list(values) if many else value
            if item is Path and info.path_type is None:
                paths = [
                    coerce_cli_path(Path(v), info, path_type=Path, param=param, ctx=ctx)
                    for v in values
                ]
                return paths if many else paths[0]
        return build_runtime_param(self.descriptor)._coerce_value(value, param=param, ctx=ctx)


def _coerce_plainly(param: Parameter) -> None:
    """Give a typer parameter ``_PlainParam``'s coercion (a file parameter keeps typer's)."""
    if (
        isinstance(param, _TyperParameter)
        and param._runtime_param is None
        and param.type_descriptor.file_annotation is None
    ):
        described = param.type_descriptor
        param._runtime_param = _PlainParam(
            parameter_info=described.parameter_info,
            annotation=described.annotation,
            descriptor=described,
        )
