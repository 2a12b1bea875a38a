#!/usr/bin/env bash
# The run command: the whole robot on this machine (simulated sensors when
# no hardware is configured). Extra arguments go to `buddybot up`.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh runtime  # the runtime only: no test tools
# Speech (`say:` sounds) needs espeak-ng, a system package: installed here when
# this host allows it (root, or sudo without a password), else the command is
# printed and the robot runs without speech (`buddybot doctor` says so too).
scripts/apt-packages.sh "text-to-speech, for say: sounds" espeak-ng || true
exec .venv/bin/buddybot up "$@"
