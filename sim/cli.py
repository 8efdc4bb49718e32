"""The simulator's ``trace-sim`` commands: parse, call ``sim.run`` (or ``sim.replay``), render.

``run``, ``scenarios`` and ``check-counterfactuals`` live here; the ``trace-sim`` program,
with the evaluation's ``baselines`` command among them, is assembled in ``evaluation/cli.py``.

Exit codes, trace-audit's (``trace_runtime.errors``): 0 ok, 1 findings
(``check-counterfactuals``), 2 usage, 3 unreadable log, 4 output that cannot be written.
"""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path
from typing import Annotated

import typer

from sim.faults import DEFAULT_ROBOT_ID, FaultRates
from sim.runner import (
    DURATION_BATCH,
    RunConfig,
    RunResult,
    SimOutputError,
    SimUsageError,
    parse_duration,
    parse_start,
    run,
)
from sim.scenarios import EPISODE_CYCLES, SCENARIOS
from trace_runtime.errors import EXIT_CANNOT_WRITE, EXIT_FINDINGS, EXIT_UNREADABLE, EXIT_USAGE

__all__ = [
    "app",
    "fail",
    "help_text",
    "new_app",
    "summary",
]


def new_app() -> typer.Typer:
    """A ``trace-sim`` app without commands: the program's name, help and click's plain help."""
    return typer.Typer(
        name="trace-sim",
        help="Warehouse robot simulator that writes TRACE audit logs (the paper's evaluation).",
        add_completion=False,
        no_args_is_help=True,
        pretty_exceptions_enable=False,
        # click's plain help, as trace-audit's: typer's rich panels import rich and pygments for
        # every --help, and print values as Python types ("<int>", "<bool>"). trace-audit's
        # command class that renames them is not imported here: sim/cli.py stays free of
        # trace_audit (tests/trace_runtime/test_layering.py), so each value is named by metavar.
        rich_markup_mode=None,
        context_settings={"max_content_width": 100},
    )


app = new_app()
"""The simulator's own commands, in the order ``trace-sim --help`` lists them."""


def fail(message: str, code: int) -> None:
    """Say ``trace-sim: message`` on stderr and exit with ``code``."""
    sys.stderr.write(f"trace-sim: {message}\n")
    raise typer.Exit(code)


def summary(text: str) -> str:
    """The first paragraph, for the command list (click cuts a derived one at ~45 characters
    with "...")."""
    return " ".join(text.strip().split("\n\n")[0].split())


def help_text(text: str) -> str:
    """Each prose paragraph on one line, so typer re-wraps it; indented examples keep theirs."""
    paras = text.strip().split("\n\n")
    return "\n\n".join(
        p if p.startswith("  ") else " ".join(line.strip() for line in p.splitlines())
        for p in paras
    )


_RUN_HELP = f"""Simulate scenarios and write the TRACE log plus a fault ground-truth sidecar.

Each cycle of a scenario run is its own write, so an injected audit-write timeout loses
exactly that cycle, as in the paper.

A --duration run (routine operation, cycling through the scenarios) writes --batch cycles
at a time, by default {DURATION_BATCH}: several times faster, and smaller. With faults on, an
injected audit-write timeout then makes one write fail and loses its whole batch ({DURATION_BATCH}
cycles, {DURATION_BATCH // 10} s of log). It strikes each write with the paper's 1%, so the
expected share of lost cycles is still 1%, in rarer and longer gaps; the ground-truth
sidecar lists every lost cycle with its batch. --batch 1 gives the paper's cycle-by-cycle
losses, at the paper runs' speed.

Examples:

  trace-sim run --scenario all --cycles 100 --seed 42 --out run.mcap

A .mcap file that exists is not overwritten (exit 4) unless --force; a log root is
continued, the robot's chain going on from its newest segment there.

  trace-sim run --duration 24h --seed 1 --out /data/amr-01

  trace-sim run --duration 2h --faults off --batch 100 --out day/ --json

Several simulated robots share one log root when each has its own --robot-id; --start
with an ISO 8601 UTC time gives them a wall clock (the segments' clock is then "system",
times are ns since the Unix epoch), with seconds a sim clock starting there (the default:
a sim clock from 0):

  trace-sim run --robot-id amr-3 --start 2026-05-04T06:00:00Z --out fleet/

A robot continued in a log root without --start goes on with its clock too: its first
cycle comes one period (0.1 s) after its last one there, on that log's clock, as a
restarted robot's clock does. A --start earlier than that restarts the clock (verify and
info say so: a clock restart, not tampering).

--key signs the robot's checkpoints with a key from trace-audit keygen (a key file, or a
pkcs11: URI of a key in a token); --witness URL has its logger submit each checkpoint to a
witness (trace-audit witness serve):

  trace-sim run --key robot.key --witness http://127.0.0.1:8080 --out logs/

--next-key rotates the robot to a new key (profile 1.5): the run's first checkpoint, signed
by --key, announces it and it signs from then on; verify --key with the first key's .pub
follows the rotation. Run it again with the same two keys and nothing is announced twice:
a chain that already handed on to --next-key is signed by it (or give --key NEW alone):

  trace-sim run --key old.key --next-key new.key --out logs/
"""


