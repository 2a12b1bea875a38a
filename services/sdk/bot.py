"""`Bot`: a program's connection to one robot, and the door to what it offers.

`Bot.connect()` resolves the router and the robot exactly like every
`buddybot` tool (`--connect`, then `[zenoh] connect` of `--config` or
$BUDDYBOT_CONFIG, then the default; the same for `--robot`), and gives up
after `timeout` seconds with `NoRouter` instead of waiting forever as a
service does. The program is a node of the robot: its liveliness token
`nodes/<name>/<zid>` is what its leases are bound to (they end when it
ends, however it ends), and `buddybot nodes` lists it.
"""

from __future__ import annotations

import argparse
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any, TypeVar, cast

from buddybot.contract import keys
from buddybot.runtime.diagnostics import Diagnostics
from buddybot.runtime.handles import Handle, Publisher
from buddybot.runtime.node import Node
from buddybot.runtime.service import add_common_arguments, resolve, setup_logging
from buddybot.runtime.session import RouterUnreachable
from buddybot.sdk.actions import ACTIONS_BURST, ACTIONS_PER_S, ActionLimit, check_rate
from buddybot.sdk.errors import NoRouter, SdkError, TimedOut
from buddybot.sdk.eyes import Eyes
from buddybot.sdk.faces import Face, on_face
from buddybot.sdk.leases import Lease, LeaseTable
from buddybot.sdk.params import Params
from buddybot.sdk.people import Event, EventStream, People, Person, check_kinds
from buddybot.sdk.speaker import Sound, SoundHandle, Speaker
from buddybot.sdk.wishes import Wishes

T = TypeVar("T")

TIMEOUT_S = 5.0
"""Default bound of the connect and of every call."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The standard `--connect`, `--robot`, `--config` and `--log-level` flags,
    for `Bot.from_args`."""
    add_common_arguments(parser)


