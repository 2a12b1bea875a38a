#!/usr/bin/env bash
# The test command: set up, lint, check schemas, run the tests.
#
#   scripts/test.sh            every test, 4 at a time (pytest-xdist)
#   scripts/test.sh --quick    lint and the pure tests only (no router, process
#                              or browser: -m "not integration and not browser")
#   scripts/test.sh ARGS...    extra ARGS go to pytest (after --quick, too)
#
# Four workers on a two-core machine: most tests wait on routers, processes
# and Chromium, not on the CPU. `-n 0` in ARGS runs in one process. Every run
# ends with its 15 slowest tests.
set -euo pipefail
cd "$(dirname "$0")/.."
quick=false
if [ "${1:-}" = --quick ]; then
    quick=true
    shift
fi
scripts/setup.sh test  # runtime + the `test` extra
$quick || scripts/test-packages.sh || true
.venv/bin/ruff check services tests benchmarks
mkdir -p .venv/typecheck && ln -sfn ../../services .venv/typecheck/buddybot
MYPYPATH=.venv/typecheck .venv/bin/mypy -p buddybot
.venv/bin/python -m buddybot schemas --check
pytest=(.venv/bin/python -m pytest --durations=15)
if $quick; then
    exec "${pytest[@]}" -n 2 -m "not integration and not browser" "$@"
fi
exec "${pytest[@]}" -n 4 --dist loadgroup "$@"
