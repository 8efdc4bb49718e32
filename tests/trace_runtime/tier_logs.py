"""Log roots for the tier tests, written by the real logger.

``make_root`` writes a log root whose cycles carry what the warm tier must notice: execution
flags, failed checks, command changes, a dropped cycle, informational ``scenario:*`` flags,
variable-length sensor readings and -0.0.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from trace_runtime import AuditLogger, LoggerConfig
from trace_runtime.records import ComplianceCheck
from trace_runtime.testing import synthetic_cycle

PERIOD_NS = 100_000_000
T0_NS = 1_000_000_000_000


def make_root(
    root: Path,
    cycles: int = 120,
    *,
    robot: str = "amr-1",
    t0_ns: int = T0_NS,
    segments: int = 1,
    flag_every: int = 40,
    drop_at: int | None = 70,
) -> Path:
    """Write ``segments`` hot segments of ``cycles`` cycles each under ``root``."""
    config = LoggerConfig(threaded=False, fsync_interval_s=None)
    index = 0
    for _ in range(segments):
        logger = AuditLogger(root, robot_id=robot, period_s=0.1, config=config)
        for _ in range(cycles):
            i = index
            index += 1
            builder = logger.cycle(t0_ns + i * PERIOD_NS)
            if drop_at is not None and i == drop_at:
                builder.abort()  # the next seal records the gap
                continue
            with builder as c:
                beams = [round(2.0 + 0.01 * ((i * 7 + k) % 13), 3) for k in range(3 + i % 5)]
                c.sensor("/sensors/lidar", {"ranges": beams, "cluster": i, "bias": -0.0})
                perception, belief, action, execution = synthetic_cycle(i, pedestrians=1 + i % 3)
                flags = ["scenario:routine"]
                checks = list(execution.checks)
                if flag_every and i % flag_every == flag_every // 2:
                    flags.append("near_miss")
                if flag_every and i % flag_every == 3:
                    checks.append(ComplianceCheck(rule="max_speed", passed=False, value=2.0))
                c.perception(perception)
                c.belief(belief)
                c.action(action)
                c.execution(execution.model_copy(update={"flags": flags, "checks": checks}))
        logger.close()
    return root


def hot_segment(root: Path) -> Path:
    return next((root / "hot").glob("*.mcap"))


def cycle_key(cycle: Any) -> tuple[Any, ...]:
    return (cycle.cycle, cycle.t_ns, cycle.payloads, cycle.sensors, cycle.summary)
