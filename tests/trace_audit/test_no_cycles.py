"""A log that holds no decision cycle, only sensor readings and a checkpoint (its seals
gone: rewritten with the plain ``mcap`` Writer), spans 0-4.9 s. A question at a time inside
that span is answered with what is wrong, the log holds no decision cycles (exit 3, as
``metrics`` says), not with a time "outside the log's range"."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.outside import cli, one_line
from tests.trace_audit.conftest import rewrite_segment
from trace_runtime import AuditLogger, LoggerConfig


@pytest.fixture(scope="module")
def no_cycles(tmp_path_factory: pytest.TempPathFactory) -> Path:
    where = tmp_path_factory.mktemp("no-cycles")
    logger = AuditLogger(where / "root", robot_id="r", config=LoggerConfig(threaded=False))
    for i in range(50):
        with logger.cycle(i * 100_000_000) as cycle:
            cycle.sensor("/sensors/lidar", {"i": i})
    logger.close()
    return rewrite_segment(
        where / "root" / "hot" / "r_000000.mcap",
        where / "sensors-only.mcap",
        lambda m: None if m.topic == "/trace/seal" else m.data,
    )


@pytest.mark.parametrize(
    "args",
    [
        ("explain", "--t", "2"),
        ("export", "--t", "2"),
        ("metrics",),
    ],
    ids=lambda a: a[0],
)
def test_a_log_without_decision_cycles_says_so(
    no_cycles: Path, tmp_path: Path, args: tuple[str, ...]
) -> None:
    extra = ("--out", str(tmp_path / "out.mcap")) if args[0] == "export" else ()
    done = cli(args[0], no_cycles, *args[1:], *extra)
    one_line(done, 3, "the log holds no decision cycles")
    assert "outside the log's range" not in done.stderr
