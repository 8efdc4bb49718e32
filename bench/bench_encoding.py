"""Validation + canonical encoding of the four layer records: the candidates, side by side.

    .venv/bin/python bench/bench_encoding.py [--quick]

For the records of ``synthetic_cycle`` (a ~4.2 KB cycle), handed over built (pydantic
models) and as plain dicts, each candidate turns one cycle's four records into message
bytes. Times are microseconds per cycle (four records), the median of several runs, each
run timing every candidate once in turn so machine noise hits them alike; read the ratios.

- pydantic (the baseline of the ratios): ``model_validate`` for dicts, the model's serializer
  (Rust) for both.
- orjson, fixed key order: ``model_dump`` + orjson for models; for dicts orjson of the dict
  as given, NO validation (a lower bound; the key order is the robot's, not the schema's).
- msgspec mirror: a ``msgspec.Struct`` per model (``trace_runtime.encoding.codec._mirror``),
  converted from the dict (validation), then ``to_builtins`` + orjson (the canonical spelling), or
  msgspec's own JSON encoder (spells ``1e21`` where orjson and pydantic spell ``1e+21``).
- msgspec Structs built by the robot: encode only (what it would cost if the public records
  were Structs; they are not, so this is a floor, not a candidate).
- chosen (``trace_runtime.encoding.codec``): built records by orjson reading the validated fields
  (pydantic's bytes); dicts by the mirror and msgspec's encoder (the mirror bounds floats
  below 1e16, where msgspec spells as orjson does); pydantic for anything the mirror refuses
  (e.g. a dict with models nested inside).

Also per cycle, for scale: SHA-256 of the four messages, zstd-3 of them, and one
``CycleBuilder.sensor`` call (encode + digest + EvidenceRef).
"""

from __future__ import annotations

import argparse
import hashlib
import statistics
import time
from collections.abc import Callable
from typing import Any

import msgspec
import orjson
import zstandard

from trace_runtime.encoding.codec import _encode_mirror, _mirror, encode_layer, layer_message
from trace_runtime.record_model import RecordModel
from trace_runtime.records import LAYER_MODELS
from trace_runtime.testing import CaptureLogger, synthetic_cycle

MODELS = list(LAYER_MODELS.values())


def _v1_encode(cycle: int, record: RecordModel) -> bytes:
    """The baseline path per record (labelled v1): pydantic's serializer, then the stamp."""
    body = type(record).__pydantic_serializer__.to_json(record, by_alias=True)
    return b'{"cycle":%d,"t_ns":%d,' % (cycle, cycle * 100) + body[1:]


def _stamp(cycle: int, body: dict[str, Any]) -> dict[str, Any]:
    return {"cycle": cycle, "t_ns": cycle * 100, **body}


def candidates(
    built: list[tuple[RecordModel, ...]], dicts: list[list[dict[str, Any]]]
) -> dict[str, Callable[[], object]]:
    """name -> a function that encodes every cycle once."""
    structs = [
        [msgspec.convert(d, _mirror(m), strict=True) for m, d in zip(MODELS, c, strict=True)]
        for c in dicts
    ]
    mixed = [
        [{k: getattr(r, k) for k in type(r).model_fields} for r in c] for c in built
    ]  # top-level dicts holding built models: what a robot gets by nesting cycle.sensor() refs

    def pydantic_built() -> None:
        for i, c in enumerate(built):
            for r in c:
                _v1_encode(i, r)

    def pydantic_dicts() -> None:
        for i, c in enumerate(dicts):
            for m, d in zip(MODELS, c, strict=True):
                _v1_encode(i, m.model_validate(d))

    def orjson_built() -> None:
        for i, c in enumerate(built):
            for r in c:
                orjson.dumps(_stamp(i, r.model_dump(by_alias=True)))

    def orjson_dicts_unvalidated() -> None:
        for i, c in enumerate(dicts):
            for d in c:
                orjson.dumps(_stamp(i, d))

    def msgspec_dicts_orjson() -> None:
        for i, c in enumerate(dicts):
            for m, d in zip(MODELS, c, strict=True):
                body = msgspec.to_builtins(msgspec.convert(d, _mirror(m), strict=True))
                orjson.dumps(_stamp(i, body))

    def msgspec_dicts_own_json() -> None:
        enc = msgspec.json.encode
        for _i, c in enumerate(dicts):
            for m, d in zip(MODELS, c, strict=True):
                enc(msgspec.convert(d, _mirror(m), strict=True))

    def msgspec_built_from_attributes() -> None:
        for i, c in enumerate(built):
            for m, r in zip(MODELS, c, strict=True):
                value = msgspec.convert(r, _mirror(m), strict=True, from_attributes=True)
                orjson.dumps(_stamp(i, msgspec.to_builtins(value)))

    def msgspec_structs_encode_only() -> None:
        enc = msgspec.json.encode
        for c in structs:
            for s in c:
                enc(s)

    def chosen_built() -> None:
        for i, c in enumerate(built):
            for r in c:
                encode_layer(i, i * 100, r)

    def chosen_dicts() -> None:
        for i, c in enumerate(dicts):
            for m, d in zip(MODELS, c, strict=True):
                _encode_mirror(i, i * 100, msgspec.convert(d, _mirror(m), strict=True))

    def chosen_mixed() -> None:  # the mirror refuses, pydantic validates
        for i, c in enumerate(mixed):
            for m, d in zip(MODELS, c, strict=True):
                try:
                    msgspec.convert(d, _mirror(m), strict=True)
                except msgspec.ValidationError:
                    encode_layer(i, i * 100, m.model_validate(d), m)

    return {
        "pydantic, built (v1)": pydantic_built,
        "pydantic, dicts (v1: validate + serialize)": pydantic_dicts,
        "orjson fixed order, built (model_dump)": orjson_built,
        "orjson, dicts, NO validation": orjson_dicts_unvalidated,
        "msgspec mirror, dicts, + orjson": msgspec_dicts_orjson,
        "msgspec mirror, dicts, msgspec JSON": msgspec_dicts_own_json,
        "msgspec mirror, built (from_attributes) + orjson": msgspec_built_from_attributes,
        "msgspec Structs built, encode only (floor)": msgspec_structs_encode_only,
        "chosen, built: orjson reading the fields": chosen_built,
        "chosen, dicts: mirror + msgspec JSON": chosen_dicts,
        "chosen, dicts holding models (pydantic decides)": chosen_mixed,
    }


