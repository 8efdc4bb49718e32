"""The incident report: structure, numbers equal to explain's, no network, hostile logs, tiers."""

from __future__ import annotations

import json
import logging
import re
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from tests.trace_audit.conftest import (
    PERIOD_NS,
    fill_cycle,
    stretch,
    t_ns,
    t_s,
    write_log,
)
from tests.trace_audit.in_flight import cut_in_flight
from tests.trace_audit.incident_html import parse_report
from trace_audit.causal import format_value
from trace_audit.cli import app
from trace_audit.incident import build_report, parse_window
from trace_audit.incident.page import SECTIONS
from trace_runtime import AuditLogger, LoggerConfig, open_segment
from trace_runtime.errors import UsageError

runner = CliRunner()


@pytest.fixture(scope="module")
def sim_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from sim.runner import RunConfig, run

    out = tmp_path_factory.mktemp("sim") / "run.mcap"
    run(RunConfig(out=out, scenario="all", cycles=100, seed=42))
    return out


@pytest.fixture(scope="module")
def first_stop(sim_log: Path) -> str:
    from trace_audit.transitions import why

    return f"{why(sim_log, 'STOP').transitions[0].t_ns / 1e9:.9g}"


def _cli(*args: str) -> Any:
    return runner.invoke(app, [str(a) for a in args])


def test_the_papers_stop_has_every_section_the_same_numbers_and_no_fetch(
    sim_log: Path, first_stop: str, tmp_path: Path
) -> None:
    out = tmp_path / "incident.html"
    done = _cli("report", sim_log, "--t", first_stop, "--out", out, "--json")
    assert done.exit_code == 0, done.output
    summary = json.loads(done.stdout)
    html = out.read_text(encoding="utf-8")
    assert summary["size_bytes"] == len(html.encode()) < 2_000_000  # a 30 s window
    page = parse_report(html)
    assert page.section_ids == [s for s, _ in SECTIONS if s != "rules"] == summary["sections"]
    assert not page.fetches and not page.handlers
    assert {"img", "iframe", "link", "object", "embed"}.isdisjoint(page.tags)
    assert page.svgs == 5  # factors, scene, causal chain, tree, execution
    assert not re.search(r"https?://", html)

    explained = json.loads(_cli("explain", sim_log, "--t", first_stop, "--json").stdout)
    assert page.data() == explained  # the page carries explain --json for the same t
    d = explained["decision"]
    assert d["command"] == "STOP" and summary["command"] == "STOP"
    assert page.by_id["reason"] == d["rationale"]
    factors = page.section_text["factors"]
    for f in d["factors"]:
        assert format_value(f["value"], f["unit"]) in factors, f
    alternatives = page.section_text["counterfactuals"]
    for a in d["alternatives"]:
        assert f"{a['score']:.2f}" in alternatives and a["rejected_because"] in alternatives
    for cf in d["counterfactuals"]:
        assert cf["text"] in page.by_id["what-ifs"]
    scores = explained["scores"]
    audit = page.section_text["auditability"]
    for name, fmt in (("et", ".2f"), ("et_partial", ".2f"), ("tcs", ".2f"), ("dr", ".0f")):
        assert f"{scores[name]:{fmt}}" in audit
    # the paper's example: a person about 1.5 m away, perceived, and drawn in the scene
    distance = next(f for f in d["factors"] if f["name"] == "distance")
    assert 1.0 < distance["value"] < 2.0
    assert "person" in page.section_text["scene"]
    assert f"{distance['value']} m" in page.section_text["scene"]


def test_window_metrics_equal_metrics_over_the_same_window(sim_log: Path, first_stop: str) -> None:
    report = build_report(sim_log, t=first_stop, window_s=12)
    data = report.data
    assert data.end_ns - data.start_ns <= 12_000_000_000
    shown = json.loads(
        _cli(
            "metrics",
            sim_log,
            "--start",
            f"{data.start_ns / 1e9}",
            "--end",
            f"{data.end_ns / 1e9}",
            "--json",
        ).stdout
    )["overall"]
    audit = parse_report(report.html).section_text["auditability"]
    assert f"{shown['tc']:.3f}" in audit
    assert f"{shown['decisions']} (" in audit
    assert f"{shown['declared_dropped']} cycles" in audit


def test_a_broken_chain_is_drawn_broken_with_its_reason(tmp_path: Path) -> None:
    log = write_log(tmp_path / "r.mcap", [stretch("ped_close", 5, "null_ref")])
    report = build_report(log, t=t_s(3))
    page = parse_report(report.html)
    assert "breaks at evidence_ref" in page.section_text["causal"]
    assert report.data.entities[0].evidence_failed
    assert "no evidence ref recorded" in page.section_text["scene"]


