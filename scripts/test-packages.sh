#!/usr/bin/env bash
# Make sure the Debian packages the tests drive are installed:
#
#   scripts/test-packages.sh              chromium espeak-ng sox (scripts/test.sh)
#   scripts/test-packages.sh PACKAGE...   only these (scripts/chromium.sh)
#
# chromium: the browser tests (Playwright drives Debian's build, no download);
# espeak-ng: the text-to-speech tests; sox: FLAC/Ogg copies of the test sounds.
# Installs them as root or with sudo without a password (scripts/apt-packages.sh);
# otherwise prints the one command that would, and the tests needing a missing
# program skip with that reason.
set -euo pipefail
cd "$(dirname "$0")/.."
packages=("$@")
[ ${#packages[@]} -gt 0 ] || packages=(chromium espeak-ng sox)
scripts/apt-packages.sh "the tests needing them are skipped without them" "${packages[@]}"
