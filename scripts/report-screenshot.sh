#!/usr/bin/env bash
# Regenerate docs/report-demo.png: the incident report of the demo's first STOP, as headless
# Chromium shows its first screen (the README shows it). Fresh profile, no network.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/bootstrap.sh
bash scripts/install-browser.sh
browser=$(command -v chromium || command -v chromium-browser || true)
if [ -z "$browser" ]; then
  echo "report-screenshot: chromium is not installed (scripts/install-browser.sh)" >&2
  exit 2
fi
repo=$PWD
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"  # relative paths, so the page names the log as the demo does, not a temp dir
"$repo/.venv/bin/trace-sim" run --scenario all --cycles 100 --seed 42 --out demo.mcap >/dev/null
t=$("$repo/.venv/bin/trace-audit" why demo.mcap --action STOP --json | "$repo/.venv/bin/python" -c \
  'import json,sys; print(json.load(sys.stdin)["transitions"][0]["t_ns"] / 1e9)')
"$repo/.venv/bin/trace-audit" report demo.mcap --t "$t" --out incident.html --plain >/dev/null
"$browser" --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
  --disable-background-networking --disable-component-update --disable-sync \
  --hide-scrollbars --user-data-dir="$work/profile" --window-size=1000,1800 \
  --screenshot="$repo/docs/report-demo.png" "file://$work/incident.html" 2>/dev/null
echo "wrote docs/report-demo.png"
