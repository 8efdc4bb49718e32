"""Metrics on small logs written by hand with the plain ``mcap`` Writer, values known exactly.

These logs do not go through our logger: the payloads are JSON built here, the seals are
computed with hashlib, so the metrics are checked against the format, not against our code.
"""

from __future__ import annotations

import hashlib
import json
import statistics
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from mcap.writer import Writer

from trace_audit.log_time import hour_of
from trace_audit.metrics import (
    MetricsConfig,
    MetricsReport,
    TCSWeights,
    compute_metrics,
    parse_thresholds,
)
from trace_runtime.errors import UsageError
from trace_runtime.tiers import compact

SCHEMAS = Path(__file__).resolve().parents[3] / "schemas"
GENESIS = "0" * 64
PERIOD = 100_000_000
T0 = 5_000_000_000
LAYERS = ("perception", "belief", "action", "execution")


def _json(value: Any) -> bytes:
    return json.dumps(value, separators=(",", ":")).encode()


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


@dataclass
class HandLog:
    """Writes a TRACE segment with the plain mcap Writer; seals by hand."""

    path: Path
    robot: str = "amr-7"
    segment: int = 0
    prev_seal: str = GENESIS
    first_cycle: int = 0
    channels: dict[str, int] = field(default_factory=dict)
    sequences: dict[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._file = self.path.open("wb")
        self.writer = Writer(self._file)
        self.writer.start(profile="trace", library="hand-built test log")
        self.writer.add_metadata(
            "trace.session",
            {
                "robot_id": self.robot,
                "period_ns": str(PERIOD),
                "segment": str(self.segment),
                "prev_seal": self.prev_seal,
                "first_cycle": str(self.first_cycle),
                "tier": "hot",
                "profile_version": "1",
            },
        )

    def _channel(self, topic: str) -> int:
        if topic not in self.channels:
            name = "trace." + topic.rsplit("/", 1)[-1].capitalize()
            if not topic.startswith("/trace/"):
                name = "trace.Sensor"
            schema = self.writer.register_schema(
                name=name, encoding="jsonschema", data=(SCHEMAS / f"{name}.json").read_bytes()
            )
            self.channels[topic] = self.writer.register_channel(
                topic=topic, message_encoding="json", schema_id=schema
            )
        return self.channels[topic]

    def _write(self, topic: str, t_ns: int, data: bytes, sequence: int) -> None:
        self.writer.add_message(
            self._channel(topic), log_time=t_ns, data=data, publish_time=t_ns, sequence=sequence
        )

    def sensor(self, t_ns: int, reading: Any) -> dict[str, Any]:
        """Write a /sensors/lidar message; return a ref that resolves to it."""
        data = _json(reading)
        seq = self.sequences.get("lidar", 0)
        self.sequences["lidar"] = seq + 1
        self._write("/sensors/lidar", t_ns, data, seq)
        return {
            "topic": "/sensors/lidar",
            "log_time_ns": t_ns,
            "sequence": seq,
            "digest": _sha(data),
        }

    def cycle(
        self,
        cycle: int,
        t_ns: int,
        layers: dict[str, Any],
        *,
        dropped: int = 0,
        tamper: str | None = None,
        seal: bool = True,
    ) -> None:
        digests: dict[str, str] = {}
        for name in LAYERS:
            if name not in layers:
                continue
            data = _json({"cycle": cycle, "t_ns": t_ns, **layers[name]})
            digests[f"/trace/{name}"] = _sha(data)
            if tamper == name:
                data = data.replace(b'"p":0.9', b'"p":0.1')
            self._write(f"/trace/{name}", t_ns, data, cycle)
        if not seal:
            return
        seal_data = _json(
            {
                "cycle": cycle,
                "t_ns": t_ns,
                "digests": digests,
                "prev": self.prev_seal,
                "dropped": dropped,
            }
        )
        self._write("/trace/seal", t_ns, seal_data, cycle)
        self.prev_seal = _sha(seal_data)

    def close(self) -> None:
        self.writer.finish()
        self._file.close()


def layers(
    ref: dict[str, Any] | None,
    *,
    scenario: str | None = "a",
    edge: bool = True,
    truncated: bool = False,
    cf: bool = True,
    none_applicable: bool = False,
    action: bool = True,
) -> dict[str, Any]:
    """One warehouse decision: ped_1 (entity) -> dist -> risk; factors risk and ped_1."""
    out: dict[str, Any] = {
        "perception": {
            "entities": [
                {
                    "id": "ped_1",
                    "class": "person",
                    "pose": {
                        "position": [1.5, 0.0, 0.0],
                        "orientation": [0, 0, 0, 1],
                        "frame": "map",
                    },
                    "velocity": None,
                    "confidence": {"person": 0.9},
                    "evidence": [{"sensor": "lidar", "weight": 1.0, "region": None, "ref": ref}],
                }
            ],
            "sensors_used": ["lidar"],
            "sensors_unavailable": [],
        },
        "belief": {
            "nodes": [
                {
                    "id": "ped_1",
                    "kind": "entity",
                    "label": "",
                    "p": 0.9,
                    "value": None,
                    "unit": None,
                    "entity": "ped_1",
                },
                {
                    "id": "dist",
                    "kind": "state",
                    "label": "",
                    "p": 0.95,
                    "value": 1.5,
                    "unit": "m",
                    "entity": None,
                },
                {
                    "id": "risk",
                    "kind": "state",
                    "label": "",
                    "p": 0.7,
                    "value": 0.7,
                    "unit": None,
                    "entity": None,
                },
            ],
            "edges": [{"parent": "ped_1", "child": "dist", "p": 0.95, "rule": "range"}]
            + ([{"parent": "dist", "child": "risk", "p": 0.8, "rule": "ttc"}] if edge else []),
        },
        "execution": {
            "intended": {"linear": 0.0, "angular": 0.0},
            "actual": {"linear": 0.0, "angular": 0.0},
            "deviation": 0.0,
            "checks": [],
            "flags": [f"scenario:{scenario}"] if scenario else [],
        },
    }
    if action:
        out["action"] = {
            "command": "STOP",
            "parameters": {},
            "score": 0.9,
            "alternatives": [{"command": "SLOW", "score": 0.4, "rejected_because": "too close"}],
            "rationale": {
                "text": "pedestrian at 1.5 m",
                "truncated": truncated,
                "factors": [
                    {"node": "risk", "name": "collision risk", "value": 0.7, "unit": None},
                    {"node": "ped_1", "name": "", "value": 1.5, "unit": "m"},
                ],
            },
            "counterfactuals": (
                [{"factor": "dist", "comparison": ">=", "threshold": 2.0, "would_select": "SLOW"}]
                if cf
                else []
            ),
            "counterfactuals_none_applicable": none_applicable,
            "tree": None,
        }
    return out


def t(i: int) -> int:
    return T0 + i * PERIOD


@pytest.fixture
def known_log(tmp_path: Path) -> Path:
    """Ten logged cycles (two dropped) with one known fault each; see the expectations below."""
    log = HandLog(tmp_path / "known.mcap")
    for i in range(6):
        ref = log.sensor(t(i), {"ranges": [1.5, 1.6], "i": i})
        kind: dict[str, Any] = {}
        if i == 1:
            ref = None  # type: ignore[assignment]  # evidence link lost
        if i == 2:
            kind["edge"] = False  # causal edge dist -> risk not written
        if i == 3:
            kind["truncated"] = True
        if i == 4:
            kind["cf"] = False
        if i == 5:
            kind.update(cf=False, none_applicable=True)
        log.cycle(i, t(i), layers(ref, **kind))
    # cycles 6 and 7 were dropped by the writer: the next seal declares them
    ref = log.sensor(t(8), {"ranges": [9.9]})
    ref["digest"] = _sha(b"something else")  # the ref does not match the logged reading
    log.cycle(8, t(8), layers(ref, scenario="b"), dropped=2)
    ref = log.sensor(t(9), {"ranges": [1.5]})
    log.cycle(9, t(9), layers(ref, scenario="b", action=False))  # sealed, action missing
    ref = log.sensor(t(10), {"ranges": [1.4]})
    log.cycle(10, t(10), layers(ref, scenario=None), tamper="belief")  # altered after sealing
    log.cycle(11, t(11), layers(ref, scenario="b"))  # ref to the previous cycle's reading
    log.close()
    return log.path


ET = {0: 1, 1: 0, 2: 0.5, 3: 1, 4: 1, 5: 1, 8: 0, 9: 0, 10: 1, 11: 1}
ET_PARTIAL = {
    0: 1,
    1: (3 / 5 + 2 / 4) / 2,
    2: (1 / 5 + 1) / 2,
    3: 1,
    4: 1,
    5: 1,
    8: (4 / 5 + 3 / 4) / 2,
    9: 0,
    10: 1,
    11: 1,
}
DR = {0: 1, 1: 1, 2: 1, 3: 0, 4: 0, 5: 1, 8: 1, 9: 0, 10: 1, 11: 1}
# 10: a layer altered after sealing; 8: its sealed evidence ref names other content than
# the reading logged (the one seal check, ``verify_cycle``, which explain and verify use too)
INTACT = {c: int(c not in (8, 10)) for c in ET}
CONTINUITY = {c: (1 / 3 if c == 8 else 1.0) for c in ET}


def _tcs(c: int, w: TCSWeights) -> float:
    if not INTACT[c] and w.integrity_gate:
        return 0.0
    total = w.et + w.et_partial + w.dr + w.continuity + w.integrity
    return (
        w.et * ET[c]
        + w.et_partial * ET_PARTIAL[c]
        + w.dr * DR[c]
        + w.continuity * CONTINUITY[c]
        + w.integrity * INTACT[c]
    ) / total


def test_overall_values_match_the_hand_computation(known_log: Path) -> None:
    report = compute_metrics([known_log], MetricsConfig(max_listed=100))
    o = report.overall
    assert (o.decisions, o.sealed, o.unsealed) == (10, 10, 0)
    assert o.et.mean == pytest.approx(statistics.fmean(ET.values()))
    assert o.et.std == pytest.approx(statistics.pstdev(ET.values()))
    assert o.et.across == "decisions"
    assert o.fully_traceable == 6
    assert o.fully_traceable_share.mean == pytest.approx(0.6)
    assert o.et_partial.mean == pytest.approx(statistics.fmean(ET_PARTIAL.values()))
    assert (o.factors, o.factors_traceable) == (18, 13)
    assert (o.dr, o.reconstructable, o.not_reconstructable) == (pytest.approx(0.7), 7, 3)
    # window: t11 - t0 + one period = 1.2 s; one gap of 0.3 - 0.1 = 0.2 s
    assert o.window_s == pytest.approx(1.2)
    assert (o.gaps, o.gap_s, o.missing_cycles, o.declared_dropped) == (1, pytest.approx(0.2), 2, 2)
    assert o.tc == pytest.approx(1 - 0.2 / 1.2)
    assert (o.integrity_ok, o.integrity_failed) == (8, 2)
    w = TCSWeights()
    assert o.tcs.mean == pytest.approx(statistics.fmean(_tcs(c, w) for c in ET))
    assert o.tcs.std == pytest.approx(statistics.pstdev(_tcs(c, w) for c in ET))


def test_failures_name_each_decision_and_what_is_missing(known_log: Path) -> None:
    report = compute_metrics([known_log], MetricsConfig(max_listed=100))
    by_cycle = {f.cycle: f.problems for f in report.failures}
    assert sorted(by_cycle) == [1, 2, 3, 4, 8, 9, 10]
    assert report.failures_total == 7
    assert any("evidence_ref missing" in p for p in by_cycle[1])
    assert any("factor risk (collision risk): belief_path missing" in p for p in by_cycle[2])
    assert by_cycle[3] == ("DR: rationale truncated",)
    assert by_cycle[4] == ("DR: no counterfactuals and not declared none-applicable",)
    assert any("sensor_reading missing (digest" in p for p in by_cycle[8])
    assert (
        "integrity: sensor reading /sensors/lidar#6 does not match the digest its evidence "
        "ref names"
    ) in by_cycle[8]
    assert "DR: action not logged" in by_cycle[9] and "ET: action not logged" in by_cycle[9]
    assert by_cycle[10] == ("integrity: /trace/belief does not match its seal digest",)
    (gap,) = report.gaps
    assert (
        gap.after_cycle,
        gap.before_cycle,
        gap.gap_ns,
        gap.missing_cycles,
        gap.declared_dropped,
    ) == (5, 8, 2 * PERIOD, 2, 2)


def test_grouping_by_scenario_splits_windows_and_gaps(known_log: Path) -> None:
    report = compute_metrics([known_log], MetricsConfig(by="scenario"))
    groups = {g.name: g for g in report.groups}
    assert list(groups) == ["a", "b", "(none)"]
    a, b, none = groups["a"], groups["b"], groups["(none)"]
    assert (a.decisions, b.decisions, none.decisions) == (6, 3, 1)
    assert a.et.mean == pytest.approx(4.5 / 6)
    assert (a.tc, a.window_s) == (pytest.approx(1.0), pytest.approx(0.6))
    # b holds cycles 8 (after the gap), 9 and 11
    assert (b.window_s, b.gap_s) == (pytest.approx(0.5), pytest.approx(0.2))
    assert b.tc == pytest.approx(0.6)
    assert none.integrity_failed == 1
    across = report.across_groups
    assert across is not None and across.groups == 3 and across.et.across == "scenarios"
    assert across.et.mean == pytest.approx(statistics.fmean([4.5 / 6, 1 / 3, 1.0]))
    assert across.et.std == pytest.approx(statistics.pstdev([4.5 / 6, 1 / 3, 1.0]))
    assert sum(g.window_s for g in report.groups) == pytest.approx(report.overall.window_s)


def test_sensor_window_bound_is_respected(known_log: Path) -> None:
    # with no window, cycle 11's ref to cycle 10's reading no longer resolves
    wide = compute_metrics([known_log], MetricsConfig(max_listed=100))
    narrow = compute_metrics([known_log], MetricsConfig(sensor_window=0, max_listed=100))
    assert 11 not in {f.cycle for f in wide.failures}
    assert 11 in {f.cycle for f in narrow.failures}
    assert narrow.overall.fully_traceable == wide.overall.fully_traceable - 1


def test_gap_tolerance_decides_what_a_gap_is(tmp_path: Path) -> None:
    log = HandLog(tmp_path / "jitter.mcap")
    times = [0, 140, 200, 300, 460, 560]  # ms: +40 ms late is jitter, +60 ms late is a gap
    for i, ms in enumerate(times):
        ref = log.sensor(T0 + ms * 1_000_000, {"i": i})
        log.cycle(i, T0 + ms * 1_000_000, layers(ref))
    log.close()
    strict = compute_metrics([log.path], MetricsConfig(gap_tolerance=0.0)).overall
    default = compute_metrics([log.path], MetricsConfig()).overall
    assert strict.gaps == 2 and strict.gap_s == pytest.approx(0.04 + 0.06)
    assert default.gaps == 1 and default.gap_s == pytest.approx(0.06)
    assert default.tc == pytest.approx(1 - 0.06 / 0.66)


def test_removed_cycle_breaks_the_chain_and_leaves_a_gap(tmp_path: Path) -> None:
    log = HandLog(tmp_path / "cut.mcap")
    for i in range(6):
        ref = log.sensor(t(i), {"i": i})
        if i == 3:
            # written and sealed, then cut out of the file: the seal digest still advances
            log.prev_seal = _sha(b"seal of a cycle that was removed")
            continue
        log.cycle(i, t(i), layers(ref))
    log.close()
    report = compute_metrics([log.path], MetricsConfig(max_listed=10))
    assert report.overall.gaps == 1 and report.overall.declared_dropped == 0
    (failure,) = report.failures
    assert failure.cycle == 4
    assert failure.problems == (
        "integrity: hash chain broken: prev is not the previous seal's digest",
    )


def test_unsealed_tail_counts_as_a_decision_without_integrity(tmp_path: Path) -> None:
    log = HandLog(tmp_path / "tail.mcap")
    for i in range(3):
        ref = log.sensor(t(i), {"i": i})
        log.cycle(i, t(i), layers(ref), seal=(i < 2))
    log.close()
    o = compute_metrics([log.path]).overall
    assert (o.decisions, o.sealed, o.unsealed, o.integrity_failed) == (3, 2, 1, 1)
    assert o.window_s == pytest.approx(0.2)  # the unsealed cycle closes no interval
    assert o.et.mean == 1.0 and o.dr == 1.0
    assert o.tcs.mean == pytest.approx(2 / 3)


def _two_segments(tmp_path: Path) -> Path:
    """Two segments of one robot: the chain, a ref and a drop cross the boundary."""
    (tmp_path / "root").mkdir()
    seg0 = HandLog(tmp_path / "root" / "amr-7_000000.mcap")
    ref = None
    for i in range(4):
        ref = log_ref = seg0.sensor(t(i), {"i": i})
        seg0.cycle(i, t(i), layers(log_ref, scenario="a" if i < 2 else "b"))
    seg0.close()
    seg1 = HandLog(
        tmp_path / "root" / "amr-7_000001.mcap", segment=1, prev_seal=seg0.prev_seal, first_cycle=4
    )
    # the first cycle of segment 1 cites the reading logged in segment 0's last cycle
    seg1.cycle(4, t(4), layers(ref, scenario="b"))
    for i in range(6, 9):  # cycle 5 dropped across the segment boundary
        log_ref = seg1.sensor(t(i), {"i": i})
        seg1.cycle(i, t(i), layers(log_ref, scenario="b"), dropped=1 if i == 6 else 0)
    seg1.close()
    return tmp_path / "root"


def _comparable(report: MetricsReport) -> tuple[Any, ...]:
    return (report.overall, report.groups, report.failures, report.gaps, report.failures_total)


def test_segments_continue_the_chain_and_window_and_processes_agree(tmp_path: Path) -> None:
    root = _two_segments(tmp_path)
    one = compute_metrics([root], MetricsConfig(by="scenario", max_listed=50))
    two = compute_metrics([root], MetricsConfig(by="scenario", max_listed=50, workers=2))
    o = one.overall
    assert o.decisions == 8 and o.fully_traceable == 8 and o.integrity_failed == 0
    assert (o.gaps, o.declared_dropped, o.missing_cycles) == (1, 1, 1)
    assert o.window_s == pytest.approx(0.9)
    assert _comparable(one) == _comparable(two)
    assert len(one.segments) == 2


def test_progress_callback_reaches_the_total(known_log: Path) -> None:
    seen: list[tuple[int, int | None]] = []
    compute_metrics([known_log], progress=lambda done, total: seen.append((done, total)))
    assert seen and seen[-1] == (10, 10)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("ET=0.95,DR=95%", {"ET": 0.95, "DR": 0.95}),
        (" tc = 1 ", {"TC": 1.0}),
        ("et_full=0.5", {"ET_full": 0.5}),
    ],
)
def test_parse_thresholds(text: str, expected: dict[str, float]) -> None:
    assert parse_thresholds(text) == pytest.approx(expected)


