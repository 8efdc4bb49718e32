"""trace_runtime.tlog.signed_note: C2SP signed-note, tlog-checkpoint and tlog-cosignature/v1.

Known answers come from outside our code: the PeterNeumann key, text and signed note of Go's
golang.org/x/mod/sumdb/note tests, and the example checkpoint, cosigned message and
cosignature line of c2sp.org/tlog-cosignature, spelled out here by hand from its wording.
"""

from __future__ import annotations

import base64
import hashlib

import pytest
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from hypothesis import given, settings
from hypothesis import strategies as st

from trace_runtime.errors import NoteError, UnverifiedNoteError
from trace_runtime.tlog.keys import Ed25519Signer
from trace_runtime.tlog.signed_note import (
    COSIGNATURE,
    ED25519,
    MAX_SIGNATURES,
    Checkpoint,
    NoteSigner,
    NoteVerifier,
    cosignature_line,
    cosignature_message,
    format_checkpoint,
    key_id,
    open_note,
    parse_checkpoint,
    parse_verifier_key,
    sign_note,
    verifier_key,
    verify_cosignature,
)

# ---- Go's sumdb/note test key and note ----
PETER_SKEY_MATERIAL = "AYEKFALVFGyNhPJEMzD1QIDr+Y7hfZx09iUvxdXHKDFz"  # 0x01 || seed
PETER_VKEY = "PeterNeumann+c74f20a3+ARpc2QcUPDhMQegwxbzhKqiBfsVkmqq/LDE4izWy10TW"
PETER_TEXT = (
    "If you think cryptography is the answer to your problem,\n"
    "then you don't know what your problem is.\n"
)
PETER_SIG = (
    "— PeterNeumann x08go/ZJkuBS9UG/SffcvIAQxVBtiFupLLr8pAcElZInNIuGUgYN1FFYC2pZSNXgK"
    "vqfqdngotpRZb6KE6RyyBwJnAM=\n"
)
PETER_NOTE = PETER_TEXT + "\n" + PETER_SIG

# ---- c2sp.org/tlog-cosignature's example ----
SOFA_BODY = "example.com/behind-the-sofa\n20852163\nCsUYapGGPo4dkMgIAUqom/Xajj7h2fB2MPA3j2jxq2I=\n"
SOFA_COSIG = (
    "— witness.example.com/w1 jWbPPwAAAABkGFDLEZMHwSRaJNiIDoe9DYn/zXcrtPHeolMI5OWXEhZCB9dlrD"
    "JsX3b2oyin1nPZqhf5nNo0xUe+mbIUBkBIfZ+qnA==\n"
)


def _key(seed: bytes) -> Ed25519Signer:
    return Ed25519Signer(Ed25519PrivateKey.from_private_bytes(seed))


def _signer(name: str, seed: bytes = b"\x05" * 32, sig_type: int = ED25519) -> NoteSigner:
    key = _key(seed)
    return NoteSigner(name, key, key.public_key.raw, sig_type)


def _peter() -> NoteSigner:
    return _signer("PeterNeumann", base64.b64decode(PETER_SKEY_MATERIAL)[1:])


# ---- signed notes: known answers ----


def test_go_s_known_note_signs_and_opens_byte_for_byte() -> None:
    peter = _peter()
    assert peter.vkey == PETER_VKEY
    assert peter.key_id == 0xC74F20A3
    assert sign_note(PETER_TEXT, peter) == PETER_NOTE
    opened = open_note(PETER_NOTE, [parse_verifier_key(PETER_VKEY)])
    assert opened.text == PETER_TEXT
    assert [(s.name, s.key_id) for s in opened.verified] == [("PeterNeumann", 0xC74F20A3)]
    assert opened.verified[0].timestamp is None
    assert open_note(PETER_NOTE.encode(), [peter.verifier]).text == PETER_TEXT


