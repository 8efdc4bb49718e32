"""Failed execution checks per robot and rule: counted from the logged records only, the
first and last to fail in each robot's chain order, the same however the scan is spread
(one process or several, hot, warm or cold), and never made up where none failed."""

from __future__ import annotations

import json
import random
import shutil
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st
from mcap.reader import make_reader

from tests.trace_audit.metrics.test_scan import HandLog, layers, t
from trace_audit.jsonout import to_jsonable
from trace_audit.metrics import MetricsConfig, MetricsReport, compute_metrics
from trace_audit.metrics.sums import MAY_FAIL_A_CHECK, failed_check_rules
from trace_runtime.records import TOPIC_EXECUTION

RULES = ("min_clearance", "max_speed", "stop_response")
GOLDEN_ROOT = Path(__file__).parents[1] / "data" / "metrics_golden" / "root"


@dataclass(frozen=True)
class Written:
    """One execution record as the test wrote it."""

    robot: str
    cycle: int
    t_ns: int
    checks: tuple[dict[str, Any], ...]


def _checks(rng: random.Random) -> tuple[dict[str, Any], ...]:
    """A check per rule, about a third failing; now and then a rule checked twice."""
    rules = [*RULES, *((rng.choice(RULES),) if rng.random() < 0.2 else ())]
    return tuple(
        {"rule": rule, "passed": rng.random() > 0.35, "value": rng.random(), "limit": 0.5}
        for rule in rules
    )


def _segment(
    path: Path,
    robot: str,
    cycles: range,
    offset_ns: int,
    rng: random.Random,
    *,
    prev: HandLog | None = None,
    number: int = 0,
) -> tuple[HandLog, list[Written]]:
    log = HandLog(
        path,
        robot=robot,
        segment=number,
        prev_seal=prev.prev_seal if prev else "0" * 64,
        first_cycle=cycles.start,
    )
    written: list[Written] = []
    for i in cycles:
        at = t(i) + offset_ns
        record = layers(log.sensor(at, {"i": i}))
        checks = _checks(rng)
        record["execution"]["checks"] = list(checks)
        log.cycle(i, at, record)
        written.append(Written(robot, i, at, checks))
    log.close()
    return log, written


def two_robot_root(base: Path, seed: int = 7) -> tuple[Path, list[Written]]:
    """A root of robot r1 in two segments (its chain continues across them) and r2 in one,
    30 ms after r1; every execution record carries checks, some failing."""
    root = base / "root"
    root.mkdir()
    rng = random.Random(seed)
    first, written = _segment(root / "r1_000000.mcap", "r1", range(0, 6), 0, rng)
    _, more = _segment(root / "r1_000001.mcap", "r1", range(6, 12), 0, rng, prev=first, number=1)
    _, other = _segment(root / "r2_000000.mcap", "r2", range(0, 9), 30_000_000, rng)
    return root, [*written, *more, *other]


def expected_failures(written: Iterable[Written]) -> dict[tuple[str, str], tuple[int, ...]]:
    """(robot, rule) -> (failed, first t, first cycle, last t, last cycle), counted here."""
    out: dict[tuple[str, str], tuple[int, ...]] = {}
    for record in written:
        for check in record.checks:
            if check["passed"]:
                continue
            key = (record.robot, check["rule"])
            n, first_t, first_cycle, _, _ = out.get(key, (0, record.t_ns, record.cycle, 0, 0))
            out[key] = (n + 1, first_t, first_cycle, record.t_ns, record.cycle)
    return out


def reported(report: MetricsReport) -> dict[tuple[str, str], tuple[int, ...]]:
    assert report.failed_checks is not None
    return {
        (r.robot, r.rule): (r.failed, r.first_t_ns, r.first_cycle, r.last_t_ns, r.last_cycle)
        for r in report.failed_checks.rules
    }


@pytest.mark.parametrize("workers", [1, 2])
def test_failed_checks_per_rule_are_the_records_own(tmp_path: Path, workers: int) -> None:
    root, written = two_robot_root(tmp_path)
    report = compute_metrics([root], MetricsConfig(workers=workers))
    expected = expected_failures(written)
    assert reported(report) == expected
    # the first and last of r1 lie in different segments: the merge keeps chain order
    first_cycle, last_cycle = expected["r1", "min_clearance"][2], expected["r1", "min_clearance"][4]
    assert first_cycle < 6 <= last_cycle
    assert report.failed_checks is not None
    assert [(r.robot, r.rule) for r in report.failed_checks.rules] == sorted(expected)
    assert report.failed_checks.total == sum(v[0] for v in expected.values())


