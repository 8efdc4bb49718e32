"""``trace-audit publish``: each robot's tree as C2SP tlog-tiles in a folder any static web
server serves. Parses its arguments and calls one library function
(``trace_audit.publish.publish_root``)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from trace_audit.cli.app import EXIT_FINDINGS, app, guarded, help_text
from trace_audit.cli.doc import Column, Doc, Seg
from trace_audit.cli.options import JsonOption, PlainOption, key_option, robot_option
from trace_audit.cli.output import emit, progress_bar, setup_logging

if TYPE_CHECKING:
    from trace_audit.publish import PublishReport

__all__ = ["publish_command"]

_HELP = """Publish each robot's tree as C2SP tlog-tiles, for any transparency-log client.

Writes OUT/ROBOT/checkpoint (the robot's newest signed checkpoint note, as the log carries
it), the hash tiles OUT/ROBOT/tile/L/N and the entry bundles OUT/ROBOT/tile/entries/N (each
entry a seal's stored bytes), up to that checkpoint's tree size. Run it again after the
robot logged more: only new tiles and the checkpoint are written; published tiles are
compared, never rewritten. Serve OUT with any static web server (docs/integrity.md,
"Publishing a fleet's logs"). Exit 1 when a robot's seals do not make the tree its signed
checkpoints state, or its published tiles differ from the log; 2 when a robot's log is not
signed (nothing would vouch for its tiles).

With --key (the robot's public key as verify takes it; repeat for a fleet's keys), the
checkpoint note must verify under one of the keys, or under a key the robot's chain announced
from it (key rotation, followed as verify follows it: the robot's first key is enough), or
nothing is published for that robot (exit 1); without it, signatures are not checked here
(the auditor checks them). When the root's witness store holds the same checkpoint cosigned
(witness push), that note is served, with the witness's cosignature lines.

[bold]Examples[/bold]:

  trace-audit publish /data/fleet --out /srv/tlog --key keys/amr-7.pub

  python -m http.server -d /srv/tlog 8080
"""


@app.command("publish", help=help_text(_HELP))
def publish_command(
    root: Annotated[Path, typer.Argument(help="A log root or segment.", show_default=False)],
    *,
    out: Annotated[
        Path, typer.Option("--out", help="The folder to publish into.", show_default=False)
    ],
    robot: Annotated[
        list[str] | None, robot_option("Only this robot's tree (repeat for several).")
    ] = None,
    key: Annotated[
        list[Path] | None,
        key_option(
            "A robot's Ed25519 public key (PEM, OpenSSH or 32 raw bytes): each robot's "
            "checkpoint note must verify under one of them. Repeat for several."
        ),
    ] = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    from trace_audit.publish import publish_root
    from trace_runtime.tlog.keys import load_public_key

    setup_logging()
    keys = guarded(lambda: [load_public_key(k) for k in key or ()])
    if json_out or plain or not sys.stderr.isatty():
        report = guarded(lambda: publish_root(root, out, robots=robot or (), keys=keys))
    else:
        with progress_bar("publishing seals") as bar:
            task = bar.task_ids[0]

            def progress(name: str, done: int, total: int) -> None:
                bar.update(task, description=f"publishing {name}", completed=done, total=total)

            report = guarded(
                lambda: publish_root(root, out, robots=robot or (), keys=keys, progress=progress)
            )
    emit(report, _publish_doc, json_out=json_out, plain=plain)
    if not report.ok:
        raise typer.Exit(EXIT_FINDINGS)


def _publish_doc(r: PublishReport) -> Doc:
    doc = Doc()
    doc.title(
        [
            f"Published {r.root} to {r.out}: ",
            Seg("ok", "bold green") if r.ok else Seg("problems", "bold red"),
        ]
    )
    doc.fields(
        [
            (
                "signatures",
                f"checked with key {', '.join(k[:16] + '…' for k in r.key_ids)}"
                if r.key_ids
                else Seg("not checked (no --key): the auditor checks them", "yellow"),
            ),
        ]
    )
    doc.table(
        [Column("robot"), Column("origin"), Column("tree size", "right"),
         Column("before", "right"), Column("written", "right"), Column("kept", "right"),
         Column("cosigned by"), Column("problems", wrap=True)],
        [
            [p.robot_id, p.origin, "-" if p.tree_size is None else str(p.tree_size),
             "-" if p.previous_size is None else str(p.previous_size), str(p.written),
             str(p.kept), ", ".join(p.cosigned_by) or "-", "; ".join(p.problems)]
            for p in r.robots
        ],
    )  # fmt: skip
    for p in r.robots:
        if p.announced_keys:
            doc.line(
                f"{p.robot_id}: note checked under the key its chain announced "
                f"({len(p.announced_keys)} rotation(s) from the key given)"
            )
        if p.removed:
            doc.line(f"{p.robot_id}: removed {p.removed} unfinished file(s) a killed run left")
    return doc