EVIL = '</script><script>alert(1)</script><img src="https://evil.example/x.png" onerror=x>'


def _hostile_log(path: Path) -> Path:
    """A log whose free-text session fields carry markup (the layers are poisoned later)."""
    logger = AuditLogger(
        path,
        robot_id="amr-7",
        period_s=0.1,
        config=LoggerConfig(threaded=False, fsync_interval_s=None),
        software_version=EVIL,
        policy_version="<b>p</b>",
    )
    for i in range(5):
        c = logger.cycle(t_ns(i))
        fill_cycle(c, "ped_close")
        c.commit()
    logger.close()
    return path


def test_a_hostile_log_cannot_inject_markup_or_fetch_anything(tmp_path: Path) -> None:
    from trace_runtime.records import TOPIC_ACTION

    log = _hostile_log(tmp_path / "evil.mcap")
    evil = EVIL

    def poison(msg: Any) -> bytes:
        if msg.topic != TOPIC_ACTION:
            return bytes(msg.data)
        action = json.loads(msg.data)
        action["rationale"]["text"] = evil
        action["alternatives"][0]["rejected_because"] = evil
        action["rationale"]["factors"][0]["name"] = evil
        return json.dumps(action).encode()

    from tests.trace_audit.conftest import rewrite_segment

    tampered = rewrite_segment(log, tmp_path / "tampered.mcap", poison)
    for source in (log, tampered):
        html = build_report(source, t=t_s(3)).html
        page = parse_report(html)
        assert not page.fetches and not page.handlers, (page.fetches, page.handlers)
        assert {"img", "b"}.isdisjoint(page.tags)
        assert [kind for kind, _ in page.scripts] == ["application/json"]
        assert "evil.example" not in "".join(page.fetches)
    page = parse_report(build_report(tampered, t=t_s(3)).html)
    assert page.by_id["reason"] == evil  # shown as text, exactly
    assert page.data()["decision"]["rationale"] == evil  # and kept intact in the data block
    assert "does NOT verify" in page.section_text["integrity"]  # the edit broke the seal


def test_a_wall_clock_is_shown_in_utc_not_in_epoch_seconds(tmp_path: Path) -> None:
    wall = write_log(tmp_path / "wall.mcap", t0_ns=1_777_874_400 * 10**9)
    text = parse_report(build_report(wall, t="+4.5").html).section_text["summary"]
    assert "2026-05-04T06:00:04.500Z (+4.500 s) in the log's clock (system)" in text
    assert "1777874404" not in text


def test_a_system_clock_counting_from_zero_is_not_a_time_of_day(sample_log: Path) -> None:
    text = parse_report(build_report(sample_log, t=t_s(45)).html).section_text["summary"]
    assert "104.500 s in the log's clock (system)" in text
    assert "1970" not in text  # t = 104.5 s: seconds since the log's own zero


def test_a_log_with_hundreds_of_entities_gives_a_bounded_page(
    sample_log: Path, tmp_path: Path
) -> None:
    from tests.trace_audit.conftest import rewrite_segment
    from trace_runtime.records import TOPIC_PERCEPTION

    def crowd(msg: Any) -> bytes:
        if msg.topic != TOPIC_PERCEPTION:
            return bytes(msg.data)
        perception = json.loads(msg.data)
        template = perception["entities"][0] if perception["entities"] else None
        if template is not None:
            perception["entities"] += [{**template, "id": f"e{i}"} for i in range(2000)]
        return json.dumps(perception).encode()

    crowded = rewrite_segment(sample_log, tmp_path / "crowd.mcap", crowd)
    report = build_report(crowded, t=t_s(45))
    assert len(report.data.entities) == 2001
    assert report.size_bytes < 2_000_000
    assert "the first 60 of 2001 entities" in parse_report(report.html).section_text["scene"]


def test_a_crashed_log_is_reported_and_said_so(crashed_log: Path) -> None:
    page = parse_report(build_report(crashed_log, t=t_s(45)).html)
    assert "recovered from a segment the robot did not close" in page.section_text["summary"]
    # The chain verifies, but no checkpoint was written after this decision: not a green badge
    integrity = page.section_text["integrity"]
    assert "CLEAN, NOT ANCHORED" in integrity and "not yet: no checkpoint" in integrity


