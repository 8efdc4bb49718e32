"""trace-audit check: exit codes, JSON, and the shipped rules files on a sim and an arm log."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.trace_audit.rules.check_helpers import rules_file, run_check

ROOT = Path(__file__).resolve().parents[3]


def test_a_violated_rule_exits_1_with_the_explain_command(tmp_path: Path, sample_log: Path) -> None:
    rules = rules_file(
        tmp_path, '[[rule]]\nname = "never_stop"\nstl = "always(command.STOP < 0.5)"\n'
    )
    code, out, _ = run_check(str(sample_log), "--rules", rules, "--json")
    assert code == 1
    (rule,) = json.loads(out)["robots"][0]["rules"]
    assert rule["outcome"] == "violated"
    assert rule["violations"][0]["explain"].endswith("--cycle 40 --robot amr-7")
    assert rule["violations"][0]["start"] == "104"
    code, out, _ = run_check(str(sample_log), "--rules", rules, "--plain")
    assert code == 1 and "[VIOLATED] never_stop" in out


def test_a_satisfied_rule_exits_0(tmp_path: Path, sample_log: Path) -> None:
    rules = rules_file(tmp_path, '[[rule]]\nname = "ok"\nstl = "always(command.STOP < 1.5)"\n')
    assert run_check(str(sample_log), "--rules", rules, "--plain")[0] == 0


@pytest.mark.parametrize(
    "text",
    ['[[rule]]\nname = "bad"\nstl = "always(command.STOP <"\n', "[[rule]\n"],
)
def test_a_bad_rules_file_is_exit_2_in_one_line(
    tmp_path: Path, sample_log: Path, text: str
) -> None:
    code, out, err = run_check(str(sample_log), "--rules", rules_file(tmp_path, text))
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("trace-audit: ")
    assert "rule 'bad'" in err or "not valid TOML" in err


def test_an_unreadable_log_is_exit_3(tmp_path: Path) -> None:
    rules = rules_file(tmp_path, '[[rule]]\nname = "ok"\nstl = "always(command.STOP < 1.5)"\n')
    (tmp_path / "junk.mcap").write_bytes(b"not mcap")
    assert run_check(str(tmp_path / "junk.mcap"), "--rules", rules)[0] == 3


def test_the_warehouse_rules_hold_on_a_faults_off_sim_run(tmp_path: Path) -> None:
    out = tmp_path / "sim"
    subprocess.run(
        [
            *(sys.executable, "-m", "evaluation.cli", "run", "--duration", "1m", "--seed", "1"),
            *("--faults", "off", "--out", str(out)),
        ],
        check=True,
        cwd=ROOT,
        capture_output=True,
        timeout=120,
    )
    code, text, err = run_check(
        str(out), "--rules", str(ROOT / "docs/rules/warehouse.toml"), "--json"
    )
    assert code == 0, err
    outcomes = {r["rule"]: r["outcome"] for r in json.loads(text)["robots"][0]["rules"]}
    assert set(outcomes) >= {"person_stop_distance", "speed_limit_near_people", "time_to_stop"}
    assert set(outcomes.values()) == {"satisfied"}


def test_the_arm_rules_find_what_the_arms_own_check_finds(tmp_path: Path) -> None:
    log = tmp_path / "arm.mcap"
    script = ROOT / "examples" / "pick_and_place_arm.py"
    subprocess.run([sys.executable, str(script), "--out", str(log)], check=True, timeout=60)
    own = rules_file(
        tmp_path, '[[rule]]\nname = "own"\nstl = "always(check.ee_speed_near_hand > 0.5)"\n'
    )
    code, text, _ = run_check(str(log), "--rules", str(ROOT / "docs/rules/arm.toml"), "--json")
    assert code == 1
    rules = {r["rule"]: r for r in json.loads(text)["robots"][0]["rules"]}
    assert rules["grip_force_limit"]["outcome"] == "satisfied"
    assert rules["halt_for_hand"]["outcome"] == "satisfied"
    (own_rule,) = json.loads(run_check(str(log), "--rules", own, "--json")[1])["robots"][0]["rules"]
    cycles = [(v["first_cycle"], v["last_cycle"]) for v in rules["slow_near_hand"]["violations"]]
    assert cycles == [(v["first_cycle"], v["last_cycle"]) for v in own_rule["violations"]]
