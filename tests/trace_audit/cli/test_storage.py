"""``trace-audit compact`` / ``catalog``, and every investigator command answering the same on a
cold segment as on its hot original (a simulator run, the paper's five scenarios)."""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path
from typing import Any

import pytest
from mcap.writer import Writer
from typer.testing import CliRunner

from sim.runner import RunConfig, run
from trace_audit.cli import app
from trace_runtime import open_log, open_segment
from trace_runtime.schemas import SENSOR_SCHEMA_NAME, schema_bytes, schema_name

runner = CliRunner()


def invoke(*args: str | Path) -> Any:
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def sim_roots(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A hot simulator root and a copy of it compacted to cold with the CLI."""
    base = tmp_path_factory.mktemp("sim")
    hot = base / "hot_root"
    run(RunConfig(out=hot, scenario="all", cycles=60, seed=42))
    cold = base / "cold_root"
    shutil.copytree(hot, cold)
    result = invoke("compact", cold, "--tier", "cold", "--older-than", "0", "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert [s["status"] for s in report["segments"]] == ["compacted"]
    assert not list((cold / "hot").glob("*.mcap"))
    return hot, cold


def _normalise(text: str, hot: Path, cold: Path) -> Any:
    """JSON output with the root paths, tier names and timings that legitimately differ."""
    data = json.loads(text.replace(str(cold), str(hot)).replace("cold/", "hot/"))

    def scrub(value: Any) -> Any:
        if isinstance(value, dict):
            return {
                k: scrub(v)
                for k, v in value.items()
                if k not in ("elapsed_s", "cycles_per_s", "seconds", "bytes", "tier")
            }
        if isinstance(value, list):
            return [scrub(v) for v in value]
        return value

    return scrub(data)


@pytest.mark.parametrize(
    "command",
    [
        ["explain", "--t", "3.3"],
        ["explain", "--t", "17.05"],
        ["explain", "--t", "+29.9"],
        ["why", "--action", "STOP"],
        ["why", "--action", "STOP", "--all"],
        ["why", "--action", "CONTINUE", "--t", "25"],
        ["timeline"],
        ["metrics"],
        ["metrics", "--by", "scenario", "--failures"],
        ["export", "--t", "12.3", "--format", "json"],
        ["verify"],
    ],
)
def test_investigator_answers_are_the_same_on_cold(
    sim_roots: tuple[Path, Path], command: list[str]
) -> None:
    hot, cold = sim_roots
    json_flag = [] if command[0] == "export" else ["--json"]
    a = invoke(*command, hot, *json_flag)
    b = invoke(*command, cold, *json_flag)
    assert a.exit_code == b.exit_code, (a.output, b.output)
    assert a.exit_code in (0, 1), a.output
    assert _normalise(b.stdout, hot, cold) == _normalise(a.stdout, hot, cold)


def test_cold_meets_the_size_budget_on_a_sim_log(sim_roots: tuple[Path, Path]) -> None:
    """<= 0.5x the mcap library's default zstd chunks of the same messages and schemas."""
    hot, cold = sim_roots
    source = open_log(hot).segments[0]
    buf = io.BytesIO()
    writer = Writer(buf)
    writer.start("trace", "bench")
    channels: dict[str, int] = {}
    schemas: dict[str, int] = {}
    for msg in source.iter_messages():
        if msg.topic not in channels:
            name = schema_name(msg.topic) if msg.topic.startswith("/trace/") else SENSOR_SCHEMA_NAME
            if name not in schemas:
                schemas[name] = writer.register_schema(name, "jsonschema", schema_bytes(msg.topic))
            channels[msg.topic] = writer.register_channel(msg.topic, "json", schemas[name])
        writer.add_message(
            channels[msg.topic], msg.log_time_ns, msg.data, msg.log_time_ns, msg.sequence
        )
    writer.finish()
    cold_bytes = sum(p.stat().st_size for p in (cold / "cold").glob("*.mcap"))
    assert cold_bytes <= 0.5 * len(buf.getvalue())


def test_compact_json_report_and_catalog(tmp_path: Path, sim_roots: tuple[Path, Path]) -> None:
    hot, _cold = sim_roots
    root = tmp_path / "root"
    shutil.copytree(hot, root)
    dry = invoke("compact", root, "--tier", "warm", "--older-than", "0", "--dry-run", "--json")
    assert dry.exit_code == 0, dry.output
    planned = json.loads(dry.stdout)
    assert planned["dry_run"] and planned["reference"] == "newest log time"
    assert [s["status"] for s in planned["segments"]] == ["planned"]
    assert list((root / "hot").glob("*.mcap"))

    done = invoke("compact", root, "--tier", "warm", "--older-than", "0", "--json")
    report = json.loads(done.stdout)
    segment = report["segments"][0]
    assert segment["status"] == "compacted" and segment["target"].startswith("warm/")
    assert report["bytes_before"] == segment["bytes_before"] > segment["bytes_after"] > 0
    assert open_segment(root / segment["target"]).session.tier == "warm"

    catalog = invoke("catalog", root, "--json")
    assert catalog.exit_code == 0, catalog.output
    rows = json.loads(catalog.stdout)["segments"]
    assert [(r["tier"], r["lossy"]) for r in rows] == [("warm", True)]
    assert rows[0]["cycles"] == len([c for c in open_log(root).iter_cycles() if c.sealed])

    text = invoke("catalog", root, "--plain")
    assert "warm*" in text.stdout and "* lossy" in text.stdout
    rendered = invoke("compact", root, "--tier", "cold", "--older-than", "0", "--plain")
    assert rendered.exit_code == 0 and "compacted" in rendered.stdout


@pytest.mark.parametrize(
    ("args", "code", "message"),
    [
        (["--tier", "lukewarm"], 2, "unknown target tier"),
        (["--tier", "cold", "--older-than", "soon"], 2, "bad duration"),
        (["--tier", "warm", "--from", "cold"], 2, "cannot compact cold into warm"),
        (["--tier", "cold", "--retention", "-"], 2, "bad duration"),
    ],
)
def test_compact_usage_errors(tmp_path: Path, args: list[str], code: int, message: str) -> None:
    (tmp_path / "hot").mkdir()
    result = invoke("compact", tmp_path, *args)
    assert result.exit_code == code
    assert message in result.stderr and "Traceback" not in result.output


def test_compact_of_a_missing_root_is_unreadable_input(tmp_path: Path) -> None:
    result = invoke("compact", tmp_path / "nowhere", "--tier", "cold")
    assert result.exit_code == 3
    assert "not a log root" in result.stderr


def test_compact_and_catalog_have_help_with_examples() -> None:
    for command in ("compact", "catalog"):
        result = invoke(command, "--help")
        assert result.exit_code == 0 and "Examples" in result.stdout


def test_a_log_on_the_robots_own_clock_is_not_dated_1970(tmp_path: Path) -> None:
    """The sim writes times from 0 s: the catalog and compaction show them as seconds; a
    system clock's times stay UTC dates."""
    from tests.trace_audit.conftest import write_log

    root = write_log(tmp_path / "root")
    shown = CliRunner().invoke(app, ["catalog", str(root), "--plain"]).output
    assert "100.000 s" in shown and "1970" not in shown
    moved = CliRunner().invoke(
        app, ["compact", str(root), "--tier", "cold", "--dry-run", "--plain"]
    )
    assert "1970" not in moved.output and "109.900 s" in moved.output
