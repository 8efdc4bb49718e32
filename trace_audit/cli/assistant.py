"""``trace-audit mcp``: the investigator's questions served to an AI assistant over the
Model Context Protocol (``trace_audit.assistant``; docs/assistant.md)."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Annotated

import typer

from trace_audit.cli.app import app, fail, guarded, help_text
from trace_runtime.errors import EXIT_NOT_INSTALLED

__all__ = ["mcp_command"]

_MCP_HELP = """Serve the logs under the roots to an AI assistant (an MCP client: Claude
Desktop, VS Code, ...) as read-only tools named like the commands: robots, why, explain,
timeline, metrics, verify, check, prove, and with --index find and query.

Every answer carries its integrity (verified, unverified or integrity failed, with the
findings: the log's verify, kept while its files are unchanged) and the trace-audit
command that reproduces it. With --key, verified includes the checkpoints' signatures by
the robot's key (and with --witness-key, what the witness cosigned in the log root's witness
store); without it the answer says signatures were not checked. A tool reads only under the
roots (no '..', no links out, no FIFOs), writes nothing, and each call is bounded in size
(~200 KB of data, cuts said) and time (--timeout). Over stdio by default (the client starts
this command); --http serves streamable HTTP on a loopback address only. Needs the assistant
extra. docs/assistant.md.

[bold]Examples[/bold]:

  trace-audit mcp --root /data/robots

  trace-audit mcp --root /data/amr-7 --root /data/amr-9 --index /data/idx

  trace-audit mcp --root /data/amr-7 --key amr-7.pub --witness-key "$WKEY"

  trace-audit mcp --root /data/robots --http 127.0.0.1:8765
"""


@app.command("mcp", help=help_text(_MCP_HELP))
def mcp_command(
    root: Annotated[
        list[Path],
        typer.Option(
            "--root",
            help="A folder whose logs the tools may read (repeat for several).",
            show_default=False,
        ),
    ],
    *,
    index: Annotated[
        Path | None,
        typer.Option(
            "--index",
            help="A fleet index (trace-audit index): adds the find and query tools.",
            show_default=False,
        ),
    ] = None,
    http: Annotated[
        str | None,
        typer.Option(
            "--http",
            help="Serve streamable HTTP at 127.0.0.1:PORT instead of stdio (loopback only).",
            show_default=False,
        ),
    ] = None,
    timeout: Annotated[
        float, typer.Option("--timeout", help="Seconds a tool call may run before it is stopped.")
    ] = 60.0,
    key: Annotated[
        Path | None,
        typer.Option(
            "--key",
            help="The robot's Ed25519 public key (as verify --key takes it): integrity then "
            "includes the checkpoint signatures (key rotations followed).",
            show_default=False,
        ),
    ] = None,
    witness_key: Annotated[
        str | None,
        typer.Option(
            "--witness-key",
            help="The witness's verifier key (witness vkey --cosignature): integrity then "
            "includes the log root's witness store, each cosignature checked.",
            show_default=False,
        ),
    ] = None,
) -> None:
    if importlib.util.find_spec("mcp") is None:
        fail(
            "the MCP server needs the assistant extra: pip install 'trace-audit[assistant]'",
            EXIT_NOT_INSTALLED,
        )
    from trace_audit.assistant.serve import serve

    guarded(
        lambda: serve(
            root, index=index, http=http, timeout_s=timeout, key=key, witness_key=witness_key
        )
    )
