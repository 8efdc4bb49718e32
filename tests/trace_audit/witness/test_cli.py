"""``trace-audit witness`` is a sub-command group: ``serve``, ``push`` and ``vkey`` each have
their own options and ``--help``; an option of another one is a usage error (exit 2, one
line on stderr, like every other usage error); ``vkey`` prints the key alone."""

from __future__ import annotations

import re

import pytest

from tests.trace_audit.witness.conftest import ORIGIN, WITNESS_NAME, Keys, run_cli

OPTIONS = {
    "serve": {"--state", "--key", "--log", "--listen", "--name", "--tiles", "--help"},
    "push": {"--witness", "--robot", "--json", "--plain", "--help"},
    "vkey": {"--key", "--origin", "--cosignature", "--help"},
}


def _options(help_text: str) -> set[str]:
    """The options an ``Options:`` section lists (each line's first flag)."""
    section = help_text.split("\nOptions:\n", 1)[1]
    return set(re.findall(r"^  (--[a-z-]+)", section, flags=re.MULTILINE))


def test_the_group_help_lists_its_three_commands() -> None:
    shown = run_cli("witness", "--help")
    assert shown.returncode == 0
    listed = shown.stdout.split("\nCommands:\n", 1)[1]
    assert re.findall(r"^  ([a-z]+) ", listed, flags=re.MULTILINE) == ["serve", "push", "vkey"]


@pytest.mark.parametrize("command", sorted(OPTIONS))
def test_each_command_help_shows_its_own_options_only(command: str) -> None:
    shown = run_cli("witness", command, "--help")
    assert shown.returncode == 0
    usage = shown.stdout.splitlines()[0]  # the program is "python -m trace_audit.cli" here
    assert usage.startswith("Usage: ") and f" witness {command} [OPTIONS]" in usage
    assert _options(shown.stdout) == OPTIONS[command]
    assert not re.search(r"\b(serve|push|vkey): ", shown.stdout)  # no per-action prefixes


@pytest.mark.parametrize(
    ("args", "other"),
    [
        (("vkey", "--listen", "x"), "--listen"),
        (("serve", "--origin", "x"), "--origin"),
        (("push", "root", "--witness", "http://127.0.0.1:1", "--cosignature"), "--cosignature"),
    ],
)
def test_an_option_of_another_command_is_a_usage_error_in_one_line(
    args: tuple[str, ...], other: str
) -> None:
    done = run_cli("witness", *args)
    assert (done.returncode, done.stdout) == (2, "")
    # click may add "(Possible options: ...)" before the pointer to the command's help
    line = (
        rf"trace-audit: No such option: {other}\b[^\n]* \(see '[^\n]* witness {args[0]} --help'\)\n"
    )
    assert re.fullmatch(line, done.stderr)


def test_vkey_prints_the_robot_and_the_witness_key_alone(keys: Keys) -> None:
    robot = run_cli("witness", "vkey", "--key", str(keys.robot_pub), "--origin", ORIGIN)
    assert (robot.returncode, robot.stdout) == (0, keys.robot_vkey + "\n")
    witness = run_cli(
        "witness", "vkey", "--key", str(keys.witness_pub), "--origin", WITNESS_NAME,
        "--cosignature",
    )  # fmt: skip
    assert (witness.returncode, witness.stdout) == (0, keys.witness_verifier.vkey + "\n")


def test_vkey_refuses_a_name_c2sp_does_not_allow(keys: Keys) -> None:
    bad = run_cli("witness", "vkey", "--key", str(keys.robot_pub), "--origin", "two words")
    assert bad.returncode == 2 and bad.stdout == ""
    assert bad.stderr.startswith("trace-audit: --origin: ") and bad.stderr.count("\n") == 1
