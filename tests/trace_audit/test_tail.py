"""``trace-audit tail``: a robot logging in another process, watched from a terminal.

The robot logs when the test tells it to (one line on its stdin: how many cycles), so each
check measures how soon after a write its decision change is printed."""

from __future__ import annotations

import contextlib
import json
import queue
import signal
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.outside import REPO, cli

COMMANDS = ("STOP", "SLOW", "CONTINUE")

ROBOT = """
    import sys
    from trace_runtime import AuditLogger, LoggerConfig
    from trace_runtime.testing import synthetic_cycle
    commands = ("STOP", "SLOW", "CONTINUE")
    config = LoggerConfig(threaded=False, max_segment_s=float(sys.argv[2]))
    log = AuditLogger(sys.argv[1], robot_id="r", config=config)
    i = 0
    for line in sys.stdin:
        for _ in range(int(line)):
            p, b, a, e = synthetic_cycle(i)
            a = a.model_copy(update={"command": commands[(i // 3) % 3]})
            log.log_cycle(i * 100_000_000, perception=p, belief=b, action=a, execution=e)
            i += 1
        print(i, flush=True)
"""
"""A robot that logs the number of cycles each stdin line asks for (its command changes every
third cycle), rotating every ``argv[2]`` seconds of log time, and answers the count."""

WITHIN_S = 3.0
"""How soon a change must be printed after the robot wrote it: a poll of 0.2 s, a re-read
and a process's scheduling; generous, for a loaded test machine."""


def _log(robot: subprocess.Popen[str], cycles: int) -> None:
    assert robot.stdin is not None and robot.stdout is not None
    robot.stdin.write(f"{cycles}\n")
    robot.stdin.flush()
    assert robot.stdout.readline().strip(), robot.stderr


