"""The note a robot's published ``checkpoint`` serves, and whose keys it was checked with.

Given the robot's public key(s) (``publish --key``), the newest signed checkpoint's note must
verify under one of them, or under a key the robot's chain announced from one of them (key
rotation, followed as verify follows it: ``key_chain``), the key's name being the
checkpoint's origin, as any signed-note verifier checks it; otherwise the robot publishes
nothing (a problem, exit 1). Without a key the signature is not checked here: the auditor
checks it, with a key from a channel they trust, and the report says it was not checked.

When the root's witness store (``<root>/witness/<robot>.jsonl``) holds the same checkpoint
cosigned, that is served instead: the robot's note byte for byte with every stored
witness's cosignature line after it, so a client that requires a witness's cosignature can
check it and one that does not ignores the lines it does not know. A stored note is used
only when it begins with the robot's very note and adds well-formed signature lines; any
other (another tree, another robot signature, a damaged line) is left out, never trusted.
The cosignatures themselves are not verified here (publish holds no witness key): the
client checks them, as it checks the robot's.
"""

from __future__ import annotations

import base64
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from trace_audit.key_chain import followed_keys
from trace_runtime.errors import NoteError, UnverifiedNoteError, WitnessStoreError
from trace_runtime.records import Checkpoint
from trace_runtime.tlog.checkpoints import check_note
from trace_runtime.tlog.cosignature_store import read_cosigned
from trace_runtime.tlog.keys import PublicKey
from trace_runtime.tlog.signed_note import MAX_SIGNATURES, NoteSignature, open_note

__all__ = ["ServedNote", "served_note", "signature_problem"]

_COSIGNATURE_BYTES = 8 + 64  # after the key id: the cosignature's time, then its signature
_DASH = "\u2014 "


@dataclass(frozen=True, slots=True)
class ServedNote:
    """The bytes of ``checkpoint`` and the witnesses whose cosignature lines they carry."""

    note: str
    witnesses: tuple[str, ...] = ()


def signature_problem(
    checkpoint: Checkpoint, keys: Sequence[PublicKey], announcing: Sequence[Checkpoint] = ()
) -> tuple[str | None, list[str]]:
    """Why ``checkpoint``'s note does not verify under the key the chain reached from one of
    ``keys``, following the rotations the robot's ``announcing`` checkpoints announce
    (``key_chain``, as verify follows them): None when it does (or no key was given), with
    the verifier keys followed to get there."""
    if not keys:
        return None, []
    states: set[str] = set()
    why = ""
    for key in keys:
        chain = followed_keys(list(announcing), key)
        state = check_note(checkpoint, chain.key)
        if state == "valid":
            return None, list(chain.announced)
        states.add(state)
        if state == "key_mismatch" and chain.announced and not why:
            why = f", nor by a key announced from it ({chain.why_not(checkpoint.key_id)})"
    size = checkpoint.tree_size
    if "bad_signature" in states:
        return f"the note of checkpoint {size} carries a signature that does not verify", []
    if "mismatch" in states:
        return f"the note of checkpoint {size} does not state its tree", []
    given = ", ".join(key.key_id[:16] for key in keys)
    return f"the note of checkpoint {size} is not signed by the key given ({given}){why}", []


def served_note(root: str | Path, robot: str, checkpoint: Checkpoint) -> ServedNote:
    """The note to serve for ``checkpoint`` (see the module doc)."""
    note = checkpoint.note or ""
    try:
        stored = read_cosigned(root, robot)
    except WitnessStoreError:  # a robot id no store file can be named after: none is kept
        return ServedNote(note)
    lines: dict[tuple[str, int], str] = {}  # one line a witness key: the first stored
    for record in stored:
        same = (record.tree_size, record.root) == (checkpoint.tree_size, checkpoint.root)
        if same and record.note.startswith(note):
            for sig in _cosignatures(record.note):
                lines.setdefault((sig.name, sig.key_id), _line(sig))
    if not lines:
        return ServedNote(note)
    chosen = list(lines.items())[: MAX_SIGNATURES - 1]
    return ServedNote(note + "".join(line for _, line in chosen), tuple(n for (n, _), _ in chosen))


def _cosignatures(note: str) -> tuple[NoteSignature, ...]:
    """The cosignatures of a note whose every line is well formed (none otherwise: a line
    any client would refuse is never served)."""
    try:
        open_note(note, [])
    except UnverifiedNoteError as err:  # well formed, no key known here: as expected
        unverified: tuple[NoteSignature, ...] = err.unverified
    except NoteError:
        return ()
    return tuple(s for s in unverified if len(s.signature) == _COSIGNATURE_BYTES)


def _line(sig: NoteSignature) -> str:
    raw = sig.key_id.to_bytes(4, "big") + sig.signature
    return f"{_DASH}{sig.name} {base64.b64encode(raw).decode()}\n"
