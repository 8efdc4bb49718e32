"""The logger API as an integrator meets it (issue 15): field docs in ``help()``, a clock
that steps back (a declared step, issue 42), checkpoints on a grid of log time whatever the
batching, the logger's own per-cycle cost at close, and execution channels beside planar
motion."""

from __future__ import annotations

import pydoc
import statistics
from pathlib import Path

import orjson
import pytest
from hypothesis import given
from hypothesis import strategies as st

from trace_runtime import (
    ActuatorChannel,
    AuditLogger,
    Execution,
    LoggerConfig,
    Motion,
    open_log,
    open_segment,
    records,
)
from trace_runtime.costs import TIMING_METADATA, CostHistogram, bucket_bounds, bucket_of
from trace_runtime.encoding.codec import layer_message
from trace_runtime.errors import RecordError, UsageError
from trace_runtime.logger.cycle_builder import COST_SAMPLE_EVERY
from trace_runtime.record_model import RecordModel
from trace_runtime.records import LAYER_MODELS, MESSAGE_MODELS, TOPIC_EXECUTION
from trace_runtime.testing import CaptureLogger, synthetic_cycle
from trace_runtime.tlog.checkpoints import decode_checkpoint, iter_checkpoints

PERIOD_NS = 100_000_000


def _record_classes() -> list[type[RecordModel]]:
    return [
        cls
        for cls in vars(records).values()
        if isinstance(cls, type)
        and issubclass(cls, RecordModel)
        and cls is not RecordModel
        and not cls.__name__.startswith("_")
    ]


# --- help() ----------------------------------------------------------------------------------


@pytest.mark.parametrize("model", _record_classes(), ids=lambda m: m.__name__)
def test_help_on_a_record_class_lists_every_field_with_its_meaning(
    model: type[RecordModel],
) -> None:
    text = pydoc.render_doc(model, renderer=pydoc.plaintext)
    assert "(undocumented)" not in text
    for name, info in model.model_fields.items():
        key = info.alias or name
        assert info.description, f"{model.__name__}.{name} has no description"
        assert f"{key}" in text and info.description.split()[0] in text


def test_help_names_the_json_key_of_a_renamed_field() -> None:
    assert "class (Python: cls): str" in (records.Entity.__doc__ or "")
    assert "not a topic" in (records.Evidence.__doc__ or "")


def test_json_schemas_keep_the_short_class_description() -> None:
    schema = records.Execution.model_json_schema()
    assert "Fields (JSON name" not in schema["description"]
    assert schema["properties"]["channels"]["description"].startswith("intended vs actual")


# --- time going backwards --------------------------------------------------------------------


@pytest.mark.parametrize("make", ["logger", "capture"])
def test_a_cycle_earlier_than_the_previous_one_is_a_clock_step_not_an_error(
    tmp_path: Path, make: str
) -> None:
    """The control loop never sees an exception for a clock that stepped back: the cycle
    keeps its number, and the writer declares the step in the segment it begins."""
    log = (
        AuditLogger(tmp_path / "t.mcap", robot_id="r", config=LoggerConfig(threaded=False))
        if make == "logger"
        else CaptureLogger()
    )
    with log:
        log.log_cycle(5 * PERIOD_NS, action=synthetic_cycle(0)[2])
        log.log_cycle(5 * PERIOD_NS, action=synthetic_cycle(1)[2])  # the same time: no step
        stepped = log.log_cycle(5 * PERIOD_NS - 1, action=synthetic_cycle(2)[2])
        number = log.log_cycle(6 * PERIOD_NS, action=synthetic_cycle(3)[2])
        with pytest.raises(RecordError, match="negative"):
            log.cycle(-1)  # no clock counts below zero: a bug in the robot
    assert (stepped, number, log.stats.clock_steps) == (2, 3, 1)
    if make == "logger":
        before, after = open_segment(tmp_path / "t.mcap"), open_segment(tmp_path / "t.000001.mcap")
        assert [c.cycle for c in before.iter_cycles()] == [0, 1]
        assert [c.cycle for c in after.iter_cycles()] == [2, 3]
        assert after.session.clock_step_from_ns == 5 * PERIOD_NS
        assert before.session.clock_step_from_ns is None
        chain = [(c.cycle, status.state) for c, status in open_log(tmp_path).iter_chain("r")]
        assert chain == [(n, "verified") for n in range(4)]  # one chain across the step


