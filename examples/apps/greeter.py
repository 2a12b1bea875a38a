"""greeter: say hello to everyone who arrives, with a line for the time of day.

Only arrivals that happen while the app runs are greeted: a person already
standing there when it starts comes as a replayed ARRIVED and is left alone.

    buddybot app run examples/apps/greeter.py
"""

from __future__ import annotations

import datetime
import logging
import threading

from buddybot.apps import App
from buddybot.sdk import Bot, Event, SdkError

log = logging.getLogger("greeter")

LINES = {
    "morning": "Good morning! Lovely to see you.",
    "afternoon": "Good afternoon! How is your day going?",
    "evening": "Good evening! Nice of you to drop by.",
    "night": "Hello, night owl! It is late, isn't it?",
}


def part_of_day(hour: int) -> str:
    """05-11 morning, 12-16 afternoon, 17-21 evening, 22-04 night."""
    if 5 <= hour < 12:
        return "morning"
    if 12 <= hour < 17:
        return "afternoon"
    if 17 <= hour < 22:
        return "evening"
    return "night"


def line_for(now: datetime.datetime) -> str:
    return LINES[part_of_day(now.hour)]


class Greeter(App):
    name = "greeter"

    def run(self, bot: Bot, stop_event: threading.Event) -> None:
        self.bot = bot
        bot.on("ARRIVED", self.arrived)
        print("greeter: waiting for visitors", flush=True)
        stop_event.wait()

    def arrived(self, event: Event) -> None:
        if event.replayed:
            return  # already there when the app started: not an arrival
        line = line_for(datetime.datetime.now())
        try:
            state = self.bot.say(line).wait(timeout=60)
        except SdkError as exc:  # no speaker, or someone else holds it
            log.warning("could not greet person %d: %s", event.person.id, exc)
            return
        print(f"greeter: person {event.person.id} arrived; said {line!r} ({state})", flush=True)
