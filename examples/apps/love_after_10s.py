"""love_after_10s: LOVE eyes and a sound once someone has stood there for 10 s.

The 10 s count from the person's arrival, not from the app's start: a
person already there when the app starts comes as a replayed ARRIVED whose
`arrived_ns` lies in the past, and is loved as soon as their 10 s are up.
When the loved people have all left, the app releases the eyes and the
robot's own behaviour takes them back at once.

    buddybot app run examples/apps/love_after_10s.py
"""

from __future__ import annotations

import logging
import threading
import time

from buddybot.apps import App
from buddybot.sdk import Bot, Event, SdkError, TimedOut

DWELL_S = 10.0
"""How long a person stands there before the LOVE eyes."""
SOUND = "greeting"
"""The sound played with them: a name of `[audio.sounds]`."""
POLL_S = 0.2

log = logging.getLogger("love_after_10s")


class Dwell:
    """Who is present since when, and whose dwell is up: pure, times in ns."""

    def __init__(self, dwell_s: float) -> None:
        self.dwell_ns = int(dwell_s * 1e9)
        self.waiting: dict[int, int] = {}
        """Person id -> the time their dwell is up."""
        self.loved: set[int] = set()

    def arrived(self, person_id: int, arrived_ns: int) -> None:
        if person_id not in self.loved:
            self.waiting[person_id] = arrived_ns + self.dwell_ns

    def left(self, person_id: int) -> bool:
        """Forget the person; True when they were the last one loved (release now)."""
        self.waiting.pop(person_id, None)
        was_loved = person_id in self.loved
        self.loved.discard(person_id)
        return was_loved and not self.loved

    def due(self, now_ns: int) -> list[int]:
        """The persons whose dwell is up at `now_ns` (each once)."""
        ready = sorted(p for p, at in self.waiting.items() if at <= now_ns)
        for person_id in ready:
            del self.waiting[person_id]
            self.loved.add(person_id)
        return ready


class LoveAfter10s(App):
    name = "love_after_10s"

    def run(self, bot: Bot, stop_event: threading.Event) -> None:
        dwell = Dwell(DWELL_S)
        print(f"love_after_10s: LOVE after {DWELL_S:g} s in front of the robot", flush=True)
        with bot.events("ARRIVED", "LEFT") as events:
            while not stop_event.is_set():
                try:
                    event: Event | None = events.get(POLL_S)
                except TimedOut:
                    event = None
                if event is not None and event.kind == "ARRIVED":
                    arrived = event.person.arrived_ns or event.stamp_ns
                    dwell.arrived(event.person.id, arrived)
                elif event is not None and dwell.left(event.person.id):
                    bot.eyes.release()
                    print(f"love_after_10s: person {event.person.id} left; eyes released",
                          flush=True)
                for person_id in dwell.due(time.time_ns()):
                    self.love(bot, person_id)

    def love(self, bot: Bot, person_id: int) -> None:
        try:
            bot.eyes.express("love")
            bot.play(SOUND)
        except SdkError as exc:  # refused (an operator holds the eyes), or no service
            log.warning("no love for person %d: %s", person_id, exc)
            return
        print(f"love_after_10s: person {person_id} stayed {DWELL_S:g} s: LOVE", flush=True)
