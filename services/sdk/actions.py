"""A program's actions, limited and counted on its own side.

Every action a program asks of the robot (an expression, a gaze, a sound,
a spoken text, a lease) first takes a token of one bucket per `Bot`: at
most `actions_per_s` on average, `actions_burst` at once. Over the limit
the action raises `Refused("rate limited: ...")` at once and nothing is
sent, so an app looping on actions neither blocks nor floods the bus (the
arbiter limits eyes commands per lease as well: this is the first
fence, not the only one). `actions` and `rate_limited` are counted in the
bot node's diagnostics (`diagnostics/<name>`, `buddybot echo`), whose
status turns WARN while the program runs over the limit, which the
dashboard's node table shows.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from buddybot.runtime.diagnostics import Diagnostics
from buddybot.runtime.rates import TokenBucket
from buddybot.sdk.errors import Refused

if TYPE_CHECKING:
    from buddybot.runtime.node import Node
    from buddybot.sdk.leases import LeaseTable

ACTIONS_PER_S = 20.0
"""Default sustained actions per second of one Bot."""
ACTIONS_BURST = 40.0
"""Default actions one Bot may ask at once."""
MAX_ACTIONS_PER_S = 10000.0
CALM_S = 10.0
"""The WARN status of a limited program clears at its first action this long
after its last refusal."""
LIMITED = "actions over the limit refused:"


def check_rate(actions_per_s: float, burst: float) -> tuple[float, float]:
    """(rate, burst) when the rate is in (0, MAX] and the burst in [1, MAX];
    ValueError naming the bad one."""
    def number(value: float) -> bool:
        return (not isinstance(value, bool) and isinstance(value, int | float)
                and math.isfinite(value) and value <= MAX_ACTIONS_PER_S)

    if not (number(actions_per_s) and actions_per_s > 0):
        raise ValueError(f"actions_per_s must be > 0 and <= {MAX_ACTIONS_PER_S:g}, "
                         f"not {actions_per_s!r}")
    if not (number(burst) and burst >= 1):
        raise ValueError(f"actions_burst must be >= 1 and <= {MAX_ACTIONS_PER_S:g}, "
                         f"not {burst!r}")
    return float(actions_per_s), float(burst)


class ActionLimit:
    """The token bucket of one Bot and its counters (thread-safe)."""

    def __init__(self, diagnostics: Diagnostics, actions_per_s: float = ACTIONS_PER_S,
                 burst: float = ACTIONS_BURST,
                 clock: Callable[[], float] = time.monotonic) -> None:
        rate, depth = check_rate(actions_per_s, burst)
        self.diagnostics = diagnostics
        self._clock = clock
        self._lock = threading.Lock()
        self._bucket = TokenBucket(rate, depth, clock())
        self._limited_at: float | None = None
        for name in ("actions", "rate_limited"):
            diagnostics.values.setdefault(name, 0)

    def take(self, what: str) -> None:
        """Count one action `what`; Refused("rate limited: ...") when over the limit."""
        with self._lock:
            now = self._clock()
            allowed = self._bucket.take(now)
            if not allowed:
                self._limited_at = now
            calm = self._limited_at is not None and now - self._limited_at >= CALM_S
        diag = self.diagnostics
        diag.increment("actions" if allowed else "rate_limited")
        bucket = self._bucket
        if not allowed:
            # one status per episode (set() publishes only a change), not one per refusal
            diag.set("WARN", f"{LIMITED} {bucket.rate_per_s:g} actions/s (burst "
                     f"{bucket.burst:g}): see rate_limited")
            raise Refused(f"rate limited: {what} refused, more than {bucket.rate_per_s:g} "
                          f"actions/s (burst {bucket.burst:g}) from this program")
        if calm and diag.message.startswith(LIMITED):
            diag.set("OK", "running")


class Actuator:
    """What `bot.eyes` and the speaker share: the bot's node, its leases, the
    timeout of its calls, and its action limit, taken once per action."""

    def __init__(self, node: Node, leases: LeaseTable, timeout: float,
                 limit: ActionLimit | None = None) -> None:
        self.node = node
        self.leases = leases
        self.timeout = timeout
        self.limit = limit
        """The program's action limit: one token per action."""
        self._lock = threading.Lock()

    def _take(self, what: str) -> None:
        """Count the action `what` against the limit (Refused over it)."""
        if self.limit is not None:
            self.limit.take(what)