@pytest.mark.parametrize("text", ["ET", "ET=95", "XX=0.5", "DR=abc", "TC=-0.1", "ET=nan"])
def test_parse_thresholds_rejects(text: str) -> None:
    with pytest.raises(UsageError):
        parse_thresholds(text)


def test_thresholds_pass_and_fail(known_log: Path) -> None:
    report = compute_metrics([known_log], MetricsConfig(thresholds={"ET": 0.6, "DR": 0.75}))
    checks = {c.metric: c.passed for c in report.thresholds}
    assert checks == {"ET": True, "DR": False} and not report.passed


def test_tcs_weights_are_configurable(known_log: Path) -> None:
    w = TCSWeights.parse("et=1,et_partial=0,dr=0,continuity=0,integrity=0,gate=off")
    report = compute_metrics([known_log], MetricsConfig(weights=w))
    assert report.overall.tcs.mean == pytest.approx(statistics.fmean(ET.values()))
    with pytest.raises(UsageError):
        TCSWeights.parse("et=0,et_partial=0,dr=0,continuity=0,integrity=0")
    with pytest.raises(UsageError):
        TCSWeights.parse("speed=1")


def test_bad_config_is_a_usage_error() -> None:
    with pytest.raises(UsageError):
        MetricsConfig(by="weekday")  # type: ignore[arg-type]
    with pytest.raises(UsageError):
        MetricsConfig(workers=0)


