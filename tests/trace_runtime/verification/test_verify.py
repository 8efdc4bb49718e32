"""``verify`` (through the investigator's ``verify_log``) on clean, crashed, gapped, damaged,
compacted logs: what a clean log looks like (zero findings, the validated range, what is
anchored) and which notes are not tampering.

The tamper campaign lives in test_tamper.py; what ``trace-audit verify`` and ``keygen``
print and exit is pinned in tests/trace_audit/cli/test_verify.py.
"""

from __future__ import annotations

import os
import shutil
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.trace_audit.conftest import PERIOD_NS, T0_NS, fill_cycle, write_log
from tests.trace_audit.profile_writer import write_profile_log
from tests.trace_runtime.verification.test_tamper import write_signed_log
from trace_audit.verify import verify_log
from trace_runtime import AuditLogger, LoggerConfig, open_log, open_segment
from trace_runtime.errors import LogReadError
from trace_runtime.testing import simulate_crash
from trace_runtime.tlog.keys import Ed25519Signer, generate_keypair, load_public_key

REPO = Path(__file__).resolve().parents[3]


def _kinds(items: list) -> list[str]:  # type: ignore[type-arg]
    return [f.kind for f in items]


# --- clean logs -------------------------------------------------------------------------------


def test_a_clean_log_reports_its_validated_range(sample_log: Path) -> None:
    report = verify_log(sample_log)
    assert report.ok and report.findings == []
    assert (report.cycle_range.first_cycle, report.cycle_range.last_cycle) == (0, 99)
    assert (report.cycle_range.start_ns, report.cycle_range.end_ns) == (
        T0_NS,
        T0_NS + 99 * PERIOD_NS,
    )
    assert report.cycles == report.cycles_valid == 100
    assert report.checkpoints == report.checkpoints_valid == 1  # the closing one
    (robot,) = report.robots
    assert (robot.robot_id, robot.anchored_cycle, robot.unanchored_cycles) == ("amr-7", 99, 0)
    # The fixture's "clear" cycles log a scan no evidence cites: their 1.3 seals cover it.
    assert set(_kinds(report.notes)) == {"signatures_unchecked"}
    assert not report.signatures_checked


def test_declared_drops_are_gaps_not_tampering(tmp_path: Path) -> None:
    skipped = {5, 6, 40}
    path = write_log(tmp_path / "gaps.mcap", skip=lambda i: i in skipped)
    report = verify_log(path)
    assert report.ok, report.findings
    gaps = [n for n in report.notes if n.kind == "declared_gap"]
    assert [(g.where.first_cycle, g.where.last_cycle) for g in gaps] == [(5, 6), (40, 40)]
    assert report.declared_dropped == 3 and report.cycles_valid == 97


def test_a_crashed_log_has_an_unanchored_tail_but_no_finding(crashed_log: Path) -> None:
    report = verify_log(crashed_log)
    assert report.ok, report.findings
    assert {"recovered", "unanchored"} <= set(_kinds(report.notes))
    (robot,) = report.robots
    assert robot.anchored_cycle is None and robot.unanchored_cycles == 100


def test_two_robots_in_one_root_are_verified_separately(tmp_path: Path) -> None:
    root = tmp_path / "fleet"
    write_log(root, robot_id="amr-1")
    write_log(root, robot_id="amr-2")
    report = verify_log(root)
    assert report.ok and [r.robot_id for r in report.robots] == ["amr-1", "amr-2"]
    assert report.cycles_valid == 200


def test_a_clock_restart_between_segments_is_a_note_not_a_finding(tmp_path: Path) -> None:
    root = write_log(tmp_path / "root")
    write_log(root)  # the same robot again, its clock from the same time
    report = verify_log(root)
    assert report.ok and report.findings == []
    (note,) = [n for n in report.notes if n.kind == "clock_restart"]
    assert (note.segment_no, note.where.first_cycle) == (1, 100)
    assert "not after cycle 99" in note.message
    assert "clock_restart" not in _kinds(verify_log(write_log(tmp_path / "one")).notes)


def test_an_honest_profile_log_has_no_clock_note(tmp_path: Path) -> None:
    report = verify_log(write_profile_log(tmp_path / "p.mcap"))
    assert report.ok and "clock_backwards" not in _kinds(report.notes)


def test_a_signed_log_without_the_key_is_checked_but_says_so(tmp_path: Path) -> None:
    signer = Ed25519Signer.generate()
    path = write_signed_log(tmp_path / "run.mcap", signer, 30)
    unchecked = verify_log(path)
    assert unchecked.ok and "signatures_unchecked" in _kinds(unchecked.notes)
    checked = verify_log(path, key=signer.public_key)
    assert checked.ok and checked.signatures_checked and checked.key_id == signer.key_id
    assert checked.checkpoints_valid == checked.checkpoints == 3  # at 1 s, 2 s and the close


def test_unsigned_checkpoints_are_findings_when_a_key_is_expected(sample_log: Path) -> None:
    report = verify_log(sample_log, key=Ed25519Signer.generate().public_key)
    assert _kinds(report.findings) == ["unsigned_checkpoint"]
    assert report.findings[0].covers(99)


