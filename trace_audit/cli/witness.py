"""trace-audit commands for witnesses and proofs: ``witness serve|push|vkey``, ``prove`` and
``verify-proof``. Each parses its arguments and calls one library function
(``trace_audit.witness.server.serve``, ``trace_audit.witness.push.push_root``,
``trace_audit.proof.make_bundle`` / ``check_bundle``)."""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from trace_audit.cli.app import (
    EXIT_CANNOT_WRITE,
    EXIT_FINDINGS,
    EXIT_USAGE,
    app,
    fail,
    guarded,
    help_text,
)
from trace_audit.cli.doc import Column, Doc, Seg
from trace_audit.cli.options import JsonOption, PlainOption, robot_option
from trace_audit.cli.output import emit, setup_logging

if TYPE_CHECKING:
    from trace_audit.proof import BundleCheck
    from trace_audit.witness.push import PushReport

_WITNESS_HELP = """Run a witness, submit a log's checkpoints to one, or print a verifier key.

serve: a C2SP tlog-witness on --listen HOST:PORT. POST /add-checkpoint cosigns a robot's
checkpoint when its note verifies under the robot's key (--log, one per robot) and the
consistency proof from the size it last cosigned verifies (404 unknown origin, 403 bad
signature, 409 conflict with its size, 422 bad proof); GET /checkpoint/ORIGIN answers the
latest cosigned note. State (SQLite, fsynced) in --state DIR; its key: --key (keygen).
Stops on SIGINT/SIGTERM (exit 0).

push: submit a log root's signed checkpoints (oldest first, from the witness's size) to
--witness URL and store each cosignature in ROOT/witness/ROBOT.jsonl (a robot that was
offline).

vkey: print the C2SP verifier key of a public key (--key PUB) under --origin NAME: a
robot's (for serve --log) or, with --cosignature, a witness's (for verify --witness-key).

[bold]Examples[/bold]:

  trace-audit witness vkey --key amr-7.pub --origin trace.local/amr-7

  trace-audit witness serve --state st --key w.key --log VKEY

  trace-audit witness push /data/amr-7 --witness http://witness:7380
"""

_PROVE_HELP = """Write a proof bundle of one decision cycle: checkable without the log.

The bundle (JSON, docs/integrity.md "Proof bundles") holds the cycle's messages and seal,
the seal's inclusion proof in the robot's tree of the newest signed checkpoint that covers
it (cosigned when the root's witness store holds one) and that checkpoint's note. Check it
with verify-proof. An existing --out file is never overwritten (exit 4).

[bold]Examples[/bold]:

  trace-audit prove /data/amr-7 --cycle 1204 --out stop-1204.json
"""

_VERIFY_PROOF_HELP = """Check a proof bundle without the log: the messages' digests against
the seal, the seal's leaf in the tree (inclusion proof), the checkpoint note's signature by
the robot's key (--key) and, with --witness-key, the witness's cosignature and its time.
Exit 0 when every step verifies, 1 when one does not.

[bold]Examples[/bold]:

  trace-audit verify-proof stop-1204.json --key amr-7.pub --witness-key VKEY
"""


