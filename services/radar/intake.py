"""Frames from the bus to the presence rule, fairly: a flood cannot starve a real sensor.

Zenoh's thread only sorts (a few dict operations); one worker thread runs
the handler. Items on keys the handler has *trusted* (keys carrying a
sensor heard steadily, see `PresenceTracker.established`) go to a
priority lane: at most `per_key` pending per key, keys served round-robin.
Everything else shares one bounded FIFO, oldest dropped and counted. The
worker always serves the priority lane first, so thousands of frames from
invented sensors wait (or are dropped) behind a real sensor's frames,
never in front of them, and a real sensor is never taken for silent
because its frames sat in a queue behind a flood.

No I/O and no Zenoh here: it is tested with plain threads.
"""

from __future__ import annotations

import collections
import threading
from collections.abc import Callable
from typing import Generic, TypeVar

from buddybot.runtime.limits import BoundedDict

T = TypeVar("T")


class Intake(Generic[T]):
    """`submit(key, item)` from any thread; `handler(key, item)` runs on one worker."""

    def __init__(self, handler: Callable[[str, T], None], *, general_size: int = 256,
                 per_key: int = 16, max_trusted: int = 16,
                 on_error: Callable[[BaseException], None] | None = None,
                 name: str = "intake") -> None:
        self._handler = handler
        self._on_error = on_error or (lambda exc: None)
        self._cond = threading.Condition()
        self._general: collections.deque[tuple[str, T]] = collections.deque(maxlen=general_size)
        self._per_key = per_key
        # Trusted key -> its pending items; LRU-bounded, served round-robin.
        self._lanes: BoundedDict[str, collections.deque[T]] = BoundedDict(max_trusted)
        self._pending_priority = 0
        self._closed = False
        self.dropped = 0
        """Items dropped from the shared FIFO (it was full)."""
        self.dropped_trusted = 0
        """Items dropped from a trusted key's lane (its handler fell behind)."""
        self.handled = 0
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> Intake[T]:
        self._thread.start()
        return self

    # -- producer side (Zenoh's thread: keep it cheap) --

    def submit(self, key: str, item: T) -> None:
        with self._cond:
            lane = self._lanes.get(key)
            if lane is not None:
                if len(lane) == lane.maxlen:
                    self.dropped_trusted += 1
                    self._pending_priority -= 1
                lane.append(item)
                self._pending_priority += 1
            else:
                if len(self._general) == self._general.maxlen:
                    self.dropped += 1
                self._general.append((key, item))
            self._cond.notify()

    # -- the handler's side --

    def trust(self, key: str) -> None:
        """Serve `key` first from now on (call from the handler). At most
        `max_trusted` keys; the one least recently served or trusted loses its lane."""
        with self._cond:
            if key in self._lanes:
                self._lanes.touch(key)
                return
            if len(self._lanes) == self._lanes.max_items:
                oldest = next(iter(self._lanes))
                lost = self._lanes.pop(oldest)
                if lost:
                    self._pending_priority -= len(lost)
                    self.dropped_trusted += len(lost)
            self._lanes[key] = collections.deque(maxlen=self._per_key)

    def trusted(self) -> list[str]:
        with self._cond:
            return list(self._lanes)

    def pending(self) -> int:
        with self._cond:
            return self._pending_priority + len(self._general)

    def _next(self) -> tuple[str, T] | None:
        if self._pending_priority:
            for key, lane in self._lanes.items():  # least recently served first
                if lane:
                    self._pending_priority -= 1
                    # Served: to the back of the round (touch is "most recent").
                    self._lanes.touch(key)
                    return key, lane.popleft()
        if self._general:
            return self._general.popleft()
        return None

    def _run(self) -> None:
        while True:
            with self._cond:
                item = self._next()
                while item is None:
                    if self._closed:
                        return
                    self._cond.wait()
                    item = self._next()
            try:
                self._handler(*item)
            except Exception as exc:  # one bad item must not end the worker
                self._on_error(exc)
            self.handled += 1

    def close(self, timeout: float = 2.0) -> None:
        with self._cond:
            self._closed = True
            self._general.clear()
            for lane in self._lanes.values():
                lane.clear()
            self._pending_priority = 0
            self._cond.notify()
        if threading.current_thread() is not self._thread and self._thread.is_alive():
            self._thread.join(timeout)
