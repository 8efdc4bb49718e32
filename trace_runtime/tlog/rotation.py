"""Key rotation in a robot's chain (profile 1.5): a checkpoint announces the key that signs
the robot's later checkpoints, and the key it is signed with signs that announcement.

The announcement is the checkpoint's ``next_key``, the new key's C2SP verifier key under
the robot's origin, and ``next_key_signature``, an Ed25519 signature by the announcing
checkpoint's key over ``rotation_bytes``: the robot, the place in the chain (cycle and head
seal) and both keys, so it cannot be replayed for another robot or elsewhere in the chain.
A verifier given the robot's first key follows the announcements in chain order
(``KeyChain``); a checkpoint under any key that was not announced so is a ``key_mismatch``,
and so is one under a key already rotated away from (a retired key, maybe a stolen one).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Literal, Protocol

from trace_runtime.errors import NoteError
from trace_runtime.records import Checkpoint
from trace_runtime.tlog.keys import PublicKey, Signer
from trace_runtime.tlog.signed_note import ED25519, parse_verifier_key, verifier_key

__all__ = [
    "ROTATION_FORMAT",
    "AnnouncementState",
    "Announcing",
    "KeyChain",
    "KeyRotation",
    "announce",
    "check_announcement",
    "follow_keys",
    "rotation_bytes",
]

ROTATION_FORMAT = "trace-key-rotation/1"
"""First line of the bytes a key rotation signs."""


class Announcing(Protocol):
    """What an announcement is checked from: a ``Checkpoint``, or the same six values and
    the origin carried out of the chain (a proof bundle's ``key_rotations``)."""

    @property
    def robot_id(self) -> str: ...
    @property
    def cycle(self) -> int: ...
    @property
    def head(self) -> str: ...
    @property
    def key_id(self) -> str | None: ...
    @property
    def origin(self) -> str | None: ...
    @property
    def next_key(self) -> str | None: ...
    @property
    def next_key_signature(self) -> str | None: ...


def rotation_bytes(checkpoint: Announcing, next_key: str) -> bytes:
    """The exact bytes the announcing key signs (docs/integrity.md, PROFILE section 6):
    ``name=value`` lines in fixed order, like ``checkpoints.signing_bytes``."""
    c = checkpoint
    lines = (
        ROTATION_FORMAT,
        f"robot_id={c.robot_id}",
        f"cycle={c.cycle}",
        f"head={c.head}",
        f"key_id={c.key_id or ''}",
        f"next_key={next_key}",
    )
    return ("\n".join(lines) + "\n").encode()


def announce(
    checkpoint: Checkpoint, signer: Signer, origin: str, next_key: PublicKey
) -> dict[str, str]:
    """The fields by which ``checkpoint`` (signed by ``signer``) announces ``next_key``."""
    vkey = verifier_key(origin, next_key.raw)
    signature = signer.sign(rotation_bytes(checkpoint, vkey))
    return {"next_key": vkey, "next_key_signature": signature.hex()}


AnnouncementState = Literal["none", "valid", "bad_signature", "malformed"]
"""``none``: the checkpoint announces no key; ``valid``: it announces one, signed by ``key``;
``bad_signature``: the signature does not verify; ``malformed``: no usable Ed25519 verifier
key, or one under another name than the checkpoint's origin, or a signature missing."""


def check_announcement(
    checkpoint: Announcing, key: PublicKey
) -> tuple[AnnouncementState, PublicKey | None]:
    """Check a checkpoint's key announcement against the key that signed the checkpoint;
    with ``valid``, the announced key."""
    c = checkpoint
    if c.next_key is None and c.next_key_signature is None:
        return "none", None
    if c.next_key is None or c.next_key_signature is None:
        return "malformed", None
    try:
        verifier = parse_verifier_key(c.next_key)
    except NoteError:
        return "malformed", None
    if verifier.sig_type != ED25519 or (c.origin is not None and verifier.name != c.origin):
        return "malformed", None
    # 128 hex digits: the schema's pattern (a checkpoint), or the reader's check (a bundle)
    signature = bytes.fromhex(c.next_key_signature)
    if not key.verify(signature, rotation_bytes(c, c.next_key)):
        return "bad_signature", None
    return "valid", verifier.public_key


@dataclass(frozen=True, slots=True)
class KeyRotation:
    """One rotation a verifier followed: the cycle of the checkpoint that announced it, the
    key rotated from and to by key id (SHA-256 of the raw key, as ``keygen`` and ``verify``
    show it), and the new key as announced (its C2SP verifier key)."""

    cycle: int
    from_key_id: str | None
    to_key_id: str
    to_vkey: str


@dataclass(slots=True)
class KeyChain:
    """The key a robot's checkpoints must be signed with, followed through its rotations
    in chain order; ``retired`` the keys rotated away from, by key id, with the cycle of
    the checkpoint that announced their successor."""

    key: PublicKey | None
    retired: dict[str, int] = field(default_factory=dict)
    announced: list[str] = field(default_factory=list)
    """The verifier keys followed, in chain order (``next_key`` as stored)."""
    rotations: list[KeyRotation] = field(default_factory=list)
    """The same rotations with where they happened and both keys' ids."""

    def rotate(self, announced_at: int, next_key: PublicKey, vkey: str) -> None:
        before = None if self.key is None else self.key.key_id
        if self.key is not None and self.key.key_id != next_key.key_id:
            self.retired[self.key.key_id] = announced_at
        self.retired.pop(next_key.key_id, None)
        self.key = next_key
        self.announced.append(vkey)
        self.rotations.append(KeyRotation(announced_at, before, next_key.key_id, vkey))

    def follow(self, checkpoint: Announcing, key: PublicKey) -> AnnouncementState:
        """Move on past ``checkpoint``, verified under ``key`` (the chain's key there): a
        valid announcement makes the key it announces the chain's; any other state leaves
        the key as it was (the caller says why, when the state is a problem)."""
        state, announced = check_announcement(checkpoint, key)
        if announced is not None:
            self.rotate(checkpoint.cycle, announced, checkpoint.next_key or "")
        return state

    def copy(self) -> KeyChain:
        """The same state, to be moved on independently (another copy of a segment)."""
        return KeyChain(self.key, dict(self.retired), list(self.announced), list(self.rotations))

    def why_not(self, key_id: str | None) -> str:
        """Why a checkpoint signed by ``key_id`` does not count, in words."""
        short = (key_id or "?")[:16]
        cycle = self.retired.get(key_id or "")
        if cycle is not None:
            return f"it is signed by key {short}…, retired by the rotation at cycle {cycle}"
        return f"it is signed by another key ({short}…), never announced in the chain"


def follow_keys(
    checkpoints: Iterable[Checkpoint],
    key: PublicKey,
    signed_by: Callable[[Checkpoint, PublicKey], bool],
) -> KeyChain:
    """The chain of keys from ``key`` through the announcements of ``checkpoints`` (the
    robot's, in chain order), as verify follows them: a checkpoint moves the key on only
    when the chain's key at that point signed it (``signed_by``) and its announcement
    verifies under that key. For a reader that checks one statement of the chain (the
    newest note, a proof bundle's checkpoint) rather than every checkpoint: one signed by
    another key, or whose announcement does not verify, moves nothing."""
    chain = KeyChain(key)
    for checkpoint in checkpoints:
        current = chain.key
        if current is not None and signed_by(checkpoint, current):
            chain.follow(checkpoint, current)
    return chain
