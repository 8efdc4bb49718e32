"""One live writer per robot and log root (``trace_runtime.logger.lock``): a second logger
is refused, in the same process or another, and ``kill -9`` releases the lock."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from tests.trace_runtime.robot_helpers import lock_holder, log_cycles
from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.errors import LogLockedError, UnsafePathError


def test_a_second_logger_for_the_same_robot_and_root_is_refused(tmp_path: Path) -> None:
    root = tmp_path / "root"
    first = AuditLogger(root, robot_id="r")
    with pytest.raises(LogLockedError, match=f"pid {os.getpid()}") as caught:
        AuditLogger(root, robot_id="r")
    assert caught.value.pid == os.getpid()
    log_cycles(first, range(3))
    first.close()  # releases the lock
    second = AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False))
    log_cycles(second, range(3, 5))
    second.close()
    assert [c.cycle for c in open_log(root).iter_cycles()] == list(range(5))


def test_a_second_logger_on_the_same_file_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    first = AuditLogger(path, robot_id="r", config=LoggerConfig(threaded=False))
    with pytest.raises(LogLockedError):
        AuditLogger(path, robot_id="other", config=LoggerConfig(threaded=False))
    first.close()


def test_a_file_inside_a_root_takes_the_robots_root_lock(tmp_path: Path) -> None:
    """A second logger given a segment path inside the root (not the root) would fork the
    chain of the logger writing the root; it is refused like one given the root."""
    root = tmp_path / "root"
    first = AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False))
    with pytest.raises(LogLockedError):
        AuditLogger(root / "hot" / "r_000007.mcap", robot_id="r")
    first.close()


def test_two_robots_on_one_root_are_independent(tmp_path: Path) -> None:
    root = tmp_path / "root"
    a = AuditLogger(root, robot_id="a", config=LoggerConfig(threaded=False))
    b = AuditLogger(root, robot_id="b", config=LoggerConfig(threaded=False))
    log_cycles(a, range(3))
    log_cycles(b, range(4))
    a.close()
    b.close()
    robots = {s.session.robot_id for s in open_log(root).segments}
    assert robots == {"a", "b"}


def test_a_live_process_holds_the_lock_and_kill_9_releases_it(tmp_path: Path) -> None:
    root = tmp_path / "root"
    with lock_holder(root, 5) as holder:
        with pytest.raises(LogLockedError, match=f"pid {holder.pid}"):
            AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False))
        holder.send_signal(signal.SIGKILL)
        holder.wait(10)
    # The kernel released the lock with the process: no stale lock, and the chain goes on.
    logger = AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False))
    log_cycles(logger, range(5, 8))
    logger.close()
    assert [c.cycle for c in open_log(root).iter_cycles()] == list(range(8))


def test_a_link_planted_at_the_lock_name_is_refused_and_its_target_untouched(
    tmp_path: Path,
) -> None:
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me\n")
    root = tmp_path / "root"
    (root / ".locks").mkdir(parents=True)
    (root / ".locks" / "r.lock").symlink_to(victim)
    with pytest.raises(UnsafePathError, match="symbolic link"):
        AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False))
    assert victim.read_text() == "keep me\n"
