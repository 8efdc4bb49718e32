"""The tamper campaign: hundreds of seeded mutations of a signed log, each one detected and located.

One small log is written once through the real logger (signed checkpoints every second of
log time). Each mutation decodes the log into cycles and checkpoints, changes something, and
writes a structurally valid MCAP again (the plain ``mcap`` Writer in one chunk, or
``SegmentWriter`` in chunks of a few cycles), as someone editing a log with ordinary tools
would. ``verify_log`` must then report a finding of an expected kind whose cycle range covers
the cycle that was touched; an unmodified rewrite must give no finding at all.
"""

from __future__ import annotations

import random
import shutil
import struct
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import orjson
import pytest
from mcap.writer import Writer

from tests.trace_audit.conftest import fill_cycle
from trace_audit.verify import VerifyReport, verify_log
from trace_runtime import AuditLogger, LoggerConfig, open_segment
from trace_runtime.chain import digest
from trace_runtime.encoding.codec import encode_seal
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.logger.mcap_out import OutMessage
from trace_runtime.logger.segment_writer import SegmentWriter
from trace_runtime.records import (
    LAYER_TOPICS,
    TOPIC_ACTION,
    TOPIC_CHECKPOINT,
    TOPIC_SEAL,
    Checkpoint,
    Seal,
)
from trace_runtime.schemas import SENSOR_SCHEMA_NAME, schema_bytes, schema_name
from trace_runtime.session import SESSION_METADATA, SessionInfo
from trace_runtime.tlog.checkpoints import (
    decode_checkpoint,
    encode_checkpoint,
    make_checkpoint,
    signing_bytes,
)
from trace_runtime.tlog.keys import Ed25519Signer, Signer

T0_NS = 100_000_000_000
PERIOD_NS = 100_000_000
CYCLES = 60
MUTATIONS = 240
# A clear aisle's scan is cited by no evidence ref: the 1.3 seal alone covers it.
SITUATIONS = ("ped_far", "ped_close", "blocked", "clear", "ped_close", "ped_far")


