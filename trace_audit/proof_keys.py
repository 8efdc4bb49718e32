"""The key rotations a proof bundle carries (``trace-proof/5``'s ``key_rotations``), so an
auditor who holds the robot's first key checks a decision signed after a rotation.

``prove`` carries every announcement (profile 1.5) the robot's chain made before the
checkpoint whose note the bundle holds, in chain order, as the six values the announcing
key signed (``tlog.rotation.rotation_bytes``): robot, cycle, head, key id, next key and the
signature. ``verify-proof --key K`` follows them from K with the runtime's rotation logic
(``KeyChain.follow``, ``check_announcement``: the ones ``verify`` uses), and the note must
verify under the key it reaches. K may also be a key a rotation announced (an auditor given
the new key): the rotations before it are then not checked (there is no key to check them
with), and the step says so. A key that is neither is a failed step, not a guess.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass

from trace_audit.key_chain import announcing_checkpoints
from trace_audit.proof_data import BadBundleError, field_of
from trace_runtime.errors import NoteError
from trace_runtime.reading.logset import Log
from trace_runtime.tlog.keys import PublicKey
from trace_runtime.tlog.rotation import KeyChain
from trace_runtime.tlog.signed_note import parse_verifier_key

__all__ = ["ROTATION_FIELDS", "CarriedRotation", "followed_key", "rotations_before"]

ROTATION_FIELDS = ("robot_id", "cycle", "head", "key_id", "next_key", "next_key_signature")
"""A carried rotation's fields: exactly these (the values ``rotation_bytes`` signs)."""

Rotation = dict[str, str | int]


@dataclass(frozen=True, slots=True)
class CarriedRotation:
    """An announcement out of its chain (``tlog.rotation.Announcing``), under the origin of
    the bundle's note."""

    robot_id: str
    cycle: int
    head: str
    key_id: str | None
    origin: str | None
    next_key: str | None
    next_key_signature: str | None


def rotations_before(log: Log, robot: str, note: str) -> list[Rotation]:
    """The key rotations ``robot``'s chain announced before the checkpoint whose note is
    ``note``: what takes its first key to the key that signed the note."""
    carried: list[Rotation] = []
    seen: set[tuple[int, str]] = set()
    for c in announcing_checkpoints(log, robot, before=note):
        if c.key_id is None or c.next_key is None or c.next_key_signature is None:
            continue  # an unsigned checkpoint's announcement hands no key on
        if (c.cycle, c.head) in seen:  # the same checkpoint in another copy of its segment
            continue
        seen.add((c.cycle, c.head))
        values = (c.robot_id, c.cycle, c.head, c.key_id, c.next_key, c.next_key_signature)
        carried.append(dict(zip(ROTATION_FIELDS, values, strict=True)))
    return carried


def followed_key(
    bundle: Mapping[str, object], key: PublicKey, origin: str, steps: list[tuple[str, bool, str]]
) -> PublicKey | None:
    """The key the bundle's note must verify under: ``key`` moved on through the bundle's
    rotations (none before ``/5``); None after a failed ``keys`` step."""
    if "key_rotations" not in bundle:
        return key
    carried = _carried(field_of(bundle, "key_rotations", list), origin)
    if not carried:
        return key
    start = _start(carried, key)
    if start is None:
        given = key.key_id[:16]
        why = f"the key given ({given}…) neither signed the first key rotation nor was announced"
        steps.append(("keys", False, why))
        return None
    chain = KeyChain(key)
    for rotation in carried[start:]:
        current = chain.key
        if current is None or chain.follow(rotation, current) != "valid":
            why = f"the key rotation at cycle {rotation.cycle} does not verify under its key"
            steps.append(("keys", False, why))
            return None
    followed = f"followed {len(carried) - start} key rotation(s) from the key given"
    if start:
        followed += f"; {start} before it not checked (give the robot's first key for those)"
    steps.append(("keys", True, followed))
    return chain.key


def _start(carried: list[CarriedRotation], key: PublicKey) -> int | None:
    """Where ``key`` enters the rotations: 0 when it announced the first, i + 1 when
    rotation i announced it; None when it is neither."""
    if carried[0].key_id == key.key_id:
        return 0
    for i, rotation in enumerate(carried):
        if _announced_id(rotation) == key.key_id:
            return i + 1
    return None


def _announced_id(rotation: CarriedRotation) -> str:
    try:
        return parse_verifier_key(rotation.next_key or "").public_key.key_id
    except NoteError as err:
        raise BadBundleError("a key rotation's next_key is not a verifier key") from err


def _hex(value: object, digits: int) -> bool:
    return isinstance(value, str) and len(value) == digits and set(value) <= set("0123456789abcdef")


def _carried(items: list[object], origin: str) -> list[CarriedRotation]:
    """The rotations as the bundle carries them, of the documented shape and one chain:
    one robot's, in cycle order, each signed by the key the one before announced."""
    carried: list[CarriedRotation] = []
    for item in items:
        if not isinstance(item, dict) or set(item) != set(ROTATION_FIELDS):
            raise BadBundleError("a key rotation's fields are missing or unknown")
        robot, cycle, head, key_id, next_key, signature = (item[f] for f in ROTATION_FIELDS)
        if not isinstance(robot, str) or not robot or not isinstance(next_key, str):
            raise BadBundleError("a key rotation's robot_id or next_key is not text")
        if type(cycle) is not int or cycle < 0:
            raise BadBundleError("a key rotation's cycle is not a cycle number")
        if not (_hex(head, 64) and _hex(key_id, 64) and _hex(signature, 128)):
            raise BadBundleError("a key rotation's head, key_id or signature is not hex")
        carried.append(CarriedRotation(robot, cycle, head, key_id, origin, next_key, signature))
    for before, after in itertools.pairwise(carried):
        if after.robot_id != before.robot_id or after.cycle <= before.cycle:
            raise BadBundleError("the key rotations are not one robot's, in chain order")
        if after.key_id != _announced_id(before):
            raise BadBundleError("a key rotation is not signed by the key the one before announced")
    return carried
