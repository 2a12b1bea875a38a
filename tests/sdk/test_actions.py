"""`buddybot.sdk.actions`: a Bot's action limit (pure: a fake clock, a probe-less
Diagnostics): the burst, then the rate, refused at once with the reason, counted."""

from __future__ import annotations

import contextlib
import math

import pytest

from buddybot.runtime.diagnostics import Diagnostics
from buddybot.sdk import Refused
from buddybot.sdk.actions import ActionLimit, check_rate


class Clock:
    def __init__(self) -> None:
        self.now = 50.0

    def __call__(self) -> float:
        return self.now


def _limit(rate: float, burst: float) -> tuple[ActionLimit, Diagnostics, Clock]:
    diag = Diagnostics("app", 2.0, None, lambda: [])
    clock = Clock()
    return ActionLimit(diag, rate, burst, clock=clock), diag, clock


def test_actions_over_the_limit_are_refused_at_once_and_counted() -> None:
    limit, diag, clock = _limit(rate=4.0, burst=2.0)
    assert diag.values == {"actions": 0, "rate_limited": 0}  # shown before any action
    limit.take("express")
    limit.take("play")
    with pytest.raises(Refused, match=r"rate limited: say refused, more than 4 actions/s "
                       r"\(burst 2\)"):
        limit.take("say")
    clock.now += 0.25  # one token back
    limit.take("lease")
    with pytest.raises(Refused, match="rate limited"):
        limit.take("look_at")
    assert diag.values == {"actions": 3, "rate_limited": 2}


def test_a_loop_gets_the_rate_and_no_more() -> None:
    limit, diag, clock = _limit(rate=20.0, burst=40.0)
    for _ in range(1000):  # 10 s of a loop asking every 10 ms
        with contextlib.suppress(Refused):
            limit.take("express")
        clock.now += 0.01
    assert 40 + 20 * 10 - 1 <= diag.values["actions"] <= 40 + 20 * 10 + 1
    assert diag.values["actions"] + diag.values["rate_limited"] == 1000


@pytest.mark.parametrize("rate, burst, why", [
    (0, 40, "actions_per_s"), (-1, 40, "actions_per_s"), (math.inf, 40, "actions_per_s"),
    (math.nan, 40, "actions_per_s"), (True, 40, "actions_per_s"), ("20", 40, "actions_per_s"),
    (1e9, 40, "actions_per_s"), (20, 0.5, "actions_burst"), (20, math.nan, "actions_burst"),
])
def test_an_absurd_limit_is_refused_naming_it(rate: object, burst: object, why: str) -> None:
    with pytest.raises(ValueError, match=why):
        check_rate(rate, burst)  # type: ignore[arg-type]
    assert check_rate(20, 40) == (20.0, 40.0)
