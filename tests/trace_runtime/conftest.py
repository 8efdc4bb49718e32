"""Fixtures for the runtime tests: logs written through the real logger into tmp_path."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from trace_runtime import AuditLogger, LoggerConfig
from trace_runtime.testing import synthetic_cycle

PERIOD_NS = 100_000_000


def write_log(
    path: Path, cycles: int, *, config: LoggerConfig | None = None, robot_id: str = "amr-1"
) -> AuditLogger:
    """Write ``cycles`` synthetic cycles (with a sensor reading each) and close the logger."""
    logger = AuditLogger(
        path, robot_id=robot_id, period_s=0.1, config=config or LoggerConfig(threaded=False)
    )
    for i in range(cycles):
        with logger.cycle(i * PERIOD_NS) as c:
            c.sensor("/sensors/lidar", {"ranges": [1.0 + i / 100, 2.0], "cluster": i})
            p, b, a, e = synthetic_cycle(i)
            c.perception(p)
            c.belief(b)
            c.action(a)
            c.execution(e)
    logger.close()
    return logger


@pytest.fixture
def log_writer() -> Callable[..., AuditLogger]:
    return write_log
