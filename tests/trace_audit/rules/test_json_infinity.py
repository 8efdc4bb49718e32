"""check --json: a robustness that is infinite (nothing of the class was perceived) is
null, never the invalid JSON token Infinity."""

from __future__ import annotations

import json
from pathlib import Path

from tests.trace_audit.rules.check_helpers import rule_text, rules_file, run_check


def test_an_infinite_robustness_is_null_in_json(tmp_path: Path, sample_log: Path) -> None:
    rules = rules_file(tmp_path, rule_text("far", "always(nearest.vehicle > 1.0)"))
    code, out, _ = run_check(str(sample_log), "--rules", rules, "--json")
    assert code == 0 and "Infinity" not in out
    (rule,) = json.loads(out)["robots"][0]["rules"]
    assert rule["robustness"] is None and rule["outcome"] == "satisfied"
    code, out, _ = run_check(str(sample_log), "--rules", rules, "--plain")
    assert code == 0 and "robustness inf" in out
