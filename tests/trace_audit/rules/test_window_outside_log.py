"""check over a window outside the log: exit 2 naming the log's range, as timeline does."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.trace_audit.rules.check_helpers import rule_text, rules_file, run_check


@pytest.mark.parametrize(("start", "end"), [("300", None), ("140", "130"), (None, "10")])
def test_a_window_outside_the_log_exits_2_naming_its_range(
    tmp_path: Path, sample_log: Path, start: str | None, end: str | None
) -> None:
    rules = rules_file(tmp_path, rule_text("stop", "always(command.STOP < 0.5)"))
    args = [str(sample_log), "--rules", rules, "--plain"]
    args += ["--from", start] if start else []
    args += ["--to", end] if end else []
    code, out, err = run_check(*args)
    assert code == 2, (out, err)
    assert "the log's range" in err and len(err.strip().splitlines()) == 1
