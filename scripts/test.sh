#!/usr/bin/env bash
# The test command: set up, lint, check schemas, run the tests.
#
#   scripts/test.sh            every test: those marked `quiet` alone first, then the
#                              rest three per CPU core at a time (pytest-xdist)
#   scripts/test.sh --quick    lint, types and the pure tests only (no router, process,
#                              browser or neural network: markers integration, browser,
#                              model), property tests at a tenth of their examples
#   scripts/test.sh ARGS...    extra ARGS go to pytest (after --quick, too), e.g.
#                              --hypothesis-profile=nightly for ten times the examples
#
# Three workers per core: most tests wait on routers, processes and Chromium,
# not on the CPU. `-n N` in ARGS sets the number of workers, `-n 0` runs
# in one process. Every run ends with its 15 slowest tests and the wall time
# of each phase (also when a phase fails).
set -euo pipefail
cd "$(dirname "$0")/.."
quick=false
if [ "${1:-}" = --quick ]; then
    quick=true
    shift
fi

# The suite starts hundreds of Python processes (pytest's workers, services,
# CLIs). With PYTHONDONTWRITEBYTECODE set, as some machines do, no compiled
# module is ever kept, so each of them compiles again what it imports:
# collecting the tests alone costs 11 CPU-s a worker instead of 3.5.
unset PYTHONDONTWRITEBYTECODE

phases=()
now() { echo "${EPOCHREALTIME/./}"; }  # microseconds
started=$(now)
# phase NAME COMMAND...: run it and note its wall time; its status is the phase's.
phase() {
    local name=$1 t0 rc=0
    t0=$(now)
    shift
    "$@" || rc=$?
    phases+=("$(printf '%-8s %7s s%s' "$name" "$(elapsed "$t0")" \
        "$([ "$rc" = 0 ] || echo "  (status $rc)")")")
    return "$rc"
}
elapsed() {  # seconds since $1, one decimal
    local tenths=$((($(now) - $1) / 100000))
    echo "$((tenths / 10)).$((tenths % 10))"
}
report() {
    # A lint or type error ends the run before the background collection is waited for.
    [ -z "${warming:-}" ] || kill "$warming" 2>/dev/null || true
    echo "== wall time per phase ($($quick && echo quick || echo full) run) =="
    printf '%s\n' "${phases[@]}"
    printf '%-8s %7s s\n' total "$(elapsed "$started")"
}
trap report EXIT

phase setup scripts/setup.sh test  # runtime + the `test` extra
$quick || phase packages scripts/test-packages.sh || true
# ESPHome in its own cached venv, for the ESP32 firmware's checks (skipped without).
esphome_venv() { local exe; exe=$(scripts/esphome.sh) && export BUDDYBOT_ESPHOME="$exe"; }
$quick || [ -n "${BUDDYBOT_ESPHOME:-}" ] || phase esphome esphome_venv || true
# ROS 2 Jazzy's wheels in their own cached venv, for the real ROS 2 checks (skipped without).
ros2_venv() { local exe; exe=$(scripts/ros2-venv.sh) && export BUDDYBOT_ROS2_PYTHON="$exe"; }
$quick || [ -n "${BUDDYBOT_ROS2_PYTHON:-}" ] || phase ros2 ros2_venv || true
pytest=(.venv/bin/python -m pytest --durations=15)
# Collecting the tests compiles them (pytest's assertion rewriting, kept in
# __pycache__): done once here, in the background on the core the one-thread
# type check leaves idle, instead of by each of the test processes below.
warming=
if [ $# = 0 ]; then
    "${pytest[@]}" --collect-only -q -p no:cacheprovider >/dev/null 2>&1 &
    warming=$!
fi
phase ruff .venv/bin/ruff check services tests benchmarks
mkdir -p .venv/typecheck && ln -sfn ../../services .venv/typecheck/buddybot
phase mypy env MYPYPATH=.venv/typecheck .venv/bin/mypy -p buddybot
checks() {
    .venv/bin/python -m buddybot schemas --check && .venv/bin/python -m buddybot reference --check
}
phase checks checks
[ -z "$warming" ] || phase collect wait "$warming" || true
warming=
if $quick; then
    phase pytest "${pytest[@]}" -n "$(nproc)" --hypothesis-profile=quick \
        -m "not integration and not browser and not model" "$@"
    exit
fi
# Tests that measure frame times (marked `quiet`) run alone, while the machine is
# otherwise idle; everything else runs in parallel. Both runs happen whatever the
# first gives, so one report shows every failure. Other runs of this suite on the
# machine (another clone, CI) are kept off the quiet tests by one lock file: the
# quiet phase holds it alone, the parallel phase shared. When another run holds
# it, this one runs its parallel phase first and its quiet tests once alone.
ok() { [ "$1" = 0 ] || [ "$1" = 5 ]; }  # 5: that phase selected no test
lock="${TMPDIR:-/tmp}/buddybot-tests.lock"
locked() {  # locked -x|-s COMMAND...: with the machine's test lock, where flock exists
    local mode=$1
    shift
    if command -v flock >/dev/null; then flock "$mode" "$lock" "$@"; else "$@"; fi
}
quiet_phase() { locked -x "${pytest[@]}" -n 0 --phase quiet "$@"; }
rest_phase() { locked -s "${pytest[@]}" -n "$(($(nproc) * 3))" --dist loadgroup --phase rest "$@"; }
quiet=0 rest=0
if ! command -v flock >/dev/null || flock -x -n "$lock" true; then
    phase quiet quiet_phase "$@" || quiet=$?
    phase rest rest_phase "$@" || rest=$?
else
    echo "buddybot: another test run holds $lock: the quiet tests run last, alone" >&2
    phase rest rest_phase "$@" || rest=$?
    phase quiet quiet_phase "$@" || quiet=$?
fi
if ! ok "$rest"; then exit "$rest"; fi
if ! ok "$quiet"; then exit "$quiet"; fi
if [ "$quiet" = 5 ] && [ "$rest" = 5 ]; then exit 5; fi
exit 0
