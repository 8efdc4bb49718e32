"""Checkpoints: signed statements of a robot's chain head (``/trace/checkpoint``).

Anyone can recompute a hash chain; a checkpoint states the chain head (the digest of the
last seal) and is signed with the robot's Ed25519 key, like a Certificate Transparency
signed tree head or a CloudTrail digest file. A signed head vouches for every cycle the
chain reaches back to. This module builds, encodes, decodes, reads and checks them; the
signed bytes (``signing_bytes``) are specified in docs/integrity.md.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator
from typing import TYPE_CHECKING, Literal

import orjson

from trace_runtime.errors import NoteError, RecordError, UnverifiedNoteError
from trace_runtime.record_model import validate_record
from trace_runtime.records import TOPIC_CHECKPOINT, Checkpoint
from trace_runtime.tlog.keys import PublicKey, Signer
from trace_runtime.tlog.merkle import CompactRange
from trace_runtime.tlog.signed_note import (
    NoteSigner,
    NoteVerifier,
    format_checkpoint,
    open_note,
    parse_checkpoint,
    sign_note,
)

if TYPE_CHECKING:
    from trace_runtime.encoding.cycles import RawMessage
    from trace_runtime.reading.reader import Segment

__all__ = [
    "CHECKPOINT_FORMAT",
    "CheckpointState",
    "NoteState",
    "check_checkpoint",
    "check_note",
    "decode_checkpoint",
    "encode_checkpoint",
    "iter_checkpoints",
    "make_checkpoint",
    "signing_bytes",
]

CHECKPOINT_FORMAT = "trace-checkpoint/1"
"""First line of the signed bytes; bumped if the signed fields ever change. Profile 1.2 keeps
it: the tree fields are signed by the checkpoint's C2SP note, so a verifier that knows only
these bytes checks a 1.2 checkpoint's head signature as before."""


def signing_bytes(checkpoint: Checkpoint) -> bytes:
    """The exact bytes an Ed25519 checkpoint signature covers (docs/integrity.md).

    Not JSON: one ``name=value`` line per field of the unsigned body, in fixed order, decimal
    integers, lowercase hex digests, ``true``/``false``, empty for an absent key id. Every
    language produces these bytes the same way; the message's own JSON never has to be
    re-serialised to check a signature.
    """
    c = checkpoint
    lines = (
        CHECKPOINT_FORMAT,
        f"robot_id={c.robot_id}",
        f"segment={c.segment}",
        f"first_cycle={c.first_cycle}",
        f"cycle={c.cycle}",
        f"t_ns={c.t_ns}",
        f"sealed={c.sealed}",
        f"head={c.head}",
        f"final={'true' if c.final else 'false'}",
        f"key_id={c.key_id or ''}",
    )
    return ("\n".join(lines) + "\n").encode()


def _tree_fields(
    tree: CompactRange, origin: str | None, note_signer: NoteSigner | None
) -> dict[str, object]:
    """A checkpoint's statement of the robot's tree (profile 1.2): its size, root and compact
    range, and with a ``note_signer`` the signed C2SP note of (origin, size, root)."""
    if origin is None:
        raise ValueError("a checkpoint with a tree names its origin")
    root_hash = tree.root()
    fields: dict[str, object] = {
        "tree_size": tree.size,
        "root": root_hash.hex(),
        "range": [h.hex() for h in tree.hashes],
    }
    if note_signer is not None:
        if note_signer.name != origin:
            raise ValueError("a checkpoint's note is signed under the key name origin")
        fields["note"] = sign_note(format_checkpoint(origin, tree.size, root_hash), note_signer)
    return fields


def make_checkpoint(
    *,
    robot_id: str,
    segment: int,
    first_cycle: int,
    cycle: int,
    t_ns: int,
    sealed: int,
    head: str,
    final: bool = False,
    signer: Signer | None = None,
    tree: CompactRange | None = None,
    origin: str | None = None,
    note_signer: NoteSigner | None = None,
    tree_size: int | None = None,
    root: str | None = None,
    range: list[str] | None = None,
    note: str | None = None,
    next_key: str | None = None,
    next_key_signature: str | None = None,
) -> Checkpoint:
    """Build a checkpoint of the chain head; signed when ``signer`` is given.

    Profile 1.2: ``tree`` is the robot's tree through the head seal and ``origin`` its C2SP
    origin; with a ``note_signer`` (the same key, named ``origin``) the checkpoint carries
    the signed C2SP note of (origin, tree size, root). The signature over ``signing_bytes``
    is unchanged (``trace-checkpoint/1``): the note is what signs the tree. The tree's fields
    may also be given as they are stated (``tree_size``, ``root``, ``range``, ``note``), and
    so may a key rotation's announcement (profile 1.5: ``next_key``, ``next_key_signature``;
    ``tlog.rotation.announce`` makes one).
    """
    tree_fields: dict[str, object] = {
        "tree_size": tree_size,
        "root": root,
        "range": range,
        "origin": origin,
        "note": note,
    }
    if tree is not None:
        tree_fields.update(_tree_fields(tree, origin, note_signer))
    body = Checkpoint(
        cycle=cycle,
        t_ns=t_ns,
        robot_id=robot_id,
        segment=segment,
        first_cycle=first_cycle,
        sealed=sealed,
        head=head,
        final=final,
        key_id=None if signer is None else signer.key_id,
        next_key=next_key,
        next_key_signature=next_key_signature,
        **tree_fields,
    )
    if signer is None:
        return body
    return body.model_copy(update={"signature": signer.sign(signing_bytes(body)).hex()})