def test_robots_are_separate_streams_and_groups(tmp_path: Path) -> None:
    """Two robots interleaved in time: no false gaps, one chain each, grouped by robot."""
    (tmp_path / "fleet").mkdir()
    logs = [HandLog(tmp_path / "fleet" / f"{name}.mcap", robot=name) for name in ("r1", "r2")]
    for i in range(5):
        for k, log in enumerate(logs):
            if log.robot == "r2" and i == 2:
                continue  # r2 misses one cycle; r1 does not
            at = t(i) + k * 30_000_000  # r2 runs 30 ms after r1
            log.cycle(i, at, layers(log.sensor(at, {"i": i})))
    for log in logs:
        log.close()
    report = compute_metrics([tmp_path / "fleet"], MetricsConfig(by="robot"))
    groups = {g.name: g for g in report.groups}
    assert (groups["r1"].gaps, groups["r2"].gaps) == (0, 1)
    assert groups["r1"].window_s == pytest.approx(0.5) and groups["r1"].tc == 1.0
    assert groups["r2"].tc == pytest.approx(1 - 0.1 / 0.5)
    assert report.overall.integrity_failed == 0
    assert report.overall.window_s == pytest.approx(1.0)


def test_group_by_segment_and_hour(tmp_path: Path) -> None:
    root = _two_segments(tmp_path)
    by_segment = compute_metrics([root], MetricsConfig(by="segment"))
    assert [g.name for g in by_segment.groups] == ["amr-7_000000.mcap", "amr-7_000001.mcap"]
    assert [g.decisions for g in by_segment.groups] == [4, 4]
    by_hour = compute_metrics([root], MetricsConfig(by="hour"))
    assert [g.name for g in by_hour.groups] == ["+0000h"]  # the robot's own clock, not 1970


