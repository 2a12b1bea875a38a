"""When `people/state` goes out: at once when who is there, or what they do,
changes; at most every `position_period_s` when only where they are does.

A visitor's distance and direction change with every face frame (30 a
second), and every reader of `people/state` (controller, dashboard, the
ROS 2 bridge, apps) pays for each sample it receives. Ten positions a
second keep a map or a radar-led gaze smooth; arrivals, zones, engagement,
names and sensors are news and never wait. A state held back goes out at
the next input or tick once the period is over, with its own stamp.
"""

from __future__ import annotations

import dataclasses
import math

from buddybot.people.model import Person

WHERE = frozenset({"distance_m", "yaw_rad", "pitch_rad", "bearing_rad"})
"""The fields that say where a person is; every other field is news."""

_NEWS = tuple(f.name for f in dataclasses.fields(Person) if f.name not in WHERE)


def _news(person: Person) -> tuple[object, ...]:
    return tuple(getattr(person, name) for name in _NEWS)


def moved_only(now: tuple[Person, ...], before: tuple[Person, ...]) -> bool:
    """True when `now` lists the same people as `before`, differing at most in
    where they are."""
    return len(now) == len(before) and all(
        _news(a) == _news(b) for a, b in zip(now, before, strict=True))


class StatePacer:
    """Decides, for each state the model is in after a step, whether it goes out
    now and with which stamp. Pure: the caller passes its clock (seconds)."""

    def __init__(self) -> None:
        self.published: tuple[Person, ...] | None = None
        """The last state that went out (None: none yet)."""
        self._sent_at = -math.inf
        self._held: tuple[tuple[Person, ...], int] | None = None
        """A state held back and the stamp of the input that made it."""

    def offer(self, people: tuple[Person, ...], stamp_ns: int, now_s: float,
              period_s: float) -> int | None:
        """The stamp to publish `people` with now, or None: unchanged since the
        last one published, or held back (it only moved, within `period_s`)."""
        if self._held is not None and people == self._held[0]:
            stamp_ns = self._held[1]  # nothing new since it was held back
        if people == self.published:
            self._held = None
            return None
        if (self.published is not None and now_s - self._sent_at < period_s
                and moved_only(people, self.published)):
            self._held = (people, stamp_ns)
            return None
        self.published, self._sent_at, self._held = people, now_s, None
        return stamp_ns

    @property
    def holding(self) -> bool:
        """Whether a state is waiting for its period to end."""
        return self._held is not None