def test_one_process_and_two_give_the_same_report(tmp_path: Path) -> None:
    root, _ = two_robot_root(tmp_path)
    reports = [compute_metrics([root], MetricsConfig(workers=n)) for n in (1, 2)]
    one, two = (to_jsonable(r) for r in reports)
    for data in (one, two):
        for name in ("elapsed_s", "cycles_per_s"):
            data.pop(name)
    assert one == two


def test_a_window_counts_only_the_checks_inside_it(tmp_path: Path) -> None:
    root, written = two_robot_root(tmp_path)
    start, end = t(3), t(8)
    report = compute_metrics([root], MetricsConfig(start_ns=start, end_ns=end))
    inside = [w for w in written if start <= w.t_ns <= end]
    assert reported(report) == expected_failures(inside)


def test_a_selected_robot_counts_its_own_checks_only(tmp_path: Path) -> None:
    root, written = two_robot_root(tmp_path)
    report = compute_metrics([root], robots=["r2"])
    assert reported(report) == expected_failures(w for w in written if w.robot == "r2")


def test_no_failed_check_leaves_the_field_out(tmp_path: Path) -> None:
    log = HandLog(tmp_path / "clean.mcap")
    for i in range(4):
        record = layers(log.sensor(t(i), {"i": i}))
        record["execution"]["checks"] = [
            {"rule": "max_speed", "passed": True, "value": 0.1, "limit": 1.0, "detail": "false"}
        ]
        log.cycle(i, t(i), record)
    log.close()
    report = compute_metrics([log.path])
    assert report.failed_checks is None
    assert "failed_checks" not in to_jsonable(report)


def _plain_count(root: Path) -> dict[tuple[str, str], int]:
    """Failed checks per robot and rule, read with the plain ``mcap`` reader (not ours)."""
    out: dict[tuple[str, str], int] = {}
    for path in sorted(root.rglob("*.mcap")):
        with path.open("rb") as f:
            reader = make_reader(f)
            meta = {m.name: m.metadata for m in reader.iter_metadata()}
            robot = meta["trace.session"]["robot_id"]
            for _schema, _channel, message in reader.iter_messages(topics=[TOPIC_EXECUTION]):
                for check in json.loads(message.data)["checks"]:
                    if not check["passed"]:
                        key = (robot, check["rule"])
                        out[key] = out.get(key, 0) + 1
    return out


@pytest.mark.parametrize("tier", ["hot", "cold", "warm"])
def test_a_sim_root_in_every_tier_counts_what_the_plain_reader_counts(
    tmp_path: Path, tier: str
) -> None:
    from trace_runtime.tiers import WarmPolicy, compact

    expected = _plain_count(GOLDEN_ROOT)
    assert expected  # the sim's robots do fail checks
    root = tmp_path / "root"
    shutil.copytree(GOLDEN_ROOT, root)
    if tier != "hot":
        compact(
            root,
            tier,
            older_than_ns=0,
            sources=["hot"],
            retention_ns=None,
            warm=WarmPolicy(context_ns=0) if tier == "warm" else None,
        )
        assert not list((root / "hot").glob("*.mcap"))
    report = compute_metrics([root])
    assert {key: v[0] for key, v in reported(report).items()} == expected


_CHECK = st.fixed_dictionaries(
    {"rule": st.text(min_size=1, max_size=8), "passed": st.booleans()},
    optional={"value": st.floats(allow_nan=False), "detail": st.text(max_size=8)},
)


@given(st.lists(_CHECK, max_size=5), st.booleans())
def test_a_record_with_a_failed_check_is_always_parsed(checks: list[Any], spaced: bool) -> None:
    """The byte shortcut never skips a failing check, whatever the JSON's spacing."""
    record = {"deviation": 0.0, "checks": checks, "flags": []}
    data = json.dumps(record, separators=(", ", ": ") if spaced else (",", ":")).encode()
    if failed_check_rules(json.loads(data)):
        assert MAY_FAIL_A_CHECK in data


def test_only_checks_whose_passed_is_false_fail() -> None:
    record = {
        "checks": [
            {"rule": "a", "passed": False},
            {"rule": "b", "passed": True},
            {"rule": "c", "passed": 0},
            "not a check",
            {"rule": "a", "passed": False},
        ]
    }
    assert failed_check_rules(record) == ["a", "a"]
    assert failed_check_rules({"checks": None}) == []
    assert failed_check_rules(None) == []
