"""``trace-audit prove`` and ``verify-proof``: one decision's proof bundle, written from the
log and checked without it. Each parses its arguments and calls one library function
(``trace_audit.proof.write_bundle``, ``trace_audit.proof.verify_proof``)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from trace_audit.cli.app import EXIT_FINDINGS, app, guarded, help_text
from trace_audit.cli.doc import Column, Doc, Seg
from trace_audit.cli.options import EvidenceOption, JsonOption, PlainOption, robot_option
from trace_audit.cli.output import emit, setup_logging
from trace_runtime.clock import show_instant

if TYPE_CHECKING:
    from trace_audit.proof import BundleCheck, WrittenBundle

__all__ = ["prove_command", "verify_proof_command"]

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
the robot's key (--key; after a key rotation, the key the bundle's rotations lead to from
it, so the robot's first key is enough) and, with --witness-key, the witness's cosignature
and its time. Exit 0 when every step verifies, 1 when one does not.

[bold]Examples[/bold]:

  trace-audit verify-proof stop-1204.json --key amr-7.pub --witness-key VKEY
"""


@app.command("prove", help=help_text(_PROVE_HELP))
def prove_command(
    log: Annotated[Path, typer.Argument(help="A log root or segment.", show_default=False)],
    *,
    cycle: Annotated[int, typer.Option("--cycle", help="The cycle to prove.", show_default=False)],
    out: Annotated[
        Path, typer.Option("--out", help="The bundle file to write.", show_default=False)
    ],
    robot: Annotated[str | None, robot_option("The robot (needed on a fleet root).")] = None,
    evidence: EvidenceOption = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    from trace_audit.proof import write_bundle

    setup_logging()
    written = guarded(lambda: write_bundle(log, cycle, out, robot=robot, evidence=evidence or ()))
    emit(written, _written_doc, json_out=json_out, plain=plain)


def _written_doc(w: WrittenBundle) -> Doc:
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
    from trace_audit.proof import verify_proof

    setup_logging()
    result = guarded(lambda: verify_proof(bundle, key, witness_key=witness_key))
    emit(result, _check_doc, json_out=json_out, plain=plain)
    if not result.ok:
        raise typer.Exit(EXIT_FINDINGS)


def _check_doc(r: BundleCheck) -> Doc:
    doc = Doc()
    verdict = Seg("VERIFIED", "bold green") if r.ok else Seg("DOES NOT VERIFY", "bold red")
    doc.title([f"Proof {r.path}: ", verdict])
    fields = [("cycle", "not read" if r.cycle is None else f"{r.cycle} at {_when(r.t_ns)}")]
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


def _when(t_ns: int | None) -> str:
    """A bundle's time: it does not name its clock, so a time of day when it can only be
    one (after 2000, as a wall clock's), else seconds; the nanoseconds either way."""
    return "?" if t_ns is None else f"{show_instant(t_ns, 'system')} (t_ns {t_ns})"
