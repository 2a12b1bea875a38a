"""Scenario time from the wall clock, shared by every process of one simulated world.

Each simulated sensor runs in its own process (maybe on its own host);
they agree on what the world looks like because they agree on the
scenario, the random seed and the wall-clock start, not because they talk.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field


@dataclass(frozen=True)
class SimClock:
    """Scenario seconds = (wall time - start) x speed; `start` 0 means "now"."""

    start: float = 0.0
    speed: float = 1.0
    _made: float = field(default_factory=time.time)

    @property
    def origin(self) -> float:
        return self.start or self._made

    def now(self) -> float:
        return self.at(time.time())

    def at(self, wall: float) -> float:
        return max(0.0, (wall - self.origin) * self.speed)