def test_key_id_is_the_spec_s_hash() -> None:
    pub = _key(b"\x07" * 32).public_key.raw
    for sig_type in (ED25519, COSIGNATURE):
        digest = hashlib.sha256(b"a.example/k\n" + bytes([sig_type]) + pub).digest()
        assert key_id("a.example/k", sig_type, pub) == int.from_bytes(digest[:4], "big")
    vkey = verifier_key("a.example/k", pub)
    name, hash16, material = vkey.split("+")
    assert name == "a.example/k"
    assert hash16 == f"{key_id('a.example/k', ED25519, pub):08x}"
    assert base64.b64decode(material) == b"\x01" + pub
    cosig = verifier_key("a.example/k", pub, COSIGNATURE)
    assert base64.b64decode(cosig.split("+")[2]) == b"\x04" + pub
    assert parse_verifier_key(cosig).sig_type == COSIGNATURE


# ---- signed notes: round trips, known and unknown keys ----


def test_round_trip_with_several_signers() -> None:
    a, b = _signer("a.example/log", b"\x01" * 32), _signer("b.example/log", b"\x02" * 32)
    text = "line one\n\nline three after a blank line\n"
    note = sign_note(text, [a, b])
    both = open_note(note, [a.verifier, b.verifier])
    assert both.text == text
    assert [s.name for s in both.verified] == ["a.example/log", "b.example/log"]
    only_b = open_note(note, [b.verifier])
    assert [s.name for s in only_b.verified] == ["b.example/log"]
    assert [s.name for s in only_b.unverified] == ["a.example/log"]
    assert only_b.verified_by(b.verifier) is not None
    assert only_b.verified_by(a.verifier) is None


def test_unknown_keys_are_ignored_even_sharing_a_name_or_an_id() -> None:
    known = _signer("log.example/k", b"\x01" * 32)
    same_name = _signer("log.example/k", b"\x02" * 32)  # another key under the known name
    note = sign_note("hello\n", known) + same_name.signature_line("hello\n")
    opened = open_note(note, [known.verifier])
    assert len(opened.verified) == 1 and len(opened.unverified) == 1
    # the known name and id but the wrong name: a signature by "another" key
    renamed = note.replace("— log.example/k ", "— other.example/k ", 1)
    with pytest.raises(UnverifiedNoteError) as info:
        open_note(renamed, [known.verifier])
    assert [s.name for s in info.value.unverified] == ["other.example/k", "log.example/k"]


def test_no_known_signature_is_an_unverified_note() -> None:
    note = sign_note("hello\n", _signer("a.example/k"))
    with pytest.raises(UnverifiedNoteError, match="no known key signed"):
        open_note(note, [])
    with pytest.raises(UnverifiedNoteError):
        open_note(note, [_signer("b.example/k", b"\x09" * 32).verifier])


def test_a_known_key_s_bad_signature_rejects_the_note() -> None:
    peter = _peter()
    with pytest.raises(NoteError, match="does not verify"):
        open_note(PETER_NOTE.replace("problem,", "problem;"), [peter.verifier])
    raw = bytearray(base64.b64decode(PETER_SIG.split(" ")[2]))
    for position in (4, 40, 67):
        flipped = bytearray(raw)
        flipped[position] ^= 0x01
        line = f"— PeterNeumann {base64.b64encode(bytes(flipped)).decode()}\n"
        with pytest.raises(NoteError, match="does not verify"):
            open_note(PETER_TEXT + "\n" + line, [peter.verifier])
    short = f"— PeterNeumann {base64.b64encode(bytes(raw[:40])).decode()}\n"
    with pytest.raises(NoteError, match="wrong length"):
        open_note(PETER_TEXT + "\n" + short, [peter.verifier])
    # a bad signature by a known key rejects the note even beside a good one
    bad = f"— PeterNeumann {base64.b64encode(bytes(raw[:4]) + bytes(64)).decode()}\n"
    with pytest.raises(NoteError, match="does not verify"):
        open_note(PETER_TEXT + "\n" + bad + PETER_SIG, [peter.verifier])


def test_a_repeated_signature_counts_once() -> None:
    opened = open_note(PETER_NOTE + PETER_SIG, [_peter().verifier])
    assert len(opened.verified) == 1


