"""``check --from/--to``: a signal a rule reads that occurs in the log, only not in the
window, is not called a typo; the note says it does not occur in the window and where the
log shows it. A signal the whole log never shows keeps the typo note. Run from outside."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.outside import cli
from tests.trace_audit.conftest import write_log

RULES = """
[[rule]]
name = "no_reroute_while_stopped"
stl = "always(command.REROUTE < 0.5 or command.HANDOVER < 0.5)"
"""


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    where = tmp_path_factory.mktemp("unseen")
    (where / "rules.toml").write_text(RULES, encoding="utf-8")
    # REROUTE is in force at 107.0-107.9 s (cycles 70-79) of this 100-109.9 s log
    return write_log(where / "run.mcap"), where / "rules.toml"


def test_a_signal_only_outside_the_window_is_placed_not_called_a_typo(
    log: tuple[Path, Path],
) -> None:
    path, rules = log
    done = cli("check", path, "--rules", rules, "--from", "+0", "--to", "+2", "--plain")
    assert done.returncode in (0, 1), done.stderr
    text = " ".join(done.stdout.split())  # the terminal's wrapping undone
    assert "command.REROUTE (a typo?)" not in text, text
    assert (
        "note: command.REROUTE does not occur in the window; the log shows it "
        "107.000 s .. 107.900 s (cycles 70-79)"
    ) in text, text
    assert "note: the log never shows command.HANDOVER (a typo?)" in text, text


def test_the_json_says_where_the_log_shows_it(log: tuple[Path, Path]) -> None:
    path, rules = log
    done = cli("check", path, "--rules", rules, "--from", "+0", "--to", "+2", "--json")
    rule = json.loads(done.stdout)["robots"][0]["rules"][0]
    assert rule["unseen"] == ["command.REROUTE", "command.HANDOVER"]
    assert rule["seen_outside"] == [
        {
            "signal": "command.REROUTE",
            "first_ns": 107_000_000_000,
            "last_ns": 107_900_000_000,
            "first_cycle": 70,
            "last_cycle": 79,
        }
    ]


def test_without_a_window_only_the_never_shown_signal_gets_a_note(
    log: tuple[Path, Path],
) -> None:
    path, rules = log
    done = cli("check", path, "--rules", rules, "--plain")
    text = " ".join(done.stdout.split())
    assert "REROUTE" not in text.split("note:", 1)[-1], text
    assert "note: the log never shows command.HANDOVER (a typo?)" in text, text
