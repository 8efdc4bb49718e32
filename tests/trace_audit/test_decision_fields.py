"""``iter_decision_fields`` gives what ``iter_decisions`` gives of each decision's own
fields, from the action message alone (``trace_runtime.encoding.partial.DecisionFields``)."""

from __future__ import annotations

from pathlib import Path

from sim import FaultRates, RunConfig, run
from trace_audit.layers import iter_decision_fields, iter_decisions

FAULTS = FaultRates(rationale_truncation=0.1, counterfactual_timeout=0.1, audit_write_timeout=0.05)


def test_decision_fields_are_the_decisions_own(tmp_path: Path) -> None:
    run(RunConfig(out=tmp_path / "root", total_cycles=400, seed=9, faults=FAULTS))
    fast = list(iter_decision_fields(tmp_path / "root"))
    full = [d for d in iter_decisions(tmp_path / "root") if d.decision.command is not None]
    assert len(fast) == len(full) > 300
    for (robot, segment, fields), (full_robot, decision) in zip(fast, full, strict=True):
        assert (robot, segment) == (full_robot, decision.segment)
        assert (fields.cycle, fields.t_ns, fields.command) == (
            decision.cycle,
            decision.t_ns,
            decision.command,
        )
        assert fields.score == decision.score
        assert fields.rationale.text == decision.rationale
        assert fields.truncated == decision.truncated
        assert len(fields.alternatives) == len(decision.alternatives)
        assert len(fields.counterfactuals) == len(decision.counterfactuals)
        assert fields.counterfactuals_none_applicable == decision.counterfactuals_none_applicable
        assert [(f.node, f.name, f.value, f.unit) for f in fields.factors] == [
            (f.node, f.name, f.value, f.unit) for f in decision.factors
        ]
    assert any(f.truncated for _r, _s, f in fast)