MALFORMED = [
    (PETER_TEXT, "no blank line"),
    (PETER_TEXT + "\n", "empty or does not end"),
    (PETER_TEXT + "\n" + PETER_SIG[:-1], "does not end in a newline"),
    ("\x01" + PETER_NOTE, "control character"),
    (PETER_NOTE.replace("\n", "\r\n", 1), "control character"),
    (PETER_TEXT + "\n" + PETER_SIG.replace("PeterNeumann", "Peter Neumann"), "standard base64"),
    (PETER_TEXT + "\n" + PETER_SIG.replace("PeterNeumann", "Peter+Neumann"), "plus"),
    (PETER_TEXT + "\n" + PETER_SIG.replace("PeterNeumann", "Peter\u00a0Neumann"), "space"),
    (PETER_NOTE + "Unexpected line.\n", "em dash"),
    (PETER_TEXT + "\n" + "- PeterNeumann AAAAAAAA\n", "em dash"),
    (PETER_TEXT + "\n" + "— PeterNeumann\n", "no signature"),
    (PETER_TEXT + "\n" + "— PeterNeumann \n", "no signature"),
    (PETER_TEXT + "\n" + "—  AAAAAAAA\n", "non-empty"),
    (PETER_TEXT + "\n" + "— PeterNeumann AAAA\n", "too short"),
    (PETER_TEXT + "\n" + "— PeterNeumann AAAAAAA\n", "base64"),
    (PETER_TEXT + "\n" + "— PeterNeumann AAAAAAAA!\n", "base64"),
    (PETER_TEXT + "\n" + "— PeterNeumann AAAAAAAA====\n", "base64"),
    (PETER_TEXT + "\n" + PETER_SIG + PETER_SIG.replace(" x", "  x"), "base64"),
]


def test_a_signature_in_a_second_spelling_is_refused() -> None:
    """A signature ending "nAN=" decodes to the bytes of "nAM=" (only unused bits differ);
    accepted, one signature could arrive under two spellings and count as two lines."""
    assert PETER_SIG.endswith("nAM=\n")
    other = PETER_SIG.replace("nAM=\n", "nAN=\n")
    with pytest.raises(NoteError, match="not canonical base64"):
        open_note(PETER_NOTE.replace(PETER_SIG, other), [_peter().verifier])
    assert len(open_note(PETER_NOTE, [_peter().verifier]).verified) == 1


@pytest.mark.parametrize(("note", "message"), MALFORMED)
def test_malformed_notes_are_one_line_errors(note: str, message: str) -> None:
    with pytest.raises(NoteError, match=message) as info:
        open_note(note, [_peter().verifier])
    assert "\n" not in str(info.value)


def test_invalid_utf8_and_size_limits() -> None:
    with pytest.raises(NoteError, match="UTF-8"):
        open_note(b"\xff" + PETER_NOTE.encode(), [])
    with pytest.raises(NoteError, match="UTF-8"):
        open_note("\ud800" + PETER_NOTE, [])
    with pytest.raises(NoteError, match="over 1048576 bytes"):
        open_note("a" * (1 << 20) + "\n\n" + PETER_SIG, [])
    many = PETER_TEXT + "\n" + PETER_SIG * (MAX_SIGNATURES + 1)
    with pytest.raises(NoteError, match="more than 100 signatures"):
        open_note(many, [_peter().verifier])
    assert open_note(PETER_TEXT + "\n" + PETER_SIG * MAX_SIGNATURES, [_peter().verifier])


def test_signing_refuses_what_is_not_a_note() -> None:
    peter = _peter()
    for text in ("no final newline", "tab\there\n", "\ud800\n", ""):
        with pytest.raises(NoteError):
            sign_note(text, peter)
    with pytest.raises(NoteError, match="at least one signer"):
        sign_note("x\n", [])
    for name in ("", "has space", "has+plus", "tab\tname", "nbsp\u00a0name", "line\u2028sep"):
        with pytest.raises(NoteError):
            _signer(name)
    with pytest.raises(NoteError, match="timestamp"):
        peter.signature_line("x\n", timestamp=5)


