"""The null logger, the scaling loop's records, and ``trace-sim baselines`` end to end."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest
from typer.testing import CliRunner

from evaluation.baselines import BaselinesConfig, BaselinesReport, run_baselines
from evaluation.baselines.cost import log_synthetic_cycle, synthetic_cycle
from evaluation.cli import app
from sim import FaultRates, RunConfig, run
from trace_audit.metrics import compute_metrics
from trace_runtime.testing import CaptureLogger


def test_the_null_logger_runs_the_same_cycles_and_writes_no_log(tmp_path: Path) -> None:
    results = {}
    for audit in (True, False):
        out = tmp_path / f"{audit}.mcap"
        results[audit] = run(
            RunConfig(out=out, scenario="multi_ped", cycles=30, seed=4,
                      faults=FaultRates.off(), audit=audit)
        )  # fmt: skip
        assert out.exists() is audit
    assert results[True].commands == results[False].commands
    assert results[False].written == 30 and results[False].bytes_written == 0


@pytest.mark.parametrize(("n", "k"), [(1, 2), (7, 5)])
def test_synthetic_scaling_records_are_valid_and_sized_by_n_and_k(n: int, k: int) -> None:
    log = CaptureLogger()
    with log.cycle(0) as c:
        log_synthetic_cycle(c, synthetic_cycle(n, k, 0))
    cycle = log.cycles[0]
    assert cycle.perception is not None and len(cycle.perception.entities) == n
    assert cycle.action is not None and len(cycle.action.alternatives) == k - 1
    assert len(cycle.action.counterfactuals or []) == n * (k - 1)


SMALL = BaselinesConfig(
    seed=3,
    seeds=2,
    cycles=20,
    train_runs=1,
    explain_per_seed=6,
    overhead_repeats=1,
    scaling_entities=(1, 4),
    scaling_actions=(2,),
    scaling_cycles=3,
    scaling_repeats=1,
)


def test_baselines_report_has_every_method_scored_on_the_same_runs(tmp_path: Path) -> None:
    report = run_baselines(SMALL)
    data = report.as_dict()
    assert set(data["methods"]) == {"TRACE", "LIME", "SHAP", "attention"}
    for name in ("LIME", "SHAP", "attention"):
        m = data["methods"][name]
        assert m["decisions"] == 2 * 6
        assert 0.0 <= m["ET"] <= m["ET_partial"] + 1e-9 <= 1.0 + 1e-9
        # none of the three makes counterfactuals, so none reconstructs a decision
        assert m["DR"] == 0.0
        assert m["bytes_per_decision"] > 0 and m["ms_per_decision"] > 0
    assert data["overhead"]["same_commands"] is True
    assert [(p["entities"], p["actions"]) for p in data["scaling"]] == [(1, 2), (4, 2)]
    assert 0.0 <= data["policy_accuracy"] <= 1.0
    # TRACE's row is the investigator's metrics on the same seeds' logs
    ets = []
    for seed in (3, 4):
        out = tmp_path / f"{seed}.mcap"
        run(RunConfig(out=out, cycles=20, seed=seed))
        ets.append(compute_metrics([out]).overall.et.mean)
    assert data["methods"]["TRACE"]["ET"] == pytest.approx(sum(ets) / 2, abs=1e-4)


def test_the_command_rejects_bad_options_with_exit_2() -> None:
    result = CliRunner().invoke(app, ["baselines", "--seeds", "0", "--json"])
    assert result.exit_code == 2
    assert "seeds must be at least 1" in result.output


def test_the_command_prints_json_and_a_plain_table(monkeypatch: pytest.MonkeyPatch) -> None:
    import evaluation.baselines

    real = evaluation.baselines.run_baselines

    def small(config: BaselinesConfig, progress: object = None) -> BaselinesReport:
        # keep the command's parsing; shrink only what it has no option for
        return real(replace(config, **{k: getattr(SMALL, k) for k in _NO_OPTION}))

    monkeypatch.setattr(evaluation.baselines, "run_baselines", small)
    args = ["baselines", "--seeds", "1", "--cycles", "10", "--explain", "3"]
    result = CliRunner().invoke(app, [*args, "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["seeds"] == [1]
    assert data["methods"]["LIME"]["decisions"] == 3
    plain = CliRunner().invoke(app, [*args, "--plain"])
    assert plain.exit_code == 0, plain.output
    rows = [line.split("\t") for line in plain.output.splitlines()]
    assert [r[0] for r in rows[1:5]] == ["TRACE", "LIME", "SHAP", "attention"]
    table = CliRunner().invoke(app, args)
    assert table.exit_code == 0, table.output
    # one seed: the table says so and shows no "± 0.0" that would read as a measured spread
    text = " ".join(table.output.split())  # rich wraps the title to the terminal
    assert "one seed: no spread" in text and "±" not in text
    assert f"{data['methods']['TRACE']['decisions']} logged decisions" in text


_NO_OPTION = (
    "train_runs",
    "overhead_repeats",
    "scaling_entities",
    "scaling_actions",
    "scaling_cycles",
    "scaling_repeats",
)
