"""Compaction and retention never delete the last good copy, evidence, or someone else's file.

Each test builds a real root with ``AuditLogger``, damages or edits it by hand (bytes flipped,
files rewritten with the plain ``mcap`` library, foreign files dropped in), runs
``compact`` / ``trace-audit compact``, and checks what is left with ``verify``.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from tests.trace_runtime.tier_logs import cycle_key, make_root
from tests.trace_runtime.verification.test_tamper import _write_plain, decode
from trace_audit.cli import app
from trace_audit.verify import verify_log
from trace_runtime import open_log, open_segment
from trace_runtime.errors import TraceError, VerificationError
from trace_runtime.records import TOPIC_ACTION, TOPIC_CHECKPOINT
from trace_runtime.tiers import ColdOptions, compact
from trace_runtime.tiers.retention import RETENTION_LOG
from trace_runtime.tlog.checkpoints import decode_checkpoint, encode_checkpoint, make_checkpoint
from trace_runtime.tlog.keys import Ed25519Signer

SMALL_BLOCKS = ColdOptions(block_cycles=16)


def invoke(*args: str | Path) -> Any:
    return CliRunner().invoke(app, [str(a) for a in args])


def flip_in_chunk(path: Path, which: int = 1) -> None:
    """Flip one byte inside the compressed payload of the ``which``-th chunk: disk decay."""
    offset = open_segment(path).chunks()[which].offset
    data = bytearray(path.read_bytes())
    data[offset + 80] ^= 0x10
    path.write_bytes(bytes(data))


def _names(root: Path) -> list[str]:
    """The files in the root's tier directories (not the writer's lock files)."""
    return sorted(
        p.relative_to(root).as_posix()
        for tier in ("hot", "warm", "cold")
        for p in root.glob(f"{tier}/*")
    )


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, list[Any]]:
    """A hot root of two segments and the same root fully compacted to cold."""
    base = tmp_path_factory.mktemp("pair")
    hot = make_root(base / "hot-root", cycles=40, segments=2, drop_at=None)
    cold = base / "cold-root"
    shutil.copytree(hot, cold)
    compact(cold, "cold", older_than_ns=0, include_unfinished=True, cold=SMALL_BLOCKS)
    original = [cycle_key(c) for c in open_log(hot).iter_cycles()]
    return hot, cold, original


def _interrupted(pair: tuple[Path, Path, list[Any]], tmp_path: Path) -> tuple[Path, str]:
    """A root as a compaction killed after the rename of segment 0 leaves it: the hot source
    and its verified cold replacement, side by side."""
    hot, cold, _ = pair
    root = tmp_path / "root"
    shutil.copytree(hot, root)
    name = sorted(p.name for p in (hot / "hot").glob("*.mcap"))[0]
    (root / "cold").mkdir()
    shutil.copy(cold / "cold" / name, root / "cold" / name)
    return root, name


# --- C: the last good copy ------------------------------------------------------------------


def test_a_decayed_source_never_costs_the_verified_replacement(
    pair: tuple[Path, Path, list[Any]], tmp_path: Path
) -> None:
    root, name = _interrupted(pair, tmp_path)
    good = (root / "cold" / name).read_bytes()
    flip_in_chunk(root / "hot" / name)
    result = invoke("compact", root, "--tier", "cold", "--older-than", "0", "--plain")
    assert result.exit_code == 0, result.output
    assert (root / "cold" / name).read_bytes() == good  # the verified copy stayed
    assert not (root / "hot" / name).exists()  # completed from it
    assert "verified replacement" in result.output
    report = verify_log(root)
    assert report.ok, report.findings
    assert [cycle_key(c) for c in open_log(root).iter_cycles()] == pair[2]


def test_a_decayed_replacement_is_redone_from_the_intact_source(
    pair: tuple[Path, Path, list[Any]], tmp_path: Path
) -> None:
    root, name = _interrupted(pair, tmp_path)
    flip_in_chunk(root / "cold" / name, 0)
    report = compact(root, "cold", older_than_ns=0, include_unfinished=True, cold=SMALL_BLOCKS)
    assert "discarded" in report.leftovers[0].action
    assert not report.failed
    assert _names(root) == sorted(f"cold/{p.name}" for p in (pair[0] / "hot").glob("*.mcap"))
    assert verify_log(root).ok
    assert [cycle_key(c) for c in open_log(root).iter_cycles()] == pair[2]


def test_a_source_edited_after_its_replacement_was_made_keeps_both_copies(
    pair: tuple[Path, Path, list[Any]], tmp_path: Path
) -> None:
    """The hot file was rewritten (a cycle's action changed) after the cold copy was made:
    the copies disagree and the hot one has findings. Both are evidence; neither is removed."""
    root, name = _interrupted(pair, tmp_path)
    hot = root / "hot" / name
    decoded = decode(hot)
    unit = decoded.units[decoded.cycles()[5]]
    unit.messages = [
        m if m.topic != TOPIC_ACTION else type(m)(m.topic, m.sequence, m.log_time_ns, b"{}")
        for m in unit.messages
    ]
    _write_plain(decoded, hot)
    before = {p: p.read_bytes() for p in (hot, root / "cold" / name)}
    result = invoke("compact", root, "--tier", "cold", "--older-than", "1000d", "--plain")
    assert result.exit_code == 1, result.output
    assert "held" in result.output
    assert {p: p.read_bytes() for p in before} == before


def test_verification_error_is_a_trace_error() -> None:
    assert issubclass(VerificationError, TraceError)


# --- D: retention never deletes evidence ----------------------------------------------------


def _retained(root: Path, *extra: str) -> Any:
    return invoke(
        "compact", root, "--tier", "cold", "--older-than", "0", "--retention", "0s", *extra
    )


def _cold_root_from(hot: Path, tmp_path: Path) -> Path:
    """``hot`` (a hot root, possibly edited) compacted to cold, retention off."""
    compact(hot, "cold", older_than_ns=0, include_unfinished=True, retention_ns=None)
    assert not list((hot / "hot").glob("*.mcap"))
    return hot


def test_retention_keeps_a_segment_whose_checkpoint_head_was_forged(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", cycles=40, segments=3, drop_at=None)
    first, victim, newest = sorted((root / "hot").glob("*.mcap"))
    decoded = decode(victim)
    (index,) = decoded.checkpoints()
    message = decoded.units[index].messages[0]
    checkpoint = decode_checkpoint(message.data)
    forged = checkpoint.model_copy(update={"head": "ab" * 32})
    decoded.units[index].messages[0] = type(message)(
        message.topic, message.sequence, message.log_time_ns, encode_checkpoint(forged)
    )
    _write_plain(decoded, victim)
    _cold_root_from(root, tmp_path)
    assert "checkpoint_mismatch" in [f.kind for f in verify_log(root).findings]
    result = _retained(root, "--json")
    assert result.exit_code == 0, result.output
    assert (root / "cold" / victim.name).exists()
    assert "held: findings" in result.output
    assert victim.name in result.output
    # The segment before it verifies and is deleted, recorded first; the newest is young.
    assert sorted(p.name for p in (root / "cold").glob("*.mcap")) == [victim.name, newest.name]
    (line,) = (root / RETENTION_LOG).read_bytes().splitlines()
    assert first.name in line.decode()


def test_retention_keeps_a_cycle_missing_a_layer_its_seal_names(tmp_path: Path) -> None:
    """The seal names /trace/action, the cycle has none: ``verify_cycle`` says modified."""
    root = make_root(tmp_path / "log", cycles=30, segments=2, drop_at=None)
    victim = sorted((root / "hot").glob("*.mcap"))[0]  # the older: past any retention
    decoded = decode(victim)
    unit = decoded.units[decoded.cycles()[4]]
    unit.messages = [m for m in unit.messages if m.topic != TOPIC_ACTION]
    _write_plain(decoded, victim)
    _cold_root_from(root, tmp_path)
    assert not verify_log(root).ok
    result = _retained(root)
    assert (root / "cold" / victim.name).exists(), result.output
    assert "held: findings" in result.output


def test_retention_checks_signatures_with_the_given_key(tmp_path: Path) -> None:
    """Checkpoints signed by another key chain-verify; with the robot's key they are findings."""
    robot = Ed25519Signer.generate()
    other = Ed25519Signer.generate()
    root = make_root(tmp_path / "log", cycles=30, segments=2, drop_at=None)
    victim = sorted((root / "hot").glob("*.mcap"))[0]
    decoded = decode(victim)
    for index in decoded.checkpoints():
        message = decoded.units[index].messages[0]
        c = decode_checkpoint(message.data)
        resigned = make_checkpoint(
            robot_id=c.robot_id,
            segment=c.segment,
            first_cycle=c.first_cycle,
            cycle=c.cycle,
            t_ns=c.t_ns,
            sealed=c.sealed,
            head=c.head,
            final=c.final,
            signer=other,
        )
        decoded.units[index].messages[0] = type(message)(
            TOPIC_CHECKPOINT, message.sequence, message.log_time_ns, encode_checkpoint(resigned)
        )
    _write_plain(decoded, victim)
    _cold_root_from(root, tmp_path)
    pub = tmp_path / "robot.pub"
    pub.write_bytes(robot.public_pem())
    result = _retained(root, "--key", pub)
    assert (root / "cold" / victim.name).exists(), result.output
    assert "held: findings" in result.output
    result = _retained(root)  # without the key the chain is all there is to check
    assert result.exit_code == 0, result.output
    assert not (root / "cold" / victim.name).exists()


# --- E: only the tool's own files -----------------------------------------------------------


def test_partial_files_that_are_not_the_tools_own_are_left_alone(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", cycles=20, segments=2, drop_at=None)
    (root / "cold").mkdir()
    name = sorted(p.name for p in (root / "hot").glob("*.mcap"))[0]
    foreign = {
        root / "hot" / "notes.partial": b"my notes, do not delete\n",
        root / "cold" / "README.mcap.partial": b"plain text\n",
        # the tool's own name, but not its header: someone else's file in the way
        root / "cold" / f"{name}.partial": b"not a partial segment\n",
    }
    for path, data in foreign.items():
        path.write_bytes(data)
    report = compact(root, "cold", older_than_ns=0, include_unfinished=True)
    for path, data in foreign.items():
        assert path.read_bytes() == data
    actions = {leftover.path: leftover.action for leftover in report.leftovers}
    assert all("left alone" in actions[path.relative_to(root).as_posix()] for path in foreign)
    (failed,) = report.failed
    assert failed.source == f"hot/{name}" and "in the way" in failed.detail
    assert (root / "hot" / name).exists()
