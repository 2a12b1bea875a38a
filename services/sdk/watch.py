"""Callbacks for one kind of news, each returned as a disposable.

The SDK's `on_...` calls share this: a program registers a callback and gets
a `Watch` to close (or use as a context manager); the newest value is
replayed to a callback that comes after it (the robot's latched state is
news to a program that just started); a failing callback is logged and
never stops the others.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any, Generic, TypeVar

T = TypeVar("T")

log = logging.getLogger("buddybot.sdk")


class Watch:
    """One registered callback: `close()` stops it (idempotent)."""

    def __init__(self, on_close: Callable[[Watch], None]) -> None:
        self._on_close = on_close
        self.closed = False

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._on_close(self)

    def __enter__(self) -> Watch:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Watchers(Generic[T]):
    """The callbacks of one kind of news (`what`, for the log), and its newest value."""

    def __init__(self, what: str) -> None:
        self.what = what
        self._lock = threading.Lock()
        self._callbacks: dict[Watch, Callable[[T], Any]] = {}
        self._last: tuple[T] | None = None

    def add(self, callback: Callable[[T], Any]) -> Watch:
        """Call `callback(value)` for each value from now on, first with the newest
        value if one came already."""
        watch = Watch(self._remove)
        with self._lock:
            self._callbacks[watch] = callback
            last = self._last
        if last is not None:
            self._call(callback, last[0])
        return watch

    def notify(self, value: T) -> None:
        with self._lock:
            self._last = (value,)
            callbacks = list(self._callbacks.values())
        for callback in callbacks:
            self._call(callback, value)

    def _call(self, callback: Callable[[T], Any], value: T) -> None:
        try:
            callback(value)
        except Exception:
            log.exception("%s callback %r failed on %r", self.what, callback, value)

    def _remove(self, watch: Watch) -> None:
        with self._lock:
            self._callbacks.pop(watch, None)

    def clear(self) -> None:
        with self._lock:
            self._callbacks.clear()
