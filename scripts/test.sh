#!/usr/bin/env bash
# The test command: set up, lint, check schemas, run the tests.
#
#   scripts/test.sh            every test: those marked `quiet` alone first, then the
#                              rest three per CPU core at a time (pytest-xdist)
#   scripts/test.sh --quick    lint and the pure tests only (no router, process
#                              or browser: -m "not integration and not browser")
#   scripts/test.sh ARGS...    extra ARGS go to pytest (after --quick, too)
#
# Three workers per core: most tests wait on routers, processes and Chromium,
# not on the CPU. `-n N` in ARGS sets the number of workers, `-n 0` runs
# in one process. Every run ends with its 15 slowest tests.
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
.venv/bin/python -m buddybot reference --check
pytest=(.venv/bin/python -m pytest --durations=15)
if $quick; then
    exec "${pytest[@]}" -n "$(nproc)" -m "not integration and not browser" "$@"
fi
# Tests that measure frame times (marked `quiet`) run first, alone, while the
# machine is otherwise idle; then everything else in parallel. Both runs happen
# whatever the first gives, so one report shows every failure.
ok() { [ "$1" = 0 ] || [ "$1" = 5 ]; }  # 5: that phase selected no test
set +e
"${pytest[@]}" -n 0 --phase quiet "$@"
quiet=$?
"${pytest[@]}" -n "$(($(nproc) * 3))" --dist loadgroup --phase rest "$@"
rest=$?
set -e
if ! ok "$rest"; then exit "$rest"; fi
if ! ok "$quiet"; then exit "$quiet"; fi
if [ "$quiet" = 5 ] && [ "$rest" = 5 ]; then exit 5; fi
exit 0
