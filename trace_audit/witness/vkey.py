"""A C2SP verifier key (``name+hash+base64``) of a public key file: what a witness is told
about a robot (``witness serve --log``) and what a verifier is told about a witness
(``verify --witness-key``, ``verify-proof --witness-key``)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from trace_runtime.errors import NoteError, UsageError
from trace_runtime.tlog.keys import load_public_key
from trace_runtime.tlog.signed_note import COSIGNATURE, ED25519, verifier_key

__all__ = ["VerifierKey", "verifier_key_of"]


@dataclass(frozen=True, slots=True)
class VerifierKey:
    """A public key named for notes: ``vkey`` is the line a verifier is given."""

    origin: str
    cosignature: bool
    vkey: str


def verifier_key_of(
    public_key: str | Path, origin: str, *, cosignature: bool = False
) -> VerifierKey:
    """The verifier key of the Ed25519 public key in ``public_key`` under ``origin``: a
    robot's note signatures, or with ``cosignature`` a witness's timestamped cosignatures.
    ``UsageError`` for a name C2SP does not allow."""
    public = load_public_key(Path(public_key))
    try:
        line = verifier_key(origin, public.raw, COSIGNATURE if cosignature else ED25519)
    except NoteError as err:
        raise UsageError(f"--origin: {err}") from err
    return VerifierKey(origin, cosignature, line)
