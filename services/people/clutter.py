"""Where the radar shows something that is not a person: pure, bounded.

A fan or a curtain moves enough for a presence radar and never walks
through the room; the camera never sees a face there. Once a person
shown only by the radar has stayed within `spread_m` of where it was first
seen for the clutter time, that place is a spot: the radar showing
something there again is not a person. A spot is forgotten once the radar
has shown nothing there for `forget_ns` (the fan was switched off, the
picture there changed). Places are floor-plan points (x, y) in metres; an
LD2410 gives only a distance, taken as (distance, 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

Point = tuple[float, float]

MAX_SPOTS = 16
"""Spots remembered at most (the oldest seen is forgotten): a room has a few."""


@dataclass
class Spots:
    """The clutter spots and when the radar last showed something at each."""

    spread_m: float
    forget_ns: int
    _spots: dict[Point, int] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self._spots)

    def add(self, at: Point, stamp_ns: int) -> None:
        self._spots[at] = stamp_ns
        while len(self._spots) > MAX_SPOTS:
            oldest = min(self._spots, key=lambda p: self._spots[p])
            del self._spots[oldest]

    def near(self, at: Point) -> Point | None:
        """The spot within `spread_m` of `at`, if any."""
        for spot in self._spots:
            if math.dist(spot, at) <= self.spread_m:
                return spot
        return None

    def shown(self, at: Point, stamp_ns: int) -> bool:
        """The radar shows something at `at` now: True (and the spot kept) if it is
        a spot's clutter."""
        spot = self.near(at)
        if spot is None:
            return False
        self._spots[spot] = max(self._spots[spot], stamp_ns)
        return True

    def hidden(self, nearer_than_m: float, stamp_ns: int) -> None:
        """An LD2410 shows only its nearest target: the spots beyond `nearer_than_m`
        (one-dimensional, (distance, 0)) are hidden by it, not gone."""
        for spot in self._spots:
            if spot[0] > nearer_than_m + self.spread_m:
                self._spots[spot] = max(self._spots[spot], stamp_ns)

    def expire(self, now_ns: int) -> None:
        """Forget the spots the radar has shown nothing at for `forget_ns`."""
        for spot in [p for p, seen in self._spots.items() if now_ns - seen >= self.forget_ns]:
            del self._spots[spot]

    def clear(self) -> None:
        self._spots.clear()
