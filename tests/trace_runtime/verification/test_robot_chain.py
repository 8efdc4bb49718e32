"""``verify`` reads a log through the one owner of multi-file logs
(``trace_runtime.reading.logset``): the same copy of every segment as every other reader, the
same unreadable-file problems; and it agrees with PROFILE §6 that checkpoints are a SHOULD.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from tests.trace_audit.conftest import PERIOD_NS, T0_NS, write_log
from tests.trace_runtime.tier_logs import make_root
from tests.trace_runtime.verification.test_tamper import _write_plain, decode, write_signed_log
from trace_audit.verify import verify_log
from trace_runtime import open_log
from trace_runtime.tiers import compact
from trace_runtime.tlog.keys import Ed25519Signer


def _kinds(items: list) -> list[str]:  # type: ignore[type-arg]
    return [f.kind for f in items]


def _root_with_warm_and_cold_copies(tmp_path: Path) -> Path:
    """Segment 0 in warm (lossy) and in cold (lossless, of the hot original), as a root holds
    it when a hot -> cold compaction ran while an older warm copy was still there."""
    template = make_root(tmp_path / "template", cycles=60, flag_every=0, drop_at=None)
    warm = tmp_path / "warm-run"
    shutil.copytree(template, warm)
    compact(warm, "warm", older_than_ns=0, include_unfinished=True)
    cold = tmp_path / "cold-run"
    shutil.copytree(template, cold)
    compact(cold, "cold", older_than_ns=0, sources=["hot"], include_unfinished=True)
    root = tmp_path / "root"
    (root / "warm").mkdir(parents=True)
    (root / "cold").mkdir()
    (name,) = [p.name for p in (warm / "warm").glob("*.mcap")]
    shutil.copy(warm / "warm" / name, root / "warm" / name)
    shutil.copy(cold / "cold" / name, root / "cold" / name)
    return root


def test_verify_reads_the_copy_every_other_reader_reads(tmp_path: Path) -> None:
    """A lossless cold copy outranks a lossy warm one (logset's one tier policy): verify
    checks every payload of the cold copy and counts the warm one as the spare."""
    root = _root_with_warm_and_cold_copies(tmp_path)
    (read,) = open_log(root).segments
    assert read.session.tier == "cold"
    report = verify_log(root)
    assert report.ok, report.findings
    main = [s for s in report.segments if not s.copy]
    assert [s.tier for s in main] == ["cold"]
    assert report.cycles_summarised == 0 and report.cycles_valid == 60
    assert "duplicate_segment" in _kinds(report.notes)


def test_unreadable_and_foreign_files_come_from_the_log_problems(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", cycles=20)
    (root / "hot" / "zz_garbage.mcap").write_bytes(b"not an mcap file at all")
    foreign = root / "hot" / "zz_foreign.mcap"
    from mcap.writer import Writer

    with open(foreign, "wb") as f:
        writer = Writer(f)
        writer.start(profile="ros2", library="someone else")
        writer.finish()  # type: ignore[no-untyped-call]
    problems = {p.path.name: p.foreign for p in open_log(root).problems}
    assert problems == {"zz_garbage.mcap": False, "zz_foreign.mcap": True}
    report = verify_log(root)
    assert [(f.kind, f.segment) for f in report.findings] == [("damaged", "hot/zz_garbage.mcap")]
    assert ("skipped_file", "hot/zz_foreign.mcap") in [(n.kind, n.segment) for n in report.notes]


# --- PROFILE §6: checkpoints are a SHOULD ------------------------------------------------------


def _without_checkpoints(source: Path, out: Path) -> Path:
    """The same log as another writer (plain ``mcap`` library) that skips checkpoints writes it."""
    decoded = decode(source)
    decoded.units = [u for u in decoded.units if u.kind != "checkpoint"]
    _write_plain(decoded, out)
    return out


def test_a_finished_log_without_any_checkpoint_is_a_note_not_a_finding(tmp_path: Path) -> None:
    signer = Ed25519Signer.generate()
    source = write_signed_log(tmp_path / "signed.mcap", signer, 30)
    path = _without_checkpoints(source, tmp_path / "other-writer.mcap")
    report = verify_log(path)
    assert report.ok, report.findings
    (note,) = [n for n in report.notes if n.kind == "no_checkpoints"]
    assert "end not anchored: no final checkpoint" in note.message
    assert "unanchored" in _kinds(report.notes)
    # With the robot's key the investigator expects signatures: nothing vouches for the log.
    keyed = verify_log(path, key=signer.public_key)
    assert _kinds(keyed.findings) == ["unsigned_checkpoint"]


def test_a_missing_final_checkpoint_is_still_truncation_when_others_exist(tmp_path: Path) -> None:
    signer = Ed25519Signer.generate()
    source = write_signed_log(tmp_path / "signed.mcap", signer, 30)
    decoded = decode(source)
    finals = [i for i, u in enumerate(decoded.units) if u.kind == "checkpoint"]
    assert len(finals) == 3
    del decoded.units[finals[-1]]  # the closing checkpoint only
    path = tmp_path / "cut.mcap"
    _write_plain(decoded, path)
    report = verify_log(path, key=signer.public_key)
    assert _kinds(report.findings) == ["truncated"]
    assert report.findings[0].where.first_cycle == 30


def test_a_half_copied_segment_beside_its_original_is_read_once_and_accuses_nothing(
    tmp_path: Path,
) -> None:
    """A copy cut short (cp interrupted, a disk filled) holds a prefix of the segment: its
    last seal is the original's seal of that cycle. verify notes it instead of calling the
    two a fork, and metrics count each decision once."""
    from trace_audit.metrics import compute_metrics

    root = write_log(tmp_path / "root")
    original = root / "hot" / "amr-7_000000.mcap"
    (root / "hot" / "copy").mkdir()
    half = root / "hot" / "copy" / original.name
    half.write_bytes(original.read_bytes()[: original.stat().st_size // 2])
    report = verify_log(root)
    assert report.ok, report.findings
    assert report.cycles == 100
    (note,) = [n for n in report.notes if n.kind == "duplicate_segment"]
    assert "cut short" in note.message
    assert compute_metrics([root]).overall.decisions == 100
    assert compute_metrics([original, half]).overall.decisions == 100


def test_a_cut_copy_that_differs_from_the_original_is_still_a_fork(tmp_path: Path) -> None:
    """Only a proven prefix is set aside: a truncated copy of another recording at the same
    chain position is read, and verify reports the two heads."""
    root = write_log(tmp_path / "root")
    other = write_log(tmp_path / "other.mcap", skip=lambda i: i == 5)
    (root / "hot" / "copy").mkdir()
    cut = root / "hot" / "copy" / "amr-7_000000.mcap"
    cut.write_bytes(other.read_bytes()[: other.stat().st_size // 2])
    report = verify_log(root)
    assert not report.ok
    assert "modified" in _kinds(report.findings)


def _half(src: Path, dst: Path) -> Path:
    dst.parent.mkdir(parents=True, exist_ok=True)
    dst.write_bytes(src.read_bytes()[: src.stat().st_size // 2])
    return dst


def test_a_half_copy_of_a_crashed_segment_gives_way_to_the_longer_recovered_file(
    tmp_path: Path,
) -> None:
    """Both files are unfinished (the robot was killed): the longer one is read, wherever
    it sorts, and the half copy is noted as cut short, not a fork."""
    from trace_audit.metrics import compute_metrics

    root = write_log(tmp_path / "root", finish=False)
    crashed = root / "hot" / "amr-7_000000.mcap"
    alone = verify_log(root)
    half = _half(crashed, root / "hot" / "amr-7_000000-copy.mcap")  # sorts after, read first
    report = verify_log(root)
    assert report.ok, report.findings
    assert report.cycles == alone.cycles
    assert compute_metrics([root]).overall.decisions == alone.cycles
    assert compute_metrics([half, crashed]).overall.decisions == alone.cycles
    assert open_log(root).shadowed[0].path == half


def test_a_cut_hot_copy_beside_the_intact_cold_segment_is_not_read(tmp_path: Path) -> None:
    """The original was compacted to cold; a half copy of the hot file sits in hot/: the
    intact cold copy is read (every cycle), and nothing is called modified."""
    root = write_log(tmp_path / "root")
    hot = root / "hot" / "amr-7_000000.mcap"
    saved = hot.read_bytes()
    compact(root, "cold", older_than_ns=0)
    assert not hot.exists()
    (root / "hot" / "amr-7_000000.mcap").write_bytes(saved[: len(saved) // 2])
    report = verify_log(root)
    assert report.ok, report.findings
    assert report.cycles == 100
    log = open_log(root)
    assert [s.session.tier for s in log.segments] == ["cold"]
    assert log.end_ns - log.start_ns == 99 * 100_000_000


def test_a_fork_is_read_once_and_still_reported(tmp_path: Path, caplog) -> None:  # type: ignore[no-untyped-def]
    """Another recording's cut file at the same position: the finished original is read
    (counted once), a warning names both files, and verify reports the fork."""
    from trace_audit.metrics import compute_metrics

    root = write_log(tmp_path / "root")
    other = write_log(tmp_path / "other.mcap", skip=lambda i: i == 5)
    _half(other, root / "hot" / "amr-7_000000-copy.mcap")
    with caplog.at_level("WARNING", logger="trace_runtime"):
        log = open_log(root)
    assert [s.path.name for s in log.segments] == ["amr-7_000000.mcap"]
    assert "two different recordings of segment 0" in caplog.text
    assert compute_metrics([root]).overall.decisions == 100
    report = verify_log(root)
    assert not report.ok and "modified" in _kinds(report.findings)
    assert report.cycles == 100


def test_a_segment_starting_at_the_instant_its_predecessor_ended_is_one_clock_run(
    tmp_path: Path,
) -> None:
    """``clock.clock_restarted``: only a time earlier than the chain's last is a restart; a
    segment whose first cycle has the very time the one before ended on stays one run."""
    root = write_log(tmp_path / "root")
    last_ns = T0_NS + 99 * PERIOD_NS
    write_log(root, t0_ns=last_ns)  # the same robot again, starting on the same instant
    report = verify_log(root)
    assert report.ok, report.findings
    assert "clock_restart" not in _kinds(report.notes)
    assert [r.cycle_range.end_ns for r in report.robots] == [last_ns + 99 * PERIOD_NS]

    earlier = write_log(tmp_path / "earlier")
    write_log(earlier, t0_ns=last_ns - 1)  # one nanosecond back: a restart
    (note,) = [n for n in verify_log(earlier).notes if n.kind == "clock_restart"]
    assert (note.segment_no, note.where.first_cycle, note.where.start_ns) == (1, 100, last_ns - 1)
