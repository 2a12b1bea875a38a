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
venv="${BUDDYBOT_CACHE:-$HOME/.cache/buddybot}/esphome-$version"
. "$(dirname "$0")/cached-venv.sh"
cached_venv "$venv" "ESPHome $version" \
    "the ESPHome checks of tests/deploy/test_esphome.py skip" \
    "import esphome" "esphome==$version"
echo "$venv/bin/esphome"
