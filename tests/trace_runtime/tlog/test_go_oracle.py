"""The reference implementations as the oracle: Go's golang.org/x/mod/sumdb/note opens the
notes trace_runtime.tlog.signed_note signs (and signs notes it must open), and
golang.org/x/mod/sumdb/tlog hashes, proves and checks the trees trace_runtime.tlog.merkle builds.

The oracle (go_oracle/main.go) is built once per session with Debian's Go and
golang-golang-x-mod-dev (scripts/install-go.sh); without them these tests skip, saying why.
"""

from __future__ import annotations

import base64
import json
import os
import random
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

from trace_runtime.errors import NoteError
from trace_runtime.tlog.keys import Ed25519Signer
from trace_runtime.tlog.merkle import (
    consistency_proof,
    inclusion_proof,
    leaf_hash,
    node_hash,
    root_of,
)
from trace_runtime.tlog.signed_note import (
    COSIGNATURE,
    NoteSigner,
    cosignature_line,
    format_checkpoint,
    open_note,
    parse_verifier_key,
    sign_note,
    verifier_key,
)

ORACLE_SOURCE = Path(__file__).parent / "go_oracle" / "main.go"
GOPATH = Path(os.environ.get("TRACE_GOPATH", "/usr/share/gocode"))
PACKAGES = ("golang.org/x/mod/sumdb/note", "golang.org/x/mod/sumdb/tlog")

Ask = Callable[[dict[str, Any]], dict[str, Any]]


