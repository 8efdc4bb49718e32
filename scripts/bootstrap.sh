#!/usr/bin/env bash
# Make (or refresh) the project's virtual environment in .venv and install the project with
# its dev tools. Idempotent and quick when nothing changed: it reinstalls only when
# pyproject.toml differs from what the environment was built from.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if ! "$PY" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
  echo "bootstrap: Python 3.11 or newer is needed (found: $("$PY" --version 2>&1))" >&2
  exit 2
fi
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
stamp=.venv/.trace-installed
want=$(sha256sum pyproject.toml | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "bootstrap: installing into .venv (first run or pyproject.toml changed) ..." >&2
  log=.venv/install.log
  # Quiet when it works; the whole pip output when it does not.
  if ! { .venv/bin/python -m pip install --upgrade pip && .venv/bin/python -m pip install -e ".[dev,all]"; } >"$log" 2>&1; then
    cat "$log" >&2
    echo "bootstrap: installation failed (log above, also in $log)" >&2
    exit 1
  fi
  echo "$want" > "$stamp"
fi
