"""Persons and their events, as a program sees them.

Two sources, one view. `people/state` (latched) says who is there now;
`people/events` (a stream, not latched) says what changes. A program that
subscribes gets both, told apart: first the state present at subscription,
each person as an ARRIVED with `replayed=True` and their real arrival time
(in the past), then the live events (`replayed=False`).

The two keys arrive on separate workers, in either order. `PeopleView`
(pure) keeps them consistent: a live ARRIVED not yet in the state counts
as present, a live LEFT hides a person the state still lists, so a
subscription made between an event and the next state neither misses the
person nor sees them twice.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import replace
from typing import Any

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.handles import Subscription
from buddybot.runtime.node import Node
from buddybot.sdk import identity
from buddybot.sdk.errors import NoService, SdkError, TimedOut
from buddybot.sdk.identity import KnownPerson
from buddybot.sdk.persons import Event, PeopleNow, Person, person_from
from buddybot.sdk.triggers import Dwell, Motion, Trigger, Within
from buddybot.sdk.watch import Watch, Watchers

KINDS: tuple[str, ...] = ("ARRIVED", "ZONE_CHANGED", "ENGAGEMENT_CHANGED", "LEFT")
"""Every event kind, in the order a visit goes through them."""
TICK_S = 0.1
"""How often derived events (triggers.py) are checked besides every `people/state`."""

log = logging.getLogger("buddybot.sdk")


def check_kinds(kinds: Iterable[str]) -> frozenset[str]:
    """The kinds asked for (all when none), or ValueError naming the valid ones."""
    wanted = frozenset(kinds) or frozenset(KINDS)
    unknown = sorted(wanted - set(KINDS))
    if unknown:
        raise ValueError(f"unknown event kind(s) {', '.join(unknown)} "
                         f"(known: {', '.join(KINDS)})")
    return wanted


class PeopleView:
    """Who is present, from the latched state and the live events (pure)."""

    def __init__(self) -> None:
        self.has_state = False
        self._state: dict[int, Person] = {}
        self._arrived: dict[int, Person] = {}
        """Live ARRIVED whose person the state does not list yet."""
        self._left: set[int] = set()
        """Live LEFT whose person the state still lists."""

    def on_state(self, msg: m.PeopleState) -> None:
        self.has_state = True
        self._state = {p.id: person_from(p) for p in msg.people}
        for pid in list(self._arrived):
            if pid in self._state:
                del self._arrived[pid]
        self._left &= set(self._state)

    def on_event(self, msg: m.PersonEvent) -> Event:
        """The live event, its person completed from what is known of them."""
        known = self._state.get(msg.person_id) or self._arrived.get(msg.person_id)
        person = (Person(id=msg.person_id, zone=msg.zone, engagement=msg.engagement)
                  if known is None else replace(known, zone=msg.zone,
                                                engagement=msg.engagement))
        if msg.kind == "ARRIVED" and msg.person_id not in self._state:
            person = replace(person, arrived_ns=msg.stamp_ns)
            self._arrived[msg.person_id] = person
        elif msg.kind == "LEFT":
            self._arrived.pop(msg.person_id, None)
            if msg.person_id in self._state:
                self._left.add(msg.person_id)
        elif msg.person_id in self._arrived:
            self._arrived[msg.person_id] = person
        return Event(kind=msg.kind, person=person, stamp_ns=msg.stamp_ns)

    def present(self) -> tuple[Person, ...]:
        """Everyone present now, by id."""
        found = {pid: p for pid, p in self._state.items() if pid not in self._left}
        found.update(self._arrived)
        return tuple(found[pid] for pid in sorted(found))

    def replay(self, kinds: frozenset[str]) -> list[Event]:
        """The events that stand for the present state: an ARRIVED per person,
        stamped with their arrival, when ARRIVED is asked for."""
        if "ARRIVED" not in kinds:
            return []
        return [Event(kind="ARRIVED", person=p, stamp_ns=p.arrived_ns or 0, replayed=True)
                for p in self.present()]


class EventStream:
    """A subscription to person events: a disposable, iterable both ways.

    `for event in stream` and `async for event in stream` end when the
    stream is closed (`close()`, `unsubscribe()`, `with`, or the bot
    closing); `get(timeout)` waits for one event at most `timeout` seconds.
    """

    def __init__(self, kinds: frozenset[str],
                 on_close: Callable[[EventStream], None] | None = None) -> None:
        self.kinds = kinds
        self._items: deque[Event] = deque()
        self._cond = threading.Condition()
        self._closed = False
        self._on_close = on_close
        self._replayed_ids: set[int] = set()
        self._waiters: list[tuple[asyncio.AbstractEventLoop, asyncio.Future[None]]] = []

    @property
    def closed(self) -> bool:
        return self._closed

    def push(self, event: Event) -> None:
        """Queue `event` when its kind is wanted (a live ARRIVED of a person
        already replayed to this stream is the same arrival: dropped)."""
        if event.kind not in self.kinds:
            return
        if event.replayed:
            self._replayed_ids.add(event.person.id)
        elif event.kind == "ARRIVED" and event.person.id in self._replayed_ids:
            return
        with self._cond:
            if self._closed:
                return
            self._items.append(event)
            self._cond.notify_all()
        self._wake_async()

    def get(self, timeout: float) -> Event:
        """The next event; TimedOut after `timeout` s, SdkError once closed."""
        end = time.monotonic() + timeout
        with self._cond:
            while not self._items:
                if self._closed:
                    raise SdkError("the event stream is closed")
                left = end - time.monotonic()
                if left <= 0:
                    raise TimedOut(f"no {'/'.join(sorted(self.kinds))} event within "
                                   f"{timeout:g} s")
                self._cond.wait(left)
            return self._items.popleft()

    def poll(self) -> Event | None:
        """The next event if one is waiting, else None at once (a loop that also
        waits on something else)."""
        with self._cond:
            return self._items.popleft() if self._items else None

    def close(self) -> None:
        with self._cond:
            if self._closed:
                return
            self._closed = True
            self._cond.notify_all()
        self._wake_async()
        if self._on_close is not None:
            self._on_close(self)

    unsubscribe = close

    def __enter__(self) -> EventStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __iter__(self) -> EventStream:
        return self

    def __next__(self) -> Event:
        with self._cond:
            while not self._items and not self._closed:
                self._cond.wait()
            if not self._items:
                raise StopIteration
            return self._items.popleft()

    def __aiter__(self) -> EventStream:
        return self

    async def __anext__(self) -> Event:
        loop = asyncio.get_running_loop()
        while True:
            future: asyncio.Future[None] = loop.create_future()
            with self._cond:
                if self._items:
                    return self._items.popleft()
                if self._closed:
                    raise StopAsyncIteration
                self._waiters.append((loop, future))
            await future

    def _wake_async(self) -> None:
        with self._cond:
            waiters, self._waiters = self._waiters, []
        for loop, future in waiters:
            loop.call_soon_threadsafe(_resolve, future)


def _resolve(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)


class People:
    """`bot.people`: the view kept current from the bus, and the streams fed from it."""

    def __init__(self, node: Node, timeout: float) -> None:
        self.timeout = timeout
        self._node = node
        self._view = PeopleView()
        self._lock = threading.Condition()
        self._streams: list[EventStream] = []
        self._triggers: list[tuple[Trigger, EventStream]] = []
        self._ticking = False
        self._watching = False
        """Subscribed to `controller/state` (on the first `attended`)."""
        self._attention: m.ControllerState | None = None
        """The robot's own behaviour's latest state (subscribed on first `attended`)."""
        self._states: Watchers[PeopleNow] = Watchers("people state")
        self._watching_states = False
        """Subscribed to `people/state` for `on_state` (inline, on its first use)."""
        self._handles: list[Subscription] = []
        self._viewing = False
        """Subscribed to `people/state` and `people/events` for the view (on the
        first call that reads it: a program using only `on_state` pays for neither)."""

    def _on_state(self, msg: m.PeopleState, _key: str) -> None:
        with self._lock:
            self._view.on_state(msg)
            self._lock.notify_all()
            self._fire()

    def on_state(self, callback: Callable[[PeopleNow], Any]) -> Watch:
        """Call `callback(now)` with every `people/state` as the people service
        published it (the latched one first), until the returned watch or the
        bot closes: for a behaviour that decides on who is there as a whole.
        It runs on the thread that receives the state (no queue: an arrival
        is the robot's wake-up path), so keep it quick."""
        with self._lock:
            if not self._watching_states:
                self._watching_states = True
                self._handles.append(self._node.subscribe(
                    keys.PEOPLE_STATE, lambda msg, _key: self._states.notify(PeopleNow(
                        tuple(person_from(p) for p in msg.people), msg.stamp_ns))))
        return self._states.add(callback)

    def _fire(self) -> None:
        """Feed every trigger the persons present now (lock held)."""
        if not self._triggers:
            return
        now, present = time.time_ns(), self._view.present()
        for trigger, stream in list(self._triggers):
            for event in trigger.update(now, present):
                stream.push(event)

    def _tick(self) -> None:
        with self._lock:
            self._fire()

    def _on_event(self, msg: m.PersonEvent, _key: str) -> None:
        with self._lock:
            event = self._view.on_event(msg)
            for stream in list(self._streams):
                stream.push(event)

    def _wait_state(self, timeout: float | None) -> None:
        """Open the view (lock held) and block until its first state came, or NoService."""
        if not self._viewing:
            self._viewing = True
            self._handles += [
                self._node.subscribe(keys.PEOPLE_STATE, self._on_state, delivery="queue"),
                self._node.subscribe(keys.PEOPLE_EVENTS, self._on_event, delivery="queue"),
            ]
        limit = self.timeout if timeout is None else timeout
        if not self._lock.wait_for(lambda: self._view.has_state, limit):
            raise NoService(f"no {keys.PEOPLE_STATE.pattern} within {limit:g} s: is the "
                            "people service running (`buddybot run people`)?")

    def now(self, timeout: float | None = None) -> tuple[Person, ...]:
        """Everyone present now (waits for the first state up to `timeout`)."""
        with self._lock:
            self._wait_state(timeout)
            return self._view.present()

    def events(self, kinds: Iterable[str] = (), timeout: float | None = None) -> EventStream:
        """A stream of `kinds` (all when empty): the replayed state, then live events."""
        wanted = check_kinds(kinds)
        stream = EventStream(wanted, on_close=self._forget)
        with self._lock:
            self._wait_state(timeout)
            for event in self._view.replay(wanted):
                stream.push(event)
            self._streams.append(stream)
        return stream

    def on(self, kinds: Iterable[str], callback: Callable[[Event], Any],
           timeout: float | None = None) -> EventStream:
        """Call `callback(event)` on a thread of its own for each event until the
        returned stream is closed; a failing callback is logged, never fatal."""
        stream = self.events(kinds, timeout)

        def run() -> None:
            for event in stream:
                try:
                    callback(event)
                except Exception:
                    log.exception("event callback %r failed on %s", callback, event)

        threading.Thread(target=run, name="sdk-events", daemon=True).start()
        return stream

    def attended(self, timeout: float | None = None) -> Person | None:
        """The person the robot's own behaviour attends to now (its visit's person,
        `controller/state`), if present; None when it attends to nobody. NoService
        without the robot's behaviour running."""
        limit = self.timeout if timeout is None else timeout
        with self._lock:
            if not self._watching:
                self._watching = True
                self._handles.append(self._node.subscribe(
                    keys.CONTROLLER_STATE, self._on_controller, delivery="queue"))
            if not self._lock.wait_for(lambda: self._attention is not None, limit):
                raise NoService(f"no {keys.CONTROLLER_STATE.pattern} within {limit:g} s: "
                                "is the controller running (`buddybot run controller`)?")
            self._wait_state(limit)
            state = self._attention
            assert state is not None
            if state.phase == "idle" or state.person_id is None:
                return None
            return next((p for p in self._view.present() if p.id == state.person_id), None)

    def _on_controller(self, msg: m.ControllerState, _key: str) -> None:
        with self._lock:
            self._attention = msg
            self._lock.notify_all()

    # -- derived events: dwell, distance, approach --

    def trigger(self, trigger: Trigger, kinds: Iterable[str],
                timeout: float | None = None) -> EventStream:
        """A stream of the events `trigger` derives from who is present (checked
        on every `people/state` and every `TICK_S`)."""
        stream = EventStream(frozenset(kinds), on_close=self._forget)
        with self._lock:
            self._wait_state(timeout)
            self._triggers.append((trigger, stream))
            self._fire()
            if not self._ticking:
                self._ticking = True
                self._node.every(TICK_S, self._tick, name="sdk-triggers")
        return stream

    def dwell(self, seconds: float, timeout: float | None = None) -> EventStream:
        """DWELL once per person `seconds` after they arrived (a person already
        there counts from their arrival, not from now)."""
        return self.trigger(Dwell(seconds), ("DWELL",), timeout)

    def within(self, metres: float, margin_m: float = 0.2,
               timeout: float | None = None) -> EventStream:
        """NEAR when a person comes within `metres`, FAR when they are more than
        `margin_m` beyond it again (no flicker for someone standing on the line)."""
        return self.trigger(Within(metres, margin_m), ("NEAR", "FAR"), timeout)

    def motion(self, speed_mps: float = 0.3, window_s: float = 1.0,
               timeout: float | None = None) -> EventStream:
        """APPROACHING / RECEDING when a person's distance changes faster than
        `speed_mps` over `window_s`: someone walking up, or walking away."""
        return self.trigger(Motion(speed_mps, window_s), ("APPROACHING", "RECEDING"), timeout)

    # -- names, with consent (the identity service) --

    def enrol(self, name: str, samples: int = 5, timeout_s: float = 10.0,
              replace: bool = False, credential: str = "") -> int:
        """Remember the one face in front of the camera now under `name`: only with
        that person's consent, and as an operator (the robot's operator secret as
        `credential`). Takes `samples` frames within `timeout_s`; returns the
        samples stored. Refused (no face, two faces, `name` enrolled and not
        `replace`, no operator), ValueError (a name empty or over 64 characters),
        NoService."""
        return identity.enrol(self._node, name, samples, timeout_s, replace, credential)

    def known(self, timeout: float | None = None) -> tuple[KnownPerson, ...]:
        """Everybody enrolled (name, enrolled, last seen, samples), by name."""
        return identity.known(self._node, self.timeout if timeout is None else timeout)

    def forget(self, name: str, timeout: float | None = None, credential: str = "") -> None:
        """Erase `name`'s face templates at once (an operator's act, as `enrol`);
        Refused when nobody has that name."""
        identity.forget(self._node, self.timeout if timeout is None else timeout, name,
                        credential)

    def forget_all(self, timeout: float | None = None, credential: str = "") -> list[str]:
        """Erase everybody's face templates (an operator's act); the names forgotten."""
        return identity.forget(self._node, self.timeout if timeout is None else timeout,
                               None, credential)

    def _forget(self, stream: EventStream) -> None:
        with self._lock:
            if stream in self._streams:
                self._streams.remove(stream)
            self._triggers = [(t, s) for t, s in self._triggers if s is not stream]

    def close(self) -> None:
        self._states.clear()
        with self._lock:
            streams = list(self._streams) + [s for _t, s in self._triggers]
        for stream in streams:
            stream.close()
        for handle in self._handles:
            handle.close()