_Out = Annotated[
    Path, typer.Option("--out", "-o", metavar="PATH", help="a .mcap file or a log root directory")
]
_Scenario = Annotated[
    str, typer.Option(metavar="TEXT", help="all, or one of: " + ", ".join(SCENARIOS))
]
_Cycles = Annotated[
    int, typer.Option(metavar="INTEGER", help="decision cycles per scenario (10 Hz)")
]
_Seed = Annotated[int, typer.Option(metavar="INTEGER", help="random seed; same seed, same log")]
_Faults = Annotated[
    str, typer.Option(metavar="on|off", help="on: inject faults at the paper's rates; off: none")
]
_Duration = Annotated[
    str | None,
    typer.Option(
        metavar="TEXT", help="routine operation for this long (e.g. 24h), cycling through scenarios"
    ),
]
_Batch = Annotated[
    int | None,
    typer.Option(
        metavar="INTEGER",
        help=f"cycles per write, --duration runs only (default {DURATION_BATCH}); "
        "1 writes cycle by cycle like the paper's runs",
    ),
]
_RobotId = Annotated[
    str,
    typer.Option(
        "--robot-id",
        metavar="TEXT",
        help="the robot's id; robots with distinct ids share a log root",
    ),
]
_Start = Annotated[
    str | None,
    typer.Option(
        metavar="TEXT",
        help="the first cycle's time: an ISO 8601 UTC time (e.g. 2026-05-04T06:00:00Z, "
        "a wall clock) or seconds (a sim clock); default a sim clock from 0, or, for a "
        "robot continued in a log root, one period after its last cycle there",
    ),
]
_Key = Annotated[
    str | None,
    typer.Option(
        "--key",
        metavar="PATH|URI",
        help="the robot's private key (trace-audit keygen): a key file or a pkcs11: URI of a "
        "key in a token; checkpoints signed",
    ),
]
_NextKey = Annotated[
    str | None,
    typer.Option(
        "--next-key",
        metavar="PATH|URI",
        help="rotate to this key (a key file or a pkcs11: URI): --key announces it at the "
        "first checkpoint, unless the robot's chain already did; needs --key",
    ),
]
_Witness = Annotated[
    str | None,
    typer.Option(
        metavar="URL",
        help="a witness (trace-audit witness serve) the logger submits checkpoints to",
    ),
]
_Json = Annotated[bool, typer.Option("--json", help="print the summary as JSON")]
_Force = Annotated[
    bool, typer.Option("--force", help="replace an --out .mcap file that exists (and its sidecar)")
]


