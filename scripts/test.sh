#!/usr/bin/env bash
# Everything CI checks: lint, format, strict types, and the test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/bootstrap.sh
bash scripts/install-browser.sh
bash scripts/install-go.sh
bash scripts/install-softhsm.sh
# the C++ robot the recorder's tests run against (tests/trace_runtime/recorder/)
bash scripts/build-cpp.sh
.venv/bin/ruff check .
.venv/bin/ruff format --check .
.venv/bin/mypy trace_runtime trace_audit sim evaluation
.venv/bin/python -m pytest "$@"
