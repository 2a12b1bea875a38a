#!/usr/bin/env bash
# Make sure the Debian packages the tests drive are installed:
#
#   scripts/test-packages.sh              chromium espeak-ng sox (scripts/test.sh)
#   scripts/test-packages.sh PACKAGE...   only these (scripts/chromium.sh)
#
# chromium: the browser tests (Playwright drives Debian's build, no download);
# espeak-ng: the text-to-speech tests; sox: FLAC/Ogg copies of the test sounds.
# Installs with apt-get when run as root; otherwise prints the one command that
# would, and the tests needing a missing program skip with that reason.
set -euo pipefail
packages=("$@")
[ ${#packages[@]} -gt 0 ] || packages=(chromium espeak-ng sox)
missing=()
for package in "${packages[@]}"; do
    # Each of these packages installs a program of its own name.
    command -v "$package" >/dev/null 2>&1 || missing+=("$package")
done
[ ${#missing[@]} -gt 0 ] || exit 0
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "installing ${missing[*]} (Debian packages) for the tests..." >&2
    apt-get update -qq >/dev/null
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
else
    echo "not installed: ${missing[*]}; the tests needing them will be skipped." >&2
    echo "to run them: sudo apt-get install ${missing[*]}" >&2
fi