def test_a_robot_restarted_with_its_clock_from_zero_is_not_mixed_into_the_window(
    tmp_path: Path,
) -> None:
    """Two runs of one robot in one root, both starting at the same clock time (a monotonic
    clock after a reboot): the report of a decision in the second run draws only its run."""
    root = write_log(tmp_path / "root")
    write_log(root)  # the same robot again: the chain goes on, the times start over
    data = build_report(root, t=t_s(45)).data
    segment = data.explanation.decision.segment
    cycles = [s.cycle for s in data.samples]
    assert cycles and cycles == sorted(cycles)
    assert data.explanation.cycle in cycles
    assert data.integrity_scope == (segment,)
    run_cycles = {c.cycle for c in open_segment(root / "hot" / segment).iter_cycles()}
    assert set(cycles) <= run_cycles
    assert data.metrics.overall.decisions == len(cycles)
    # Segment 0 is in the root, outside the window: not "removed by retention"
    (start,) = [n for n in data.integrity.notes if n.kind == "chain_start"]
    assert "retention" not in start.message and "outside the window" in start.message
    # and the page's metrics command scores what the page scored: the run's segment alone
    page = parse_report(build_report(root, t=t_s(45)).html).section_text["reproduce"]
    assert f"metrics {root / 'hot' / segment} --start" in page


def test_a_decision_a_checkpoint_vouches_for_is_anchored(sample_log: Path) -> None:
    integrity = parse_report(build_report(sample_log, t=t_s(45)).html).section_text["integrity"]
    assert "NOT ANCHORED" not in integrity
    assert "yes: a checkpoint vouches for the chain through cycle 99" in integrity


def test_warm_summary_says_what_was_not_retained_and_cold_matches_hot(tmp_path: Path) -> None:
    from trace_runtime.tiers import compact

    root = write_log(tmp_path / "root", max_segment_s=3.0)
    hot = build_report(root, t=t_s(45)).data
    compact(root, "cold", older_than_ns=0)
    cold = build_report(root, t=t_s(45)).data
    assert cold.explanation.scores == hot.explanation.scores
    assert cold.samples == hot.samples and cold.entities == hot.entities

    warm_root = write_log(tmp_path / "warm", max_segment_s=3.0)
    compact(warm_root, "warm", older_than_ns=0)
    summary_cycle = build_report(warm_root, t=t_s(5))  # routine driving: summarised
    assert summary_cycle.data.decision.summary
    text = parse_report(summary_cycle.html).section_text["summary"]
    assert "warm-tier summary" in text and "Not retained" in text
    full = build_report(warm_root, t=t_s(45))  # a STOP: kept in full
    assert not full.data.decision.summary and not full.data.not_retained


def test_a_signed_log_names_the_key_and_counts_valid_signatures(tmp_path: Path) -> None:
    from trace_runtime.tlog.keys import generate_keypair, load_public_key

    pair = generate_keypair(tmp_path / "keys")
    logger = AuditLogger(
        tmp_path / "signed.mcap",
        robot_id="amr-7",
        period_s=PERIOD_NS / 1e9,
        config=LoggerConfig(
            threaded=False, fsync_interval_s=None, checkpoint_key=pair.private_path
        ),
    )
    for i in range(30):
        c = logger.cycle(t_ns(i))
        fill_cycle(c, "ped_close")
        c.commit()
    logger.close()
    report = build_report(
        tmp_path / "signed.mcap", t=t_s(20), key=load_public_key(pair.public_path)
    )
    text = parse_report(report.html).section_text["integrity"]
    checked = report.data.integrity.checkpoints
    assert checked >= 1 and f"key {pair.key_id}" in text
    assert f"{checked} of {checked} checkpoints valid" in text


@pytest.mark.parametrize(
    ("text", "seconds"), [("30", 30.0), ("30s", 30.0), ("2m", 120.0), ("1.5min", 90.0)]
)
def test_window_lengths_parse(text: str, seconds: float) -> None:
    assert parse_window(text) == seconds


@pytest.mark.parametrize("text", ["", "0", "-5s", "abc", "nan", "1e9", "5h"])
def test_bad_window_lengths_are_usage_errors(text: str) -> None:
    with pytest.raises(UsageError):
        parse_window(text)


def test_cli_errors_are_one_line_with_the_documented_code(sample_log: Path, tmp_path: Path) -> None:
    cases = [
        (["report", sample_log, "--t", "5", "--out", tmp_path / "a.html"], 2),  # before the log
        (
            ["report", sample_log, "--t", t_s(3), "--window", "zero", "--out", tmp_path / "b.html"],
            2,
        ),
        (["report", tmp_path / "missing.mcap", "--t", "1"], 3),
        (["report", sample_log, "--t", t_s(3), "--out", tmp_path / "no" / "dir" / "c.html"], 4),
        (["report", sample_log, "--t", t_s(3), "--out", "."], 2),  # a directory, not a file
        (["report", sample_log, "--t", t_s(3), "--out", tmp_path], 2),
    ]
    for args, code in cases:
        done = runner.invoke(app, [str(a) for a in args])
        assert done.exit_code == code, (args, done.output)
        assert "Traceback" not in done.output
    assert not list(tmp_path.glob("*.html")) and not list(tmp_path.glob(".*partial"))


