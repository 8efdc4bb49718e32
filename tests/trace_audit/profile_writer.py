"""A TRACE log written from schemas/PROFILE.md alone, with the plain ``mcap`` writer.

This is what a developer in another language would do: no ``trace_runtime`` anywhere, only
the profile's words (header, session keys, one channel per layer with the schema files, JSON
messages with cycle and t_ns, log_time = t_ns, sequence = cycle, sensors before layers before
the seal, SHA-256 digests of the stored bytes, the seal chain, a final checkpoint). ``Faults``
switch on one deviation at a time so tests can check that ``doctor`` names the rule broken.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from mcap.writer import CompressionType, Writer

SCHEMAS = Path(__file__).resolve().parents[2] / "schemas"
LAYERS = ("perception", "belief", "action", "execution")
GENESIS = "0" * 64
PERIOD_NS = 100_000_000


@dataclass(frozen=True)
class Faults:
    """One deviation from the profile each (all off: a conforming log)."""

    log_time_off_by: int = 0  # /trace/action's MCAP log_time = t_ns + this
    sequence_off_by: int = 0  # /trace/belief's MCAP sequence = cycle + this
    sensor_after_layers: bool = False  # cycle 3's sensor message after its perception
    spaced_json: bool = False  # json.dumps default separators for /trace/action
    profile: str = "trace"
    second_session: bool = False
    schema_encoding: str = "jsonschema"
    unsealed_tail: bool = False  # a closed file ends with layer messages and no seal
    no_session: bool = False
    lz4: bool = False
    clock_step_back_at: int | None = None  # from this cycle on, t_ns is 2.5 periods earlier
    profile_version: str = "1.1"  # "1.3": every seal covers the cycle's sensor readings
    radar: bool = False  # each cycle also logs a radar reading that no evidence ref cites
    seal_without_sensors_at: int | None = None  # (1.3) this cycle's seal leaves 'sensors' out


def _compact(value: object, spaced: bool = False) -> bytes:
    if spaced:
        return json.dumps(value).encode()
    return json.dumps(value, separators=(",", ":"), ensure_ascii=False).encode()


def _sensor_line(topic: str, sequence: int, log_time: int, data: bytes) -> bytes:
    """``<L>:<topic>\\n<sequence>\\n<log_time>\\n<data digest>\\n`` (PROFILE §6, ``sensors``)."""
    name = topic.encode()
    hexed = hashlib.sha256(data).hexdigest()
    return str(len(name)).encode() + b":" + name + f"\n{sequence}\n{log_time}\n{hexed}\n".encode()


def _layer(name: str, cycle: int, t_ns: int, distance: float, ref: dict[str, object]) -> dict:
    stamp = {"cycle": cycle, "t_ns": t_ns}
    if name == "perception":
        entity = {
            "id": "person_1",
            "class": "person",
            "pose": {"position": [distance, 0.0, 0.0]},
            "confidence": {"person": 0.9},
            "evidence": [{"sensor": "range", "weight": 1.0, "ref": ref}],
        }
        return {**stamp, "entities": [entity], "sensors_used": ["range"]}
    if name == "belief":
        return {
            **stamp,
            "nodes": [
                {"id": "person_1", "kind": "entity", "p": 0.9, "entity": "person_1"},
                {"id": "distance", "kind": "state", "p": 0.95, "value": distance, "unit": "m"},
            ],
            "edges": [{"parent": "person_1", "child": "distance", "p": 0.95, "rule": "range"}],
        }
    if name == "action":
        command = "STOP" if distance < 2.0 else "CONTINUE"
        return {
            **stamp,
            "command": command,
            "alternatives": [{"command": "SLOW", "score": 0.2, "rejected_because": "rule"}],
            "rationale": {
                "text": f"person at {distance} m",
                "factors": [{"node": "distance", "value": distance, "unit": "m"}],
            },
            "counterfactuals_none_applicable": True,
        }
    return {
        **stamp,
        "intended": {"linear": 0.5},
        "actual": {"linear": 0.48},
        "deviation": 0.02,
    }


def write_profile_log(path: Path, cycles: int = 30, faults: Faults = Faults()) -> Path:
    """Write a TRACE segment the way PROFILE.md describes; return its path."""
    with path.open("wb") as stream:
        writer = Writer(
            stream,
            compression=CompressionType.LZ4 if faults.lz4 else CompressionType.ZSTD,
            chunk_size=4096,  # a stock writer cutting chunks by size (PROFILE section 5)
        )
        writer.start(profile=faults.profile, library="profile-only test writer")
        channels: dict[str, int] = {}
        for name in (*LAYERS, "seal", "checkpoint"):
            schema_name = f"trace.{name.capitalize()}"
            schema_id = writer.register_schema(
                schema_name, faults.schema_encoding, (SCHEMAS / f"{schema_name}.json").read_bytes()
            )
            channels[name] = writer.register_channel(f"/trace/{name}", "json", schema_id)
        sensor_schema = writer.register_schema(
            "trace.Sensor", "jsonschema", (SCHEMAS / "trace.Sensor.json").read_bytes()
        )
        range_channel = writer.register_channel("/sensors/range", "json", sensor_schema)
        radar_channel = writer.register_channel("/sensors/radar", "json", sensor_schema)
        session = {
            "robot_id": "profile-bot",
            "period_ns": str(PERIOD_NS),
            "software_version": "1.0",
            "policy_version": "p1",
            "clock": "sim",
            "segment": "0",
            "prev_seal": GENESIS,
            "first_cycle": "0",
            "tier": "hot",
            "profile_version": faults.profile_version,
        }
        if not faults.no_session:
            writer.add_metadata("trace.session", session)
        if faults.second_session:
            writer.add_metadata("trace.session", {**session, "robot_id": "other-bot"})
        prev = GENESIS
        last_seal = (0, 0)
        for cycle in range(cycles):
            t_ns = 1_000_000_000 + cycle * PERIOD_NS
            if faults.clock_step_back_at is not None and cycle >= faults.clock_step_back_at:
                t_ns -= PERIOD_NS * 5 // 2
            distance = round(1.0 + (cycle % 10) * 0.4, 2)
            reading = _compact({"range_m": distance})
            ref = {
                "topic": "/sensors/range",
                "log_time_ns": t_ns,
                "sequence": cycle,
                "digest": hashlib.sha256(reading).hexdigest(),
            }

            lines: list[bytes] = []  # PROFILE §6: each reading's line, in file order

            def sensor(
                cycle: int = cycle, t_ns: int = t_ns, reading: bytes = reading, lines: list = lines
            ) -> None:
                writer.add_message(range_channel, t_ns, reading, t_ns, sequence=cycle)
                lines.append(_sensor_line("/sensors/range", cycle, t_ns, reading))

            if faults.radar:
                echo = _compact({"targets": []})
                writer.add_message(radar_channel, t_ns - 1, echo, t_ns - 1, sequence=cycle)
                lines.append(_sensor_line("/sensors/radar", cycle, t_ns - 1, echo))

            late_sensor = faults.sensor_after_layers and cycle == 3
            if not late_sensor:
                sensor()
            digests: dict[str, str] = {}
            for name in LAYERS:
                data = _compact(
                    _layer(name, cycle, t_ns, distance, ref),
                    spaced=faults.spaced_json and name == "action",
                )
                log_time = t_ns + (faults.log_time_off_by if name == "action" else 0)
                sequence = cycle + (faults.sequence_off_by if name == "belief" else 0)
                writer.add_message(channels[name], log_time, data, log_time, sequence=sequence)
                digests[f"/trace/{name}"] = hashlib.sha256(data).hexdigest()
                if late_sensor and name == "perception":
                    sensor()
            if faults.unsealed_tail and cycle == cycles - 1:
                break
            fields: dict[str, object] = {
                "cycle": cycle,
                "t_ns": t_ns,
                "digests": digests,
                "prev": prev,
                "dropped": 0,
            }
            if faults.profile_version == "1.3" and faults.seal_without_sensors_at != cycle:
                cover = hashlib.sha256(b"".join(lines)).hexdigest()
                fields["sensors"] = {"count": len(lines), "digest": cover}
            seal = _compact(fields)
            writer.add_message(channels["seal"], t_ns, seal, t_ns, sequence=cycle)
            prev = hashlib.sha256(seal).hexdigest()
            last_seal = (cycle, t_ns)
        checkpoint = {
            "cycle": last_seal[0],
            "t_ns": last_seal[1],
            "robot_id": "profile-bot",
            "segment": 0,
            "first_cycle": 0,
            "sealed": last_seal[0] + 1,
            "head": prev,
            "final": True,
            "key_id": None,
            "signature": None,
        }
        writer.add_message(
            channels["checkpoint"],
            last_seal[1],
            _compact(checkpoint),
            last_seal[1],
            sequence=last_seal[0],
        )
        writer.finish()
    return path