@pytest.fixture(scope="session")
def ask(tmp_path_factory: pytest.TempPathFactory) -> Ask:
    """Send one request to the built oracle, get its answer."""
    go = shutil.which("go")
    if go is None:
        pytest.skip("go not found: install Debian's golang-go (scripts/install-go.sh)")
    missing = [p for p in PACKAGES if not (GOPATH / "src" / p).is_dir()]
    if missing:
        pytest.skip(
            f"go packages not found under {GOPATH}/src: {', '.join(missing)} "
            "(Debian's golang-golang-x-mod-dev; scripts/install-go.sh)"
        )
    where = tmp_path_factory.mktemp("go-oracle")
    binary = where / "oracle"
    env = {
        **os.environ,
        "GOPATH": str(GOPATH),
        "GO111MODULE": "off",
        "GOCACHE": str(where / "cache"),
        "GOFLAGS": "",
        "CGO_ENABLED": "0",
    }
    built = subprocess.run(
        [go, "build", "-o", str(binary), str(ORACLE_SOURCE)],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert built.returncode == 0, f"go build of the oracle failed:\n{built.stderr}"

    def run(request: dict[str, Any]) -> dict[str, Any]:
        done = subprocess.run(
            [str(binary)],
            input=json.dumps(request),
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )
        assert done.returncode == 0, done.stderr
        answer: dict[str, Any] = json.loads(done.stdout)
        return answer

    return run


def b64(data: bytes) -> str:
    return base64.b64encode(data).decode()


def unb64(text: str) -> bytes:
    return base64.b64decode(text)


def signer_from_seed(seed: bytes) -> Ed25519Signer:
    return Ed25519Signer(Ed25519PrivateKey.from_private_bytes(seed))


def note_signer(name: str, seed: bytes, sig_type: int = 0x01) -> NoteSigner:
    key = signer_from_seed(seed)
    return NoteSigner(name, key, key.public_key.raw, sig_type)


TEXTS = [
    format_checkpoint("example.com/robots/amr-1", 12345, bytes(range(32))),
    format_checkpoint("trace.example/log", 0, b"\xff" * 32, ["ext one", "ext+two"]),
    "a poem\n\nwith a blank line inside\nand ùnicode — dashes\n",
    "x\n",
]


# ---- signed notes ----


def test_go_opens_the_notes_python_signs(ask: Ask) -> None:
    logs = [note_signer("example.com/robots/amr-1", bytes([i]) * 32) for i in range(1, 3)]
    stranger = note_signer("stranger.example/k", b"\x09" * 32)
    cases = []
    expected = []
    for text in TEXTS:
        note = sign_note(text, logs)
        cases.append({"note": note, "vkeys": [logs[0].vkey]})
        expected.append(("", text, [f"{logs[0].name}+{logs[0].key_id:08x}"], 1))
        cases.append({"note": note, "vkeys": [s.vkey for s in logs]})
        expected.append(("", text, [f"{s.name}+{s.key_id:08x}" for s in logs], 0))
    answers = ask({"open": cases})["open"]
    for answer, (error, text, verified, unknown) in zip(answers, expected, strict=True):
        assert answer["error"] == error
        assert answer["text"] == text
        assert answer["verified"] == verified
        assert len(answer["unknown"]) == unknown

    note = sign_note(TEXTS[0], logs[0])
    body, _, sig = note.rpartition("\n\n")
    sig_bytes = bytearray(unb64(sig.split(" ")[2]))
    sig_bytes[10] ^= 1
    bad_sig = body + "\n\n" + " ".join([*sig.split(" ")[:2], b64(bytes(sig_bytes))]) + "\n"
    tampered = [
        note.replace("12345", "12346"),  # the text
        bad_sig,  # one bit of the signature
    ]
    answers = ask({"open": [{"note": n, "vkeys": [logs[0].vkey]} for n in tampered]})["open"]
    assert "invalid signature" in answers[0]["error"]
    assert "invalid signature" in answers[1]["error"]
    only_stranger = ask({"open": [{"note": note, "vkeys": [stranger.vkey]}]})["open"][0]
    assert "no verifiable signatures" in only_stranger["error"]


def test_go_reads_a_cosigned_checkpoint(ask: Ask) -> None:
    """Go's note package knows no cosignature type, but it must parse our cosignature line as
    a well-formed signature by an unknown key, and verify the log's signature beside it."""
    log = note_signer("example.com/robots/amr-1", b"\x01" * 32)
    witness = note_signer("witness.example/w1", b"\x02" * 32, COSIGNATURE)
    body = TEXTS[0]
    note = sign_note(body, log) + cosignature_line(body, witness, 1_700_000_000)
    answer = ask({"open": [{"note": note, "vkeys": [log.vkey]}]})["open"][0]
    assert answer["error"] == ""
    assert answer["verified"] == [f"{log.name}+{log.key_id:08x}"]
    assert answer["unknown"] == [f"{witness.name}+{witness.key_id:08x}"]


def test_python_opens_the_notes_go_signs(ask: Ask) -> None:
    seed = bytes(range(100, 132))
    requests = [{"text": t, "name": "go.example/signer", "seed": b64(seed)} for t in TEXTS]
    requests.append({"text": TEXTS[0], "name": "go.example/random", "seed": ""})
    answers = ask({"sign": requests})["sign"]
    ours = note_signer("go.example/signer", seed)
    for text, answer in zip(TEXTS, answers, strict=False):
        assert answer["error"] == ""
        # the same key: Go's verifier key is ours, and Ed25519 being deterministic, so is
        # the whole signed note, byte for byte
        assert answer["vkey"] == ours.vkey == verifier_key(ours.name, ours.public_key_raw)
        assert answer["note"] == sign_note(text, ours)
        opened = open_note(answer["note"], [parse_verifier_key(answer["vkey"])])
        assert opened.text == text
        assert [s.name for s in opened.verified] == ["go.example/signer"]
        with pytest.raises(NoteError, match="does not verify"):
            open_note("Z" + answer["note"][1:], [ours.verifier])
    random_key = answers[-1]
    opened = open_note(random_key["note"], [parse_verifier_key(random_key["vkey"])])
    assert opened.text == TEXTS[0] and len(opened.verified) == 1


# ---- trees ----


def _leaves(count: int, seed: int) -> list[bytes]:
    rng = random.Random(seed)
    return [rng.randbytes(rng.randrange(0, 80)) for _ in range(count)]


def test_hashes_and_roots_match_tlog(ask: Ask) -> None:
    data = _leaves(300, seed=1)
    sizes = [*range(1, 301)]
    answer = ask(
        {
            "leaves": [b64(d) for d in data],
            "roots": sizes,
            "node_pair": [b64(b"\x01" * 32), b64(b"\x02" * 32)],
        }
    )
    hashes = [leaf_hash(d) for d in data]
    assert [unb64(h) for h in answer["record_hashes"]] == hashes
    assert unb64(answer["node_hash"]) == node_hash(b"\x01" * 32, b"\x02" * 32)
    assert [unb64(r) for r in answer["roots"]] == [root_of(hashes[:n]) for n in sizes]


LARGE_SIZES = [63, 64, 65, 127, 128, 129, 1000, 1023, 1024, 1025, 4095, 4097, 6000]


def _record_pairs() -> list[tuple[int, int]]:
    pairs = [(n, i) for n in range(1, 41) for i in range(n)]
    rng = random.Random(2)
    for n in LARGE_SIZES:
        pairs += [(n, 0), (n, n - 1), *((n, rng.randrange(n)) for _ in range(6))]
    return pairs


def _tree_pairs() -> list[tuple[int, int]]:
    pairs = [(m, n) for n in range(1, 41) for m in range(1, n + 1)]
    rng = random.Random(3)
    for n in LARGE_SIZES:
        pairs += [(1, n), (n - 1, n), (n, n), *((rng.randrange(1, n), n) for _ in range(6))]
    return pairs


def test_inclusion_proofs_check_in_tlog(ask: Ask) -> None:
    data = _leaves(max(LARGE_SIZES), seed=4)
    hashes = [leaf_hash(d) for d in data]
    pairs = _record_pairs()
    roots = {n: root_of(hashes[:n]) for n in {n for n, _ in pairs}}
    proofs = [inclusion_proof(i, hashes[:n]) for n, i in pairs]
    checks = [
        {"size": n, "index": i, "proof": [b64(p) for p in proof], "root": b64(roots[n])}
        for (n, i), proof in zip(pairs, proofs, strict=True)
    ]
    # and each one with one bit of one proof hash flipped, which tlog must refuse
    bad = []
    for check in checks:
        if check["proof"]:
            proof = [unb64(p) for p in check["proof"]]
            j = len(proof) // 2
            proof[j] = bytes([proof[j][0] ^ 0x80]) + proof[j][1:]
            bad.append({**check, "proof": [b64(p) for p in proof]})
    answer = ask(
        {
            "leaves": [b64(d) for d in data],
            "records": checks + bad,
            "prove_records": [[n, i] for n, i in pairs],
        }
    )
    assert answer["records"][: len(checks)] == [""] * len(checks)
    assert all(err != "" for err in answer["records"][len(checks) :])
    assert [[unb64(h) for h in p] for p in answer["prove_records"]] == proofs
    assert len(checks) > 800


def test_consistency_proofs_check_in_tlog(ask: Ask) -> None:
    data = _leaves(max(LARGE_SIZES), seed=5)
    hashes = [leaf_hash(d) for d in data]
    pairs = _tree_pairs()
    roots = {n: root_of(hashes[:n]) for pair in pairs for n in pair}
    proofs = [consistency_proof(m, hashes[:n]) for m, n in pairs]
    checks = [
        {
            "old": m,
            "new": n,
            "proof": [b64(p) for p in proof],
            "old_root": b64(roots[m]),
            "new_root": b64(roots[n]),
        }
        for (m, n), proof in zip(pairs, proofs, strict=True)
    ]
    bad = []
    for check in checks:
        if check["proof"]:
            proof = [unb64(p) for p in check["proof"]]
            proof[-1] = proof[-1][:31] + bytes([proof[-1][31] ^ 1])
            bad.append({**check, "proof": [b64(p) for p in proof]})
    answer = ask(
        {
            "leaves": [b64(d) for d in data],
            "trees": checks + bad,
            "prove_trees": [[m, n] for m, n in pairs],
        }
    )
    assert answer["trees"][: len(checks)] == [""] * len(checks)
    assert all(err != "" for err in answer["trees"][len(checks) :])
    assert [[unb64(h) for h in p] for p in answer["prove_trees"]] == proofs
    assert len(checks) > 800


def _mangled_notes(count: int) -> list[bytes]:
    """A signed note (one known signature, one unknown), mangled at random: bits flipped,
    bytes dropped, and note syntax (newlines, spaces, dashes, pluses, padding) inserted."""
    signer = note_signer("example.com/robots/amr-1", b"\x01" * 32)
    other = note_signer("other.example/k", b"\x02" * 32)
    base = (sign_note(TEXTS[0], signer) + other.signature_line(TEXTS[0])).encode()
    pieces = [b"\n", b" ", b"\xe2\x80\x94 ", b"+", b"=", b"A", b"\xc2\xa0", b"\x00", b"\xff"]
    rng = random.Random(6)
    notes = []
    for _ in range(count):
        note = bytearray(base)
        for _ in range(rng.randint(1, 3)):
            at = rng.randrange(len(note))
            op = rng.choice(("flip", "drop", "insert"))
            if op == "flip":
                note[at] ^= 1 << rng.randrange(8)
            elif op == "drop":
                del note[at]
            else:
                note[at:at] = rng.choice(pieces)
        notes.append(bytes(note))
    return notes


def test_mangled_notes_open_exactly_when_go_opens_them(ask: Ask) -> None:
    """Differential: each mangled note opens in Python if and only if it opens in Go, with
    the same text and the same verified key."""
    signer = note_signer("example.com/robots/amr-1", b"\x01" * 32)
    notes = [n for n in _mangled_notes(600) if _is_utf8(n)]
    answers = ask({"open": [{"note": n.decode(), "vkeys": [signer.vkey]} for n in notes]})["open"]
    opened_somewhere = 0
    for note, answer in zip(notes, answers, strict=True):
        try:
            opened = open_note(note, [signer.verifier])
        except NoteError as err:
            assert answer["error"] != "", f"Go opened what Python refused ({err}): {note!r}"
            continue
        assert answer["error"] == "", f"Python opened what Go refused: {note!r}"
        assert answer["text"] == opened.text
        assert answer["verified"] == [f"{s.name}+{s.key_id:08x}" for s in opened.verified]
        opened_somewhere += 1
    assert opened_somewhere > 10


def _is_utf8(data: bytes) -> bool:
    """JSON carries text: invalid UTF-8 cannot reach the oracle as it is (both refuse it,
    which test_signed_note checks on the Python side)."""
    try:
        data.decode()
    except UnicodeDecodeError:
        return False
    return True