def test_cli_help_shows_an_example() -> None:
    done = runner.invoke(app, ["report", "--help"])
    assert done.exit_code == 0 and "trace-audit report run.mcap --t 20.0" in done.output


def test_cli_reports_a_cycle_number_and_says_where_it_wrote(
    sample_log: Path, tmp_path: Path
) -> None:
    out = tmp_path / "by-cycle.html"
    done = _cli("report", sample_log, "--cycle", "45", "--out", out, "--json")
    assert done.exit_code == 0, done.output
    summary = json.loads(done.stdout)
    assert (summary["cycle"], summary["t_ns"]) == (45, t_ns(45))
    assert summary["out"] == str(out.resolve()) and out.stat().st_size == summary["size_bytes"]
    plain = _cli("report", sample_log, "--cycle", "45", "--out", out, "--plain")
    assert plain.exit_code == 0 and str(out.resolve()) in plain.stdout


def _verdicts(log: Path, t: str, out: Path) -> tuple[dict[str, Any], str, Any]:
    """The report's JSON summary, its terminal Integrity line and the page, for one t."""
    done = _cli("report", log, "--t", t, "--out", out, "--json")
    assert done.exit_code == 0, done.output
    plain = _cli("report", log, "--t", t, "--out", out, "--plain")
    assert plain.exit_code == 0, plain.output
    line = next(x for x in plain.stdout.splitlines() if x.startswith("Integrity"))
    return json.loads(done.stdout), line, parse_report(out.read_text("utf-8"))


def test_the_cycle_in_flight_at_a_crash_is_unsealed_everywhere_not_a_failure(
    crashed_log: Path, tmp_path: Path
) -> None:
    """PROFILE §8: the cycle the robot was writing when it was killed is UNSEALED (amber):
    its content cannot be verified, but it is the normal end of a crashed segment."""
    cut = cut_in_flight(crashed_log, tmp_path / "cut.mcap")
    summary, line, page = _verdicts(cut, t_s(99), tmp_path / "cut.html")
    assert summary["cycle"] == 99
    assert (summary["integrity"], summary["integrity_ok"], summary["decision_verified"]) == (
        "unsealed",
        True,
        False,
    )
    assert summary["integrity_findings"] == 0
    assert summary["anchored"] is False and summary["anchored_through"] is None
    assert "UNSEALED: the robot stopped while writing this cycle" in line
    assert "NOT clean" not in line
    text = " ".join([page.by_id["in-short"], *page.section_text.values()])
    assert "does NOT verify" not in text
    assert "the robot stopped while writing this decision" in page.by_id["in-short"]
    integrity = page.section_text["integrity"]
    assert "UNSEALED" in integrity and "its content cannot be verified" in integrity
    assert "is chained" not in integrity  # it never reached the chain
    assert "the chain ends at the seal of cycle 98" in integrity


def test_an_unsealed_last_cycle_of_a_closed_segment_is_still_not_clean(
    crashed_log: Path, tmp_path: Path
) -> None:
    closed = cut_in_flight(crashed_log, tmp_path / "closed.mcap", finished=True)
    summary, line, page = _verdicts(closed, t_s(99), tmp_path / "closed.html")
    assert (summary["integrity"], summary["integrity_ok"]) == ("failed", False)
    assert summary["integrity_findings"] >= 1
    assert "NOT clean" in line and "UNSEALED" not in line
    assert "record of this decision does NOT verify" in page.by_id["in-short"]


def test_terminal_and_json_carry_the_pages_anchoring_verdict(
    crashed_log: Path, sample_log: Path, tmp_path: Path
) -> None:
    """A crashed log's page says CLEAN, NOT ANCHORED: so do the terminal line and --json."""
    summary, line, page = _verdicts(crashed_log, t_s(45), tmp_path / "crashed.html")
    assert "CLEAN, NOT ANCHORED" in page.section_text["integrity"]
    assert (summary["integrity"], summary["integrity_ok"]) == ("not_anchored", True)
    assert summary["anchored"] is False and summary["anchored_through"] is None
    assert line.split(None, 1)[1] == "clean, NOT ANCHORED (cycles 0..99)"
    summary, line, page = _verdicts(sample_log, t_s(45), tmp_path / "finished.html")
    assert "NOT ANCHORED" not in page.section_text["integrity"]
    assert (summary["integrity"], summary["anchored"], summary["anchored_through"]) == (
        "clean",
        True,
        99,
    )
    assert line.split(None, 1)[1] == "clean"


def test_a_recovered_log_is_warned_about_once(
    crashed_log: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING, logger="trace_runtime"):
        build_report(crashed_log, t=t_s(45))
    assert sum("no footer" in m for m in caplog.messages) == 1
