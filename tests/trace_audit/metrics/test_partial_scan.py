"""The scan's partial decoding (``trace_runtime.encoding.partial``) scores every decision as the
whole layers do, and hands a sink (the fleet index's rows) what the whole layers give it: a
scan that reads every layer in full is the reference. A message orjson refuses still fails
the scan as before where its seal does not vouch for it."""

from __future__ import annotations

from pathlib import Path

import pytest

from sim import FaultRates, RunConfig, run
from tests.trace_runtime import hostile
from tests.trace_runtime.conftest import write_log
from trace_audit.fleet.rows import ROW_TABLES, SegmentRows
from trace_audit.metrics import MetricsConfig, scan
from trace_audit.metrics.scan import score_segment
from trace_audit.metrics.sums import DecisionSink, ScanResult
from trace_runtime.errors import PayloadError
from trace_runtime.reading.reader import open_segment

FAULTS = FaultRates(
    lidar_unavailable=0.05,
    camera_unavailable=0.15,
    evidence_corruption=0.08,
    edge_write_failure=0.08,
    rationale_truncation=0.06,
    counterfactual_timeout=0.06,
    audit_write_timeout=0.04,
)


def _whole(path: Path, config: MetricsConfig, sink: DecisionSink | None = None) -> ScanResult:
    """The scan on whole layers: every layer parsed in full (``Cycle.layer``), no shape."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(scan, "read_layer", lambda cycle, shape: cycle.layer(shape.topic))
        return score_segment(path, None, config, sink)


def test_the_index_rows_are_the_same_from_its_shapes_and_from_whole_layers(
    tmp_path: Path,
) -> None:
    result = run(RunConfig(out=tmp_path / "run.mcap", total_cycles=600, seed=5, faults=FAULTS))
    (path,) = result.segments
    config = MetricsConfig(max_listed=0)
    shaped = SegmentRows(open_segment(path), previous_command=None, run=None)
    whole = SegmentRows(open_segment(path), previous_command=None, run=None)
    assert score_segment(path, None, config, shaped) == _whole(path, config, whole)
    assert shaped.decisions == result.written > 500
    for name in ROW_TABLES:
        table, days = shaped.table(name)
        reference, reference_days = whole.table(name)
        assert table.equals(reference), name
        assert days == reference_days
    # every column the shapes feed holds values (none left out by a key not declared)
    entities = shaped.table("entities")[0].to_pydict()
    for column in ("entity", "class", "confidence", "distance", "x", "y"):
        assert any(v is not None for v in entities[column]), column
    assert any(entities["evidence"])
    decisions = shaped.table("decisions")[0].to_pydict()
    for column in ("lead_factor", "lead_value", "factors", "nearest"):
        assert any(decisions[column]), column
    assert any(decisions["alternatives"]) and any(decisions["counterfactuals"])


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
