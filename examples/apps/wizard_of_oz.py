"""wizard_of_oz: drive the robot from a terminal, as HRI studies do (Wizard of Oz).

Type a command and Enter:

    1..8 or a name      an expression: 1 awake, 2 sleepy, 3 sleep, 4 grin, 5 sad,
                        6 love, 7 star, 8 look_random (or its name: "love")
    left right up down centre    turn the gaze
    say TEXT            speak TEXT
    release             give the eyes back to the robot's own behaviour
    help                this list
    quit                stop (so do Ctrl-D and Ctrl-C)

It runs at app priority: the dashboard's operator lease overrides it.

    buddybot app run examples/apps/wizard_of_oz.py
"""

from __future__ import annotations

import queue
import sys
import threading
from dataclasses import dataclass
from typing import TextIO

from buddybot.apps import App
from buddybot.sdk import ALIASES, Bot, SdkError

KEYS = {"1": "awake", "2": "sleepy", "3": "sleep", "4": "grin", "5": "sad", "6": "love",
        "7": "star", "8": "look_random"}
GAZE_RAD = 0.35
GAZES = {"left": (GAZE_RAD, 0.0), "right": (-GAZE_RAD, 0.0), "up": (0.0, GAZE_RAD),
         "down": (0.0, -GAZE_RAD), "centre": (0.0, 0.0), "center": (0.0, 0.0)}
HELP = __doc__.split("Type a command and Enter:")[1].split("It runs at")[0].rstrip()


@dataclass(frozen=True)
class Command:
    verb: str
    """"express", "look", "say", "release", "help", "quit" or "unknown"."""
    arg: str = ""
    yaw: float = 0.0
    pitch: float = 0.0


def parse(line: str) -> Command | None:
    """One typed line as a command; None for an empty line. Pure."""
    text = line.strip()
    if not text:
        return None
    word, _, rest = text.partition(" ")
    word = word.lower()
    if word in KEYS or word in ALIASES:
        return Command("express", KEYS.get(word, word))
    if word in GAZES:
        yaw, pitch = GAZES[word]
        return Command("look", word, yaw, pitch)
    if word == "say":
        return Command("say", rest.strip()) if rest.strip() else Command("unknown", text)
    if word in ("release", "help", "quit"):
        return Command(word)
    if word in ("?", "h"):
        return Command("help")
    if word in ("q", "exit"):
        return Command("quit")
    return Command("unknown", text)


def _read_lines(stream: TextIO, lines: queue.Queue[str | None]) -> None:
    """stdin on its own thread, so the app still sees its stop_event while waiting."""
    for line in stream:
        lines.put(line)
    lines.put(None)  # end of input


class WizardOfOz(App):
    name = "wizard_of_oz"

    def run(self, bot: Bot, stop_event: threading.Event) -> None:
        lines: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=_read_lines, args=(sys.stdin, lines), daemon=True).start()
        print(f"wizard_of_oz: ready (robot {bot.robot}); 'help' lists the commands",
              flush=True)
        while not stop_event.is_set():
            try:
                line = lines.get(timeout=0.2)
            except queue.Empty:
                continue
            command = parse(line) if line is not None else Command("quit")
            if command is None:
                continue
            if command.verb == "quit":
                break
            print(f"wizard_of_oz: {self.do(bot, command)}", flush=True)

    def do(self, bot: Bot, command: Command) -> str:
        """Carry out one command; what happened, in words."""
        try:
            if command.verb == "express":
                bot.eyes.express(command.arg)
            elif command.verb == "look":
                bot.eyes.look_at(command.yaw, command.pitch)
            elif command.verb == "say":
                bot.say(command.arg)
            elif command.verb == "release":
                bot.eyes.release()
            elif command.verb == "help":
                return HELP
            else:
                return f"unknown command {command.arg!r} ('help' lists them)"
        except (SdkError, ValueError) as exc:
            return f"{command.verb} {command.arg}: not done: {exc}"
        return f"{command.verb} {command.arg}".rstrip() + ": ok"
