"""The store of cosigned checkpoints beside a log: appended, read back, tolerant of a torn
last line, and never followed through a link or into a FIFO."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from trace_runtime.errors import UnsafePathError, WitnessStoreError
from trace_runtime.tlog.cosignature_store import (
    append_cosigned,
    read_cosigned,
    store_path,
)
from trace_runtime.tlog.keys import Ed25519Signer
from trace_runtime.tlog.signed_note import (
    COSIGNATURE,
    NoteSigner,
    NoteVerifier,
    cosignature_line,
    format_checkpoint,
    open_note,
    sign_note,
)

ORIGIN = "trace.local/amr-7"


def _signers() -> tuple[NoteSigner, NoteSigner]:
    robot, witness = Ed25519Signer.generate(), Ed25519Signer.generate()
    return (
        NoteSigner(ORIGIN, robot, robot.public_key.raw),
        NoteSigner("witness.test", witness, witness.public_key.raw, COSIGNATURE),
    )


def _cosigned(size: int, robot: NoteSigner, witness: NoteSigner, stamp: int) -> tuple[str, str]:
    body = format_checkpoint(ORIGIN, size, bytes([size % 256]) * 32)
    return sign_note(body, robot), cosignature_line(body, witness, stamp)


def test_append_then_read(tmp_path: Path) -> None:
    robot, witness = _signers()
    stamp = int(time.time())
    for size in (3, 9):
        note, line = _cosigned(size, robot, witness, stamp + size)
        append_cosigned(tmp_path, "amr-7", note, [line], witness_url="http://w")
    got = read_cosigned(tmp_path, "amr-7")
    assert [(c.tree_size, c.timestamp, c.witness) for c in got] == [
        (3, stamp + 3, "witness.test"),
        (9, stamp + 9, "witness.test"),
    ]
    opened = open_note(got[1].note, [robot.verifier, witness.verifier])
    assert len(opened.verified) == 2 and got[1].root == (bytes([9]) * 32).hex()
    assert read_cosigned(tmp_path, "amr-8") == []


def test_a_torn_last_line_and_junk_are_skipped(tmp_path: Path) -> None:
    robot, witness = _signers()
    note, line = _cosigned(5, robot, witness, 1)
    append_cosigned(tmp_path, "amr-7", note, [line])
    path = store_path(tmp_path, "amr-7")
    with open(path, "ab") as f:
        f.write(b'not json\n[1,2]\n{"robot_id": "amr-7"}\n{"robot_id": "amr-7", "orig')
    assert [c.tree_size for c in read_cosigned(tmp_path, "amr-7")] == [5]


def test_what_is_not_a_cosigned_checkpoint_is_refused(tmp_path: Path) -> None:
    robot, witness = _signers()
    note, line = _cosigned(5, robot, witness, 1)
    with pytest.raises(WitnessStoreError):
        append_cosigned(tmp_path, "amr-7", note, [])
    with pytest.raises(WitnessStoreError):
        append_cosigned(tmp_path, "amr-7", "hello\n\n\u2014 x AAAA\n", [line])
    with pytest.raises(WitnessStoreError):
        append_cosigned(tmp_path, "../etc", note, [line])
    with pytest.raises(WitnessStoreError):
        append_cosigned(tmp_path, "amr-7", note, [robot.signature_line("x\n")])


def test_links_and_fifos_are_refused(tmp_path: Path) -> None:
    robot, witness = _signers()
    note, line = _cosigned(5, robot, witness, 1)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    root = tmp_path / "root"
    root.mkdir()
    (root / "witness").symlink_to(elsewhere)
    with pytest.raises(UnsafePathError):
        append_cosigned(root, "amr-7", note, [line])
    with pytest.raises(UnsafePathError):
        read_cosigned(root, "amr-7")
    (root / "witness").unlink()
    (root / "witness").mkdir()
    (elsewhere / "amr-7.jsonl").write_text("")
    store_path(root, "amr-7").symlink_to(elsewhere / "amr-7.jsonl")
    with pytest.raises(UnsafePathError):
        read_cosigned(root, "amr-7")
    with pytest.raises(UnsafePathError):
        append_cosigned(root, "amr-7", note, [line])
    assert (elsewhere / "amr-7.jsonl").read_text() == ""
    store_path(root, "amr-7").unlink()
    os.mkfifo(store_path(root, "amr-7"))
    with pytest.raises(UnsafePathError):
        read_cosigned(root, "amr-7")
    assert NoteVerifier.of(ORIGIN, robot.public_key_raw)