class _BrokenSigner:
    key_id = "broken"

    def sign(self, data: bytes) -> bytes:
        return b"short"


def test_a_signer_that_does_not_make_ed25519_signatures_is_refused() -> None:
    pub = _key(b"\x01" * 32).public_key.raw
    with pytest.raises(NoteError, match="64-byte"):
        NoteSigner("a.example/k", _BrokenSigner(), pub).signature_line("x\n")


BAD_VKEYS = [
    "PeterNeumann+c74f20a4+ARpc2QcUPDhMQegwxbzhKqiBfsVkmqq/LDE4izWy10TW",  # wrong key id
    "PeterNeumann+c74f20a+ARpc2QcUPDhMQegwxbzhKqiBfsVkmqq/LDE4izWy10TW",  # 7 hex digits
    "PeterNeumann+0xc74f20+ARpc2QcUPDhMQegwxbzhKqiBfsVkmqq/LDE4izWy10TW",  # int() would take it
    "PeterNeumann+c74f_20a+ARpc2QcUPDhMQegwxbzhKqiBfsVkmqq/LDE4izWy10TW",
    "PeterNeumann+c74f20a3+ARpc2QcUPDhMQegwxbzhKqiBfsVkmqq/LDE4izWy10T",  # bad base64
    "PeterNeumann+cc469956+ARpc2QcUPDhMQegwxbzhKqiBfsVkmqq/LDE4izWy10TWBADKEY==",  # Go's: length
    "PeterNeumann+173116ae+ZRpc2QcUPDhMQegwxbzhKqiBfsVkmqq/LDE4izWy10TW",  # Go's: algorithm
    "Peter Neumann+c74f20a3+ARpc2QcUPDhMQegwxbzhKqiBfsVkmqq/LDE4izWy10TW",
    "+c74f20a3+ARpc2QcUPDhMQegwxbzhKqiBfsVkmqq/LDE4izWy10TW",
    "PeterNeumann",
    "",
]


@pytest.mark.parametrize("vkey", BAD_VKEYS)
def test_bad_verifier_keys(vkey: str) -> None:
    with pytest.raises(NoteError):
        parse_verifier_key(vkey)


def test_two_known_keys_with_one_name_and_id_are_refused() -> None:
    v = _peter().verifier
    other = NoteVerifier(v.name, v.sig_type, _key(b"\x03" * 32).public_key, v.key_id)
    with pytest.raises(NoteError, match="share the name"):
        open_note(PETER_NOTE, [v, other])


# ---- checkpoints ----


def test_checkpoint_round_trip_and_the_spec_s_example() -> None:
    parsed = parse_checkpoint(SOFA_BODY)
    assert parsed.origin == "example.com/behind-the-sofa"
    assert parsed.size == 20852163
    assert parsed.root == base64.b64decode("CsUYapGGPo4dkMgIAUqom/Xajj7h2fB2MPA3j2jxq2I=")
    assert parsed.extensions == ()
    assert parsed.body() == SOFA_BODY
    with_ext = format_checkpoint("o.example/log", 0, b"\x00" * 32, ["ext a", "ext+b"])
    assert (
        with_ext == "o.example/log\n0\nAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA=\next a\next+b\n"
    )
    assert parse_checkpoint(with_ext) == Checkpoint(
        "o.example/log", 0, b"\x00" * 32, ("ext a", "ext+b")
    )


ROOT64 = "CsUYapGGPo4dkMgIAUqom/Xajj7h2fB2MPA3j2jxq2I="

