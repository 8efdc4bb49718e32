"""The ``trace-sim`` program: the simulator's commands and the evaluation's ``baselines``.

``baselines`` reads the simulator's logs with the investigator (``trace_audit``), so it sits
above both; the simulator's own commands come from ``sim/cli.py``, which never imports the
investigator. Parse, call ``evaluation.baselines.run_baselines``, render.
"""

from __future__ import annotations

import json
import logging
import sys
from typing import Annotated, Any

import typer

from sim.cli import app as simulator_app
from sim.cli import fail, help_text, new_app, summary
from sim.runner import SimUsageError
from trace_runtime.errors import EXIT_USAGE

__all__ = ["app", "main"]

_BASELINES_HELP = """Measure TRACE against LIME, SHAP and attention on the paper's runs.

Trains a learned policy (random forest) and a one-layer attention model on runs with other
seeds, explains their decisions on --seeds evaluation runs (5 scenarios x --cycles each,
faults at the paper's rates), and scores every method's output with the metrics TRACE is
scored with (docs/metrics.md, "Explanation baselines"). Then TRACE's cost per cycle with
the audit logger on and off (same runs), and its growth with entities n and actions k.
Needs the [baselines] extra. Figures: mean over seeds (std across seeds with --json).

Examples:

  trace-sim baselines

  trace-sim baselines --seed 7 --seeds 10 --json > baselines.json
"""


def baselines_cmd(  # noqa: PLR0917 - typer maps each option to a parameter
    cycles: Annotated[
        int, typer.Option(metavar="INTEGER", help="decision cycles per scenario and run")
    ] = 100,
    seed: Annotated[
        int, typer.Option(metavar="INTEGER", help="first evaluation seed (the others follow)")
    ] = 1,
    seeds: Annotated[
        int, typer.Option(metavar="INTEGER", help="evaluation runs, one per seed")
    ] = 5,
    explain: Annotated[
        int,
        typer.Option(
            metavar="INTEGER", help="decisions explained per run by each method (a random sample)"
        ),
    ] = 100,
    as_json: Annotated[bool, typer.Option("--json", help="print the report as JSON")] = False,
    plain: Annotated[
        bool, typer.Option("--plain", help="tab-separated lines, no colour or progress")
    ] = False,
) -> None:
    """Measure TRACE against LIME, SHAP and attention on the paper's runs."""
    runtime_log = logging.getLogger("trace_runtime")
    level = runtime_log.level
    runtime_log.setLevel(logging.ERROR)  # injected write timeouts are part of the runs
    try:
        from evaluation.baselines import BaselinesConfig, run_baselines

        config = BaselinesConfig(seed=seed, seeds=seeds, cycles=cycles, explain_per_seed=explain)
        if as_json or plain or not sys.stderr.isatty():
            report = run_baselines(config)
        else:
            from rich.console import Console

            with Console(stderr=True).status("baselines") as status:
                report = run_baselines(config, progress=status.update)
    except ImportError as err:
        fail(f"needs the [baselines] extra ({err.name} is not installed)", EXIT_USAGE)
        return
    except SimUsageError as err:
        fail(str(err), EXIT_USAGE)
        return
    finally:
        runtime_log.setLevel(level)
    data = report.as_dict()
    if as_json:
        sys.stdout.write(json.dumps(data, indent=2) + "\n")
    elif plain:
        _render_baselines_plain(data)
    else:
        _render_baselines(data)


def _render_baselines_plain(data: dict[str, Any]) -> None:
    out = ["method\tET\tET_partial\tDR\tms_per_decision\tbytes_per_decision\tdecisions"]
    for name, m in data["methods"].items():
        out.append(
            f"{name}\t{m['ET']}\t{m['ET_partial']}\t{m['DR']}\t{m['ms_per_decision']}\t"
            f"{m['bytes_per_decision']}\t{m['decisions']}"
        )
    o = data["overhead"]
    out.append(f"overhead_us\ton {o['on_us']}\toff {o['off_us']}\tdiff {o['overhead_us']}")
    cpu = f"on {o['on_cpu_us']}\toff {o['off_cpu_us']}\tdiff {o['overhead_cpu_us']}"
    out.append(f"overhead_cpu_us\t{cpu}")
    out.append(f"policy_accuracy\t{data['policy_accuracy']}")
    out.append(f"attention_accuracy\t{data['attention_accuracy']}")
    for p in data["scaling"]:
        out.append(
            f"scaling\tn={p['entities']}\tk={p['actions']}\ton {p['on_us']}\t"
            f"off {p['off_us']}\tdiff {p['overhead_us']}\tcpu_diff {p['overhead_cpu_us']}"
        )
    sys.stdout.write("\n".join(out) + "\n")


