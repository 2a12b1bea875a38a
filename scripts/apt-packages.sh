#!/usr/bin/env bash
# Install Debian/Ubuntu packages the robot or its tests use, when this host allows it:
#
#   scripts/apt-packages.sh "WHAT FOR" PACKAGE...
#
# Each PACKAGE installs a program of its own name; those already on PATH are
# skipped. With apt-get and root, or sudo without a password (`sudo -n true`),
# the missing ones are installed; otherwise the one command that would is
# printed and the status is 1 (callers go on: what needs the program says so).
set -euo pipefail
why=$1
shift
missing=()
for package in "$@"; do
    command -v "$package" >/dev/null 2>&1 || missing+=("$package")
done
[ ${#missing[@]} -gt 0 ] || exit 0
install=(env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}")
if command -v apt-get >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ]; then
        sudo=()
    elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
        sudo=(sudo -n)
    else
        echo "buddybot: not installed: ${missing[*]} ($why)" >&2
        echo "buddybot: to install: sudo apt-get install ${missing[*]}" >&2
        exit 1
    fi
    echo "buddybot: installing ${missing[*]} (Debian packages, $why)..." >&2
    if "${sudo[@]}" apt-get update -qq >/dev/null && "${sudo[@]}" "${install[@]}" >/dev/null; then
        exit 0
    fi
    echo "buddybot: could not install ${missing[*]}; to try by hand:" \
         "sudo apt-get install ${missing[*]}" >&2
    exit 1
fi
echo "buddybot: not installed: ${missing[*]} ($why); install it with this system's" \
     "package manager" >&2
exit 1
