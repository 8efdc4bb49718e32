"""The key rotation bytes (profile 1.5) as docs/integrity.md §13 states them: an
announcement checked in any language with nothing but the recipe (six lines from the
checkpoint's JSON, pure Ed25519), and a checker that refuses what the recipe refuses."""

from __future__ import annotations

import base64

import orjson
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from trace_runtime.tlog.checkpoints import decode_checkpoint, encode_checkpoint, make_checkpoint
from trace_runtime.tlog.keys import Ed25519Signer
from trace_runtime.tlog.rotation import KeyChain, announce, check_announcement

ORIGIN = "fleet.example.com/amr-7"


def _announcing(old: Ed25519Signer, new: Ed25519Signer) -> bytes:
    body = make_checkpoint(robot_id="amr-7", segment=2, first_cycle=36, cycle=41,
                           t_ns=4_100_000_000, sealed=6, head="ab" * 32, signer=old,
                           origin=ORIGIN)  # fmt: skip
    return encode_checkpoint(body.model_copy(update=announce(body, old, ORIGIN, new.public_key)))


def test_an_announcement_checks_with_nothing_but_the_recipe() -> None:
    old, new = Ed25519Signer.generate(), Ed25519Signer.generate()
    value = orjson.loads(_announcing(old, new))
    lines = (
        "trace-key-rotation/1\n"
        f"robot_id={value['robot_id']}\ncycle={value['cycle']}\nhead={value['head']}\n"
        f"key_id={value['key_id']}\nnext_key={value['next_key']}\n"
    )
    Ed25519PublicKey.from_public_bytes(old.public_key.raw).verify(
        bytes.fromhex(value["next_key_signature"]), lines.encode()
    )  # raises InvalidSignature if the bytes differ from the recipe
    name, _, material = value["next_key"].split("+", 2)  # base64 may hold a "+" too
    assert name == ORIGIN and base64.b64decode(material) == b"\x01" + new.public_key.raw


def test_the_checker_follows_only_what_the_old_key_announced() -> None:
    old, new, evil = (Ed25519Signer.generate() for _ in range(3))
    checkpoint = decode_checkpoint(_announcing(old, new))
    assert check_announcement(checkpoint, old.public_key) == ("valid", new.public_key)
    assert check_announcement(checkpoint, evil.public_key)[0] == "bad_signature"
    moved = checkpoint.model_copy(update={"cycle": 42})  # replayed elsewhere in the chain
    assert check_announcement(moved, old.public_key)[0] == "bad_signature"
    renamed = checkpoint.model_copy(update={"origin": "fleet.example.com/amr-8"})
    assert check_announcement(renamed, old.public_key)[0] == "malformed"
    half = checkpoint.model_copy(update={"next_key_signature": None})
    assert check_announcement(half, old.public_key)[0] == "malformed"
    plain = checkpoint.model_copy(update={"next_key": None, "next_key_signature": None})
    assert check_announcement(plain, old.public_key) == ("none", None)


def test_a_checkpoint_that_announces_nothing_is_written_as_in_profile_1_4() -> None:
    body = make_checkpoint(robot_id="amr-7", segment=0, first_cycle=0, cycle=3, t_ns=3,
                           sealed=4, head="cd" * 32, signer=Ed25519Signer.generate())  # fmt: skip
    assert b"next_key" not in encode_checkpoint(body)
    assert decode_checkpoint(encode_checkpoint(body)) == body


def test_a_retired_key_is_told_from_one_never_announced() -> None:
    old, new = Ed25519Signer.generate(), Ed25519Signer.generate()
    chain = KeyChain(old.public_key)
    chain.rotate(41, new.public_key, "vkey")
    assert chain.key == new.public_key
    assert "retired by the rotation at cycle 41" in chain.why_not(old.key_id)
    assert "never announced" in chain.why_not("00" * 32)
