"""Input limits written once: plausible stamps, bounded text, bounded tables.

Every input can be hostile or broken. One sample stamped far in the future
must not freeze a service that orders by stamp; one client inventing
thousands of sensor ids must not grow a table without end; one huge string
must not become a huge log line. These helpers are pure (no I/O, no Zenoh)
so every service applies the same rule and tests need no processes.
"""

from __future__ import annotations

import collections
from collections.abc import Iterator
from typing import Generic, TypeVar

K = TypeVar("K")
V = TypeVar("V")

STAMP_PAST_S = 10.0
"""A sensor stamp older than this (relative to arrival) is not believed."""
STAMP_FUTURE_S = 1.0
"""A stamp further ahead than this is a wrong clock or an attack."""
LOG_TEXT_MAX = 200
"""Characters of untrusted text (names, paths, errors) put in one log line."""


def stamp_plausible(
    stamp_ns: int, now_ns: int, past_s: float = STAMP_PAST_S, future_s: float = STAMP_FUTURE_S
) -> bool:
    """Whether `stamp_ns` lies in [now - past_s, now + future_s]."""
    return now_ns - int(past_s * 1e9) <= stamp_ns <= now_ns + int(future_s * 1e9)


def plausible_stamp(
    stamp_ns: int, now_ns: int, past_s: float = STAMP_PAST_S, future_s: float = STAMP_FUTURE_S
) -> tuple[int, bool]:
    """(stamp to use, replaced): an implausible stamp becomes the arrival time.

    Replacing rather than dropping keeps the data (the reading itself may be
    fine; only its clock is wrong) while making sure no stamp can hold back
    every later one in a "newest wins" comparison.
    """
    if stamp_plausible(stamp_ns, now_ns, past_s, future_s):
        return stamp_ns, False
    return now_ns, True


def clip(text: object, limit: int = LOG_TEXT_MAX) -> str:
    """`text` as a string of at most about `limit` characters, saying how much was cut."""
    value = text if isinstance(text, str) else repr(text)
    if len(value) <= limit:
        return value
    return f"{value[:limit]}... (+{len(value) - limit} chars)"


class BoundedDict(Generic[K, V]):
    """A mapping that keeps at most `max_items` entries, evicting the one
    touched least recently; `evicted` counts evictions for diagnostics.

    Used for every table keyed by something a client chooses (sensor ids,
    goal ids, page ids), so no client can make a service grow without end.
    """

    def __init__(self, max_items: int) -> None:
        if max_items < 1:
            raise ValueError("max_items must be at least 1")
        self.max_items = max_items
        self.evicted = 0
        self._data: collections.OrderedDict[K, V] = collections.OrderedDict()

    def __setitem__(self, key: K, value: V) -> None:
        if key in self._data:
            self._data.move_to_end(key)
        self._data[key] = value
        while len(self._data) > self.max_items:
            self._data.popitem(last=False)
            self.evicted += 1

    def __getitem__(self, key: K) -> V:
        return self._data[key]

    def __delitem__(self, key: K) -> None:
        del self._data[key]

    def __contains__(self, key: object) -> bool:
        return key in self._data

    def __len__(self) -> int:
        return len(self._data)

    def __iter__(self) -> Iterator[K]:
        return iter(self._data)

    def get(self, key: K, default: V | None = None) -> V | None:
        return self._data.get(key, default)

    def touch(self, key: K) -> None:
        """Mark `key` as recently used (it is evicted last)."""
        self._data.move_to_end(key)

    def pop(self, key: K, default: V | None = None) -> V | None:
        return self._data.pop(key, default)

    def items(self) -> list[tuple[K, V]]:
        return list(self._data.items())

    def values(self) -> list[V]:
        return list(self._data.values())

    def keys(self) -> list[K]:
        return list(self._data.keys())