def test_simulator_log_is_clean_and_its_drops_are_the_injected_ones(tmp_path: Path) -> None:
    sim = pytest.importorskip("sim")
    result = sim.run(sim.RunConfig(out=tmp_path / "run.mcap", cycles=60, seed=7))
    report = verify_log(result.out)
    assert report.ok, report.findings
    truth = sim.read_truth(result.truth)
    dropped = sorted(f["cycle"] for f in truth if f["kind"] == "audit_write_timeout")
    gaps = [
        (n.where.first_cycle, n.where.last_cycle) for n in report.notes if n.kind == "declared_gap"
    ]
    declared = sorted(
        c for a, b in gaps if a is not None and b is not None for c in range(a, b + 1)
    )
    assert declared == dropped
    assert report.cycles_valid == 300 - len(dropped)


# --- a robot killed with SIGKILL, then restarted -------------------------------------------------

ROBOT = """
import sys, time
from tests.trace_audit.conftest import fill_cycle
from trace_runtime import AuditLogger, LoggerConfig

root, key, cycles = sys.argv[1], sys.argv[2], int(sys.argv[3])
config = LoggerConfig(checkpoint_key=key, checkpoint_interval_s=0.1, fsync_interval_s=None)
with AuditLogger(root, robot_id="amr-9", period_s=0.01, config=config) as log:
    for i in range(cycles):
        with log.cycle() as c:
            fill_cycle(c, "ped_close" if i % 20 < 10 else "blocked")
        print(c.cycle, flush=True)
        time.sleep(0.01)
"""


def _robot(root: Path, key: Path, cycles: int, kill_after: int | None) -> int:
    """Run the robot in a subprocess; SIGKILL it after ``kill_after`` cycles. Last cycle seen."""
    command = [sys.executable, "-c", ROBOT, str(root), str(key), str(cycles)]
    with subprocess.Popen(command, stdout=subprocess.PIPE, text=True, cwd=REPO) as proc:
        assert proc.stdout is not None
        last = -1
        deadline = time.monotonic() + 60
        for line in proc.stdout:
            last = int(line)
            if (kill_after is not None and last >= kill_after) or time.monotonic() > deadline:
                os.kill(proc.pid, signal.SIGKILL)
                break
        proc.wait()
    return last


def test_a_robot_killed_mid_run_and_restarted_verifies_clean(tmp_path: Path) -> None:
    keys = generate_keypair(tmp_path / "keys")
    public = load_public_key(keys.public_path)
    root = tmp_path / "root"
    _robot(root, keys.private_path, 10_000, kill_after=45)
    crashed = verify_log(root, key=public)
    assert crashed.ok, crashed.findings
    assert "recovered" in _kinds(crashed.notes)
    (robot,) = crashed.robots
    assert robot.cycle_range.last_cycle is not None and robot.cycle_range.last_cycle >= 44

    _robot(root, keys.private_path, 30, kill_after=None)  # restarts, continues, closes
    report = verify_log(root, key=public)
    assert report.ok, report.findings
    (robot,) = report.robots
    assert len(report.segments) == 2 and robot.cycle_range.first_cycle == 0
    # The restarted robot's checkpoints vouch for the crashed tail too: the chain goes on.
    assert robot.unanchored_cycles == 0 and robot.anchored_cycle == robot.cycle_range.last_cycle
    numbers = [c.cycle for c in open_log(root).iter_cycles()]
    assert numbers == list(range(len(numbers)))


# --- compacted tiers ---------------------------------------------------------------------------


def _compact(root: Path, tier: str) -> None:
    from trace_runtime.tiers import compact

    report = compact(root, tier, older_than_ns=0, now_ns=10**20, retention_ns=None)
    assert report.segments and all(s.status == "compacted" for s in report.segments)


def test_warm_and_cold_segments_verify_clean(tmp_path: Path) -> None:
    """Warm keeps seals and checkpoints (summaries say so); cold decodes to the same bytes."""
    signer = Ed25519Signer.generate()
    root = tmp_path / "root"
    routine = ("ped_far",) * 5 + ("ped_close",)  # long routine stretches get summarised
    write_signed_log(root, signer, 160, max_segment_s=4.0, situations=routine)
    hot = verify_log(root, key=signer.public_key)
    assert hot.ok and hot.cycles_summarised == 0
    _compact(root, "warm")
    warm = verify_log(root, key=signer.public_key)
    assert warm.ok, warm.findings
    assert {s.tier for s in warm.segments} == {"warm"}
    assert 0 < warm.cycles_summarised < 160 and warm.cycles_valid == 160
    assert warm.checkpoints == warm.checkpoints_valid == hot.checkpoints
    notes = [n for n in warm.notes if n.kind == "summarised"]
    assert notes and "chain verified, payloads not retained" in notes[0].message
    _compact(root, "cold")
    cold = verify_log(root, key=signer.public_key)
    assert cold.ok, cold.findings
    assert {s.tier for s in cold.segments} == {"cold"}
    assert (cold.cycles_valid, cold.cycles_summarised) == (160, warm.cycles_summarised)
    assert cold.robots[0].anchored_cycle == 159


