"""Every tier keeps what the profile defines (PROFILE §9): a profile 1.1 robot's actuator
channels and deviation unit read the same from warm summaries and cold blocks as from the hot
log, and ``doctor`` checks the content of every tier it says conforms."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.outside import cli
from tests.trace_audit.conftest import rewrite_segment, write_log
from trace_runtime import open_log
from trace_runtime.records import TOPIC_EXECUTION
from trace_runtime.tier_formats.warm import WarmPolicy
from trace_runtime.tiers import compact

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def tiers(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The arm example's log root, and copies of it compacted to warm, cold, cold of warm."""
    base = tmp_path_factory.mktemp("tiers")
    hot = base / "hot"
    script = ROOT / "examples" / "pick_and_place_arm.py"
    subprocess.run([sys.executable, str(script), "--out", str(hot)], check=True, timeout=60)
    out = {"hot": hot}
    for name, steps in {
        "warm": ["warm"],
        "cold": ["cold"],
        "cold_of_warm": ["warm", "cold"],
    }.items():
        root = shutil.copytree(hot, base / name)
        for tier in steps:
            compact(root, tier, older_than_ns=0, warm=WarmPolicy(context_ns=0))
        out[name] = root
    return out


def _metrics(root: Path) -> dict[str, object]:
    done = cli("metrics", root, "--json")
    assert done.returncode == 0, done.stderr
    return dict(json.loads(done.stdout))


def _summary_time(root: Path) -> float:
    for cycle in open_log(root).iter_cycles():
        if cycle.is_summary and cycle.t_ns > 0:
            return cycle.t_ns / 1e9
    raise AssertionError("no summary cycle")


@pytest.mark.parametrize("tier", ["warm", "cold", "cold_of_warm"])
def test_execution_reads_the_same_in_every_tier(tiers: dict[str, Path], tier: str) -> None:
    hot = {c.cycle: c.layer(TOPIC_EXECUTION) for c in open_log(tiers["hot"]).iter_cycles()}
    other = {c.cycle: c.layer(TOPIC_EXECUTION) for c in open_log(tiers[tier]).iter_cycles()}
    assert other == hot
    assert any(e["channels"] and e["deviation_unit"] == "m/s" for e in other.values())


@pytest.mark.parametrize("tier", ["warm", "cold_of_warm"])
def test_channel_deviation_over_summaries_equals_the_hot_figure(
    tiers: dict[str, Path], tier: str
) -> None:
    hot, other = _metrics(tiers["hot"]), _metrics(tiers[tier])
    assert other["overall"]["summarized"] > 100  # type: ignore[index]
    assert other["channel_deviation"] == hot["channel_deviation"]
    assert {c["cycles"] for c in hot["channel_deviation"]} == {240}  # type: ignore[union-attr]


def test_explain_on_a_summary_cycle_shows_the_channels_in_their_units(
    tiers: dict[str, Path],
) -> None:
    t = _summary_time(tiers["warm"])
    done = cli("explain", tiers["warm"], "--t", f"{t:.3f}", "--plain")
    assert done.returncode == 0, done.stderr
    execution = done.stdout.split("Execution", 1)[1].split("Auditability", 1)[0]
    for name, unit in (("shoulder_pan", "rad/s"), ("gripper_force", "N"), ("ee_speed", "m/s")):
        assert any(name in line and unit in line for line in execution.splitlines())
    assert "? m/s" not in execution and "Intended" not in execution


@pytest.mark.parametrize("tier", ["cold", "cold_of_warm", "warm"])
def test_doctor_checks_the_content_of_compacted_tiers(tiers: dict[str, Path], tier: str) -> None:
    source = "warm" if tier == "cold_of_warm" else "hot"
    reports = {}
    for name in (source, tier):
        done = cli("doctor", tiers[name], "--json")
        assert done.returncode == 0, done.stderr
        reports[name] = json.loads(done.stdout)["segments"][0]
    assert reports[tier]["cycles"] == reports[source]["cycles"] == 240
    if tier == "warm":  # summaries replace the layer messages: fewer, each checked
        assert 0 < reports[tier]["messages"] < reports[source]["messages"]
    else:  # cold decodes to exactly its source's messages, and each is checked
        assert reports[tier]["messages"] == reports[source]["messages"]
    if tier != "cold":
        assert reports[tier]["summarised"] > 100


def test_doctor_finds_a_broken_record_inside_a_cold_block(tmp_path: Path) -> None:
    """Before, a cold root CONFORMED after decoding nothing: here a layer record that breaks
    its schema is found inside the block, as it is in the hot log."""
    source = write_log(tmp_path / "src.mcap")
    root = tmp_path / "root"
    (root / "hot").mkdir(parents=True)

    def extra_field(msg: object) -> bytes:
        data: bytes = msg.data  # type: ignore[attr-defined]
        if msg.topic == TOPIC_EXECUTION and msg.sequence == 7:  # type: ignore[attr-defined]
            return data[:-1] + b',"not_in_the_profile":1}'
        return data

    rewrite_segment(source, root / "hot" / "amr-7_000000.mcap", extra_field)
    hot = json.loads(cli("doctor", root, "--json").stdout)
    compact(root, "cold", older_than_ns=0)
    assert list((root / "cold").glob("*.mcap"))
    cold = json.loads(cli("doctor", root, "--json").stdout)
    for report in (hot, cold):
        problems = [p for s in report["segments"] for p in s["problems"]]
        assert any(p["rule"] == "schema-valid" and p["cycle"] == 7 for p in problems)
        assert report["conforms"] is False
