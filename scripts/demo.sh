#!/usr/bin/env bash
# The main job on a built-in default: simulate the paper's five warehouse scenarios into a
# TRACE log, then ask the investigator why the robot first stopped.
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
