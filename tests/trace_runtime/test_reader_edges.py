"""Reader edge cases: time lookups at chunk boundaries, empty and foreign segments."""

from __future__ import annotations

from pathlib import Path

from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.reader import open_segment
from trace_runtime.testing import synthetic_cycle

PERIOD_NS = 100_000_000


def _write_with_sensor_lead(path: Path, cycles: int, lead_ns: int) -> None:
    """One chunk per cycle; each cycle cites a camera frame taken ``lead_ns`` before it."""
    logger = AuditLogger(path, robot_id="amr-1", config=LoggerConfig(threaded=False))
    for i in range(cycles):
        t_ns = 10 * PERIOD_NS + i * PERIOD_NS
        with logger.cycle(t_ns) as c:
            c.sensor("/sensors/camera", {"frame": i}, t_ns=t_ns - lead_ns)
            c.action(synthetic_cycle(i)[2])
    logger.close()


def test_cycle_at_finds_the_cycle_when_sensor_readings_precede_it_by_several_chunks(
    tmp_path: Path,
) -> None:
    # A camera 250 ms behind a 10 Hz loop: every chunk starts 2.5 periods before its cycle,
    # so the chunks that start at or before t hold only cycles after t for three chunks.
    path = tmp_path / "lead.mcap"
    _write_with_sensor_lead(path, 20, lead_ns=250_000_000)
    segment = open_segment(path)
    for i in range(20):
        t_ns = 10 * PERIOD_NS + i * PERIOD_NS
        for probe in (t_ns, t_ns + PERIOD_NS // 2):
            found = segment.cycle_at(probe)
            assert found is not None and found.cycle == i, (i, probe)
    assert segment.cycle_at(10 * PERIOD_NS - 1) is None
    assert open_log(path).cycle_at(15 * PERIOD_NS + 10).cycle == 5
