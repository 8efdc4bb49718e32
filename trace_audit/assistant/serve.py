"""``trace-audit mcp``: the MCP server built and run, over stdio or streamable HTTP on
loopback."""

from __future__ import annotations

import ipaddress
from collections.abc import Sequence
from pathlib import Path

from mcp.server.mcpserver import MCPServer

from trace_audit.assistant.integrity import VerifyKeys
from trace_audit.assistant.roots import Roots
from trace_audit.assistant.server import Assistant
from trace_audit.assistant.tools import INSTRUCTIONS, tools_of
from trace_runtime.errors import UsageError

__all__ = ["DEFAULT_TIMEOUT_S", "build", "loopback", "serve"]

DEFAULT_TIMEOUT_S = 60.0
"""A call's time: past it the question's worker is killed and the call is an error."""


def build(
    roots: Sequence[str | Path],
    index: Path | None,
    timeout_s: float,
    keys: VerifyKeys | None = None,
) -> tuple[MCPServer, Assistant]:
    """The server and its state over ``roots`` (and ``index``, which adds find and query;
    ``keys``, which every verify checks signatures with)."""
    if index is not None and not index.is_dir():
        raise UsageError(f"--index {index}: not a folder")
    if timeout_s <= 0:
        raise UsageError("--timeout must be above 0")
    assistant = Assistant(Roots.of(roots), index.resolve() if index else None, timeout_s, keys)
    server: MCPServer = MCPServer(
        "trace-audit",
        instructions=INSTRUCTIONS,
        log_level="WARNING",  # stderr stays for the one-line problems, not each request
        tools=tools_of(assistant),
    )
    return server, assistant


def loopback(address: str) -> tuple[str, int]:
    """``HOST:PORT`` for ``--http``, refused (``UsageError``) unless HOST is a loopback
    address: the server answers whoever connects, with no authentication."""
    host, sep, port = address.rpartition(":")
    host = host.strip("[]")
    if not sep or not port.isdigit() or not 0 < int(port) < 65536:
        raise UsageError(f"--http {address}: give 127.0.0.1:PORT")
    try:
        is_loopback = host == "localhost" or ipaddress.ip_address(host).is_loopback
    except ValueError:
        is_loopback = False
    if not is_loopback:
        raise UsageError(
            f"--http {address}: only a loopback address (127.0.0.1, ::1) is served; the "
            "server has no authentication"
        )
    return host, int(port)


def serve(
    roots: Sequence[str | Path],
    *,
    index: Path | None = None,
    http: str | None = None,
    timeout_s: float = DEFAULT_TIMEOUT_S,
    key: Path | None = None,
    witness_key: str | None = None,
) -> None:
    """Run the server until its client leaves (stdio) or it is interrupted (HTTP)."""
    where = loopback(http) if http is not None else None
    keys = VerifyKeys.checked(key, witness_key)
    server, assistant = build(roots, index, timeout_s, keys)
    assistant.worker.start()
    try:
        if where is None:
            server.run("stdio")
        else:
            server.run("streamable-http", host=where[0], port=where[1])
    finally:
        assistant.worker.close()