@app.command("witness", help=help_text(_WITNESS_HELP))
def witness_command(
    action: Annotated[str, typer.Argument(help="serve, push or vkey.", show_default=False)],
    root: Annotated[
        Path | None, typer.Argument(help="push: the log root.", show_default=False)
    ] = None,
    *,
    listen: Annotated[str, typer.Option("--listen", help="serve: HOST:PORT.")] = "127.0.0.1:7380",
    state: Annotated[
        Path | None, typer.Option("--state", help="serve: the state folder.", show_default=False)
    ] = None,
    key: Annotated[
        Path | None,
        typer.Option(
            "--key",
            help="serve: the witness's private key; vkey: a public key.",
            show_default=False,
        ),
    ] = None,
    log: Annotated[
        list[str] | None,
        typer.Option("--log", help="serve: a robot's verifier key (repeat).", show_default=False),
    ] = None,
    name: Annotated[
        str, typer.Option("--name", help="serve: the witness's key name.")
    ] = "trace.local/witness",
    witness: Annotated[
        str | None, typer.Option("--witness", help="push: the witness URL.", show_default=False)
    ] = None,
    robot: Annotated[list[str] | None, robot_option("push: only this robot (repeat).")] = None,
    origin: Annotated[
        str | None, typer.Option("--origin", help="vkey: the key name.", show_default=False)
    ] = None,
    cosignature: Annotated[
        bool, typer.Option("--cosignature", help="vkey: a witness's cosignature key.")
    ] = False,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    setup_logging()
    if action == "serve":
        if state is None or key is None:
            fail("witness serve needs --state DIR and --key WITNESS_KEY", EXIT_USAGE)
        from trace_audit.witness.server import serve

        raise typer.Exit(guarded(lambda: serve(listen, state, key, log or (), name=name)))
    if action == "push":
        if root is None or witness is None:
            fail("witness push needs ROOT and --witness URL", EXIT_USAGE)
        from trace_audit.witness.push import push_root

        report = guarded(lambda: push_root(root, witness, robots=robot or ()))
        emit(report, _push_doc, json_out=json_out, plain=plain)
        if not report.ok:
            raise typer.Exit(EXIT_FINDINGS)
        return
    if action == "vkey":
        if key is None or origin is None:
            fail("witness vkey needs --key PUB and --origin NAME", EXIT_USAGE)
        from trace_runtime.errors import NoteError
        from trace_runtime.tlog.keys import load_public_key
        from trace_runtime.tlog.signed_note import COSIGNATURE, ED25519, verifier_key

        public = guarded(lambda: load_public_key(key))
        try:
            line = verifier_key(origin, public.raw, COSIGNATURE if cosignature else ED25519)
        except NoteError as err:
            fail(f"--origin: {err}", EXIT_USAGE)
        sys.stdout.write(line + "\n")
        return
    fail(f"unknown witness action {action!r} (serve, push or vkey)", EXIT_USAGE)


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


@app.command("prove", help=help_text(_PROVE_HELP))
def prove_command(
    log: Annotated[Path, typer.Argument(help="A log root or segment.", show_default=False)],
    *,
    cycle: Annotated[int, typer.Option("--cycle", help="The cycle to prove.", show_default=False)],
    out: Annotated[
        Path, typer.Option("--out", help="The bundle file to write.", show_default=False)
    ],
    robot: Annotated[str | None, robot_option("The robot (needed on a fleet root).")] = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    import orjson

    from trace_audit.proof import make_bundle
    from trace_runtime.boundary import write_new

    setup_logging()
    if os.path.lexists(out):  # before the log is read; write_new refuses it again at the end
        fail(f"{out}: cannot write: it exists, and is never overwritten", EXIT_CANNOT_WRITE)
    bundle = guarded(lambda: make_bundle(log, cycle, robot=robot))
    data = orjson.dumps(bundle, option=orjson.OPT_INDENT_2) + b"\n"
    guarded(lambda: write_new(out, data))
    written = Written(
        str(out), len(data), bundle["cycle"], bundle["leaf_index"], bundle["tree_size"],
        len(bundle["inclusion"]), bundle["cosigned"],
    )  # fmt: skip
    emit(written, _written_doc, json_out=json_out, plain=plain)


@dataclass(frozen=True, slots=True)
class Written:
    """What ``prove`` wrote."""

    path: str
    bytes: int
    cycle: int
    leaf_index: int
    tree_size: int
    proof_hashes: int
    cosigned: bool


def _written_doc(w: Written) -> Doc:
    doc = Doc()
    doc.title(f"Wrote proof bundle {w.path}")
    doc.fields(
        [
            ("size", f"{w.bytes:,} bytes"),
            ("cycle", str(w.cycle)),
            ("tree", f"leaf {w.leaf_index} of {w.tree_size}, {w.proof_hashes} proof hashes"),
            ("checkpoint", "signed and cosigned" if w.cosigned else "signed (not cosigned)"),
        ]
    )
    return doc


@app.command("verify-proof", help=help_text(_VERIFY_PROOF_HELP))
def verify_proof_command(
    bundle: Annotated[Path, typer.Argument(help="The proof bundle.", show_default=False)],
    *,
    key: Annotated[
        Path, typer.Option("--key", help="The robot's Ed25519 public key.", show_default=False)
    ],
    witness_key: Annotated[
        str | None,
        typer.Option("--witness-key", help="The witness's verifier key.", show_default=False),
    ] = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    from trace_audit.proof import check_bundle, read_bundle
    from trace_runtime.errors import NoteError
    from trace_runtime.tlog.keys import load_public_key
    from trace_runtime.tlog.signed_note import parse_verifier_key

    setup_logging()
    public = guarded(lambda: load_public_key(key))
    verifier = None
    if witness_key is not None:
        try:
            verifier = parse_verifier_key(witness_key)
        except NoteError as err:
            fail(f"--witness-key: {err}", EXIT_USAGE)
    data = guarded(lambda: read_bundle(bundle))
    result = check_bundle(data, public, witness_key=verifier, path=str(bundle))
    emit(result, _check_doc, json_out=json_out, plain=plain)
    if not result.ok:
        raise typer.Exit(EXIT_FINDINGS)


def _check_doc(r: BundleCheck) -> Doc:
    doc = Doc()
    verdict = Seg("VERIFIED", "bold green") if r.ok else Seg("DOES NOT VERIFY", "bold red")
    doc.title([f"Proof {r.path}: ", verdict])
    fields = [("cycle", "not read" if r.cycle is None else f"{r.cycle} (t_ns {r.t_ns})")]
    if r.leaf_index is None or r.tree_size is None:  # the check stopped before the tree
        fields.append(("tree", "not reached"))
    else:
        tree = f"leaf {r.leaf_index} of {r.tree_size}"
        fields.append(("tree", f"{tree} ({r.origin})" if r.origin else tree))
    doc.fields(fields)
    doc.table(
        [Column("step"), Column("result"), Column("detail", wrap=True)],
        [[name, Seg("ok", "green") if ok else Seg("FAIL", "red"), d] for name, ok, d in r.steps],
    )
    return doc
