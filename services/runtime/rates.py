"""Message and frame rates, written once (pure: the caller passes the clock).

Two estimates, because the places that show a rate want different things:
`rate_hz` counts arrivals in a fixed window (a sensor that stopped drops to
0 Hz once the window passes, which the `up` status line must show; `count_hz`
is the same for a count already made, as `topics` and `bag info` have), while
`span_hz` measures from the first to the last arrival (steady and exact for a
stream that is running: the camera's `fps`, `buddybot hz`). `RateCounter`
keeps the sliding window for the latter. `TokenBucket` limits a rate rather
than measuring one (a lease's eyes commands, a program's actions).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Sequence


def count_hz(count: int, window_s: float) -> float:
    """`count` arrivals over a window of `window_s` seconds, per second (0 for an
    empty window: a listener that heard nothing for no time measured nothing)."""
    return count / window_s if window_s > 0 else 0.0


def rate_hz(arrivals: Iterable[float], now: float, window_s: float = 3.0) -> float:
    """Messages per second over the last `window_s` seconds (0 when none arrived)."""
    return count_hz(sum(1 for t in arrivals if now - t <= window_s), window_s)


def span_hz(stamps: Sequence[float]) -> float | None:
    """Arrivals per second from the first stamp to the last (None with fewer than 2).

    Equal to one over the mean gap; infinite when all stamps are the same
    (a coarse clock must not raise ZeroDivisionError in a capture loop).
    """
    if len(stamps) < 2:
        return None
    span = stamps[-1] - stamps[0]
    return (len(stamps) - 1) / span if span > 0 else float("inf")


class RateCounter:
    """Arrival times over the last `window_s` seconds, and their rate (`span_hz`)."""

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self.stamps: deque[float] = deque()

    def add(self, now: float) -> float | None:
        """Record an arrival at `now`, forget those older than the window; the rate."""
        stamps = self.stamps
        stamps.append(now)
        while stamps and now - stamps[0] > self.window_s:
            stamps.popleft()
        return span_hz(stamps)


WHOLE_EPS = 1e-6
"""A token refilled to within this counts as whole: a wall clock in seconds since
1970 (a float) cannot hold the exact gap of one token's refill."""


class TokenBucket:
    """At most `rate_per_s` actions per second on average, `burst` at once.

    Full at the start; each `take(now)` spends one token if there is one
    (refilled at `rate_per_s` up to `burst` since the last take) and says
    whether it could, so the caller refuses at once instead of waiting.
    `rate_per_s` and `burst` may be changed between takes (live parameters).
    """

    def __init__(self, rate_per_s: float, burst: float, now: float) -> None:
        self.rate_per_s = rate_per_s
        self.burst = burst
        self.tokens = burst
        self._at = now

    def take(self, now: float) -> bool:
        """Spend one token at `now` (seconds, any monotonic clock); False when empty."""
        elapsed = max(0.0, now - self._at)
        self.tokens = min(self.burst, self.tokens + elapsed * self.rate_per_s)
        self._at = max(self._at, now)
        if self.tokens >= 1.0 - WHOLE_EPS:
            self.tokens = max(0.0, self.tokens - 1.0)
            return True
        return False
