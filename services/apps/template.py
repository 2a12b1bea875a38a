"""What `buddybot app new NAME` writes: a small app that runs as generated.

Pure: the file's text from the name, and the rules for the name (it becomes
a file, a class and a node name, so it must be valid as all three).
"""

from __future__ import annotations

import re

_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")

TEMPLATE = '''\
"""{name}: a BuddyBot app (docs/apps.md).

Run it with `buddybot app run {name}.py` while the robot runs (`buddybot up`).
"""

import threading

from buddybot.apps import App
from buddybot.sdk import Bot, Event


class {cls}(App):
    name = "{name}"

    def run(self, bot: Bot, stop_event: threading.Event) -> None:
        self.bot = bot  # for the callbacks below
        present = [person.id for person in bot.people.now()]
        print(f"{{self.name}}: watching robot {{bot.robot}}; present now: {{present}}", flush=True)
        bot.on("ARRIVED", self.arrived)
        bot.on("LEFT", self.left)
        stop_event.wait()  # the callbacks run on their own threads until the app stops

    def arrived(self, event: Event) -> None:
        if event.replayed:
            return  # was already there when the app started
        print(f"{{self.name}}: hello, person {{event.person.id}}", flush=True)

    def left(self, event: Event) -> None:
        print(f"{{self.name}}: goodbye, person {{event.person.id}}", flush=True)
'''


def check_name(name: str) -> None:
    """ValueError unless `name` can be a file, a Python class and a node name."""
    if not _NAME.match(name):
        raise ValueError(f"{name!r}: an app name starts with a letter and has only letters, "
                         "digits and '_' (it names the file, the class and the node)")


def class_name(name: str) -> str:
    """`hello_world` -> `HelloWorld`."""
    return "".join(part[:1].upper() + part[1:] for part in name.split("_") if part) or "App"


def render(name: str) -> str:
    """The app file for `name` (checked)."""
    check_name(name)
    return TEMPLATE.format(name=name, cls=class_name(name))
