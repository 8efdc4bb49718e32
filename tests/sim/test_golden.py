"""Same seed, same log content: the simulator's output pinned to digests, so that no
optimisation or restructuring changes a single value (down to the float's bits).

What is pinned is everything the simulator hands to the logger, in call order: each sensor
payload and each layer record, serialised the moment it is handed over, plus the ground-truth
sidecar and the run's counts. Evidence refs enter without their digest (the logger's hash of
the sensor payload, which is pinned itself), and the log's own bytes are not pinned: the
logger, its records and its codec change on their own schedule, and a golden over their bytes
would fail for reasons that are not the simulator's.

If a change to the simulator's behaviour is intended, re-record with
``GOLDEN_PRINT=1 pytest tests/sim/test_golden.py -s`` and say why in the commit.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import orjson
import pytest
from pydantic import BaseModel

from sim import FaultRates, RunConfig, run
from trace_runtime import CycleBuilder
from trace_runtime.records import EvidenceRef

HEAVY = FaultRates(
    lidar_unavailable=0.2,
    camera_unavailable=0.3,
    evidence_corruption=0.2,
    edge_write_failure=0.3,
    rationale_truncation=0.3,
    counterfactual_timeout=0.3,
    audit_write_timeout=0.1,
)

CASES: dict[str, RunConfig] = {
    # The paper's run: five scenarios x one full episode, faults at the paper's rates.
    "paper": RunConfig(out=Path("paper.mcap"), scenario="all", cycles=100, seed=42),
    # Every fault path many times over: sensors down, corrupt refs, lost edges and writes.
    "heavy": RunConfig(out=Path("heavy.mcap"), scenario="all", cycles=40, seed=7, faults=HEAVY),
    # Routine operation as ``--duration`` makes it: episodes in turn, 50 cycles a write, and
    # timed-out writes often enough that whole batches are lost (and their evidence forgotten).
    "duration": RunConfig(
        out=Path("root"),
        total_cycles=700,
        seed=3,
        batch_cycles=50,
        faults=FaultRates(audit_write_timeout=0.25),
    ),
}

GOLDEN = {
    "paper": "122a1c89378f49e3b15078d9645d01e2162f811d18eecc156f10fee051f221b6",
    "heavy": "b2958a064a947bf3add4c228649997408c93ec7255d43f8db5f61d816cb6142d",
    "duration": "8bd92732ab703b9bb6e9f219921500a5c4fc834983643bfa0fea8cdc8d96ac21",
}


def _pinned_ref(ref: dict[str, Any]) -> dict[str, Any]:
    return {"topic": ref["topic"], "log_time_ns": ref["log_time_ns"], "sequence": ref["sequence"]}


def _plain(obj: Any) -> Any:
    if isinstance(obj, EvidenceRef):
        return _pinned_ref(obj.__dict__)
    if isinstance(obj, BaseModel):
        return obj.model_dump()
    raise TypeError(f"cannot pin a {type(obj).__name__}")


def _without_digests(name: str, args: tuple[Any, ...]) -> tuple[Any, ...]:
    """A perception record's evidence refs as the golden pins them, whether the simulator
    hands them over as ``EvidenceRef`` models or as plain dicts of their fields: topic, time
    and sequence (the digest is the logger's; a dangling ref's two fields are kept as they
    are)."""
    if name != "perception" or not isinstance(args[0], dict):
        return args
    record = args[0]
    entities = []
    for entity in record["entities"]:
        evidence = [
            {**item, "ref": _pinned_ref(ref)}
            if isinstance(ref := item["ref"], dict) and "digest" in ref
            else item
            for item in entity["evidence"]
        ]
        entities.append({**entity, "evidence": evidence})
    return ({**record, "entities": entities}, *args[1:])


@pytest.fixture
def handed_over(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[bytes]]:
    """Every sensor payload and layer record the simulator hands to a ``CycleBuilder``."""
    calls: list[bytes] = []

    def tap(name: str) -> None:
        original = getattr(CycleBuilder, name)

        def wrapper(self: CycleBuilder, *args: Any) -> Any:
            pinned = _without_digests(name, args)
            calls.append(orjson.dumps([self.cycle, self.t_ns, name, *pinned], default=_plain))
            return original(self, *args)

        monkeypatch.setattr(CycleBuilder, name, wrapper)

    for name in ("sensor", "perception", "belief", "action", "execution"):
        tap(name)
    yield calls


def _digest(calls: list[bytes], truth: bytes, counts: dict[str, Any]) -> str:
    h = hashlib.sha256()
    for data in calls:
        h.update(len(data).to_bytes(8, "little"))
        h.update(data)
    h.update(truth)
    h.update(orjson.dumps(counts, option=orjson.OPT_SORT_KEYS))
    return h.hexdigest()


@pytest.mark.parametrize("case", list(CASES))
def test_same_seed_hands_the_logger_exactly_the_recorded_content(
    case: str, handed_over: list[bytes], tmp_path: Path
) -> None:
    config = CASES[case]
    config = RunConfig(
        **{**{f: getattr(config, f) for f in config.__slots__}, "out": tmp_path / config.out}
    )
    result = run(config)
    counts = {
        "cycles": result.cycles,
        "written": result.written,
        "dropped": result.dropped,
        "commands": result.commands,
        "faults": result.faults,
    }
    got = _digest(handed_over, result.truth.read_bytes(), counts)
    if os.environ.get("GOLDEN_PRINT"):
        print(f'    "{case}": "{got}",  # {len(handed_over)} hand-overs, {counts}')
    assert got == GOLDEN[case]
