"""The one convention between the action server and the player beyond the contract.

The player's `audio/play_file` reply is `{success, message}` (the fields
of ROS 2's std_srvs Trigger). On success the message ends with the sound's
duration, `"playing greeting (2.755 s)"`, so the action can report
progress without reading the file itself (the player may run on another
host). Both sides use these two functions; nothing else parses messages.
"""

from __future__ import annotations

import re

_DURATION = re.compile(r"\((\d+(?:\.\d+)?) s\)$")


def playing_message(name: str, duration_s: float) -> str:
    return f"playing {name} ({duration_s:.3f} s)"


def parse_duration(message: str) -> float | None:
    """The duration announced in a play reply, or None when it has none."""
    found = _DURATION.search(message.strip())
    return float(found.group(1)) if found else None
