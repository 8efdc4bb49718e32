"""A log written by the v1 logger (before the encoding rework) stays readable, verifiable,
explainable and compactable by today's code: ``tests/fixtures/v1/`` holds its bytes, the
public key of its signed checkpoints and ``explain`` output saved by the code that wrote it
(see ``tests/fixtures/v1/make_fixture.py``; never regenerate it to make this test pass)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import pytest

from trace_runtime import load_public_key, open_log, open_segment
from trace_runtime.tier_formats import cold as cold_module
from trace_runtime.tiers import ColdOptions, compact

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "v1"
SEGMENT = FIXTURE / "amr-fixture_000000.mcap"
PUBLIC_KEY = FIXTURE / "fixture-ed25519.pub"
CYCLES = 47  # 48 begun, one aborted
DROPPED = 1


def _golden() -> dict[str, Any]:
    golden: dict[str, Any] = json.loads((FIXTURE / "explain.golden.json").read_text("utf-8"))
    return golden


def test_the_v1_fixture_verifies_clean_with_its_signatures() -> None:
    from trace_audit.verify import verify_log

    report = verify_log(SEGMENT, key=load_public_key(PUBLIC_KEY))
    assert report.ok, report.findings
    assert report.signatures_checked
    assert (report.cycles, report.cycles_valid) == (CYCLES, CYCLES)
    assert report.checkpoints >= 2 and report.checkpoints_valid == report.checkpoints
    assert report.declared_dropped == DROPPED


@pytest.mark.parametrize("cycle", sorted(int(n) for n in _golden()))
def test_the_v1_fixture_explains_as_it_did_when_written(cycle: int) -> None:
    from trace_audit.explanation import explain
    from trace_audit.jsonout import to_jsonable
    from trace_audit.log_time import LogClock

    got = to_jsonable(explain(SEGMENT, cycle=cycle))
    got.pop("path")
    # Added after the golden was written: the log's clock, for showing its times. What it
    # says of this log is checked here; everything else must be as it was.
    assert got.pop("clock") == "system"
    # Added later too: what the decision knew of its sensors, read from its perception record
    # and its refs' times.
    sensors = got.pop("sensors")
    found = open_log(SEGMENT).get_cycle(cycle)
    assert found is not None
    perception = found.layer("/trace/perception")
    assert isinstance(perception, dict)
    assert sensors["used"] == perception["sensors_used"]
    assert sensors["unavailable"] == perception["sensors_unavailable"]
    assert all(c["age_ns"] >= 0 for c in sensors["cited"])
    # A sensor reading's time is now shown in the log's clock (ISO on this wall clock), as
    # every other time explain shows; the golden has it as seconds.
    clock = LogClock("system", got["log_start_ns"])
    for node in got["graph"]["nodes"]:
        if node["kind"] == "sensor":
            topic, _, when = node["id"].removeprefix("sensor:").rpartition("@")
            assert node["label"] == f"{topic} @ {clock.show(int(when))}"
            node["label"] = f"{topic} @ {int(when) / 1e9:.3f} s"
    # Added after it too: whether a chain's missing link is unknown (a recording not read);
    # this log cites no recording, so no link is.
    for chain in got["chains"]["factors"]:
        for link in chain["links"]:
            assert link.pop("unknown") is False
    # through JSON text, as the golden went: tuples become lists, keys strings
    assert json.loads(json.dumps(got, ensure_ascii=False)) == _golden()[str(cycle)]


def test_the_v1_fixture_compacts_to_cold_and_back_byte_for_byte(tmp_path: Path) -> None:
    root = tmp_path / "root"
    (root / "hot").mkdir(parents=True)
    shutil.copyfile(SEGMENT, root / "hot" / SEGMENT.name)
    hot_messages = list(open_segment(SEGMENT).iter_messages())
    hot_cycles = list(open_log(SEGMENT).iter_cycles())

    report = compact(root, "cold", older_than_ns=0, cold=ColdOptions(block_cycles=16))
    assert [s.status for s in report.segments] == ["compacted"]
    cold = root / "cold" / SEGMENT.name
    assert list(cold_module.iter_decoded(open_segment(cold).iter_messages())) == hot_messages
    cold_cycles = list(open_log(root).iter_cycles())
    assert cold_cycles == hot_cycles
    for a, b in zip(hot_cycles, cold_cycles, strict=True):
        assert a.payloads == b.payloads and a.sensors == b.sensors

    from trace_audit.verify import verify_log

    cold_report = verify_log(root, key=load_public_key(PUBLIC_KEY))
    assert cold_report.ok, cold_report.findings
    assert cold_report.cycles_valid == CYCLES
