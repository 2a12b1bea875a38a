"""love_after_10s: LOVE eyes and a sound once someone has stood there for 10 s.

`bot.people.dwell` counts the 10 s from each person's arrival, not from the
app's start: a person already there when the app starts is loved as soon as
their 10 s are up. When the loved people have all left, the app releases
the eyes and the robot's own behaviour takes them back at once.

    buddybot app run examples/apps/love_after_10s.py
"""

from __future__ import annotations

import logging
import threading

from buddybot.apps import App
from buddybot.sdk import Bot, SdkError, TimedOut

DWELL_S = 10.0
"""How long a person stands there before the LOVE eyes."""
SOUND = "greeting"
"""The sound played with them: a name of `[audio.sounds]`."""
POLL_S = 0.2

log = logging.getLogger("love_after_10s")


class LoveAfter10s(App):
    name = "love_after_10s"

    def run(self, bot: Bot, stop_event: threading.Event) -> None:
        loved: set[int] = set()
        print(f"love_after_10s: LOVE after {DWELL_S:g} s in front of the robot", flush=True)
        with bot.people.dwell(DWELL_S) as dwelt, bot.events("LEFT") as left:
            while not stop_event.is_set():
                try:
                    person = dwelt.get(POLL_S).person.id
                    if self.love(bot, person):
                        loved.add(person)
                except TimedOut:
                    pass
                while (gone := left.poll()) is not None:
                    who = gone.person.id
                    if who in loved and not (loved := loved - {who}):
                        bot.eyes.release()
                        print(f"love_after_10s: person {who} left; eyes released",
                              flush=True)

    def love(self, bot: Bot, person_id: int) -> bool:
        try:
            bot.eyes.express("love")
            bot.play(SOUND)
        except SdkError as exc:  # refused (an operator holds the eyes), or no service
            log.warning("no love for person %d: %s", person_id, exc)
            return False
        print(f"love_after_10s: person {person_id} stayed {DWELL_S:g} s: LOVE", flush=True)
        return True

