"""Retry delays, written once: exponential, capped, reset on success or after a stable run.

Every part of the robot that retries something (the supervisor restarting a
child, the camera reopening its source, the radar bridge reopening a serial
port, the eye renderer reopening a kiosk window) waits with the same rule, so
a flapping device is retried quickly at first and then no more often than the
cap. Pure (no clock, no sleeping): the caller measures time and waits, so the
rule is tested without processes or devices.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class Backoff:
    """`next()` gives the delay before the next attempt: initial, x factor, ... up to maximum.

    `reset()` starts the series again (the attempt worked); `after_run(ran_s)`
    does so by itself when the thing that failed had run for at least
    `stable_s` (a crash after an hour is not a crash loop).
    """

    initial_s: float = 0.5
    maximum_s: float = 10.0
    factor: float = 2.0
    stable_s: float | None = None
    """A run at least this long counts as healthy in `after_run` (None: never)."""
    attempts: int = field(default=0, init=False)
    """Delays handed out since the last reset."""

    @property
    def delay(self) -> float:
        """The delay `next()` would give, without advancing the series."""
        return min(self.initial_s * self.factor ** self.attempts, self.maximum_s)

    def next(self) -> float:
        """The delay before the next attempt; the one after it grows by `factor`."""
        delay = self.delay
        if delay < self.maximum_s:  # once capped, stop counting (no float overflow)
            self.attempts += 1
        return delay

    def reset(self) -> None:
        """The attempt worked: the next failure waits `initial_s` again."""
        self.attempts = 0

    def after_run(self, ran_s: float) -> float:
        """The delay after something that ran `ran_s` seconds and then failed."""
        if self.stable_s is not None and ran_s >= self.stable_s:
            self.reset()
        return self.next()
