"""Samples from Zenoh's threads to an asyncio loop, in bounded batches.

Handing every sample to the loop on its own (one `call_soon_threadsafe`
each) lets a flood queue callbacks faster than the loop runs them: memory
grows, pages get seconds-old data and the web server's own requests wait
behind the queue. A `LoopInbox` keeps what is pending itself (a subclass
decides how: newest per slot, a bounded list...), queues at most one
wake-up at a time, and delivers batches at least `min_interval_s` apart,
so under a flood the loop neither wakes per sample nor takes the GIL from
the thread that has to keep up with the bus. Used by the eye renderer and
the dashboard.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Callable
from typing import Generic, TypeVar

T = TypeVar("T")


class LoopInbox(Generic[T]):
    """The hand-off; subclasses add `put` methods that store under `self._lock` and
    then call `self._schedule()`, and implement `_take()` (called with the lock held)."""

    def __init__(self, loop: asyncio.AbstractEventLoop, deliver: Callable[[list[T]], None],
                 min_interval_s: float) -> None:
        self._loop = loop
        self._deliver = deliver
        self._min_interval = min_interval_s
        self._last = -1e9
        self._lock = threading.Lock()
        self._scheduled = False
        self.received = 0

    def _take(self) -> list[T]:
        """Everything pending, emptied (the lock is held)."""
        raise NotImplementedError

    def _schedule(self) -> None:
        """Queue one wake-up unless one is queued (call with the lock held)."""
        if self._scheduled:
            return
        self._scheduled = True
        with contextlib.suppress(RuntimeError):  # the loop is closing
            self._loop.call_soon_threadsafe(self._wake)

    def _wake(self) -> None:
        wait = self._last + self._min_interval - self._loop.time()
        if wait > 0:
            self._loop.call_later(wait, self._drain)
        else:
            self._drain()

    def _drain(self) -> None:
        self._last = self._loop.time()
        with self._lock:
            batch = self._take()
            self._scheduled = False
        self._deliver(batch)
