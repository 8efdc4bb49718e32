"""The scan's partial decoding (``trace_runtime.encoding.partial``) scores every decision as the
whole layers do: a scan handed to a sink (which parses every layer in full) is the reference.
A message orjson refuses still fails the scan as before where its seal does not vouch for it."""

from __future__ import annotations

from pathlib import Path

import pytest

from sim import FaultRates, RunConfig, run
from tests.trace_runtime import hostile
from tests.trace_runtime.conftest import write_log
from trace_audit.metrics import MetricsConfig
from trace_audit.metrics.scan import score_segment
from trace_audit.metrics.sums import ScanResult, ScoredDecision
from trace_runtime.errors import PayloadError

FAULTS = FaultRates(
    lidar_unavailable=0.05,
    camera_unavailable=0.15,
    evidence_corruption=0.08,
    edge_write_failure=0.08,
    rationale_truncation=0.06,
    counterfactual_timeout=0.06,
    audit_write_timeout=0.04,
)


def _whole(path: Path, config: MetricsConfig) -> ScanResult:
    """The scan on whole layers: a sink makes it parse every layer in full."""
    seen: list[ScoredDecision] = []
    return score_segment(path, None, config, sink=seen.append)


@pytest.mark.parametrize("by", [None, "scenario"])
def test_a_faulty_sim_log_scores_the_same_from_partial_and_whole_layers(
    tmp_path: Path, by: str | None
) -> None:
    result = run(RunConfig(out=tmp_path / "run.mcap", total_cycles=600, seed=5, faults=FAULTS))
    (path,) = result.segments
    config = MetricsConfig(by=by)  # type: ignore[arg-type]
    partial, whole = score_segment(path, None, config), _whole(path, config)
    assert partial.failures_total > 0  # the faults make failures, listed with their chains
    assert partial == whole


def test_a_damaged_action_fails_as_before_even_in_a_field_metrics_skip(tmp_path: Path) -> None:
    """``1e400`` in the decision tree (a field metrics never read): orjson refuses it, the
    partial decode would not; the cycle's digest no longer matches its seal, so the scan
    parses its layers in full and fails with the same error as before."""
    source = tmp_path / "run.mcap"
    write_log(source, 6)

    def spoil(topic: str, cycle: int, data: bytes) -> bytes:
        if topic == "/trace/action" and cycle == 3:
            return data.replace(b'"taken_path":', b'"x":1e400,"taken_path":', 1)
        return data

    bad = hostile.rewrite(source, tmp_path / "bad.mcap", spoil)
    config = MetricsConfig()
    with pytest.raises(PayloadError) as whole:
        _whole(bad, config)
    with pytest.raises(PayloadError) as partial:
        score_segment(bad, None, config)
    assert str(partial.value) == str(whole.value)
    assert "infinity" in str(partial.value)
