"""Benchmark: ``trace-audit`` start-up, as whole processes, against a bare ``python -c pass``.

Budget (DESIGN.md): ``trace-audit --help`` <= 4x a bare ``python -c pass``, measured here in
the same run. Every row is a fresh process of the same interpreter, started the way the
``trace-audit`` console script starts (``from trace_audit.cli import main; main()``), with
this checkout first on ``PYTHONPATH``; the rows are interleaved (one run of each, N times over)
so a noisy neighbour hurts them alike, and each is reported as its median, its ratio to the
anchor's median, and its fastest run:

- ``python -c pass`` (anchor): the interpreter and ``site`` alone;
- ``import trace_audit.cli``: what every command pays before it parses its arguments;
- ``trace-audit --help`` and ``trace-audit COMMAND --help`` for every registered command;
- ``explain LOG --t T --plain`` on a 1-minute simulator log (made with ``trace-sim run
  --duration 1m`` when missing), end to end: start-up, open, seek, reconstruct, render.

Output is written to /dev/null, as a script or a pager would read it (typer draws its help
without colour then, the same panels). ``--json`` prints the numbers for a README or a note.

    .venv/bin/python bench/bench_cli.py                      # 21 interleaved runs of each
    .venv/bin/python bench/bench_cli.py --runs 41 --log /tmp/bench/minute-cli
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BUDGET_HELP = 4.0
EXPLAIN_BUDGET_S = 0.3
ENTRY = "import sys; from trace_audit.cli import main; sys.argv[0] = 'trace-audit'; main()"


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    env.pop("PYTHONSTARTUP", None)
    # An installed tool runs from .pyc files (pip compiles them); without them every run
    # would compile this checkout's modules again and measure the compiler.
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env["COLUMNS"] = "100"  # the help's layout (and so its cost) must not depend on the caller
    return env


def _commands(env: dict[str, str]) -> list[str]:
    code = "from trace_audit.cli import app; print(*(c.name for c in app.registered_commands))"
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, check=True, capture_output=True, text=True
    )
    return out.stdout.split()


def _ensure_log(path: Path, env: dict[str, str]) -> Path:
    if not path.exists():
        print(f"generating {path} with trace-sim run --duration 1m ...", file=sys.stderr)
        code = "from evaluation.cli import main; main()"
        run = ["run", "--duration", "1m", "--seed", "1", "--out", str(path)]
        subprocess.run(
            [sys.executable, "-c", code, *run],
            env=env,
            check=True,
            stdout=subprocess.DEVNULL,
        )
    return path


def _middle_t(log: Path, env: dict[str, str]) -> str:
    """A time in the middle of the log, in the seconds ``--t`` takes."""
    code = (
        "import sys; from trace_runtime.reading.logset import open_log\n"
        "log = open_log(sys.argv[1])\n"
        "print((log.start_ns + log.end_ns) / 2e9)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, str(log)], env=env, check=True, capture_output=True, text=True
    )
    return out.stdout.strip()


def _time(argv: list[str], env: dict[str, str]) -> float:
    started = time.perf_counter()
    done = subprocess.run(
        argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, check=False
    )
    elapsed = time.perf_counter() - started
    if done.returncode != 0:
        raise SystemExit(f"{argv[3:]} exited {done.returncode}: {done.stderr.decode()[-400:]}")
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=21, help="interleaved runs of each row")
    parser.add_argument("--log", type=Path, help="a 1-minute log (made when missing)")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    args = parser.parse_args()

    env = _env()
    log = _ensure_log(args.log or Path(tempfile.mkdtemp()) / "minute", env)
    t = _middle_t(log, env)
    py = [sys.executable]
    rows: dict[str, list[str]] = {
        "python -c pass": [*py, "-c", "pass"],
        "import trace_audit.cli": [*py, "-c", "import trace_audit.cli"],
        "trace-audit --help": [*py, "-c", ENTRY, "--help"],
    }
    for command in _commands(env):
        rows[f"trace-audit {command} --help"] = [*py, "-c", ENTRY, command, "--help"]
    rows["explain LOG --t T --plain (1 min log)"] = [
        *py,
        "-c",
        ENTRY,
        "explain",
        str(log),
        "--t",
        t,
        "--plain",
    ]

    for argv in rows.values():  # warm the OS caches and the .pyc files once
        _time(argv, env)
    times: dict[str, list[float]] = {name: [] for name in rows}
    for _ in range(args.runs):
        for name, argv in rows.items():
            times[name].append(_time(argv, env))

    anchor = statistics.median(times["python -c pass"])
    results = {
        name: {
            "median_s": statistics.median(samples),
            "min_s": min(samples),
            "ratio": statistics.median(samples) / anchor,
        }
        for name, samples in times.items()
    }
    helps = [r["ratio"] for n, r in results.items() if n.endswith("--help")]
    explain = results["explain LOG --t T --plain (1 min log)"]
    summary = {
        "runs": args.runs,
        "cpus": os.cpu_count(),
        "load_avg_1m": os.getloadavg()[0],
        "results": results,
        "worst_help_ratio": max(helps),
        "help_budget_ratio": BUDGET_HELP,
        "explain_budget_s": EXPLAIN_BUDGET_S,
    }
    if args.json:
        print(json.dumps(summary, indent=2))
        return
    print(
        f"{args.runs} interleaved runs of each, {os.cpu_count()} CPUs, "
        f"load average {os.getloadavg()[0]:.2f}; log {log}, t = {t} s"
    )
    print(f"{'':44} {'median':>9} {'ratio':>7} {'fastest':>9}")
    for name, r in results.items():
        print(
            f"{name:44} {r['median_s'] * 1e3:7.1f}ms {r['ratio']:6.2f}x {r['min_s'] * 1e3:7.1f}ms"
        )
    verdict = "within" if max(helps) <= BUDGET_HELP else "OVER"
    print(f"slowest --help: {max(helps):.2f}x the anchor ({verdict} the {BUDGET_HELP:g}x budget)")
    verdict = "within" if explain["median_s"] <= EXPLAIN_BUDGET_S else "over"
    print(
        f"explain end to end: {explain['median_s']:.3f} s ({verdict} {EXPLAIN_BUDGET_S} s), "
        f"{explain['ratio']:.1f}x the anchor"
    )


if __name__ == "__main__":
    main()