def scale(built: list[tuple[RecordModel, ...]]) -> dict[str, Callable[[], object]]:
    """Per-cycle costs around the encoding, for scale."""
    messages = [[encode_layer(i, i * 100, r) for r in c] for i, c in enumerate(built)]
    compressor = zstandard.ZstdCompressor(level=3)

    def sha256() -> None:
        for c in messages:
            for data in c:
                hashlib.sha256(data).hexdigest()

    def zstd3() -> None:
        for c in messages:
            compressor.compress(b"".join(c))

    def sensor() -> None:
        capture = CaptureLogger()  # a fresh one per run: cycle times start again at 0
        for i in range(len(built)):
            with capture.cycle(i) as builder:
                builder.sensor("/sensors/lidar", {"ranges": [1.5, 1.6, 1.7], "cluster": i})

    return {
        "sha256 of the 4 messages": sha256,
        "zstd-3 of the 4 messages (one per chunk)": zstd3,
        "a cycle with one sensor() call (CaptureLogger)": sensor,
    }


def measure(fns: dict[str, Callable[[], object]], cycles: int, runs: int) -> dict[str, float]:
    """Median microseconds per cycle of each function over ``runs`` interleaved runs."""
    times: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(runs):
        for name, fn in fns.items():
            start = time.perf_counter_ns()
            fn()
            times[name].append((time.perf_counter_ns() - start) / 1000 / cycles)
    return {name: statistics.median(values) for name, values in times.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer cycles and runs")
    args = parser.parse_args()
    n, runs = (200, 5) if args.quick else (1000, 9)
    built = [synthetic_cycle(i) for i in range(n)]
    dicts = [[r.model_dump(by_alias=True) for r in c] for c in built]
    size = statistics.median(
        sum(len(encode_layer(i, i * 100, r)) for r in c) for i, c in enumerate(built)
    )
    print(f"{n} cycles of ~{size:.0f} B (4 layer messages), median of {runs} runs, us/cycle")
    results = measure(candidates(built, dicts), n, runs)
    base = results["pydantic, dicts (v1: validate + serialize)"]
    for name, us in results.items():
        print(f"  {name:52s} {us:7.1f}   {base / us:5.1f}x faster than v1 dicts")
    print("for scale:")
    for name, us in measure(scale(built), n, runs).items():
        print(f"  {name:52s} {us:7.1f}")
    # Same bytes whichever way the record comes in (pydantic's: the model defines the format);
    # msgspec's own JSON would not always give them (exponent spelling).
    for i, (c, d) in enumerate(zip(built, dicts, strict=True)):
        for m, r, rd in zip(MODELS, c, d, strict=True):
            assert layer_message(m, i, i * 100, rd) == encode_layer(i, i * 100, r)
    print(f"  msgspec JSON of 1e21: {msgspec.json.encode(1e21)!r}, orjson: {orjson.dumps(1e21)!r}")
    print("chosen dict path gives the v1 bytes on every record: yes")


if __name__ == "__main__":
    main()
