"""A segment without a footer is live while its logger writes it, and recovered once the
logger died: told apart by the writer's lock, seen without ever being taken."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import pytest

from tests.outside import cli
from tests.trace_runtime.robot_helpers import lock_holder, log_cycles
from trace_runtime import AuditLogger, LoggerConfig, live_writers, open_log
from trace_runtime.testing import simulate_crash


def _info(root: Path) -> dict[str, object]:
    done = cli("info", root, "--json")
    assert done.returncode == 0, done.stderr
    return dict(json.loads(done.stdout))


def test_a_robot_logging_in_another_process_is_live_and_after_kill_9_recovered(
    tmp_path: Path,
) -> None:
    root = tmp_path / "root"
    with lock_holder(root, 20) as robot:
        live = _info(root)
        assert live["live"] is True and live["recovered"] is False
        verified = cli("verify", root, "--json")
        notes = {n["kind"] for n in json.loads(verified.stdout)["notes"]}
        assert "live" in notes and "recovered" not in notes
        assert "no footer" not in verified.stderr
        explained = cli("explain", root, "--t", "1.0", "--plain")
        words = " ".join(explained.stdout.split())  # the line may wrap
        assert "(live: the log is being written)" in words, explained.stderr
        assert "recovered" not in words
        for command in (("timeline", root), ("why", root, "--action", "STOP")):
            shown = " ".join(cli(*command, "--plain").stdout.split())
            assert "live: the log is being written" in shown, command
        robot.send_signal(signal.SIGKILL)
        robot.wait(10)
    dead = _info(root)
    assert dead["live"] is False and dead["recovered"] is True
    assert dead["cycles"] == 20  # every cycle logged before the kill survived


def test_reading_a_live_log_never_takes_the_writers_lock(tmp_path: Path) -> None:
    """A robot starting while an investigator looks must not be refused its log."""
    root = tmp_path / "root"
    logger = AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False))
    log_cycles(logger, range(5))
    assert open_log(root).live
    logger.close()
    assert not open_log(root).live  # finished: a footer, no longer live
    reader = open_log(root)
    second = AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False))
    log_cycles(second, range(5, 8))
    assert reader.segments and open_log(root).live
    simulate_crash(second)
    reopened = open_log(root)
    assert not reopened.live and reopened.recovered


def test_without_a_lock_table_a_recent_write_counts_as_live(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(live_writers, "_PROC_LOCKS", tmp_path / "no-such-table")
    root = tmp_path / "root"
    logger = AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False))
    log_cycles(logger, range(3))
    simulate_crash(logger)
    segment = open_log(root).segments[0]
    assert segment.live  # written a moment ago: it may be another machine's live writer
    modified = segment.path.stat().st_mtime
    assert (
        live_writers.is_live(segment.path, "r", now=modified + live_writers.RECENT_WRITE_S + 1)
        is False
    )