@app.command("run", help=help_text(_RUN_HELP), short_help=summary(_RUN_HELP))
def run_cmd(  # noqa: PLR0917 - typer maps each option to a parameter
    out: _Out,
    scenario: _Scenario = "all",
    cycles: _Cycles = 100,
    seed: _Seed = 0,
    faults: _Faults = "on",
    duration: _Duration = None,
    batch: _Batch = None,
    robot_id: _RobotId = DEFAULT_ROBOT_ID,
    start: _Start = None,
    key: _Key = None,
    next_key: _NextKey = None,
    witness: _Witness = None,
    as_json: _Json = False,
    force: _Force = False,
) -> None:
    """Simulate scenarios and write the TRACE log plus a fault ground-truth sidecar."""
    _clear_out(out, force=force)
    # Injected audit-write timeouts make the logger warn; the summary reports them instead.
    runtime_log = logging.getLogger("trace_runtime")
    level = runtime_log.level
    runtime_log.setLevel(logging.ERROR)
    try:
        config = _run_config(
            out=out,
            scenario=scenario,
            cycles=cycles,
            seed=seed,
            faults=faults,
            duration=duration,
            batch=batch,
            robot_id=robot_id,
            start=start,
            key=key,
            next_key=next_key,
            witness=witness,
        )
        result = run(config) if as_json else _run_with_progress(config)
    except SimUsageError as err:
        fail(str(err), EXIT_USAGE)
        return
    except SimOutputError as err:
        fail(str(err), EXIT_CANNOT_WRITE)
        return
    finally:
        runtime_log.setLevel(level)  # the caller's logging is theirs (e.g. a test session)
    if as_json:
        sys.stdout.write(json.dumps(result.as_dict(), indent=2) + "\n")
    else:
        _render(result)


def _clear_out(out: Path, *, force: bool) -> None:
    """An --out file that exists is a log already: refused (exit 4, like any output that
    exists), or with --force removed so the run writes a new one (the logger itself never
    opens a segment over a file)."""
    if out.suffix != ".mcap" or not (out.is_file() or out.is_symlink()):
        return
    if not force:
        fail(
            f"{out} exists; trace-sim does not overwrite a log (--force replaces it)",
            EXIT_CANNOT_WRITE,
        )
    try:
        out.unlink()
    except OSError as err:
        fail(f"cannot replace {out}: {err.strerror or err}", EXIT_CANNOT_WRITE)


def _run_config(
    *,
    out: Path,
    scenario: str,
    cycles: int,
    seed: int,
    faults: str,
    duration: str | None,
    batch: int | None,
    robot_id: str,
    start: str | None,
    key: str | None,
    next_key: str | None,
    witness: str | None,
) -> RunConfig:
    """The run the options ask for; ``SimUsageError`` for options that do not go together."""
    if faults not in ("on", "off"):
        raise SimUsageError(f"--faults must be on or off, got {faults!r}")
    if batch is not None and duration is None:
        raise SimUsageError("--batch needs --duration (scenario runs write cycle by cycle)")
    total = parse_duration(duration) if duration is not None else None
    if next_key is not None and key is None:
        raise SimUsageError("--next-key needs --key: the key the robot signs with announces it")
    # No --start: the runner goes on from the robot's last time in a log root (or 0).
    start_ns, clock = (None, "sim") if start is None else parse_start(start)
    return RunConfig(
        out=out,
        scenario=scenario,
        cycles=cycles,
        seed=seed,
        faults=FaultRates() if faults == "on" else FaultRates.off(),
        total_cycles=total,
        batch_cycles=1 if total is None else DURATION_BATCH if batch is None else batch,
        robot_id=robot_id,
        start_ns=start_ns,
        clock=clock,
        checkpoint_key=key,
        next_key=next_key,
        witness=witness,
    )


def _run_with_progress(config: RunConfig) -> RunResult:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    with Progress(
        "[progress.description]{task.description}",
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        transient=True,
    ) as bar:
        task = bar.add_task("simulating", total=None)

        def tick(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        return run(config, progress=tick)


def _render(result: RunResult) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title="trace-sim run", show_header=False, title_justify="left")
    table.add_column(style="bold")
    table.add_column()
    # Counted per cycle the robot decided, dropped or not: the log holds the written ones,
    # so its counts (trace-audit why, timeline) are lower by the dropped cycles.
    table.add_row("cycles", f"{result.cycles:,} decided, {result.written:,} written to the log")
    table.add_row("dropped", f"{result.dropped:,} (lost writes, not in the log; seals count them)")
    per_command = ", ".join(f"{k} {v:,}" for k, v in sorted(result.commands.items()))
    table.add_row("cycles per command", f"{per_command} (of the {result.cycles:,} decided)")
    table.add_row("STOP cycles", f"{result.commands.get('STOP', 0):,}")
    table.add_row("scenarios", ", ".join(f"{k} {v:,}" for k, v in result.scenarios.items()))
    faults = ", ".join(f"{k} {v:,}" for k, v in sorted(result.faults.items())) or "none"
    table.add_row("faults injected", faults)
    table.add_row("bytes written", f"{result.bytes_written:,}")
    table.add_row("cycles per write", f"{result.batch_cycles}")
    table.add_row("speed", f"{result.cycles_per_s:,.0f} cycles/s ({result.elapsed_s:.1f} s)")
    for name, out in result.safety.items():
        table.add_row(
            f"safety: {name}",
            f"min separation person {_m(out['min_separation_person_m'])}, "
            f"vehicle {_m(out['min_separation_vehicle_m'])}; "
            f"near misses {out['near_miss_events']} ({out['near_miss_cycles']} cycles); "
            f"stops (changes to STOP) {out['stops']}, time to stop median "
            f"{_s(out['time_to_stop_median_s'])}, "
            f"max {_s(out['time_to_stop_max_s'])}",
        )
    for cls, q in result.perception.get("per_class", {}).items():
        table.add_row(
            f"perception: {cls}",
            f"precision {_share(q['precision'])}, recall {_share(q['recall'])} "
            f"(true -> perceived: {result.perception['confusion'][cls]})",
        )
    table.add_row("log", str(result.out))
    table.add_row("truth", f"{result.truth} (ground truth; metrics must not read it)")
    Console().print(table)