_ROTATION_FIELDS = {"next_key", "next_key_signature"}


def encode_checkpoint(checkpoint: Checkpoint) -> bytes:
    """The message data of a checkpoint: compact JSON of the model, like a seal. The key
    rotation fields (profile 1.5) are written only by the checkpoint that announces a key,
    so every other checkpoint is byte for byte what a 1.4 writer wrote and a 1.4 reader
    that refuses unknown properties reads it."""
    rotating = checkpoint.next_key is not None or checkpoint.next_key_signature is not None
    exclude = None if rotating else _ROTATION_FIELDS
    return checkpoint.model_dump_json(by_alias=True, exclude=exclude).encode()


def decode_checkpoint(data: bytes) -> Checkpoint:
    """Parse checkpoint message data; ``RecordError`` when it is not a valid checkpoint."""
    try:
        value = orjson.loads(data)
    except orjson.JSONDecodeError as err:
        raise RecordError(f"invalid Checkpoint: not JSON ({err})") from err
    return validate_record(Checkpoint, value)


CheckpointState = Literal["valid", "unchecked", "unsigned", "bad_signature", "key_mismatch"]
"""``valid``: signed by the expected key; ``unchecked``: no key to check against;
``unsigned``: a key was expected but the checkpoint has no signature; ``key_mismatch``: it
names another key; ``bad_signature``: it names the key but the signature does not verify."""


def check_checkpoint(checkpoint: Checkpoint, key: PublicKey | None) -> CheckpointState:
    """Check a checkpoint's signature against the expected public key (None: cannot check)."""
    if key is None:
        return "unchecked"
    if not checkpoint.signature:
        return "unsigned"
    if checkpoint.key_id != key.key_id:
        return "key_mismatch"
    try:
        signature = bytes.fromhex(checkpoint.signature)
    except ValueError:
        return "bad_signature"
    return "valid" if key.verify(signature, signing_bytes(checkpoint)) else "bad_signature"


NoteState = Literal["valid", "unchecked", "unsigned", "bad_signature", "key_mismatch", "mismatch"]
"""A 1.2 checkpoint's note: ``valid`` (signed by the expected key under the name ``origin``),
``unchecked`` (no key to check against), ``unsigned`` (a key was expected, there is no note),
``key_mismatch`` (no signature by that key under that name), ``bad_signature`` (it names the
key but does not verify, or is no signed note at all), ``mismatch`` (its body is not
exactly the checkpoint's origin, tree size and root)."""


def check_note(checkpoint: Checkpoint, key: PublicKey | None) -> NoteState:
    """Check a 1.2 checkpoint's C2SP note: its body states the checkpoint's own tree (checked
    with or without a key) and, given the robot's public key, it verifies under the key name
    ``origin`` with any signed-note verifier's rules (``signed_note.open_note``)."""
    c = checkpoint
    if c.note is None:
        return "unchecked" if key is None else "unsigned"
    if c.origin is None or c.tree_size is None or c.root is None:
        return "mismatch"
    if key is None:
        split = c.note.rfind("\n\n")
        if split < 0:
            return "bad_signature"
        text = c.note[: split + 1]
    else:
        try:
            text = open_note(c.note, [_note_verifier(c.origin, key.raw)]).text
        except UnverifiedNoteError:
            return "key_mismatch"
        except NoteError:
            return "bad_signature"
    try:
        body = parse_checkpoint(text)
    except NoteError:
        return "bad_signature"
    stated = (body.origin, body.size, body.root.hex(), body.extensions)
    if stated != (c.origin, c.tree_size, c.root, ()):
        return "mismatch"
    return "unchecked" if key is None else "valid"


@functools.lru_cache(maxsize=64)
def _note_verifier(origin: str, raw: bytes) -> NoteVerifier:
    return NoteVerifier.of(origin, raw)


def iter_checkpoints(segment: Segment) -> Iterator[RawMessage]:
    """The raw ``/trace/checkpoint`` messages of a segment, in reading order (without
    building the segment's other messages: ``McapFile.topic_messages``)."""
    yield from segment.topic_messages(TOPIC_CHECKPOINT)
