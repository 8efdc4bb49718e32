"""``trace-audit`` as a real process on files an attacker prepared (decompression bombs,
floods, hostile payloads): exit 3 with one line on stderr, or a ``damaged`` finding from
``verify``; never a traceback, and within bounds of time and memory.

The bounds here are generous for a loaded 2-core machine; ``bench/bench_hostile.py`` prints
the figures. Each file is built from the outside with the plain ``mcap`` library.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.trace_runtime import hostile
from tests.trace_runtime.conftest import write_log

MAX_SECONDS = 10.0
MAX_RSS_MB = 400.0

FILES: dict[str, Callable[[Path], Path]] = {
    "zstd-bomb": hostile.zstd_bomb,
    "zstd-bomb-declared-4k": lambda p: hostile.zstd_bomb(p, declared=4096),
    "zstd-bomb-declared-4k-crashed": lambda p: hostile.zstd_bomb(p, declared=4096, summary=False),
    "flood-one-chunk": hostile.flood,
    "flood-245-chunks": lambda p: hostile.flood(p, chunks=245),
    "flood-245-chunks-crashed": lambda p: hostile.flood(p, chunks=245, summary=False),
    "declares-2**62": hostile.huge_declared,
    "declares-2**62-crashed": lambda p: hostile.huge_declared(p, summary=False),
    "lz4-bomb": hostile.lz4_bomb,
    "lz4-bomb-declared-4k": lambda p: hostile.lz4_bomb(p, declared=4096),
}


@pytest.fixture(scope="module")
def hostile_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("hostile")
    for name, build in FILES.items():
        build(root / f"{name}.mcap")
    return root


def _assert_refused(run: hostile.Run, command: str) -> None:
    assert "Traceback" not in run.stderr, run.stderr
    assert run.seconds < MAX_SECONDS, run
    assert run.rss_mb < MAX_RSS_MB, run
    if run.code == 1 and command == "verify":
        assert "damaged" in run.stdout and not run.stderr.strip(), run
        return
    assert run.code == 3, run
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("trace-audit: "), run.stderr


@pytest.mark.parametrize("command", ["info", "verify", "metrics"])
@pytest.mark.parametrize("name", list(FILES))
def test_a_hostile_file_is_refused_in_bounded_time_and_memory(
    name: str, command: str, hostile_dir: Path
) -> None:
    run = hostile.run_cli([command, str(hostile_dir / f"{name}.mcap"), "--plain"])
    _assert_refused(run, command)


@pytest.fixture(scope="module")
def honest(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("honest") / "run.mcap"
    write_log(path, 20)
    return path


def _nested(honest: Path, target: Path, topic: str) -> Path:
    deep = hostile.deep_json(100_000)
    return hostile.rewrite(honest, target, lambda t, c, d: deep if t == topic and c == 5 else d)


@pytest.mark.parametrize("command", ["metrics", "timeline", "why"])
def test_json_nested_100000_deep_in_a_layer_is_one_line(
    command: str, honest: Path, tmp_path: Path
) -> None:
    path = _nested(honest, tmp_path / "deep.mcap", "/trace/action")
    extra = ["--action", "STOP"] if command == "why" else []
    run = hostile.run_cli([command, str(path), "--plain", *extra])
    _assert_refused(run, command)
    assert "/trace/action message: not JSON (depth limit exceeded" in run.stderr


def test_json_nested_100000_deep_in_a_seal_fails_that_decision_integrity(
    honest: Path, tmp_path: Path
) -> None:
    """A seal that is not a seal record is a finding about the log (the decision's integrity
    fails; verify calls it modified), not an unreadable file and never a traceback."""
    path = _nested(honest, tmp_path / "deep-seal.mcap", "/trace/seal")
    run = hostile.run_cli(["metrics", str(path), "--json"])
    assert "Traceback" not in run.stderr, run
    assert run.code == 0, run
    assert json.loads(run.stdout)["overall"]["integrity_failed"] >= 1
    run = hostile.run_cli(["verify", str(path), "--plain"])
    assert run.code == 1 and "not a valid seal record" in run.stdout, run


def test_verify_of_a_seal_flood_inside_the_limits_is_bounded(tmp_path: Path) -> None:
    """36,000 identical seals in ~80 KB: each chunk just inside the record limit."""
    seal = b'{"cycle":0,"t_ns":0,"digests":{},"prev":"' + b"0" * 64 + b'","dropped":0}'
    path = hostile.flood(tmp_path / "seals.mcap", total=90 * 400, chunks=400, data=seal)
    run = hostile.run_cli(["verify", str(path), "--plain"], timeout_s=MAX_SECONDS)
    assert run.code == 1 and run.seconds < MAX_SECONDS, run


@pytest.mark.parametrize(
    "override",
    [{"period_ns": "0"}, {"first_cycle": "1e30"}, {"robot_id": "amr 7"}, {"segment": "-1"}],
    ids=lambda o: next(iter(o)),
)
@pytest.mark.parametrize("command", ["info", "verify", "metrics"])
def test_a_bad_session_is_one_line(
    command: str, override: dict[str, str], honest: Path, tmp_path: Path
) -> None:
    path = hostile.rewrite(honest, tmp_path / "s.mcap", metadata=hostile.session(**override))
    run = hostile.run_cli([command, str(path), "--plain"])
    _assert_refused(run, command)
    assert "bad trace.session metadata" in run.stderr and next(iter(override)) in run.stderr
