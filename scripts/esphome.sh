#!/usr/bin/env bash
# ESPHome for the ESP32 radar firmware's checks, in a venv of its own:
#
#   scripts/esphome.sh     install it once (cached), print the `esphome` path
#
# Not a project dependency: ~250 MB with PlatformIO, and pins of packages this
# project also uses. tests/deploy/test_esphome.py finds it here (or through
# BUDDYBOT_ESPHOME, or on PATH) and runs `esphome config` on
# deploy/esphome/radar-esp32.yaml with no network; scripts/test.sh calls this
# first. The version is pinned so ESPHome's own messages, which the tests read,
# do not change under them. Offline, or where pip fails, the status is 1 and
# the tests needing ESPHome skip saying so. The cache is outside the clone so
# a fresh clone (CI) installs it once per machine, not once per run.
set -euo pipefail
version=2026.6.5
venv="${XDG_CACHE_HOME:-$HOME/.cache}/buddybot/esphome-$version"
if [ ! -f "$venv/.complete" ]; then
    echo "buddybot: installing ESPHome $version in $venv (once, ~1 min)..." >&2
    rm -rf "$venv"
    mkdir -p "$(dirname "$venv")"
    python=$(command -v python3.11 || command -v python3)
    log="$(dirname "$venv")/esphome-install.log"
    if ! { "$python" -m venv "$venv" &&
           "$venv/bin/pip" install -q --disable-pip-version-check "esphome==$version"; } \
           >"$log" 2>&1; then
        tail -n 5 "$log" >&2
        rm -rf "$venv"
        echo "buddybot: ESPHome $version could not be installed (offline?), see $log:" \
             "the ESPHome checks of tests/deploy/test_esphome.py skip" >&2
        exit 1
    fi
    touch "$venv/.complete"  # written last: a half-made venv is made again
fi
echo "$venv/bin/esphome"
