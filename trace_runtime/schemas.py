"""JSON Schemas of the /trace channels, generated from the record models.

``python -m trace_runtime.schemas [DIR]`` regenerates ``schemas/*.json``; a test fails when
the committed files drift from the models. The same bytes are embedded in every segment's
MCAP Schema records, so a log carries the schema it was written against.
"""

from __future__ import annotations

import functools
import json
import sys
from pathlib import Path
from typing import Any

from trace_runtime.records import MESSAGE_MODELS, PROFILE_VERSION

SENSOR_SCHEMA_NAME = "trace.Sensor"
_SENSOR_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "Sensor reading",
    "description": "A sensor reading that evidence refs point to. Any JSON object.",
    "type": "object",
}


def schema_name(topic: str) -> str:
    """MCAP schema name of a /trace topic, e.g. ``trace.Perception``."""
    return "trace." + topic.rsplit("/", 1)[-1].capitalize()


def channel_schema(topic: str) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of one /trace channel's messages."""
    schema = MESSAGE_MODELS[topic].model_json_schema(by_alias=True, mode="serialization")
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": f"https://trace-audit.dev/schemas/v{PROFILE_VERSION}/{schema_name(topic)}.json",
        "x-trace-topic": topic,
        **schema,
    }


@functools.cache
def schema_bytes(topic: str) -> bytes:
    """The exact bytes stored in MCAP Schema records and in ``schemas/<name>.json``."""
    if not topic.startswith("/trace/"):
        return json.dumps(_SENSOR_SCHEMA, indent=2, sort_keys=True).encode() + b"\n"
    return json.dumps(channel_schema(topic), indent=2, sort_keys=True).encode() + b"\n"


def write_schemas(directory: Path) -> list[Path]:
    """Write one ``<schema name>.json`` per channel into ``directory``."""
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for topic in MESSAGE_MODELS:
        path = directory / f"{schema_name(topic)}.json"
        path.write_bytes(schema_bytes(topic))
        written.append(path)
    sensor = directory / f"{SENSOR_SCHEMA_NAME}.json"
    sensor.write_bytes(schema_bytes("/sensors/"))
    written.append(sensor)
    return written


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("schemas")
    for path in write_schemas(target):
        print(path)