BAD_CHECKPOINTS = [
    ("o\n5\n", "at least three lines"),
    (f"o\n5\n{ROOT64}", "ending in a newline"),
    (f"\n5\n{ROOT64}\n", "empty line"),
    (f"o\n\n{ROOT64}\n", "empty line"),
    (f"o\n5\n{ROOT64}\n\n", "empty line"),
    (f"o\n5\n{ROOT64}\next\n\n", "empty line"),
    (f"o\n05\n{ROOT64}\n", "leading zero"),
    (f"o\n00\n{ROOT64}\n", "leading zero"),
    (f"o\n-5\n{ROOT64}\n", "decimal"),
    (f"o\n+5\n{ROOT64}\n", "decimal"),
    (f"o\n 5\n{ROOT64}\n", "decimal"),
    (f"o\n5_0\n{ROOT64}\n", "decimal"),
    (f"o\n\u0665\n{ROOT64}\n", "decimal"),  # an Arabic-Indic five: a digit, not ASCII
    (f"o\n9223372036854775808\n{ROOT64}\n", "2\\^63-1"),
    ("o\n5\nAAAA\n", "32 bytes"),
    (f"o\n5\n{ROOT64[:-1]}\n", "base64"),
    (f"o\n5\n{ROOT64.replace('/', '_')}\n", "base64"),
    (f"o\n5\n{ROOT64[:-2]}J=\n", "canonical base64"),  # unused bits set
    (f"o\n5\n{ROOT64}\t\n", "control"),
]


@pytest.mark.parametrize(("text", "message"), BAD_CHECKPOINTS)
def test_strict_checkpoint_parsing(text: str, message: str) -> None:
    with pytest.raises(NoteError, match=message):
        parse_checkpoint(text)


def test_origins_are_only_required_non_empty_when_read() -> None:
    """The spec: the origin SHOULD have no spaces or plus, and clients MUST NOT assume so.
    We read such an origin and never write one."""
    odd = f"a log with spaces+plus\n1\n{ROOT64}\n"
    assert parse_checkpoint(odd).origin == "a log with spaces+plus"
    with pytest.raises(NoteError):
        format_checkpoint("a log with spaces", 1, b"\x00" * 32)


def test_format_refuses_what_it_cannot_spell() -> None:
    for size in (-1, 2**63, True, 1.0):
        with pytest.raises(NoteError):
            format_checkpoint("o.example", size, b"\x00" * 32)  # type: ignore[arg-type]
    with pytest.raises(NoteError):
        format_checkpoint("o.example", 1, b"\x00" * 31)
    for ext in ("", "two\nlines", "tab\t"):
        with pytest.raises(NoteError):
            format_checkpoint("o.example", 1, b"\x00" * 32, [ext])


# ---- cosignatures ----


def test_cosignature_message_is_the_spec_s_bytes() -> None:
    """c2sp.org/tlog-cosignature: two newline-terminated lines, `cosignature/v1` and `time`,
    a space and the decimal timestamp, then the whole checkpoint body."""
    assert cosignature_message(SOFA_BODY, 1679315147) == (
        b"cosignature/v1\n"
        b"time 1679315147\n"
        b"example.com/behind-the-sofa\n"
        b"20852163\n"
        b"CsUYapGGPo4dkMgIAUqom/Xajj7h2fB2MPA3j2jxq2I=\n"
    )
    assert cosignature_message("o\n0\n" + "A" * 43 + "=\n", 0).startswith(
        b"cosignature/v1\ntime 0\n"
    )
    for stamp in (-1, 2**63, True):
        with pytest.raises(NoteError):
            cosignature_message(SOFA_BODY, stamp)


def test_the_spec_s_cosignature_line_carries_its_timestamp() -> None:
    """The example line's bytes: 4 of key id, 8 of big-endian timestamp, 64 of signature;
    its timestamp is the one of the example's signed message."""
    raw = base64.b64decode(SOFA_COSIG.split(" ")[2])
    assert len(raw) == 4 + 8 + 64
    assert int.from_bytes(raw[4:12], "big") == 1679315147