# --- checkpoints on the interval -------------------------------------------------------------


def _checkpoint_times(batch_cycles: int, threaded: bool, path: Path) -> list[tuple[int, bool]]:
    config = LoggerConfig(
        threaded=threaded,
        batch_cycles=batch_cycles,
        fsync_interval_s=None,
        checkpoint_interval_s=10.0,
    )
    start = 1_700_000_000_000_000_000
    with AuditLogger(path, robot_id="r", config=config) as log:
        for i in range(453):
            log.log_cycle(start + i * PERIOD_NS, action=synthetic_cycle(i)[2])
    return [
        ((c.t_ns - start) // PERIOD_NS, c.final)
        for c in map(decode_checkpoint, (m.data for m in iter_checkpoints(open_segment(path))))
    ]


@pytest.mark.parametrize(("batch", "threaded"), [(1, False), (7, False), (64, False), (1, True)])
def test_checkpoints_fall_on_the_interval_in_log_time_whatever_the_batching(
    tmp_path: Path, batch: int, threaded: bool
) -> None:
    got = _checkpoint_times(batch, threaded, tmp_path / "c.mcap")
    # every 100 cycles of 0.1 s from the first, and the final one at close
    assert got == [(100, False), (200, False), (300, False), (400, False), (452, True)]


def test_one_checkpoint_after_a_pause_longer_than_the_interval(tmp_path: Path) -> None:
    path = tmp_path / "p.mcap"
    config = LoggerConfig(threaded=False, fsync_interval_s=None, checkpoint_interval_s=1.0)
    with AuditLogger(path, robot_id="r", config=config) as log:
        for t_s in (0.0, 0.5, 3.7, 3.8, 4.0, 4.9):
            log.log_cycle(round(t_s * 1e9), action=synthetic_cycle(0)[2])
    times = [decode_checkpoint(m.data).t_ns for m in iter_checkpoints(open_segment(path))]
    # due at 1 s: written at 3.7 s (one, not three); next due at 4 s on the same grid
    assert times == [3_700_000_000, 4_000_000_000, 4_900_000_000]


# --- the logger's own cost -------------------------------------------------------------------


def test_the_logger_writes_its_per_cycle_cost_at_close(tmp_path: Path) -> None:
    path = tmp_path / "cost.mcap"
    with AuditLogger(path, robot_id="r", config=LoggerConfig(fsync_interval_s=None)) as log:
        for i in range(200):
            p, b, a, e = synthetic_cycle(i)
            log.log_cycle(i * PERIOD_NS, perception=p, belief=b, action=a, execution=e)
    timing = open_segment(path).metadata[TIMING_METADATA]
    # one cycle in COST_SAMPLE_EVERY is timed: cycles 0, 8, ..., 192
    timed = len(range(0, 200, COST_SAMPLE_EVERY))
    assert (timing["cycles"], timing["sample_every"]) == (str(timed), str(COST_SAMPLE_EVERY))
    histogram = CostHistogram.from_metadata(timing)
    assert histogram is not None and histogram.cycles == timed
    p50, p99 = int(timing["commit_p50_ns"]), int(timing["commit_p99_ns"])
    assert 0 < int(timing["commit_min_ns"]) <= p50 <= p99 <= int(timing["commit_max_ns"])
    assert histogram.percentile_ns(0.5) == p50 and histogram.percentile_ns(0.99) == p99


@given(st.lists(st.integers(min_value=0, max_value=10**10), min_size=1, max_size=300))
def test_histogram_percentiles_are_within_a_sixteenth_of_the_exact_ones(values: list[int]) -> None:
    histogram = CostHistogram()
    for v in values:
        histogram.add(v)
    ordered = sorted(values)
    for q in (0.0, 0.5, 0.99, 1.0):
        exact = ordered[min(len(ordered) - 1, int(q * len(ordered)))]
        got = histogram.percentile_ns(q)
        assert got is not None and abs(got - exact) <= exact / 16 + 1
    assert histogram.mean_ns == pytest.approx(statistics.fmean(values))
    again = CostHistogram.from_metadata(histogram.to_metadata())
    assert again is not None and again.counts == histogram.counts
    assert (again.min_ns, again.max_ns) == (min(values), max(values))


@given(st.integers(min_value=0, max_value=2**64 - 1))
def test_a_value_lies_within_the_bounds_of_its_bucket(value: int) -> None:
    low, high = bucket_bounds(bucket_of(value))
    assert low <= value < high
    assert CostHistogram.from_metadata({"commit_histogram": f"{bucket_of(value)}:1"})


def test_histograms_merge_like_the_union_of_their_samples() -> None:
    a, b, both = CostHistogram(), CostHistogram(), CostHistogram()
    for i, v in enumerate(range(1000, 90_000, 37)):
        (a if i % 3 else b).add(v)
        both.add(v)
    a.merge(b)
    assert (a.counts, a.cycles, a.total_ns, a.min_ns, a.max_ns) == (
        both.counts,
        both.cycles,
        both.total_ns,
        both.min_ns,
        both.max_ns,
    )


@pytest.mark.parametrize(
    "bad",
    [
        {"commit_histogram": "x:1", "cycles": "1"},
        {"commit_histogram": "20:2", "cycles": "3"},
        {"commit_histogram": "20:0", "cycles": "0"},
        {"commit_histogram": "20:1 20:1", "cycles": "2"},
        {"commit_histogram": "1:1 " * 20_000, "cycles": "20000"},
        {"commit_histogram": "1000000000000:1", "cycles": "1"},
    ],
)
def test_a_malformed_timing_record_is_refused(bad: dict[str, str]) -> None:
    with pytest.raises(ValueError):
        CostHistogram.from_metadata(bad)


# --- execution channels ----------------------------------------------------------------------


def _arm_execution() -> dict[str, object]:
    return {
        "deviation": 0.02,
        "deviation_unit": "m/s",
        "channels": [
            {"name": "elbow", "unit": "rad/s", "intended": 0.5, "actual": 0.48, "deviation": 0.02},
            {"name": "gripper_force", "unit": "N", "intended": 20.0, "actual": 19.2},
        ],
    }


def test_channels_give_the_same_bytes_as_a_dict_and_as_a_built_record() -> None:
    built = Execution(
        deviation=0.02,
        deviation_unit="m/s",
        channels=[
            ActuatorChannel(name="elbow", unit="rad/s", intended=0.5, actual=0.48, deviation=0.02),
            ActuatorChannel(name="gripper_force", unit="N", intended=20.0, actual=19.2),
        ],
    )
    model = LAYER_MODELS[TOPIC_EXECUTION]
    as_dict = layer_message(model, 3, 7, _arm_execution())
    assert as_dict == layer_message(model, 3, 7, built)
    decoded = orjson.loads(as_dict)
    assert decoded["intended"] is None and decoded["channels"][1]["deviation"] is None
    MESSAGE_MODELS[TOPIC_EXECUTION].model_validate(decoded)


@pytest.mark.parametrize(
    "change",
    [
        {"channels": [{"name": "", "unit": "N"}]},
        {"channels": [{"name": "grip", "unit": "N", "deviation": -1.0}]},
        {"channels": [{"name": "grip", "unit": "N", "intended": float("nan")}]},
        {"channels": [{"name": "grip"}]},
    ],
)
def test_a_bad_channel_is_a_record_error(change: dict[str, object]) -> None:
    with pytest.raises(RecordError):
        layer_message(LAYER_MODELS[TOPIC_EXECUTION], 0, 0, {**_arm_execution(), **change})


def test_planar_motion_written_as_in_v1_still_validates_both_ways() -> None:
    v1 = Execution(intended=Motion(linear=1.0), actual=Motion(linear=0.9), deviation=0.1)
    model = LAYER_MODELS[TOPIC_EXECUTION]
    v1_dict = {"intended": {"linear": 1.0}, "actual": {"linear": 0.9}, "deviation": 0.1}
    assert layer_message(model, 1, 2, v1) == layer_message(model, 1, 2, v1_dict)


@pytest.mark.parametrize("period_s", [0.0, -1.0, 1e-10, float("nan")])
def test_a_period_no_reader_accepts_is_refused_at_construction(
    tmp_path: Path, period_s: float
) -> None:
    """Readers refuse a period under 1 us (PROFILE section 2): the logger must not write one."""
    with pytest.raises(UsageError, match="period_s must be at least"):
        AuditLogger(tmp_path / "run.mcap", robot_id="r", period_s=period_s)
