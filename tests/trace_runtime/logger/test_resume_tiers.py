"""The logger resumes its chain from segments compacted into the warm or cold tier."""

from __future__ import annotations

import shutil
from pathlib import Path

import orjson
import pytest

from tests.trace_runtime.tier_logs import T0_NS, make_root
from trace_runtime import AuditLogger, LoggerConfig, open_log, open_segment
from trace_runtime.chain import digest
from trace_runtime.records import (
    GENESIS,
    TOPIC_SEAL,
)
from trace_runtime.testing import synthetic_cycle
from trace_runtime.tiers import compact

# --- logger resume across tiers --------------------------------------------------------------


@pytest.mark.parametrize("tier", ["warm", "cold"])
def test_logger_resumes_the_chain_from_compacted_segments(tmp_path: Path, tier: str) -> None:
    root = make_root(tmp_path / "log", cycles=20, segments=2)
    last = list(open_log(root).iter_cycles())[-1]
    compact(root, tier, older_than_ns=0, retention_ns=None)
    assert not list((root / "hot").glob("*.mcap"))
    config = LoggerConfig(threaded=False, fsync_interval_s=None)
    with AuditLogger(root, robot_id="amr-1", period_s=0.1, config=config) as logger:
        p, b, a, e = synthetic_cycle(99)
        logger.log_cycle(T0_NS + 10**11, perception=p, belief=b, action=a, execution=e)
    new = open_segment(next((root / "hot").glob("*.mcap")))
    assert new.session.segment == 2
    assert new.session.prev_seal == digest(last.payloads[TOPIC_SEAL])
    first = next(new.iter_cycles())
    assert first.cycle == last.cycle + 1
    assert orjson.loads(first.payloads[TOPIC_SEAL])["prev"] == digest(last.payloads[TOPIC_SEAL])


def test_resume_ignores_other_robots_with_a_common_prefix(tmp_path: Path) -> None:
    make_root(tmp_path / "log", cycles=5, robot="amr_2")
    shutil.copytree(tmp_path / "log", tmp_path / "copy")
    config = LoggerConfig(threaded=False, fsync_interval_s=None)
    with AuditLogger(tmp_path / "copy", robot_id="amr", period_s=0.1, config=config) as logger:
        assert logger._session.segment == 0
        assert logger._session.prev_seal == GENESIS
