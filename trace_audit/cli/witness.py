"""``trace-audit witness``: a sub-command group of its own (``serve``, ``push``, ``vkey``),
each with its own options and ``--help``. Each parses its arguments and calls one library
function: ``trace_audit.witness.server.serve``, ``trace_audit.witness.push.push_root``,
``trace_audit.witness.vkey.verifier_key_of``."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from trace_audit.cli.app import EXIT_FINDINGS, app, guarded, help_text
from trace_audit.cli.doc import Column, Doc, Seg
from trace_audit.cli.options import JsonOption, PlainOption, robot_option
from trace_audit.cli.output import emit, setup_logging
from trace_audit.cli.typer_compat import App, Group

if TYPE_CHECKING:
    from trace_audit.witness.push import PushReport

__all__ = ["witness_app"]

_WITNESS_HELP = """Run a witness, submit a log's checkpoints to one, or print a verifier key.

A witness (C2SP tlog-witness) cosigns each robot's signed checkpoints as it sees them, so a
log that later loses its newest cycles, or is rewritten, no longer matches what it cosigned
(verify --witness). See docs/witness.md.

[bold]Examples[/bold]:

  trace-audit witness vkey --key amr-7.pub --origin trace.local/amr-7

  trace-audit witness serve --state st --key w.key --log VKEY

  trace-audit witness push /data/amr-7 --witness http://witness:7380
"""

_SERVE_HELP = """Run a C2SP tlog-witness on --listen HOST:PORT.

POST /add-checkpoint cosigns a robot's checkpoint when its note verifies under the robot's
key (--log, one per robot) and the consistency proof from the size it last cosigned
verifies (404 unknown origin, 403 bad signature, 409 conflict with its size, 422 bad
proof); GET /checkpoint/ORIGIN answers the latest cosigned note. State (SQLite, fsynced)
in --state DIR; its key: --key (keygen). Stops on SIGINT/SIGTERM (exit 0).

With --tiles DIR (a folder trace-audit publish writes), GET /tiles/ROBOT/checkpoint and
/tiles/ROBOT/tile/... serve it read-only: only the names of a published tree, never a file
outside DIR or through a link.

[bold]Examples[/bold]:

  trace-audit witness serve --state st --key w.key --log VKEY

  trace-audit witness serve --state st --key w.key --log VKEY --tiles out
"""

_PUSH_HELP = """Submit a log root's signed checkpoints to a witness (a robot that was offline).

The checkpoints go oldest first, from the size the witness last cosigned, to --witness URL;
each cosignature is stored in ROOT/witness/ROBOT.jsonl. Exit 1 when any robot met a problem
(the witness unreachable, a checkpoint refused).

[bold]Examples[/bold]:

  trace-audit witness push /data/amr-7 --witness http://witness:7380
"""

_VKEY_HELP = """Print the C2SP verifier key of a public key under a key name.

A robot's (for witness serve --log: the name is its checkpoints' origin) or, with
--cosignature, a witness's (for verify --witness-key and verify-proof --witness-key).

[bold]Examples[/bold]:

  trace-audit witness vkey --key amr-7.pub --origin trace.local/amr-7

  trace-audit witness vkey --key w.pub --origin witness.example --cosignature
"""

witness_app = App(
    name="witness",
    cls=Group,
    help=help_text(_WITNESS_HELP),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)
app.add_typer(witness_app, name="witness")


@witness_app.command("serve", help=help_text(_SERVE_HELP))
def serve_command(
    *,
    state: Annotated[
        Path,
        typer.Option(
            "--state", help="The witness's state folder (SQLite, fsynced).", show_default=False
        ),
    ],
    key: Annotated[
        str,
        typer.Option(
            "--key",
            metavar="PATH|URI",
            help="The witness's private key (trace-audit keygen): a key file or a pkcs11: URI "
            "of a key in a token.",
            show_default=False,
        ),
    ],
    log: Annotated[
        list[str] | None,
        typer.Option(
            "--log",
            help="A robot's verifier key (witness vkey): the witness cosigns its checkpoints. "
            "At least one; repeat for each robot, and for a robot's next key when it rotates "
            "keys (both keys of one origin are accepted).",
            show_default=False,
        ),
    ] = None,
    listen: Annotated[
        str, typer.Option("--listen", help="The address to listen on, HOST:PORT.")
    ] = "127.0.0.1:7380",
    name: Annotated[
        str, typer.Option("--name", help="The witness's key name, in its cosignatures.")
    ] = "trace.local/witness",
    tiles: Annotated[
        Path | None,
        typer.Option(
            "--tiles",
            help="A folder publish --out wrote: served read-only under /tiles/.",
            show_default=False,
        ),
    ] = None,
) -> None:
    from trace_audit.witness.server import serve

    setup_logging()
    raise typer.Exit(guarded(lambda: serve(listen, state, key, log or (), name=name, tiles=tiles)))


@witness_app.command("push", help=help_text(_PUSH_HELP))
def push_command(
    root: Annotated[Path, typer.Argument(help="The log root.", show_default=False)],
    *,
    witness: Annotated[
        str, typer.Option("--witness", help="The witness's URL.", show_default=False)
    ],
    robot: Annotated[
        list[str] | None, robot_option("Only this robot's checkpoints (repeat for several).")
    ] = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    from trace_audit.witness.push import push_root

    setup_logging()
    report = guarded(lambda: push_root(root, witness, robots=robot or ()))
    emit(report, _push_doc, json_out=json_out, plain=plain)
    if not report.ok:
        raise typer.Exit(EXIT_FINDINGS)


def _push_doc(r: PushReport) -> Doc:
    doc = Doc()
    doc.title(
        [
            f"Pushed {r.root} to {r.witness}: ",
            Seg("ok", "bold green") if r.ok else Seg("problems", "bold red"),
        ]
    )
    doc.table(
        [Column("robot"), Column("origin"), Column("checkpoints", "right"),
         Column("cosigned", "right"), Column("witness size", "right"),
         Column("problems", wrap=True)],
        [
            [p.robot_id, p.origin, str(p.checkpoints), str(p.cosigned),
             "-" if p.witness_size is None else str(p.witness_size), "; ".join(p.problems)]
            for p in r.robots
        ],
    )  # fmt: skip
    return doc


@witness_app.command("vkey", help=help_text(_VKEY_HELP))
def vkey_command(
    *,
    key: Annotated[
        Path,
        typer.Option(
            "--key",
            help="An Ed25519 public key (PEM, OpenSSH or 32 raw bytes).",
            show_default=False,
        ),
    ],
    origin: Annotated[
        str,
        typer.Option(
            "--origin",
            help="The key name: a robot's checkpoint origin (trace.local/ROBOT), or a "
            "witness's name (its serve --name).",
            show_default=False,
        ),
    ],
    cosignature: Annotated[
        bool,
        typer.Option(
            "--cosignature",
            help="The key of a witness's (timestamped) cosignatures, not a robot's signatures.",
        ),
    ] = False,
) -> None:
    from trace_audit.witness.vkey import verifier_key_of

    setup_logging()
    named = guarded(lambda: verifier_key_of(key, origin, cosignature=cosignature))
    # The key alone, as one unwrapped line: scripts take it with $(...).
    sys.stdout.write(named.vkey + "\n")