def write_signed_log(
    path: Path,
    signer: Signer,
    cycles: int = CYCLES,
    *,
    interval_s: float = 1.0,
    max_segment_s: float = 3600.0,
    skip: Callable[[int], bool] | None = None,
    situations: tuple[str, ...] = SITUATIONS,
) -> Path:
    """A log written through ``AuditLogger`` with signed checkpoints every ``interval_s``."""
    config = LoggerConfig(
        threaded=False,
        fsync_interval_s=None,
        checkpoint_interval_s=interval_s,
        checkpoint_key=signer,
        max_segment_s=max_segment_s,
    )
    logger = AuditLogger(path, robot_id="amr-7", period_s=0.1, config=config)
    for i in range(cycles):
        c = logger.cycle(T0_NS + i * PERIOD_NS)
        if skip is not None and skip(i):
            c.abort()
            continue
        situation = situations[(i // 7) % len(situations)]
        fill_cycle(c, situation)
        if situation == "clear":
            c.sensor("/sensors/radar", {"targets": []})  # saw nothing; no evidence cites it
        c.commit()
    logger.close()
    return path


# --- decoding a log into units and writing it back -----------------------------------------


@dataclass
class Unit:
    """A cycle (its sensor, layer and seal messages) or a checkpoint, in file order."""

    kind: str
    messages: list[RawMessage]

    @property
    def cycle(self) -> int:
        return self.messages[-1].sequence

    @property
    def t_ns(self) -> int:
        return self.messages[-1].log_time_ns


@dataclass
class Decoded:
    session: SessionInfo
    units: list[Unit]

    def cycles(self) -> list[int]:
        """Indexes of the cycle units."""
        return [i for i, u in enumerate(self.units) if u.kind == "cycle"]

    def checkpoints(self) -> list[int]:
        return [i for i, u in enumerate(self.units) if u.kind == "checkpoint"]


def decode(path: Path) -> Decoded:
    segment = open_segment(path)
    units: list[Unit] = []
    current: list[RawMessage] = []
    for message in segment.iter_messages():
        if message.topic == TOPIC_CHECKPOINT:
            units.append(Unit("checkpoint", [message]))
            continue
        current.append(message)
        if message.topic == TOPIC_SEAL:
            units.append(Unit("cycle", current))
            current = []
    assert not current
    return Decoded(segment.session, units)


def write(decoded: Decoded, path: Path, rng: random.Random) -> None:
    """Write ``decoded`` as a valid, finished MCAP: one chunk (mcap Writer) or small chunks."""
    if rng.random() < 0.5:
        _write_plain(decoded, path)
    else:
        _write_chunked(decoded, path, rng)


def _write_plain(decoded: Decoded, path: Path) -> None:
    with open(path, "wb") as f:
        writer = Writer(f, chunk_size=1 << 30)  # one chunk: whole cycles stay together
        writer.start(profile="trace", library="tamper-campaign")
        writer.add_metadata(SESSION_METADATA, decoded.session.to_metadata())
        channels: dict[str, int] = {}
        for unit in decoded.units:
            for m in unit.messages:
                if m.topic not in channels:
                    name = schema_name(m.topic) if m.topic.startswith("/trace/") else None
                    schema = writer.register_schema(
                        name or SENSOR_SCHEMA_NAME, "jsonschema", schema_bytes(m.topic)
                    )
                    channels[m.topic] = writer.register_channel(m.topic, "json", schema)
                writer.add_message(
                    channels[m.topic], m.log_time_ns, m.data, m.log_time_ns, m.sequence
                )
        writer.finish()  # type: ignore[no-untyped-call]


def _write_chunked(decoded: Decoded, path: Path, rng: random.Random) -> None:
    with open(path, "wb") as f:
        writer = SegmentWriter(f, decoded.session)
        units = decoded.units
        i = 0
        while i < len(units):
            batch = units[i : i + rng.randint(2, 9)]
            i += len(batch)
            writer.write_batch(
                [
                    OutMessage(writer.channel(m.topic), m.sequence, m.log_time_ns, m.data)
                    for unit in batch
                    for m in unit.messages
                ]
            )
        writer.close()


# --- mutations -----------------------------------------------------------------------------


@dataclass
class Expect:
    """A finding of one of ``kinds`` must cover ``cycle`` (or start at it, for a cut)."""

    what: str
    kinds: frozenset[str]
    cycle: int

    def met_by(self, report: VerifyReport) -> bool:
        return any(f.kind in self.kinds and f.covers(self.cycle) for f in report.findings)


CONTENT = frozenset({"modified", "evidence_mismatch"})
CHECKPOINT = frozenset(
    {"modified", "bad_signature", "key_mismatch", "checkpoint_mismatch", "truncated"}
)


def flip_byte(d: Decoded, rng: random.Random, _: Signer) -> Expect:
    """Change one byte inside one message's payload (sensor, layer, seal or checkpoint)."""
    index = rng.randrange(len(d.units))
    unit = d.units[index]
    which = rng.randrange(len(unit.messages))
    message = unit.messages[which]
    data = bytearray(message.data)
    at = rng.randrange(len(data))
    data[at] ^= rng.randint(1, 255)
    unit.messages[which] = replace(message, data=bytes(data))
    kinds = CHECKPOINT if unit.kind == "checkpoint" else CONTENT
    return Expect(f"flip byte {at} of {message.topic} in cycle {unit.cycle}", kinds, unit.cycle)


def delete_cycle(d: Decoded, rng: random.Random, _: Signer) -> Expect:
    index = rng.choice(d.cycles())
    unit = d.units.pop(index)
    kinds = frozenset({"missing", "truncated", "checkpoint_mismatch"})
    return Expect(f"delete cycle {unit.cycle}", kinds, unit.cycle)


def swap_cycles(d: Decoded, rng: random.Random, _: Signer) -> Expect:
    a, b = sorted(rng.sample(d.cycles(), 2))
    if rng.random() < 0.5:  # often neighbours, the hardest case to tell from a modification
        b = d.cycles()[d.cycles().index(a) + 1] if a != d.cycles()[-1] else b
    d.units[a], d.units[b] = d.units[b], d.units[a]
    first, second = d.units[b].cycle, d.units[a].cycle
    return Expect(f"swap cycles {first} and {second}", frozenset({"reordered"}), second)


def swap_cycles_other_side(d: Decoded, rng: random.Random, signer: Signer) -> Expect:
    """The same swap, checked from the other cycle's side: both must be located."""
    expect = swap_cycles(d, rng, signer)
    first = int(expect.what.split()[2])
    return Expect(expect.what, expect.kinds, first)


def insert_forged(d: Decoded, rng: random.Random, _: Signer) -> Expect:
    """Insert a plausible forged cycle after a real one: fresh digests, a seal naming it."""
    cycles = d.cycles()[:-1]
    index = rng.choice(cycles)
    model = d.units[index]
    number = model.cycle + rng.choice((0, 1))
    t_ns = model.t_ns + PERIOD_NS // 2
    messages: list[RawMessage] = []
    digests: dict[str, str] = {}
    for m in model.messages:
        if m.topic == TOPIC_SEAL:
            continue
        data = m.data
        if m.topic in LAYER_TOPICS:
            value = orjson.loads(data)
            value["cycle"], value["t_ns"] = number, t_ns
            if m.topic == TOPIC_ACTION:
                value["command"] = "CONTINUE"
            data = orjson.dumps(value)
            digests[m.topic] = digest(data)
        messages.append(replace(m, data=data, log_time_ns=t_ns, sequence=m.sequence))
    prev = digest(model.messages[-1].data) if rng.random() < 0.7 else digest(b"forged")
    seal = encode_seal(Seal(cycle=number, t_ns=t_ns, digests=digests, prev=prev))
    messages.append(RawMessage(TOPIC_SEAL, number, t_ns, seal))
    d.units.insert(index + 1, Unit("cycle", messages))
    return Expect(
        f"insert forged cycle {number} after {model.cycle}", frozenset({"inserted"}), number
    )


def cut_tail(d: Decoded, rng: random.Random, _: Signer) -> Expect:
    """Cut everything after a cycle and write a clean summary, as a careful editor would."""
    cycles = d.cycles()
    keep = rng.choice(cycles[len(cycles) // 3 : -1])
    last = d.units[keep].cycle
    del d.units[keep + 1 :]
    return Expect(f"cut the log after cycle {last}", frozenset({"truncated"}), last + 1)


def resign_other_key(d: Decoded, rng: random.Random, _: Signer) -> Expect:
    """Re-sign every checkpoint with another key (the attacker's own)."""
    attacker = Ed25519Signer.generate()
    same_id = rng.random() < 0.5  # also claim the robot's key id: the signature then fails
    first = None
    for i in d.checkpoints():
        (m,) = d.units[i].messages
        c = decode_checkpoint(m.data)
        fields = c.model_dump(exclude={"signature", "key_id"})
        signed = make_checkpoint(signer=attacker, **fields)
        if same_id:
            signed = _claim_key(signed, c.key_id or "", attacker)
        d.units[i].messages[0] = replace(m, data=encode_checkpoint(signed))
        first = c.cycle if first is None else first
    assert first is not None
    kinds = frozenset({"bad_signature" if same_id else "key_mismatch"})
    return Expect(
        f"re-sign checkpoints ({'same key id' if same_id else 'own key id'})", kinds, first
    )


def _claim_key(checkpoint: Checkpoint, key_id: str, attacker: Ed25519Signer) -> Checkpoint:
    """Sign with the attacker's key while claiming the robot's key id."""
    claimed = checkpoint.model_copy(update={"key_id": key_id, "signature": None})
    return claimed.model_copy(update={"signature": attacker.sign(signing_bytes(claimed)).hex()})


def forge_and_recompute(d: Decoded, rng: random.Random, _: Signer) -> Expect:
    """Change a decision, recompute every later seal and checkpoint, sign with another key."""
    attacker = Ed25519Signer.generate()
    cycles = d.cycles()
    target = rng.choice(cycles)
    number = d.units[target].cycle
    prev: str | None = None
    for i, unit in enumerate(d.units):
        if unit.kind == "cycle":
            if i < target:
                prev = digest(unit.messages[-1].data)
                continue
            messages = unit.messages
            if i == target:
                for j, m in enumerate(messages):
                    if m.topic == TOPIC_ACTION:
                        value = orjson.loads(m.data)
                        value["command"] = "STOP" if value["command"] != "STOP" else "CONTINUE"
                        messages[j] = replace(m, data=orjson.dumps(value))
            seal = Seal.model_validate_json(messages[-1].data)
            digests = {m.topic: digest(m.data) for m in messages if m.topic in seal.digests}
            new_seal = encode_seal(
                seal.model_copy(update={"digests": digests, "prev": prev or seal.prev})
            )
            messages[-1] = replace(messages[-1], data=new_seal)
            prev = digest(new_seal)
        elif i > target:
            (m,) = unit.messages
            c = decode_checkpoint(m.data)
            fields = c.model_dump(exclude={"signature", "key_id"})
            fields["head"] = prev
            unit.messages[0] = replace(
                m, data=encode_checkpoint(make_checkpoint(signer=attacker, **fields))
            )
    return Expect(
        f"forge cycle {number} and recompute the chain", frozenset({"key_mismatch"}), number
    )


def _uncited_reading(d: Decoded, rng: random.Random) -> tuple[Unit, int]:
    """A cycle whose radar reading no evidence ref cites (a clear aisle), and its index."""
    for index in rng.sample(d.cycles(), len(d.cycles())):
        unit = d.units[index]
        for at, message in enumerate(unit.messages):
            if message.topic == "/sensors/radar":
                return unit, at
    raise AssertionError("the campaign's log has no uncited reading")


def change_uncited_reading(d: Decoded, rng: random.Random, _: Signer) -> Expect:
    """Change a reading no evidence cites: the radar "saw nothing", now it saw something."""
    unit, at = _uncited_reading(d, rng)
    reading = unit.messages[at]
    changed = b'{"targets":[{"range":0.7}]}'
    unit.messages[at] = replace(reading, data=changed)
    return Expect(f"change uncited reading of cycle {unit.cycle}", CONTENT, unit.cycle)


def delete_reading(d: Decoded, rng: random.Random, _: Signer) -> Expect:
    unit, at = _uncited_reading(d, rng)
    del unit.messages[at]
    return Expect(f"delete uncited reading of cycle {unit.cycle}", CONTENT, unit.cycle)


def add_reading(d: Decoded, rng: random.Random, _: Signer) -> Expect:
    """Add a reading (with a fresh sequence number) to a cycle that did not log it."""
    unit, at = _uncited_reading(d, rng)
    reading = unit.messages[at]
    added = replace(reading, sequence=reading.sequence + 10_000, data=b'{"targets":[]}')
    unit.messages.insert(at, added)
    return Expect(f"add a reading to cycle {unit.cycle}", CONTENT, unit.cycle)


def move_reading(d: Decoded, rng: random.Random, _: Signer) -> Expect:
    """Keep a reading's bytes, but file it under another sensor or another time."""
    unit, at = _uncited_reading(d, rng)
    reading = unit.messages[at]
    if rng.random() < 0.5:
        moved = replace(reading, topic="/sensors/sonar")
    else:
        moved = replace(reading, log_time_ns=reading.log_time_ns - PERIOD_NS // 3)
    unit.messages[at] = moved
    return Expect(f"move the reading of cycle {unit.cycle}", CONTENT, unit.cycle)


MUTATIONS_BY_NAME: dict[str, Callable[[Decoded, random.Random, Signer], Expect]] = {
    "change_uncited_reading": change_uncited_reading,
    "delete_reading": delete_reading,
    "add_reading": add_reading,
    "move_reading": move_reading,
    "flip_byte": flip_byte,
    "delete_cycle": delete_cycle,
    "swap_cycles": swap_cycles,
    "swap_cycles_other_side": swap_cycles_other_side,
    "insert_forged": insert_forged,
    "cut_tail": cut_tail,
    "resign_other_key": resign_other_key,
    "forge_and_recompute": forge_and_recompute,
}


# --- the campaign ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def signed_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Ed25519Signer]:
    signer = Ed25519Signer.generate()
    path = tmp_path_factory.mktemp("campaign") / "run.mcap"
    return write_signed_log(path, signer), signer


def _copy(decoded: Decoded) -> Decoded:
    return Decoded(decoded.session, [Unit(u.kind, list(u.messages)) for u in decoded.units])


def test_an_unmodified_rewrite_verifies_clean(
    signed_log: tuple[Path, Ed25519Signer], tmp_path: Path
) -> None:
    """The rewriting tool itself must not create findings, with either writer."""
    path, signer = signed_log
    original = decode(path)
    assert len(original.cycles()) == CYCLES and len(original.checkpoints()) >= 6
    for seed in range(4):
        out = tmp_path / f"clean-{seed}.mcap"
        write(_copy(original), out, random.Random(seed))
        report = verify_log(out, key=signer.public_key)
        assert report.ok, report.findings
        assert report.cycles_valid == CYCLES
        assert report.checkpoints_valid == report.checkpoints == len(original.checkpoints())


def test_tamper_campaign_every_mutation_is_detected_and_located(
    signed_log: tuple[Path, Ed25519Signer], tmp_path: Path
) -> None:
    path, signer = signed_log
    original = decode(path)
    rng = random.Random(20240607)
    names = list(MUTATIONS_BY_NAME)
    missed: list[str] = []
    counts: dict[str, int] = dict.fromkeys(names, 0)
    for n in range(MUTATIONS):
        name = names[n % len(names)]
        decoded = _copy(original)
        expect = MUTATIONS_BY_NAME[name](decoded, rng, signer)
        out = tmp_path / f"m{n:03d}.mcap"
        write(decoded, out, rng)
        report = verify_log(out, key=signer.public_key)
        counts[name] += 1
        if not expect.met_by(report):
            found = [
                (f.kind, f.where.first_cycle, f.where.last_cycle, f.message)
                for f in report.findings
            ]
            missed.append(
                f"#{n} {expect.what}: expected {sorted(expect.kinds)} at cycle "
                f"{expect.cycle}, got {found}"
            )
        out.unlink()
    assert not missed, f"{len(missed)} of {MUTATIONS} mutations missed:\n" + "\n".join(missed)
    assert all(count >= MUTATIONS // len(names) for count in counts.values()), counts


# --- a log root: segments removed or cut -------------------------------------------------------


@pytest.fixture(scope="module")
def signed_root(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Ed25519Signer]:
    """Four hot segments of 2 s each, checkpoints every 0.5 s."""
    signer = Ed25519Signer.generate()
    root = tmp_path_factory.mktemp("root") / "log"
    write_signed_log(root, signer, 80, interval_s=0.5, max_segment_s=2.0)
    assert len(sorted((root / "hot").glob("*.mcap"))) == 4
    return root, signer


def _copy_root(root: Path, tmp_path: Path, name: str) -> Path:
    out = tmp_path / name
    shutil.copytree(root, out)
    return out


def test_a_clean_root_verifies_across_segments(signed_root: tuple[Path, Ed25519Signer]) -> None:
    root, signer = signed_root
    report = verify_log(root, key=signer.public_key)
    assert report.ok, report.findings
    assert (report.cycle_range.first_cycle, report.cycle_range.last_cycle, report.cycles_valid) == (
        0,
        79,
        80,
    )
    assert len(report.segments) == report.segments_valid == 4
    (robot,) = report.robots
    assert robot.anchored_cycle == 79 and robot.unanchored_cycles == 0


@pytest.mark.parametrize("removed", [1, 2])
def test_removing_a_middle_segment_is_located(
    signed_root: tuple[Path, Ed25519Signer], tmp_path: Path, removed: int
) -> None:
    root, signer = signed_root
    out = _copy_root(root, tmp_path, f"minus{removed}")
    gone = out / "hot" / f"amr-7_{removed:06d}.mcap"
    before = decode(out / "hot" / f"amr-7_{removed - 1:06d}.mcap")
    tail = before.units[before.cycles()[-1]].cycle
    gone.unlink()
    report = verify_log(out, key=signer.public_key)
    (finding,) = [f for f in report.findings if f.kind == "missing_segment"]
    assert finding.segment_no == removed + 1 and finding.where.first_cycle == tail + 1
    assert f"segment(s) {removed} " in finding.message


@pytest.mark.parametrize("seed", range(12))
def test_mutating_one_segment_of_a_root_is_located(
    signed_root: tuple[Path, Ed25519Signer], tmp_path: Path, seed: int
) -> None:
    root, signer = signed_root
    rng = random.Random(seed)
    out = _copy_root(root, tmp_path, f"root-{seed}")
    victim = rng.choice(sorted((out / "hot").glob("*.mcap")))
    decoded = decode(victim)
    mutation = rng.choice([flip_byte, delete_cycle, swap_cycles, insert_forged, cut_tail])
    expect = mutation(decoded, rng, signer)
    write(decoded, victim, rng)
    report = verify_log(out, key=signer.public_key)
    assert expect.met_by(report), (expect, report.findings)
    assert all(f.segment.endswith(victim.name) or f.kind == "missing" for f in report.findings)


def test_a_raw_cut_of_the_last_segment_reads_as_a_crash(
    signed_root: tuple[Path, Ed25519Signer], tmp_path: Path
) -> None:
    """Bytes cut off the newest segment look exactly like a crash: reported, not tampering."""
    root, signer = signed_root
    out = _copy_root(root, tmp_path, "rawcut")
    last = out / "hot" / "amr-7_000003.mcap"
    data = last.read_bytes()
    # Cut into the data section (the footer's summary_start), not the file: the summary
    # repeats the schemas, so a cut by file size can land past every chunk. Several cuts:
    # whether one lands just after a checkpoint depends on the bytes before it (the schemas).
    (summary_start,) = struct.unpack_from("<Q", data, len(data) - 8 - 20)
    unanchored_seen = 0
    for numerator in (1, 2, 3, 4):
        last.write_bytes(data[: summary_start * (numerator + 3) // 8])
        report = verify_log(out, key=signer.public_key)
        assert report.ok, report.findings
        kinds = {n.kind for n in report.notes}
        assert "recovered" in kinds
        (robot,) = report.robots
        assert robot.anchored_cycle is not None
        if "unanchored" in kinds:
            unanchored_seen += 1
            assert robot.unanchored_cycles > 0
            assert robot.anchored_cycle < robot.cycle_range.last_cycle  # type: ignore[operator]
    assert unanchored_seen > 0


def test_a_raw_cut_of_a_middle_segment_is_tampering(
    signed_root: tuple[Path, Ed25519Signer], tmp_path: Path
) -> None:
    """A crash cannot cut a segment that a later segment continues from its original end."""
    root, signer = signed_root
    out = _copy_root(root, tmp_path, "midcut")
    middle = out / "hot" / "amr-7_000001.mcap"
    data = middle.read_bytes()
    middle.write_bytes(data[: len(data) // 2])
    report = verify_log(out, key=signer.public_key)
    assert not report.ok
    assert any(
        f.kind in ("missing", "modified") and f.segment.endswith("amr-7_000002.mcap")
        for f in report.findings
    ), report.findings
