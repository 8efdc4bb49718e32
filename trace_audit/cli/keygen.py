"""trace-audit ``keygen``: a signing key for a robot's checkpoints or a witness's cosignatures,
as a key pair of files or inside a PKCS#11 token; or the public key of a token's key again.

It parses its arguments, calls one library function (``trace_runtime.tlog.keys.
generate_keypair``, ``tlog.token.generate_token_key`` or ``export_token_public_key``) and
renders the typed result: rich on a terminal, plain text with ``--plain``, JSON with ``--json``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from trace_audit.cli.app import EXIT_USAGE, app, fail, guarded, help_text
from trace_audit.cli.doc import Doc, Seg
from trace_audit.cli.options import JsonOption, PlainOption
from trace_audit.cli.output import emit

if TYPE_CHECKING:  # the library is imported inside the command: start-up stays light
    from trace_runtime.tlog.keys import KeyPair
    from trace_runtime.tlog.token import TokenKeyPair

_KEYGEN_HELP = """Create an Ed25519 key pair for signing: a robot's checkpoints or a witness's
cosignatures.

Writes NAME.key (the private key, PKCS#8 PEM, file mode 0600: it stays on the host that
signs) and NAME.pub (the public key, PEM: give it to whoever verifies). A robot's logger
takes the private key as LoggerConfig(checkpoint_key="DIR/NAME.key"), verify its public key
as --key; a witness takes the private key as witness serve --key. Keys from openssl genpkey
-algorithm ed25519 work as well. A key that exists is not overwritten unless --force (exit
4, like a folder that cannot be written).

With --token 'pkcs11:token=LABEL;object=NAME?module-path=MODULE.so&pin-value=PIN' (an RFC
7512 URI; pin-source=file:/path reads the PIN from a file) the key is generated inside that
PKCS#11 token (an HSM, a smart card, SoftHSM2), sensitive and not extractable: only NAME.pub
is written, and the robot or the witness signs through the token with the same URI as its
key. A key of that name already in the token is never replaced (exit 4, --force or not);
--public-only writes its NAME.pub again from the token (a lost or doubted .pub), and makes
nothing. Needs the token extra (python-pkcs11). In the examples,
P11='module-path=/usr/lib/softhsm/libsofthsm2.so&pin-source=/etc/trace/pin'.

[bold]Examples[/bold]:

  trace-audit keygen --out keys/

  trace-audit keygen --out keys/ --token "pkcs11:token=hsm;object=amr-7?$P11"

  trace-audit keygen --out . --token "pkcs11:object=amr-7?$P11" --public-only

  trace-audit keygen --out /etc/trace --name amr-7 --json

  trace-audit keygen --out /etc/trace-witness --name witness
"""


@app.command("keygen", help=help_text(_KEYGEN_HELP))
def keygen_command(
    out: Annotated[
        Path,
        typer.Option("--out", help="Directory to write the key pair into.", show_default=False),
    ],
    *,
    name: Annotated[
        str | None,
        typer.Option(
            "--name",
            help="File name stem of the key pair [default: trace-ed25519; with --token the "
            "object's label].",
            show_default=False,
        ),
    ] = None,
    token: Annotated[
        str | None,
        typer.Option(
            "--token",
            metavar="URI",
            help="Generate the key inside this PKCS#11 token (a pkcs11: URI naming token, "
            "object, module-path and PIN); only the public key is written.",
            show_default=False,
        ),
    ] = None,
    public_only: Annotated[
        bool,
        typer.Option(
            "--public-only",
            help="With --token: write the public key of the key the token already holds "
            "(from its public key object); nothing is generated.",
        ),
    ] = False,
    force: Annotated[
        bool,
        typer.Option(
            "--force", help="Overwrite an existing key pair (or, with --public-only, .pub)."
        ),
    ] = False,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    if public_only and token is None:
        fail("--public-only reads a key in a token: give --token URI", EXIT_USAGE)
    if token is not None:
        from trace_runtime.tlog.token import export_token_public_key, generate_token_key

        action = export_token_public_key if public_only else generate_token_key
        made = guarded(lambda: action(token, out, name=name, overwrite=force))
        render = token_public_doc if public_only else token_keygen_doc
        emit(made, render, json_out=json_out, plain=plain)
        return
    from trace_runtime.tlog.keys import generate_keypair

    stem = name or "trace-ed25519"
    pair = guarded(lambda: generate_keypair(out, name=stem, overwrite=force))
    emit(pair, keygen_doc, json_out=json_out, plain=plain)


def keygen_doc(pair: KeyPair) -> Doc:
    doc = Doc()
    doc.title(["Created an Ed25519 signing key ", Seg(pair.key_id[:16] + "…", "bold")])
    doc.fields(
        [
            ("private key", f"{pair.private_path} (mode 0600; keep it on the host that signs)"),
            ("public key", f"{pair.public_path} (give it to whoever verifies)"),
            ("key id", pair.key_id),
        ]
    )
    # The same pair serves a robot or a witness; keygen cannot know which, so it says both.
    doc.line(f'On a robot:   LoggerConfig(checkpoint_key="{pair.private_path}")')
    doc.line(f"  its logs:   trace-audit verify LOG --key {pair.public_path}")
    doc.line(f"On a witness: trace-audit witness serve --key {pair.private_path} …")
    doc.line(
        f"  its vkey:   trace-audit witness vkey --cosignature --key {pair.public_path} "
        "--origin NAME"
    )
    return doc


def token_keygen_doc(made: TokenKeyPair) -> Doc:
    doc = Doc()
    doc.title(["Created an Ed25519 signing key in a token ", Seg(made.key_id[:16] + "…", "bold")])
    doc.fields(
        [
            ("private key", f"{made.uri} (in the token: sensitive, not extractable)"),
            ("public key", f"{made.public_path} (give it to whoever verifies)"),
            ("key id", made.key_id),
        ]
    )
    # The URI is shown without a pin-value: the robot names its PIN by a file instead.
    uri = made.uri if "pin-source=" in made.uri else f"{made.uri}&pin-source=file:PINFILE"
    doc.line(f'On a robot:   LoggerConfig(checkpoint_key="{uri}")')
    doc.line(f"  its logs:   trace-audit verify LOG --key {made.public_path}")
    doc.line(f"On a witness: trace-audit witness serve --key '{uri}' …")
    return doc


def token_public_doc(made: TokenKeyPair) -> Doc:
    doc = Doc()
    doc.title(["Wrote the public key of a key in a token ", Seg(made.key_id[:16] + "…", "bold")])
    doc.fields(
        [
            ("private key", f"{made.uri} (in the token, unchanged)"),
            ("public key", f"{made.public_path} (read from the token's public key object)"),
            ("key id", made.key_id),
        ]
    )
    doc.line(f"  its logs:   trace-audit verify LOG --key {made.public_path}")
    return doc