def _m(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f} m"


def _s(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f} s"


def _share(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.1f}%"


@app.command("scenarios")
def scenarios_cmd(
    as_json: Annotated[bool, typer.Option("--json", help="print as JSON")] = False,
) -> None:
    """List the scenarios.

    Example: trace-sim scenarios --json
    """
    rows = [{"name": s.name, "description": s.description} for s in SCENARIOS.values()]
    if as_json:
        sys.stdout.write(json.dumps(rows, indent=2) + "\n")
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"scenarios (episodes of {EPISODE_CYCLES} cycles)")
    table.add_column("name", style="bold")
    table.add_column("description")
    for row in rows:
        table.add_row(row["name"], row["description"])
    Console().print(table)


_CHECK_HELP = """Re-run every logged decision and counterfactual against the policy.

For each cycle the policy input is rebuilt from the logged belief graph and the previous
cycle's taken path (the policy's hysteresis). The logged command must be what the policy
chooses; each counterfactual must hold under do(factor = threshold), the change propagated
to the factor's descendants through the logged edges' rules. Cycles the log cannot re-run
(a belief edge lost, the previous cycle missing) are counted as unverifiable.

Exit 0 when everything re-runs as logged, 1 listing each one that does not, 3 when the log
cannot be read.

Example:

  trace-sim check-counterfactuals run.mcap --json
"""


@app.command("check-counterfactuals", help=help_text(_CHECK_HELP), short_help=summary(_CHECK_HELP))
def check_counterfactuals_cmd(
    log: Annotated[
        Path, typer.Argument(metavar="LOG", help="a .mcap file or a log root directory")
    ],
    as_json: Annotated[bool, typer.Option("--json", help="print the report as JSON")] = False,
    plain: Annotated[bool, typer.Option("--plain", help="plain text, no colour")] = False,
) -> None:
    """Re-run every logged decision and counterfactual against the policy."""
    from sim.replay import check_counterfactuals
    from trace_runtime import TraceError

    try:
        report = check_counterfactuals(log)
    except SimUsageError as err:
        fail(str(err), EXIT_USAGE)
        return
    except TraceError as err:
        fail(f"cannot read {log}: {err}", EXIT_UNREADABLE)
        return
    if as_json:
        sys.stdout.write(json.dumps(report.as_dict(), indent=2) + "\n")
    else:
        lines = [
            f"{report.path}: {report.cycles} cycles, {report.decisions} decisions and "
            f"{report.counterfactuals} counterfactuals re-run",
            *(
                f"unverifiable: {n} counterfactuals ({why})"
                for why, n in report.unverifiable.items()
            ),
            *(
                f"cycle {f.cycle} (t = {f.t_ns / 1e9:.1f} s): {f.what} {f.claim!r}: {f.got}"
                for f in report.findings
            ),
            "all hold" if report.ok else f"{len(report.findings)} do not hold",
        ]
        if plain:
            sys.stdout.write("\n".join(lines) + "\n")
        else:
            from rich.console import Console

            Console(highlight=False).print("\n".join(lines), markup=False)
    if not report.ok:
        raise typer.Exit(EXIT_FINDINGS)