def test_hours_of_a_wall_clock_are_utc_hours() -> None:
    assert hour_of(1_777_874_665 * 10**9, wall=True) == "2026-05-04 06:00"
    assert hour_of(3 * 3600 * 10**9 + 5, wall=False) == "+0003h"


def test_the_same_segment_in_two_tiers_is_read_once(tmp_path: Path) -> None:
    root = _two_segments(tmp_path)
    (root / "hot").mkdir()
    for path in sorted(root.glob("*.mcap")):
        path.rename(root / "hot" / path.name)
    original = (root / "hot" / "amr-7_000000.mcap").read_bytes()
    compact(root, "cold", older_than_ns=0, retention_ns=None, sources=["hot"])
    # as if the compaction was interrupted before it removed the hot source
    (root / "hot" / "amr-7_000000.mcap").write_bytes(original)
    report = compute_metrics([root])
    assert report.overall.decisions == 8
    (skipped,) = report.skipped_segments
    assert skipped.startswith(str(root / "cold" / "amr-7_000000.mcap") + " (a copy of the same")
    assert report.segments[0] == str(root / "hot" / "amr-7_000000.mcap")


def test_logging_time_is_shown_only_where_logged(tmp_path: Path, known_log: Path) -> None:
    assert compute_metrics([known_log]).logging_time == "not logged"
    log = HandLog(tmp_path / "timed.mcap")
    log.writer.add_metadata("trace.timing", {"commit_mean_ns": "118000", "cycles": "3"})
    for i in range(3):
        log.cycle(i, t(i), layers(log.sensor(t(i), {"i": i})))
    log.close()
    assert compute_metrics([log.path]).logging_time.startswith("0.118 ms mean per cycle")


