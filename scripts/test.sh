#!/usr/bin/env bash
# The test command: set up, lint, check schemas, run every test.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh test  # runtime + the `test` extra
scripts/chromium.sh || true
.venv/bin/ruff check services tests benchmarks
mkdir -p .venv/typecheck && ln -sfn ../../services .venv/typecheck/buddybot
MYPYPATH=.venv/typecheck .venv/bin/mypy -p buddybot
.venv/bin/python -m buddybot schemas --check
exec .venv/bin/python -m pytest "$@"
