"""The committed JSON Schemas are exactly what the record models generate."""

from __future__ import annotations

from pathlib import Path

from trace_runtime.schemas import write_schemas

SCHEMAS = Path(__file__).resolve().parents[2] / "schemas"


def test_committed_schemas_match_the_models(tmp_path: Path) -> None:
    generated = write_schemas(tmp_path)
    for path in generated:
        committed = SCHEMAS / path.name
        assert committed.exists(), f"{path.name} missing: run python -m trace_runtime.schemas"
        assert committed.read_bytes() == path.read_bytes(), (
            f"{path.name} drifted from the models: run python -m trace_runtime.schemas"
        )
    stale = {p.name for p in SCHEMAS.glob("*.json")} - {p.name for p in generated}
    assert not stale, f"schemas with no model behind them: {sorted(stale)}"