def _render_baselines(data: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    several = len(data["seeds"]) > 1

    def pm(m: dict[str, Any], key: str) -> str:
        s = m["spread_over_seeds"][key]
        # one seed has no spread to show: "± 0.0" would read as a measured std
        return (
            f"{s['mean'] * 100:.1f} ± {s['std'] * 100:.1f}" if several else f"{s['mean'] * 100:.1f}"
        )

    o = data["overhead"]
    title = (
        f"TRACE vs post-hoc explanations: {len(data['seeds'])} seed(s), "
        f"{data['methods']['TRACE']['decisions']} logged decisions ("
        + ("mean ± std across seeds" if several else "one seed: no spread")
        + "; CPU time)"
    )
    table = Table(title=title)
    for col in ("method", "ET %", "ET_partial %", "DR %", "ms / decision", "bytes / decision"):
        table.add_column(col, justify="left" if col == "method" else "right")
    for name, m in data["methods"].items():
        table.add_row(
            name,
            pm(m, "ET"),
            pm(m, "ET_partial"),
            pm(m, "DR"),
            f"{m['ms_per_decision']:.3f}",
            f"{m['bytes_per_decision']:,.0f}",
        )
    console = Console()
    console.print(table)
    console.print(
        f"TRACE per cycle (CPU): {o['on_cpu_us']:.0f} us logged, {o['off_cpu_us']:.0f} us with "
        f"a null logger -> {o['overhead_cpu_us']:.0f} us overhead (paper: 120 us); "
        f"wall-clock {o['overhead_us']:.0f} us"
    )
    console.print(
        f"learned policy agrees with the rule policy on {data['policy_accuracy'] * 100:.1f}% "
        f"of decisions; attention model on {data['attention_accuracy'] * 100:.1f}%"
    )
    scaling = Table(title="logging overhead per cycle (CPU us) by entities n and actions k")
    actions = sorted({p["actions"] for p in data["scaling"]})
    scaling.add_column("n", justify="right")
    for k in actions:
        scaling.add_column(f"k={k}", justify="right")
    for n in sorted({p["entities"] for p in data["scaling"]}):
        row = {p["actions"]: p["overhead_cpu_us"] for p in data["scaling"] if p["entities"] == n}
        scaling.add_row(str(n), *(f"{row[k]:.0f}" for k in actions))
    console.print(scaling)


def _program() -> typer.Typer:
    """``trace-sim``: the simulator's commands with ``baselines`` after ``scenarios`` (typer
    lists commands in the order they are registered)."""
    program = new_app()
    for command in simulator_app.registered_commands:
        program.registered_commands.append(command)
        if command.name == "scenarios":
            program.command(
                "baselines", help=help_text(_BASELINES_HELP), short_help=summary(_BASELINES_HELP)
            )(baselines_cmd)
    return program


app = _program()


def main() -> None:
    """Entry point of ``trace-sim``: usage errors are one line on stderr with exit code 2, as
    ``trace-audit``'s; run without a command, the help on stdout (exit 2)."""
    from trace_audit.cli.typer_compat import (
        TyperException,
        help_without_command,
        usage_error_line,
    )

    try:
        code = app(standalone_mode=False, prog_name="trace-sim")
    except TyperException as err:
        shown = help_without_command(err)
        if shown is not None:
            sys.stdout.write(shown)
        else:
            sys.stderr.write(usage_error_line(err, "trace-sim") or "")
        sys.exit(EXIT_USAGE)
    except typer.Abort:
        sys.stderr.write("trace-sim: interrupted\n")
        sys.exit(130)
    sys.exit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()
