"""Where tests and the tool venvs keep what is fetched once per machine."""

from __future__ import annotations

import os
from pathlib import Path


def cache_root() -> Path:
    """$BUDDYBOT_CACHE, else ~/.cache/buddybot (outside the repository), as
    scripts/esphome.sh and scripts/ros2-venv.sh place their venvs."""
    return Path(os.environ.get("BUDDYBOT_CACHE") or Path.home() / ".cache" / "buddybot")