class _Lines:
    """A process's stdout lines, read on a thread so a test can wait with a timeout; every
    line read is kept in ``seen``."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        assert proc.stdout is not None
        stream = proc.stdout
        self.reader = threading.Thread(target=lambda: [self.lines.put(x) for x in stream])
        self.reader.start()

    def until(self, needle: str, within_s: float) -> tuple[str, float]:
        """The first line holding ``needle`` and how long it took to come."""
        start = time.monotonic()
        while True:
            left = within_s - (time.monotonic() - start)
            try:
                line = self.lines.get(timeout=max(left, 0.001))
            except queue.Empty:
                pytest.fail(f"no line with {needle!r} within {within_s} s: {self.seen}")
            self.seen.append(line)
            if needle in line:
                return line, time.monotonic() - start


@contextlib.contextmanager
def _process(*args: str | Path, stdin: bool = False) -> Iterator[subprocess.Popen[str]]:
    """A fresh Python process of this checkout, killed (when still alive) and its pipes
    closed on the way out."""
    proc = subprocess.Popen(
        [sys.executable, *map(str, args)],
        stdin=subprocess.PIPE if stdin else subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
    )
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(10)
        for stream in (proc.stdin, proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()


def _robot(root: Path) -> contextlib.AbstractContextManager[subprocess.Popen[str]]:
    return _process("-c", textwrap.dedent(ROBOT), root, "1.0", stdin=True)


def _tail(root: Path, *args: str) -> contextlib.AbstractContextManager[subprocess.Popen[str]]:
    return _process("-m", "trace_audit.cli", "tail", root, *args)


def test_follow_prints_each_change_within_a_batch_across_rotation_and_kill_9(
    tmp_path: Path,
) -> None:
    root = tmp_path / "root"
    with _robot(root) as robot:
        _log(robot, 1)
        with _tail(root, "--follow") as follower:
            out = _Lines(follower)
            out.until("r_000000.mcap live", 30)
            first, _ = out.until("cycle 0 ", WITHIN_S)
            assert "STOP" in first and "leading" in first and "because" in first
            waits: list[float] = []
            for n in range(1, 12):  # cycles 1..33: three rotations (10 cycles a segment)
                _log(robot, 3)
                line, took = out.until(f"cycle {3 * n} ", WITHIN_S)
                assert f"{COMMANDS[(n - 1) % 3]} -> {COMMANDS[n % 3]}" in line, line
                waits.append(took)
            robot.send_signal(signal.SIGKILL)
            robot.wait(10)
            out.until("r_000003.mcap recovered", WITHIN_S)  # the writer is gone: not live
            follower.send_signal(signal.SIGINT)
            assert follower.wait(10) == 0
            out.reader.join(10)
            assert follower.stderr is not None
            errors = follower.stderr.read()
    assert "Traceback" not in errors and "interrupted" not in errors, errors
    assert max(waits) < WITHIN_S, waits
    shown = "\n".join(out.seen)
    for number in range(3):  # followed the logger from file to file as it rotated
        assert f"r_00000{number}.mcap finished" in shown, shown
        assert f"r_00000{number + 1}.mcap live" in shown, shown
    changes = [line for line in out.seen if " cycle " in line]
    assert len(changes) == 12, changes  # cycle 0, then every third: each printed once


def test_sigint_ends_a_follow_of_a_quiet_log_with_exit_0(tmp_path: Path) -> None:
    root = tmp_path / "root"
    with _robot(root) as robot:
        _log(robot, 4)
        with _tail(root, "--follow", "--json") as follower:
            out = _Lines(follower)
            line, _ = out.until('"cycle":3', 30)
            time.sleep(0.5)  # idle polls, then Ctrl-C
            follower.send_signal(signal.SIGINT)
            assert follower.wait(10) == 0
            out.reader.join(10)
            assert follower.stderr is not None
            errors = follower.stderr.read()
    assert "Traceback" not in errors, errors
    change = json.loads(line)
    assert change["kind"] == "change" and change["previous"] == "STOP"
    assert change["command"] == "SLOW" and change["t_ns"] == 300_000_000
    assert change["leading"]["name"] == "distance" and change["t"] == "0.300 s"


def test_without_follow_the_changes_so_far_of_the_newest_segment_then_exit(
    tmp_path: Path,
) -> None:
    root = tmp_path / "root"
    with _robot(root) as robot:
        _log(robot, 25)  # segments of cycles 0-9, 10-19 and 20-24, the last being written
        done = cli("tail", root, "--json")
    assert done.returncode == 0, done.stderr
    events = [json.loads(line) for line in done.stdout.splitlines()]
    assert events[0] == {
        "robot": "r",
        "segment": "r_000002.mcap",
        "status": "live",
        "kind": "segment",
    }
    changes = [(e["cycle"], e["previous"], e["command"]) for e in events[1:]]
    # the first cycle read opens the list; then every third cycle changes the command
    assert changes == [(20, None, "STOP"), (21, "STOP", "SLOW"), (24, "SLOW", "CONTINUE")]
    after = cli("tail", root)  # the robot was killed: its open segment is recovered
    assert after.returncode == 0, after.stderr
    assert after.stdout.startswith("-- r: r_000002.mcap recovered"), after.stdout
    assert "warning" not in after.stderr, after.stderr


def test_an_unknown_robot_or_a_file_is_a_usage_error(tmp_path: Path) -> None:
    root = tmp_path / "root"
    with _robot(root) as robot:
        _log(robot, 2)
        unknown = cli("tail", root, "--robot", "nobody")
        a_file = cli("tail", next(root.rglob("*.mcap")))
    for done in (unknown, a_file):
        assert done.returncode == 2, done.stderr
        assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr


def test_a_missing_path_is_unreadable_input_like_other_commands(tmp_path: Path) -> None:
    done = cli("tail", tmp_path / "nope")
    assert done.returncode == 3, done.stderr
    assert done.stderr.count("\n") == 1 and "no such file or directory" in done.stderr
    assert "log root" not in done.stderr


def test_a_change_right_after_a_gap_is_shown_after_a_gap_line(tmp_path: Path) -> None:
    from tests.trace_audit.conftest import write_log

    # cycles 20..39 dropped (2 s at 10 Hz); cycle 40 is the first STOP
    root = write_log(tmp_path / "root", skip=lambda i: 20 <= i < 40)
    done = cli("tail", root)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    at = next(i for i, line in enumerate(lines) if "cycle 40" in line and "-> STOP" in line)
    gap = lines[at - 1]
    assert "cycle 40  GAP of 2.0 s after cycle 19" in gap, lines
    assert "cycles 20..39 not logged, 20 declared dropped" in gap, lines
    assert sum("GAP" in line for line in lines) == 1, lines  # the one rule: one gap

    events = [json.loads(x) for x in cli("tail", root, "--json").stdout.splitlines()]
    gaps = [e for e in events if e["kind"] == "gap"]
    assert len(gaps) == 1
    assert gaps[0] | {"segment": None} == {
        "robot": "amr-7",
        "segment": None,
        "after_cycle": 19,
        "cycle": 40,
        "t_ns": 104_000_000_000,
        "gap_ns": 2_000_000_000,
        "missing_cycles": 20,
        "declared_dropped": 20,
        "kind": "gap",
        "t": "104.000 s",
        "not_logged": "cycles 20..39 not logged, 20 declared dropped by the logger",
    }
    kinds = [e["kind"] for e in events if e.get("cycle") == 40]
    assert kinds == ["gap", "change"]


def test_a_robot_asked_for_is_waited_for_when_following(tmp_path: Path) -> None:
    root = tmp_path / "root"
    root.mkdir()
    with _tail(root, "--robot", "r", "--follow") as follower:
        out = _Lines(follower)
        time.sleep(1.0)  # tail is up before the robot boots, and waits
        assert follower.poll() is None
        with _robot(root) as robot:
            _log(robot, 1)
            out.until("r_000000.mcap live", WITHIN_S)
            first, _ = out.until("cycle 0 ", WITHIN_S)
            assert "STOP" in first
        follower.send_signal(signal.SIGINT)
        assert follower.wait(10) == 0
        out.reader.join(10)


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM])
def test_a_root_that_does_not_exist_yet_is_waited_for_when_following(
    tmp_path: Path, stop: signal.Signals
) -> None:
    """Like ``tail -F``: one line on stderr says it waits; the robot then creates the root;
    Ctrl-C or SIGTERM (a service manager) ends it with exit 0."""
    root = tmp_path / "not-yet" / "root"
    with _tail(root, "--follow") as follower:
        out = _Lines(follower)
        time.sleep(1.0)  # tail is up before the robot boots, and waits
        assert follower.poll() is None
        with _robot(root) as robot:
            _log(robot, 1)
            out.until("r_000000.mcap live", WITHIN_S)
            first, _ = out.until("cycle 0 ", WITHIN_S)
            assert "STOP" in first
        follower.send_signal(stop)
        assert follower.wait(10) == 0
        out.reader.join(10)
        assert follower.stderr is not None
        errors = follower.stderr.read()
    assert errors.count("\n") == 1 and "does not exist yet; waiting" in errors, errors
    assert str(root) in errors


def test_sigterm_ends_a_follow_waiting_for_a_root_with_exit_0(tmp_path: Path) -> None:
    with _tail(tmp_path / "nope", "--follow", "--json") as follower:
        time.sleep(1.0)
        follower.send_signal(signal.SIGTERM)
        assert follower.wait(10) == 0
        assert follower.stdout is not None and follower.stdout.read() == ""
