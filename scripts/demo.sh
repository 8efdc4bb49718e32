#!/usr/bin/env bash
# The main job on a built-in default: simulate the paper's five warehouse scenarios into a
# TRACE log, ask the investigator why the robot first stopped, and write the incident report
# (one HTML page to open in a browser, print or hand over) for that first STOP.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/bootstrap.sh
out=${1:-out/demo.mcap}
mkdir -p "$(dirname "$out")"
.venv/bin/trace-sim run --scenario all --cycles 100 --seed 42 --out "$out"
echo
.venv/bin/trace-audit why "$out" --action STOP
echo
t=$(.venv/bin/trace-audit why "$out" --action STOP --json | .venv/bin/python -c \
  'import json,sys; print(json.load(sys.stdin)["transitions"][0]["t_ns"] / 1e9)')
.venv/bin/trace-audit explain "$out" --t "$t"
echo
report="${out%.mcap}-first-stop.html"
.venv/bin/trace-audit report "$out" --t "$t" --out "$report" --plain
echo "Incident report of the first STOP: $(cd "$(dirname "$report")" && pwd)/$(basename "$report")"