def test_cosign_and_verify() -> None:
    log = _signer("example.com/behind-the-sofa", b"\x01" * 32)
    witness = _signer("witness.example.com/w1", b"\x02" * 32, COSIGNATURE)
    line = cosignature_line(SOFA_BODY, witness, 1679315147)
    raw = base64.b64decode(line.split(" ")[2])
    assert raw[:4] == witness.key_id.to_bytes(4, "big")
    assert raw[4:12] == (1679315147).to_bytes(8, "big")
    assert witness.verifier.public_key.verify(raw[12:], cosignature_message(SOFA_BODY, 1679315147))
    assert verify_cosignature(SOFA_BODY, line, witness.verifier) == 1679315147
    assert verify_cosignature(SOFA_BODY, line.rstrip("\n"), witness.verifier) == 1679315147

    note = sign_note(SOFA_BODY, log) + line
    opened = open_note(note, [log.verifier, witness.verifier])
    assert [(s.name, s.timestamp) for s in opened.verified] == [
        ("example.com/behind-the-sofa", None),
        ("witness.example.com/w1", 1679315147),
    ]
    # a plain Ed25519 verifier of the same key and name is another key: the line is unknown
    same_key_plain = NoteVerifier.of(witness.name, witness.public_key_raw, ED25519)
    assert open_note(note, [log.verifier, same_key_plain]).unverified[0].name == witness.name


def test_a_cosignature_fails_on_another_checkpoint_time_or_key() -> None:
    witness = _signer("witness.example.com/w1", b"\x02" * 32, COSIGNATURE)
    line = cosignature_line(SOFA_BODY, witness, 1679315147)
    other_body = SOFA_BODY.replace("20852163", "20852164")
    with pytest.raises(NoteError, match="does not verify"):
        verify_cosignature(other_body, line, witness.verifier)
    raw = bytearray(base64.b64decode(line.split(" ")[2]))
    raw[11] ^= 1  # the timestamp's last byte
    moved = f"— witness.example.com/w1 {base64.b64encode(bytes(raw)).decode()}\n"
    with pytest.raises(NoteError, match="does not verify"):
        verify_cosignature(SOFA_BODY, moved, witness.verifier)
    raw[4] = 0x80  # a timestamp above 2^63-1
    huge = f"— witness.example.com/w1 {base64.b64encode(bytes(raw)).decode()}\n"
    with pytest.raises(NoteError, match="above 2\\^63-1"):
        verify_cosignature(SOFA_BODY, huge, witness.verifier)
    stranger = _signer("witness.example.com/w1", b"\x03" * 32, COSIGNATURE)
    with pytest.raises(UnverifiedNoteError):
        verify_cosignature(SOFA_BODY, line, stranger.verifier)
    with pytest.raises(NoteError, match="COSIGNATURE verifier"):
        verify_cosignature(SOFA_BODY, line, _peter().verifier)
    with pytest.raises(NoteError, match="one signature line"):
        verify_cosignature(SOFA_BODY, line + line, witness.verifier)


def test_cosigning_needs_a_cosigner_a_timestamp_and_a_checkpoint() -> None:
    witness = _signer("witness.example.com/w1", b"\x02" * 32, COSIGNATURE)
    with pytest.raises(NoteError, match="sig_type COSIGNATURE"):
        cosignature_line(SOFA_BODY, _peter(), 1)
    with pytest.raises(NoteError, match="needs a timestamp"):
        witness.signature_line(SOFA_BODY)
    with pytest.raises(NoteError, match="at least three lines"):
        cosignature_line("not a checkpoint\n", witness, 1)
    with pytest.raises(NoteError):
        cosignature_line(SOFA_BODY, witness, -1)


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_any_mangled_note_opens_or_is_a_note_error(data: st.DataObject) -> None:
    """Hostile bytes: a verified note, or a NoteError; never another exception."""
    note = bytearray((PETER_NOTE + PETER_SIG.replace("Peter", "Other")).encode())
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(0, len(note) - 1))
        op = data.draw(st.sampled_from(["flip", "drop", "insert"]))
        if op == "flip":
            note[at] ^= 1 << data.draw(st.integers(0, 7))
        elif op == "drop":
            del note[at]
        else:
            note.insert(at, data.draw(st.sampled_from(b"\n \x00+=A\xe2\x80\x94")))
    try:
        opened = open_note(bytes(note), [_peter().verifier])
    except NoteError:
        return
    assert opened.verified[0].name == "PeterNeumann"