def test_a_crashed_segment_compacted_later_is_not_called_truncated(tmp_path: Path) -> None:
    """Compaction writes a finished file from a crashed one; that is not a cut."""
    signer = Ed25519Signer.generate()
    root = tmp_path / "root"
    config = LoggerConfig(
        threaded=False, fsync_interval_s=None, checkpoint_interval_s=1.0, checkpoint_key=signer
    )
    crashed = AuditLogger(root, robot_id="amr-7", config=config)
    for i in range(45):
        with crashed.cycle(T0_NS + i * PERIOD_NS) as c:
            fill_cycle(c, "ped_far")
    assert crashed._segment is not None
    simulate_crash(crashed)  # killed: no closing checkpoint, no summary
    restarted = AuditLogger(root, robot_id="amr-7", config=config)
    for i in range(45, 80):
        with restarted.cycle(T0_NS + i * PERIOD_NS) as c:
            fill_cycle(c, "ped_close")
    restarted.close()
    for tier in ("hot", "warm", "cold"):
        if tier != "hot":
            _compact(root, tier)
        report = verify_log(root, key=signer.public_key)
        assert report.ok, (tier, report.findings)
        assert report.cycles_valid == 80 and report.robots[0].unanchored_cycles == 0


def test_a_segment_in_two_tiers_mid_compaction_is_verified_once_counted_once(
    tmp_path: Path,
) -> None:
    signer = Ed25519Signer.generate()
    root = tmp_path / "root"
    write_signed_log(root, signer, 60, max_segment_s=2.0)
    hot_copy = (root / "hot" / "amr-7_000001.mcap").read_bytes()
    _compact(root, "cold")
    (root / "hot" / "amr-7_000001.mcap").write_bytes(hot_copy)  # as if the swap was cut short
    report = verify_log(root, key=signer.public_key)
    assert report.ok, report.findings
    assert (report.cycles, report.cycles_valid, report.declared_dropped) == (60, 60, 0)
    assert len(report.segments) == 4 and [s.copy for s in report.segments].count(True) == 1
    (note,) = [n for n in report.notes if n.kind == "duplicate_segment"]
    assert note.segment_no == 1 and "hot, cold" in note.message


def test_a_damaged_cold_segment_is_a_finding(tmp_path: Path) -> None:
    root = tmp_path / "root"
    write_signed_log(root, Ed25519Signer.generate(), 60, max_segment_s=2.0)
    _compact(root, "cold")
    victim = root / "cold" / "amr-7_000001.mcap"
    data = bytearray(victim.read_bytes())
    data[open_segment(victim).chunks()[0].offset + 200] ^= 0x55  # inside the cold block
    victim.write_bytes(bytes(data))
    report = verify_log(root)
    assert not report.ok
    assert any(f.segment.endswith(victim.name) for f in report.findings), report.findings


def test_a_damaged_segment_in_a_root_is_a_finding_not_a_crash(tmp_path: Path) -> None:
    root = tmp_path / "root"
    write_log(root)
    (root / "hot" / "amr-7_000001.mcap").write_bytes(b"\x89MCAP0\r\n garbage")
    report = verify_log(root)
    assert "damaged" in _kinds(report.findings) and report.cycles_valid == 100
    with pytest.raises(LogReadError):
        verify_log(root / "hot" / "amr-7_000001.mcap")


def test_bytes_flipped_anywhere_in_a_segment_never_crash_verify(tmp_path: Path) -> None:
    """Damage in any record (schemas, metadata, chunks, summary): a report or exit 3."""
    root = tmp_path / "root"
    write_log(root)
    path = root / "hot" / "amr-7_000000.mcap"
    original = path.read_bytes()
    # The compressed records of each chunk (past its header: times, sizes, CRC, compression).
    chunks = [
        (c.offset + 64, c.offset + 9 + struct.unpack_from("<Q", original, c.offset + 1)[0])
        for c in open_segment(path).chunks()
    ]
    for at in range(8, len(original) - 8, len(original) // 150):
        data = bytearray(original)
        data[at] ^= 0xA5
        path.write_bytes(bytes(data))
        try:
            report = verify_log(root)
        except LogReadError:
            continue
        if any(a <= at < b for a, b in chunks):
            assert not report.ok, at  # message data is covered


def test_drops_declared_by_the_first_seal_a_log_holds_are_reported(tmp_path: Path) -> None:
    """The log directory deleted under the robot: the next segment's first seal declares the
    cycles that went with it, and verify counts them although nothing precedes that seal."""
    root = tmp_path / "root"
    logger = AuditLogger(root, robot_id="amr-1", period_s=0.1, config=LoggerConfig(threaded=False))
    for i in range(30):
        if i == 20:
            shutil.rmtree(root)
        with logger.cycle(T0_NS + i * PERIOD_NS) as c:
            fill_cycle(c, "ped_far")
    logger.close()
    report = verify_log(root)
    assert report.ok
    assert report.declared_dropped == 20
    assert [n.kind for n in report.notes if n.kind == "declared_gap"] == ["declared_gap"]