def test_analysis_window_cuts_without_false_chain_breaks(tmp_path: Path) -> None:
    root = _two_segments(tmp_path)
    config = MetricsConfig(start_ns=t(2), end_ns=t(7), max_listed=50)
    one = compute_metrics([root], config)
    two = compute_metrics(
        [root], MetricsConfig(start_ns=t(2), end_ns=t(7), max_listed=50, workers=2)
    )
    o = one.overall
    assert o.decisions == 5  # cycles 2, 3, 4, 6 and 7 (5 was dropped); both ends inclusive
    assert o.integrity_failed == 0 and o.gaps == 1
    assert o.window_s == pytest.approx(0.6)
    assert _comparable(one) == _comparable(two)
    with pytest.raises(UsageError):
        MetricsConfig(start_ns=t(5), end_ns=t(1))


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_clock_restart_between_segments_is_not_an_anomaly(tmp_path: Path, jobs: int) -> None:
    """Two runs of one robot, the second starting its clock from the same time (PROFILE
    section 4 allows it across segments): counted as a restart, each run its own window;
    a step back inside one segment stays a clock anomaly."""
    from tests.trace_audit.conftest import write_log
    from tests.trace_audit.profile_writer import Faults, write_profile_log

    root = write_log(tmp_path / "root")
    write_log(root)
    overall = compute_metrics([root], MetricsConfig(workers=jobs)).overall
    assert (overall.clock_anomalies, overall.clock_restarts) == (0, 1)
    assert overall.window_s == pytest.approx(2 * 10.0)
    stepped = write_profile_log(tmp_path / "p.mcap", faults=Faults(clock_step_back_at=12))
    inside = compute_metrics([stepped]).overall
    assert (inside.clock_anomalies, inside.clock_restarts) == (1, None)


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_segment_starting_at_the_instant_the_last_ended_is_one_run(
    tmp_path: Path, jobs: int
) -> None:
    """Equal times across segments are one run of the clock (``trace_runtime.clock``, the rule
    verify and ``Log.clock_runs`` use): no restart and no new window; the time that does
    not move on is a clock anomaly, as inside a segment. A time before it is a restart."""
    for name, first_t in (("equal", t(3)), ("earlier", t(2))):
        root = tmp_path / name
        root.mkdir()
        seg0 = HandLog(root / "amr-7_000000.mcap")
        for i in range(4):
            seg0.cycle(i, t(i), layers(seg0.sensor(t(i), {"i": i})))
        seg0.close()
        seg1 = HandLog(
            root / "amr-7_000001.mcap", segment=1, prev_seal=seg0.prev_seal, first_cycle=4
        )
        for i in range(4, 7):
            when = first_t + (i - 4) * PERIOD
            seg1.cycle(i, when, layers(seg1.sensor(when, {"i": i})))
        seg1.close()
        overall = compute_metrics([root], MetricsConfig(workers=jobs)).overall
        if name == "equal":
            assert (overall.clock_anomalies, overall.clock_restarts) == (1, None)
            assert overall.window_s == pytest.approx(0.6)  # t(0) .. t(5) in one window
        else:
            assert (overall.clock_anomalies, overall.clock_restarts) == (0, 1)
            assert overall.window_s == pytest.approx(0.4 + 0.3)  # two windows
        assert overall.gaps == 0 and overall.integrity_failed == 0