class Bot:
    """One robot, seen from a program. Use it as a context manager, or `close()`."""

    def __init__(self, node: Node, timeout: float = TIMEOUT_S,
                 actions_per_s: float = ACTIONS_PER_S,
                 actions_burst: float = ACTIONS_BURST, builtin: bool = False) -> None:
        self.node = node
        self.robot = node.robot
        self.timeout = timeout
        self.builtin = builtin
        """The robot's own behaviour (`buddybot.sdk.service`): it has `wishes`
        instead of leases on the eyes, and plays without an "audio" lease."""
        self.limit = ActionLimit(node.diagnostics, actions_per_s, actions_burst)
        """Every action of this Bot (express, look_at, play, say, lease) takes one
        token; over the limit it raises Refused("rate limited: ...") at once."""
        self.params = Params(node, timeout)
        self._people: People | None = None
        self._speaker: Speaker | None = None
        self._leases: LeaseTable | None = None
        self._eyes: Eyes | None = None
        self._wishes: Wishes | None = None
        self._lock = threading.RLock()
        """Opens `people`, `speaker`, `leases` and `eyes` once, on first use from any
        thread."""

    @classmethod
    def connect(cls, connect: list[str] | None = None, config: str | None = None,
                robot: str | None = None, name: str = "app",
                timeout: float = TIMEOUT_S, actions_per_s: float = ACTIONS_PER_S,
                actions_burst: float = ACTIONS_BURST) -> Bot:
        """Join the robot's router; NoRouter (naming the endpoints) after `timeout` s.
        `actions_per_s`/`actions_burst`: this program's action limit (ValueError
        out of range, checked before connecting)."""
        args = argparse.Namespace(connect=connect, config=config, robot=robot)
        return cls._open(args, name, timeout, check_rate(actions_per_s, actions_burst))

    @classmethod
    def from_args(cls, args: argparse.Namespace, name: str = "app",
                  timeout: float = TIMEOUT_S, actions_per_s: float = ACTIONS_PER_S,
                  actions_burst: float = ACTIONS_BURST) -> Bot:
        """`connect` with the flags of `add_arguments`; sets up logging at `--log-level`."""
        rate = check_rate(actions_per_s, actions_burst)
        setup_logging(getattr(args, "log_level", None) or "INFO")
        return cls._open(args, name, timeout, rate)

    @classmethod
    def _open(cls, args: argparse.Namespace, name: str, timeout: float,
              rate: tuple[float, float]) -> Bot:
        ctx = resolve(args, name)
        try:
            node = ctx.probe(timeout, visible=True)
        except RouterUnreachable as exc:
            raise NoRouter(str(exc), list(ctx.connect)) from None
        return cls(node, timeout, *rate)

    # -- people --

    @property
    def people(self) -> People:
        """Who is there (`bot.people.now()`), from `people/state`."""
        return self._opened("_people", lambda: People(self.node, self.timeout))

    def events(self, *kinds: str, timeout: float | None = None) -> EventStream:
        """Person events of `kinds` (all when none): first the people present now
        (ARRIVED, `replayed=True`), then the changes as they come."""
        return self.people.events(kinds, timeout)

    def on(self, kind: str | Iterable[str], callback: Callable[[Event], Any]) -> EventStream:
        """Call `callback(event)` for each event of `kind` until the returned
        stream is closed (on its own thread)."""
        kinds = (kind,) if isinstance(kind, str) else tuple(kind)
        return self.people.on(kinds, callback)

    def wait_for(self, kind: str, predicate: Callable[[Event], bool] | None = None,
                 timeout: float = 30.0) -> Event:
        """The first event of `kind` (replayed ones included) that `predicate`
        accepts; TimedOut naming what was waited for."""
        check_kinds((kind,))
        what = f"{kind} event{' matching ' + repr(predicate) if predicate else ''}"
        end = time.monotonic() + timeout
        with self.people.events((kind,), timeout) as stream:
            return _first(stream, predicate, end, f"no {what} within {timeout:g} s "
                          f"(robot {self.robot})")

    def person(self, person_id: int) -> Person | None:
        """The person with this id, if present now."""
        return next((p for p in self.people.now() if p.id == person_id), None)

    # -- leases and eyes --

    @property
    def leases(self) -> LeaseTable:
        """The leases this program holds (opened on first use)."""
        return self._opened("_leases", lambda: LeaseTable(self.node, self.timeout, self.limit))

    def lease(self, *resources: str, priority: str = "app",
              duration_s: float | None = None, credential: str = "") -> Lease:
        """Take `resources` ("expression", "gaze", "audio"; "eyes" = expression +
        gaze) from the eyes driver's arbiter; Refused naming the holder, NoService without
        an eyes driver, ValueError for a malformed request. Priority "operator"
        is granted only with the robot's operator secret as `credential`."""
        return self.leases.acquire(resources, priority, duration_s, credential=credential)

    @property
    def eyes(self) -> Eyes:
        """Expressions and gaze through the eyes driver's arbiter (opened on first use)."""
        return self._opened("_eyes", lambda: Eyes(self.node, self.leases, self.timeout,
                                                  self.limit))

    @property
    def wishes(self) -> Wishes:
        """The built-in behaviour's eyes (lowest priority, no lease); SdkError for
        any other program, whose eyes are `bot.eyes`."""
        if not self.builtin:
            raise SdkError("only the robot's own behaviour has wishes; a program uses "
                           "bot.eyes, under a lease")
        return self._opened("_wishes", lambda: Wishes(self.node))

    # -- camera --

    def on_face(self, callback: Callable[[Face], Any], camera: str = "front") -> Handle:
        """Call `callback(face)` for every face `camera`'s detector follows, on the
        thread that receives it (be quick), until the returned handle is closed."""
        return on_face(self.node, camera, callback)

    # -- speaker --

    @property
    def speaker(self) -> Speaker:
        """Sounds through the `audio/play_sound` action (opened on first use)."""
        return self._opened("_speaker", lambda: Speaker(self.node, self.leases,
                                                        self.timeout, self.limit,
                                                        builtin=self.builtin))

    def play(self, sound: Sound) -> SoundHandle:
        """Play a sound of `[audio.sounds]` by name, or a file of the player's sound
        folders (a `Path`, or a str with "/" or an audio suffix: see
        `speaker.goal_sound`), under an "audio" lease; Refused (a file outside
        the sound folders: the player's reason), NoService."""
        return self.speaker.play(sound)

    def say(self, text: str) -> SoundHandle:
        """Speak any `text` (1..240 printable characters) with espeak-ng, under an
        "audio" lease; ValueError for a malformed text, Refused, NoService."""
        return self.speaker.say(text)

    # -- the program as a node of the robot --

    @property
    def diagnostics(self) -> Diagnostics:
        """This program's `diagnostics/<name>` (`values`, `increment`, `set`):
        what `buddybot echo` and the dashboard show about it."""
        return self.node.diagnostics

    def publisher(self, topic: keys.Topic, **params: str) -> Publisher[Any]:
        """A publisher of this program's own key `topic` (its `put(msg)` checks
        the message against the topic's type)."""
        return self.node.publisher(topic, **params)

    # -- lifetime --

    def _opened(self, attr: str, make: Callable[[], T]) -> T:
        """The part kept in `attr`, made by `make` on first use (once, from any thread)."""
        with self._lock:
            part = getattr(self, attr)
            if part is None:
                part = make()
                setattr(self, attr, part)
            return cast(T, part)

    def close(self) -> None:
        """Release the leases held (bounded: a gone eyes driver ends them anyway when
        the token goes), then leave the router."""
        if self._people is not None:
            self._people.close()
        if self._speaker is not None:
            self._speaker.close()
        if self._leases is not None:
            self._leases.close(min(self.timeout, 1.0))
        self.node.close()

    def __enter__(self) -> Bot:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _first(stream: EventStream, predicate: Callable[[Event], bool] | None, end: float,
           why: str) -> Event:
    """The first event of `stream` that `predicate` accepts before `end` (monotonic)."""
    while True:
        left = end - time.monotonic()
        try:
            event = stream.get(max(0.0, left))
        except TimedOut:
            raise TimedOut(why) from None
        if predicate is None or predicate(event):
            return event
