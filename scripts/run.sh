#!/usr/bin/env bash
# The run command: the whole robot on this machine (simulated sensors when
# no hardware is configured). Extra arguments go to `buddybot up`.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh runtime  # the runtime only: no test tools
exec .venv/bin/buddybot up "$@"
