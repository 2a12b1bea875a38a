#!/usr/bin/env bash
# The test command: set up, lint, check schemas, run every test.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/chromium.sh || true
.venv/bin/ruff check services tests benchmarks
.venv/bin/python -m buddybot schemas --check
exec .venv/bin/python -m pytest "$@"
