"""Reopen delays for a camera that failed: exponential, capped, reset on success (pure)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class Backoff:
    """`next()` gives the delay before the next attempt: initial, x2, ... up to maximum."""

    initial_s: float = 0.5
    maximum_s: float = 10.0
    attempts: int = 0

    def next(self) -> float:
        delay = min(self.initial_s * (2.0 ** self.attempts), self.maximum_s)
        self.attempts += 1
        return delay

    def reset(self) -> None:
        self.attempts = 0
