"""A node's health report (`diagnostics/<node>`) and warnings that never flood the log."""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

from buddybot.contract import messages as m
from buddybot.runtime import limits
from buddybot.runtime.handles import Publisher

log = logging.getLogger("buddybot.node")


# --- diagnostics and rate-limited warnings -----------------------------------------


class RateLimitedLog:
    """Logs the first event of a burst, then at most one summary per period."""

    def __init__(self, logger: logging.Logger, period_s: float = 5.0) -> None:
        self._logger = logger
        self._period = period_s
        self._last: dict[str, float] = {}
        self._suppressed: collections.Counter[str] = collections.Counter()
        self._lock = threading.Lock()

    def warning(self, topic: str, text: str, *args: Any) -> None:
        now = time.monotonic()
        with self._lock:
            last = self._last.get(topic)
            if last is not None and now - last < self._period:
                self._suppressed[topic] += 1
                return
            suppressed = self._suppressed.pop(topic, 0)
            self._last[topic] = now
        suffix = f" (+{suppressed} more since last report)" if suppressed else ""
        self._logger.warning(text + suffix, *args)


class Diagnostics:
    """The node's health, published on `diagnostics/<node>` periodically and on change.

    Services set `level`/`message` with `set()` and keep counters in
    `values` (plain numbers and strings), e.g. frames, reconnects.
    """

    def __init__(self, name: str, period_s: float,
                 publisher: Publisher[m.DiagnosticStatus] | None,
                 dropped: Callable[[], Iterable[tuple[str, int]]]) -> None:
        """`name`: the node reported on. `publisher`: its `diagnostics/<node>`
        publisher, or None (probes): counters are kept but nothing is put on
        the bus, so a probe stays invisible. `dropped`: (label, count) of the
        samples each worker of the node dropped so far, read at each report."""
        self.name = name
        self._period = period_s
        self._dropped = dropped
        self._lock = threading.Lock()
        self.level: m.DiagnosticLevel = "OK"
        self.message = "running"
        self.values: dict[str, m.DiagnosticValue] = {}
        self._pub = publisher

    def set(self, level: m.DiagnosticLevel, message: str) -> None:
        """Change the status; publishes at once when it differs."""
        message = limits.clip(message)
        with self._lock:
            changed = (level, message) != (self.level, self.message)
            self.level, self.message = level, message
        if changed:
            (log.info if level == "OK" else log.warning)("status %s: %s", level, message)
            self.publish()

    def increment(self, name: str, by: int = 1) -> None:
        with self._lock:
            self.values[name] = int(self.values.get(name, 0)) + by

    def publish(self) -> None:
        if self._pub is None:
            return
        # Samples a worker dropped for newer ones ("latest" delivery: expected) or
        # because its queue was full (a handler slower than its input).
        dropped = {f"dropped {label}": n for label, n in self._dropped() if n}
        with self._lock:
            status = m.DiagnosticStatus(
                stamp_ns=m.now_ns(), node=self.name, level=self.level,
                message=self.message, values={**self.values, **dropped},
            )
        self._pub.put(status)

    def run(self, stop: threading.Event) -> None:
        while not stop.wait(self._period):
            try:
                self.publish()
            except Exception as exc:  # a closed session during shutdown
                log.debug("diagnostics publish failed: %s", exc)
